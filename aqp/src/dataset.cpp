// Reading AQP datasets (aqp/dataset.h).
#include "aqp/dataset.h"

#include "base/error.h"

namespace catpaq::aqp {

std::string check_aqp_index(const AqpMeta& meta, const std::vector<ArchiveEntry>& entries) {
    const size_t levels = size_t(meta.patch_level) + 1;
    if (entries.size() != meta.patches.size() * levels)
        return strprintf("the index has %zu nodes, %zu patches at %zu levels need %zu", entries.size(), meta.patches.size(),
                         levels, meta.patches.size() * levels);
    // The archive sorts entries by (level, key), and key = patch << 8 | level: entry
    // l * patches + p must be patch p at level l.
    for (size_t l = 0; l < levels; ++l)
        for (size_t p = 0; p < meta.patches.size(); ++p) {
            const ArchiveEntry& e = entries[l * meta.patches.size() + p];
            const size_t side = (size_t(1) << l) + 1;
            if (e.key != aqp_node_key(uint32_t(p), int(l)) || e.level != l || e.count != side * side)
                return strprintf("index entry %zu is not patch %zu at level %zu", l * meta.patches.size() + p, p, l);
            if (!(e.error >= 0)) return strprintf("patch %zu level %zu has an invalid error bound", p, l);
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
    return archive_->entries()[size_t(level) * meta_.patches.size() + patch];
}

PatchGrid AqpDataset::decode(uint32_t patch, int level, const PatchGrid& coarser) const {
    if (patch >= meta_.patches.size() || level < 0 || level > finest_level())
        fail("'%s' has no patch %u at level %d", path_.c_str(), patch, level);
    const size_t index = size_t(level) * meta_.patches.size() + patch;
    std::string error;
    const uint8_t* bytes = archive_->node(index, &error);
    if (!bytes) fail("'%s' patch %u level %d: %s", path_.c_str(), patch, level, error.c_str());
    PatchGrid grid;
    if (std::string e = decode_patch_node(bytes, archive_->entries()[index].size, patch, level, meta_.node_layout(),
                                          level > 0 ? &coarser : nullptr, grid);
        !e.empty())
        fail("'%s' patch %u level %d: %s", path_.c_str(), patch, level, e.c_str());
    return grid;
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
