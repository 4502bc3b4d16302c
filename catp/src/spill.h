#pragma once
// Out-of-core storage of the converter (private to the catp module).
//
// - TriangleBins: input triangles (resolved to lattice positions and attributes, or as vertex
//   indices when the vertices stay in memory) sorted into spatial blocks (cubes of the lattice,
//   named by a 64-bit key), buffered in memory up to a cap, the overflow in a scratch file. A
//   block is later loaded whole, its triangles in input order.
// - FragmentSpill: the fragments of one level of the hierarchy, in memory up to a cap, the
//   overflow in a scratch file; used one group (diamond or parent) at a time.
//
// Both keep their output identical whatever the caps: only where bytes live changes.
#include <array>
#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>
#include <unordered_map>
#include <vector>

#include "base/temp_file.h"
#include "fragment_build.h"

namespace catpaq {

// A tetrahedron of the hierarchy as (diamond, slot).
struct SlotKey {
    uint64_t diamond = 0;
    int slot = 0;
    bool operator==(const SlotKey& o) const { return diamond == o.diamond && slot == o.slot; }
    bool operator<(const SlotKey& o) const { return diamond != o.diamond ? diamond < o.diamond : slot < o.slot; }
};

// One input triangle, self-contained (when the vertices do not fit in memory): 128 bytes.
struct TriangleRecord {
    std::array<Vec3d, 3> positions;   // lattice units, on the snapping grid
    std::array<Vec3f, 3> normals;     // unit
    std::array<Rgb8, 3> colors;
    // Its place among the binned triangles: a leaf larger than a block gathers its triangles
    // from several blocks, and puts them back in this order (the order a leaf inside one block
    // gets them in), so the output does not depend on the blocks.
    uint64_t sequence;
};

// One input triangle by its corners' vertex indices (when the vertices stay in memory): 16
// bytes, an eighth of a TriangleRecord. Binning 10M triangles as TriangleRecords moved 1.3 GB
// through the buffers and the scratch file, most of the binning phase's 5.9 s.
struct TriangleCorners {
    std::array<uint32_t, 3> vertices;
    uint32_t sequence;  // as TriangleRecord's (compact bins hold fewer than 2^32 triangles)
};

// Input triangles sorted into spatial blocks. Record is TriangleRecord or TriangleCorners.
template <typename Record>
class TriangleBins {
public:
    // memory_cap: bytes of buffered records before the buffers are written out.
    TriangleBins(const std::string& near_path, uint64_t memory_cap);

    // Appends a triangle to a block (created on first use). Not thread-safe.
    void add(uint64_t block, const Record& record);
    size_t block_count() const { return keys_.size(); }
    uint64_t block_key(size_t b) const { return keys_[b]; }
    uint64_t block_records(size_t b) const { return counts_[b]; }
    // Loads a block's triangles in the order they were added (and frees its buffer).
    void load(size_t b, std::vector<Record>& out);
    uint64_t bytes_spilled() const { return file_end_; }

private:
    void flush();

    std::string near_path_;
    uint64_t memory_cap_, buffered_ = 0, file_end_ = 0;
    std::unordered_map<uint64_t, uint32_t> index_;
    std::vector<uint64_t> keys_;
    std::vector<uint64_t> counts_;
    // In-memory records of each block in chunks: no regrowth copies (page faults of a doubling
    // vector were most of the binning time, measured). A block's chunks start small and double
    // up to a cap, so many blocks under a small cap do not each claim a full chunk (that made
    // flushes of tiny runs: 30 s of a 10M build at 256 MiB).
    struct Chunk {
        std::unique_ptr<Record[]> records;
        uint32_t capacity = 0, fill = 0;
    };
    static constexpr uint32_t kFirstChunkRecords = 64, kMaxChunkRecords = (1u << 20) / sizeof(Record);
    std::vector<std::vector<Chunk>> buffers_;
    size_t last_block_ = SIZE_MAX;
    std::vector<std::vector<std::pair<uint64_t, uint32_t>>> chunks_;  // file offset, records
    std::unique_ptr<TempFile> file_;
};

extern template class TriangleBins<TriangleRecord>;
extern template class TriangleBins<TriangleCorners>;

struct SpilledFragment {
    SlotKey key;
    uint32_t vertices = 0, triangles = 0;  // the fragment's size, known without loading it
    uint32_t bytes = 0;
    int64_t file_offset = -1;  // -1: in memory, at memory_index
    uint32_t memory_index = 0;
};

class FragmentSpill {
public:
    FragmentSpill(const std::string& near_path, uint64_t memory_cap);

    // Stores a fragment: kept as it is while the memory cap allows (no copy), else serialized
    // to the scratch file. Thread-safe.
    void put(const SlotKey& key, WorkFragment&& fragment);
    // The stored fragments, in the order they were put (sort as needed). Not while putting.
    std::vector<SpilledFragment>& fragments() { return index_; }
    // A stored fragment: the one in memory, or the one read from the scratch file into
    // `scratch`. Thread-safe once putting is over.
    const WorkFragment& get(const SpilledFragment& ref, WorkFragment& scratch) const;
    // Frees a fragment held in memory once it is no longer needed (each fragment is used
    // once). Thread-safe for distinct fragments once putting is over.
    void release(const SpilledFragment& ref);
    uint64_t bytes_spilled() const { return file_end_; }

private:
    std::string near_path_;
    uint64_t memory_cap_;
    std::mutex mutex_;
    std::vector<SpilledFragment> index_;
    std::vector<WorkFragment> memory_;
    uint64_t memory_bytes_ = 0;
    uint64_t file_end_ = 0;
    std::unique_ptr<TempFile> file_;
};

}  // namespace catpaq
