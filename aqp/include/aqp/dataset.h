#pragma once
// Reading an AQP dataset: the metadata and index (from a local file), node decoding into patch
// grids, and decoded positions (world coordinates, or the exact quantization grid coordinates:
// equal grid coordinates are bit-identical positions).
#include <array>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "aqp/format.h"
#include "common_codec/archive.h"

namespace catpaq::aqp {

// The index entry number of tile `tile` at `level` (entries are sorted by level, then tile).
size_t aqp_entry_index(const AqpMeta& meta, uint32_t tile, int level);
// Checks that `entries` are exactly one node per tile and level 0..k of `meta`, with the keys,
// levels and sample counts format.h gives. Empty string on success, else the first problem.
std::string check_aqp_index(const AqpMeta& meta, const std::vector<ArchiveEntry>& entries);

class AqpDataset {
public:
    // Opens and validates header, metadata and index; throws Error naming the file and problem.
    explicit AqpDataset(const std::string& path);
    ~AqpDataset();

    const AqpMeta& meta() const { return meta_; }
    const ArchiveReader& archive() const { return *archive_; }
    size_t patch_count() const { return meta_.patches.size(); }
    int finest_level() const { return int(meta_.patch_level); }
    // The index entry of the node (tile) holding a patch at a level (valid patch and level:
    // caller bug otherwise); its error bounds all the tile's patches.
    const ArchiveEntry& entry(uint32_t patch, int level) const;
    // Decodes a patch at a level given its decoded coarser level (levels above 0 store
    // differences from it): inflates its tile's image and unpacks the patch. Throws Error
    // naming the patch on a checksum or format problem. Thread-safe.
    PatchGrid decode(uint32_t patch, int level, const PatchGrid& coarser) const;
    // Decodes a tile's patches at a level given their decoded coarser level (coarser[q] is patch
    // first_patch + q; empty at level 0; a null pointer skips that patch, left empty). Throws
    // Error naming the tile on a checksum or format problem. Thread-safe.
    std::vector<PatchGrid> decode_tile(uint32_t tile, int level, const std::vector<const PatchGrid*>& coarser) const;
    // Every patch at `level` (index = patch), decoding each level's tiles once, coarse to fine,
    // on all cores (per patch, decode() would inflate a coarse tile once for each of its
    // patches). Throws Error as decode_tile.
    std::vector<PatchGrid> decode_level(int level) const;
    // Decodes levels 0..level of a patch, coarse to fine (what a client streams in order).
    std::vector<PatchGrid> decode_levels(uint32_t patch, int level) const;
    // Decodes one level (through all the coarser ones).
    PatchGrid decode(uint32_t patch, int level) const;

    // Quantization grid coordinates of sample `index` of `grid`.
    std::array<uint64_t, 3> grid_position(const PatchGrid& grid, size_t index) const;
    Vec3d world_position(const PatchGrid& grid, size_t index) const;

private:
    std::unique_ptr<ArchiveReader> archive_;
    AqpMeta meta_;
    std::string path_;
};

}  // namespace catpaq::aqp
