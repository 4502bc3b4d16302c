#pragma once
// Reading a CATP dataset: the metadata and index (from a local file or from the bytes a client
// fetched), node decoding, and the CPU mirror of the vertex shader for whole fragments.
#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <unordered_map>
#include <vector>

#include "catp/format.h"
#include "catp/lattice.h"
#include "common_codec/archive.h"
#include "common_codec/packed_vertex.h"

namespace catpaq {

// What a client knows after loading the prefix (header, meta, index) of a dataset.
class CatpIndex {
public:
    // Parses and validates; throws Error naming `source` on a problem.
    CatpIndex(const ArchiveHeader& header, std::vector<uint8_t> meta, std::vector<ArchiveEntry> entries,
              const std::string& source);
    // Parses the prefix bytes (at least ArchiveReader::prefix_size() bytes of the file).
    static CatpIndex from_prefix(const uint8_t* data, size_t size, const std::string& source);

    const ArchiveHeader& header() const { return header_; }
    const CatpMeta& meta() const { return meta_; }
    const std::vector<ArchiveEntry>& entries() const { return entries_; }
    // Entry of a diamond, or nullptr if the diamond holds no geometry (absent from the index).
    const ArchiveEntry* find(DiamondId id) const;
    size_t entry_index(const ArchiveEntry* e) const { return size_t(e - entries_.data()); }
    // True when the dataset has a slot table (meta version 3): slot fragments can be fetched
    // on their own.
    bool has_slot_ranges() const { return !slot_offsets_.empty(); }
    // The file byte range of slot `slot`'s fragment in entry `entry_index` (which must have the
    // slot in its mask); false without a slot table.
    bool slot_range(size_t entry_index, int slot, uint64_t& offset, uint32_t& size) const;

    // World position of a lattice point.
    void lattice_to_world(const double lattice[3], double world[3]) const;
    double world_per_lattice() const { return meta_.cell; }

private:
    ArchiveHeader header_;
    CatpMeta meta_;
    std::vector<ArchiveEntry> entries_;
    std::unordered_map<uint64_t, size_t> by_key_;
    // With a slot table: per entry, 8 file offsets (0 for absent slots); sizes in the meta.
    std::vector<std::array<uint64_t, 8>> slot_offsets_;
    std::vector<std::array<uint32_t, 8>> slot_sizes_;
};

// A local dataset file: the index plus memory-mapped node bytes.
class CatpFile {
public:
    explicit CatpFile(const std::string& path);  // throws Error
    const CatpIndex& index() const { return *index_; }
    const ArchiveReader& archive() const { return *archive_; }
    // Decodes a diamond's node; throws Error on a checksum or format problem.
    DiamondFragments decode(const ArchiveEntry& entry) const;

private:
    std::unique_ptr<ArchiveReader> archive_;
    std::unique_ptr<CatpIndex> index_;
};

// The vertex shader's inputs for slot `slot` of `diamond` in a dataset: the slot's canonical
// corners minus `anchor`, the dataset's layout and default colour, and the scale for positions in
// a frame whose unit is `cell_in_frame` lattice cells' worth (meta.cell for world units).
VertexDecodeParams slot_decode_params(const CatpMeta& meta, const DiamondInfo& diamond, int slot,
                                      const LatticePoint& anchor, double cell_in_frame);

// Decodes a fragment's positions exactly as the vertex shader does (see
// common_codec/barycentric.h), appending them as xyz floats. Returns false if a vertex is corrupt.
bool decode_fragment_positions(const FragmentMesh& fragment, const VertexDecodeParams& params,
                               std::vector<float>& positions_out);

// The exact integer position (sum w_i C_i, i.e. the grid times the lattice position) of every
// vertex (in the fragment's layout): identical integers mean bit-identical decoded positions in
// every frame.
bool decode_fragment_integer_positions(const FragmentMesh& fragment, const DiamondInfo& diamond, int slot,
                                       std::vector<std::array<int64_t, 3>>& out);

}  // namespace catpaq
