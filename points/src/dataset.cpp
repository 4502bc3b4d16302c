#include "points/dataset.h"

#include "base/error.h"

namespace catpaq {

PointDataset::PointDataset(const std::string& path) : path_(path), archive_(std::make_unique<ArchiveReader>(path)) {
    if (archive_->header().kind != ArchiveKind::Points)
        fail("'%s': a %s dataset, not a point dataset", path.c_str(), archive_kind_name(archive_->header().kind));
    const std::vector<uint8_t>& bytes = archive_->meta();
    std::string problem = decode_points_meta(bytes.data(), bytes.size(), meta_);
    if (!problem.empty()) fail("'%s': %s", path.c_str(), problem.c_str());
    const std::vector<ArchiveEntry>& e = archive_->entries();
    if (e.size() != meta_.nodes.size())
        fail("'%s': %zu index entries but %zu node records", path.c_str(), e.size(), meta_.nodes.size());
    if (e.empty() || e[0].key != 1) fail("'%s': the dataset has no root node", path.c_str());
    for (size_t i = 0; i < e.size(); ++i) {
        if (e[i].key != meta_.nodes[i].key)
            fail("'%s': node record %zu is for node %llu, the index says %llu", path.c_str(), i,
                 (unsigned long long)meta_.nodes[i].key, (unsigned long long)e[i].key);
        if (e[i].level != point_node_depth(e[i].key))
            fail("'%s': node %llu has level %u, its id says %d", path.c_str(), (unsigned long long)e[i].key, e[i].level,
                 point_node_depth(e[i].key));
        if (e[i].key != 1 && find(point_node_parent(e[i].key)) < 0)
            fail("'%s': node %llu has no parent", path.c_str(), (unsigned long long)e[i].key);
        if (!(e[i].flags & kPointLeafFlag) &&
            (find(point_node_child(e[i].key, 0)) < 0 || find(point_node_child(e[i].key, 1)) < 0))
            fail("'%s': inner node %llu lacks a child", path.c_str(), (unsigned long long)e[i].key);
    }
}

PointDataset::~PointDataset() = default;

std::string PointDataset::decode(size_t i, DecodedPoints& out) const {
    std::string error;
    const uint8_t* bytes = archive_->node(i, &error);
    if (!bytes) return error;
    const ArchiveEntry& e = archive_->entries()[i];
    std::string problem = decode_point_node(bytes, e.size, out);
    if (!problem.empty())
        return strprintf("'%s': node %llu: %s", path_.c_str(), (unsigned long long)e.key, problem.c_str());
    if (out.count != e.count)
        return strprintf("'%s': node %llu holds %zu points, the index says %u", path_.c_str(), (unsigned long long)e.key,
                         out.count, e.count);
    return "";
}

}  // namespace catpaq
