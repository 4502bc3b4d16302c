// Reading AQP datasets (aqp/dataset.h).
#include "aqp/dataset.h"

#include <tbb/parallel_for.h>

#include "base/error.h"

namespace catpaq::aqp {

size_t aqp_entry_index(const AqpMeta& meta, uint32_t tile, int level) {
    size_t index = tile;
    for (int l = 0; l < level; ++l) index += meta.tile_count(l);
    return index;
}

std::string check_aqp_index(const AqpMeta& meta, const std::vector<ArchiveEntry>& entries) {
    const int levels = int(meta.patch_level) + 1;
    size_t nodes = 0;
    for (int l = 0; l < levels; ++l) nodes += meta.tile_count(l);
    if (entries.size() != nodes)
        return strprintf("the index has %zu nodes, %zu patches at %d levels in tiles need %zu", entries.size(),
                         meta.patches.size(), levels, nodes);
    // The archive sorts entries by (level, key), and key = tile << 8 | level: entry
    // aqp_entry_index(t, l) must be tile t at level l.
    size_t i = 0;
    for (int l = 0; l < levels; ++l)
        for (uint32_t t = 0; t < meta.tile_count(l); ++t, ++i) {
            const ArchiveEntry& e = entries[i];
            const size_t side = (size_t(1) << l) + 1;
            if (e.key != aqp_node_key(t, l) || e.level != l || e.count != side * side * meta.tile_patches(t, l))
                return strprintf("index entry %zu is not tile %u at level %d", i, t, l);
            if (!(e.error >= 0)) return strprintf("tile %u level %d has an invalid error bound", t, l);
        }
    return "";
}

AqpDataset::AqpDataset(const std::string& path) : path_(path) {
    archive_ = std::make_unique<ArchiveReader>(path);
    if (archive_->header().kind != ArchiveKind::Aqp)
        fail("'%s' is a %s dataset, not AQP", path.c_str(), archive_kind_name(archive_->header().kind));
    const std::vector<uint8_t>& meta = archive_->meta();
    if (std::string e = decode_aqp_meta(meta.data(), meta.size(), meta_); !e.empty())
        fail("'%s': %s", path.c_str(), e.c_str());
    if (std::string e = check_aqp_index(meta_, archive_->entries()); !e.empty()) fail("'%s': %s", path.c_str(), e.c_str());
}

AqpDataset::~AqpDataset() = default;

const ArchiveEntry& AqpDataset::entry(uint32_t patch, int level) const {
    return archive_->entries()[aqp_entry_index(meta_, meta_.tile_of(patch, level), level)];
}

std::vector<PatchGrid> AqpDataset::decode_tile(uint32_t tile, int level, const std::vector<const PatchGrid*>& coarser) const {
    if (level < 0 || level > finest_level() || tile >= meta_.tile_count(level))
        fail("'%s' has no tile %u at level %d", path_.c_str(), tile, level);
    const size_t index = aqp_entry_index(meta_, tile, level);
    std::string error;
    const uint8_t* bytes = archive_->node(index, &error);
    if (!bytes) fail("'%s' tile %u level %d: %s", path_.c_str(), tile, level, error.c_str());
    std::vector<PatchGrid> grids;
    if (std::string e = decode_tile_node(bytes, archive_->entries()[index].size, meta_.first_patch(tile, level),
                                         meta_.tile_patches(tile, level), level, meta_.node_layout(), coarser, grids,
                                         level == 0 ? meta_.tile_patch_info(tile, 0) : TilePatches{});
        !e.empty())
        fail("'%s' tile %u level %d: %s", path_.c_str(), tile, level, e.c_str());
    return grids;
}

PatchGrid AqpDataset::decode(uint32_t patch, int level, const PatchGrid& coarser) const {
    if (patch >= meta_.patches.size() || level < 0 || level > finest_level())
        fail("'%s' has no patch %u at level %d", path_.c_str(), patch, level);
    const uint32_t tile = meta_.tile_of(patch, level), first = meta_.first_patch(tile, level);
    // The tile's image, unpacking only this patch.
    std::vector<const PatchGrid*> coarser_grids;
    if (level > 0) {
        coarser_grids.assign(meta_.tile_patches(tile, level), nullptr);
        coarser_grids[patch - first] = &coarser;
    }
    try {
        return std::move(decode_tile(tile, level, coarser_grids)[patch - first]);
    } catch (const Error& e) {
        fail("patch %u level %d: %s", patch, level, e.what());
    }
}

std::vector<PatchGrid> AqpDataset::decode_level(int level) const {
    if (level < 0 || level > finest_level()) fail("'%s' has no level %d", path_.c_str(), level);
    std::vector<PatchGrid> grids;  // every patch at level l - 1, then l
    for (int l = 0; l <= level; ++l) {
        std::vector<PatchGrid> next(patch_count());
        tbb::parallel_for(uint32_t(0), meta_.tile_count(l), [&](uint32_t tile) {
            const uint32_t first = meta_.first_patch(tile, l), count = meta_.tile_patches(tile, l);
            std::vector<const PatchGrid*> coarser;
            for (uint32_t p = first; l > 0 && p < first + count; ++p) coarser.push_back(&grids[p]);
            std::vector<PatchGrid> decoded = decode_tile(tile, l, coarser);
            for (uint32_t q = 0; q < count; ++q) next[first + q] = std::move(decoded[q]);
        });
        grids.swap(next);
    }
    return grids;
}

std::vector<PatchGrid> AqpDataset::decode_levels(uint32_t patch, int level) const {
    std::vector<PatchGrid> levels;
    PatchGrid none;
    for (int l = 0; l <= level; ++l) levels.push_back(decode(patch, l, l > 0 ? levels.back() : none));
    return levels;
}

PatchGrid AqpDataset::decode(uint32_t patch, int level) const {
    if (level < 0 || level > finest_level()) fail("'%s' has no patch %u at level %d", path_.c_str(), patch, level);
    return std::move(decode_levels(patch, level).back());
}

std::array<uint64_t, 3> AqpDataset::grid_position(const PatchGrid& grid, size_t index) const {
    const AqpPatchInfo& p = meta_.patches[grid.patch];
    return {uint64_t(p.origin[0]) + grid.position[index][0], uint64_t(p.origin[1]) + grid.position[index][1],
            uint64_t(p.origin[2]) + grid.position[index][2]};
}

Vec3d AqpDataset::world_position(const PatchGrid& grid, size_t index) const {
    Vec3d out;
    for (int a = 0; a < 3; ++a) out[a] = meta_.world(grid.patch, a, grid.position[index][a]);
    return out;
}

}  // namespace catpaq::aqp
