// Point datasets behind the format seam: the kd-tree as a Hierarchy, decoding and packing nodes,
// measuring them, their drawn geometry and what `info` says about a point dataset.
#include "points_client/points_format.h"

#include <algorithm>
#include <cmath>
#include <unordered_map>

#include "base/error.h"
#include "mesh/up_axis.h"
#include "common_codec/octahedral.h"

namespace catpaq {

namespace {

// origin + v in double, one ulp outwards: the sum rounds (by half an ulp at most), and a box
// must still hold what it held relative to the origin.
double outward(double origin, float v, int direction) {
    return std::nextafter(origin + double(v), direction * INFINITY);
}

void check_index(const PointsMeta& meta, const std::vector<ArchiveEntry>& e, const std::string& source,
                 const std::unordered_map<uint64_t, size_t>& by_key) {
    if (e.size() != meta.nodes.size())
        fail("'%s': %zu index entries but %zu node records", source.c_str(), e.size(), meta.nodes.size());
    if (!by_key.count(1)) fail("'%s': the dataset has no root node", source.c_str());
    for (size_t i = 0; i < e.size(); ++i) {
        const uint64_t key = e[i].key;
        if (key == 0 || point_node_depth(key) > kPointMaxDepth)
            fail("'%s': %llu is not a node id", source.c_str(), (unsigned long long)key);
        if (key != meta.nodes[i].key)
            fail("'%s': node record %zu is for node %llu, the index says %llu", source.c_str(), i,
                 (unsigned long long)meta.nodes[i].key, (unsigned long long)key);
        if (e[i].level != point_node_depth(key))
            fail("'%s': node %llu has level %u, its id says %d", source.c_str(), (unsigned long long)key, e[i].level,
                 point_node_depth(key));
        if (key != 1 && !by_key.count(point_node_parent(key)))
            fail("'%s': node %llu has no parent", source.c_str(), (unsigned long long)key);
        if (!(e[i].flags & kPointLeafFlag) &&
            (!by_key.count(point_node_child(key, 0)) || !by_key.count(point_node_child(key, 1))))
            fail("'%s': inner node %llu lacks a child", source.c_str(), (unsigned long long)key);
        if (e[i].count == 0) fail("'%s': node %llu holds no points", source.c_str(), (unsigned long long)key);
        const PointNodeInfo& info = meta.nodes[i];
        if (!std::isfinite(e[i].error) || e[i].error < 0 || !std::isfinite(info.mean_radius) || info.mean_radius < 0)
            fail("'%s': node %llu has an invalid error or radius", source.c_str(), (unsigned long long)key);
        for (int a = 0; a < 3; ++a)
            if (!std::isfinite(info.box_min[a]) || !std::isfinite(info.box_max[a]) || info.box_min[a] > info.box_max[a])
                fail("'%s': node %llu has an invalid box", source.c_str(), (unsigned long long)key);
    }
}

}  // namespace

Hierarchy build_points_hierarchy(const PointsMeta& meta, const std::vector<ArchiveEntry>& entries, const std::string& source) {
    std::unordered_map<uint64_t, size_t> by_key;
    for (size_t i = 0; i < entries.size(); ++i)
        if (!by_key.emplace(entries[i].key, i).second)
            fail("'%s': node %llu is in the index twice", source.c_str(), (unsigned long long)entries[i].key);
    check_index(meta, entries, source, by_key);

    Hierarchy h;
    for (size_t i = 0; i < entries.size(); ++i) {
        const ArchiveEntry& entry = entries[i];
        const PointNodeInfo& info = meta.nodes[i];
        Aabb box;
        for (int a = 0; a < 3; ++a) {
            box.min[a] = outward(meta.origin[a], info.box_min[a], -1);
            box.max[a] = outward(meta.origin[a], info.box_max[a], +1);
        }
        const double error = std::max(double(entry.error), double(info.mean_radius));
        const uint32_t n = h.add_node(entry.key, entry.level, error, box, true);
        HierarchyNode& node = h.mutable_node(n);
        node.entry = uint32_t(i);
        node.payload_offset = entry.offset;
        node.payload_bytes = entry.size;
        node.checksum = entry.checksum;
        node.flags = entry.flags;
        node.primitives = entry.count;
        node.leaf = (entry.flags & kPointLeafFlag) != 0;
    }
    for (uint32_t n = 0; n < h.size(); ++n) {
        HierarchyNode& node = h.mutable_node(n);
        HierarchyPart part;
        part.id = 0;
        part.primitives = node.primitives;
        if (node.key != 1) {
            part.parent = h.find(point_node_parent(node.key));
            h.add_parent(n, part.parent);
        }
        h.mutable_node(n).parts.push_back(part);
    }
    h.finalize();
    return h;
}

const PointsNode& points_node(const DecodedNode& node) {
    const auto* points = dynamic_cast<const PointsNode*>(&node);
    if (!points) fail("a node of another format given to the point format");
    return *points;
}

PointsFormat::PointsFormat(const DatasetPrefix& prefix) : source_(prefix.source) {
    if (prefix.header.kind != ArchiveKind::Points)
        fail("'%s': a %s dataset, not a point dataset", source_.c_str(), archive_kind_name(prefix.header.kind));
    std::string problem = decode_points_meta(prefix.meta.data(), prefix.meta.size(), meta_);
    if (!problem.empty()) fail("'%s': %s", source_.c_str(), problem.c_str());
    for (int a = 0; a < 3; ++a)
        if (!std::isfinite(meta_.origin[a])) fail("'%s': the dataset origin is not finite", source_.c_str());
    hierarchy_ = build_points_hierarchy(meta_, prefix.entries, source_);
}

std::string PointsFormat::decode(uint32_t node, const uint8_t* data, size_t size,
                                 std::shared_ptr<const DecodedNode>& out) const {
    const HierarchyNode& n = hierarchy_.node(node);
    auto decoded = std::make_shared<PointsNode>();
    // Decoded arrays live only while packing: each decoding thread reuses its own.
    thread_local DecodedPoints points;
    std::string problem = decode_point_node(data, size, points);
    if (!problem.empty()) return problem;
    if (points.count != n.primitives)
        return strprintf("node %llu holds %zu points, the index says %u", (unsigned long long)n.key, points.count, n.primitives);
    // The codec refuses non-positive steps and radius bases, so this holds for any bytes it
    // accepts; checked again because the packer's logarithmic radius scale relies on it.
    for (size_t i = 0; i < points.count; ++i)
        if (!(points.radii[i] > 0) || !std::isfinite(points.radii[i]))
            return strprintf("node %llu: splat %zu has radius %g", (unsigned long long)n.key, i, double(points.radii[i]));
    decoded->splats = pack_splats(points, meta_.origin);
    decoded->part_primitives = {uint32_t(points.count)};
    decoded->bytes.gpu = uint64_t(points.count) * decoded->splats.stride;
    // Only the packed splats stay with the node (the decoded arrays go with `points`).
    decoded->bytes.cpu = decoded->splats.halves.size() * 2;
    Aabb box;
    for (size_t i = 0; i < points.count; ++i)
        for (int a = 0; a < 3; ++a) {
            const double c = meta_.origin[a] + double(points.positions[3 * i + a]);
            box.min[a] = std::min(box.min[a], c - points.radii[i]);
            box.max[a] = std::max(box.max[a], c + points.radii[i]);
        }
    // The converter's box holds the same balls; clamping keeps rounding from leaving it.
    for (int a = 0; a < 3; ++a) {
        box.min[a] = std::clamp(box.min[a], n.bounds.min[a], n.bounds.max[a]);
        box.max[a] = std::clamp(box.max[a], n.bounds.min[a], n.bounds.max[a]);
    }
    decoded->data_bounds = box;
    out = std::move(decoded);
    return "";
}

std::optional<double> PointsFormat::data_distance(uint32_t node, const DecodedNode& decoded,
                                                  const std::array<double, 3>& eye) const {
    (void)node;
    const PackedSplats& splats = points_node(decoded).splats;
    if (splats.count == 0) return std::nullopt;
    // The eye relative to the node's grid origin, and the radius of every code, once.
    const double eye_local[3] = {eye[0] - splats.origin[0], eye[1] - splats.origin[1], eye[2] - splats.origin[2]};
    std::array<float, 32> radius_of_code;
    for (uint32_t code = 0; code < radius_of_code.size(); ++code)
        radius_of_code[code] = splats.radius_base * std::exp2(float(code) * splats.radius_log2_step);
    double best = INFINITY;
    for (size_t i = 0; i < splats.count; ++i) {
        const SplatFields f = splat_fields(splats, i);
        double d2 = 0;
        for (int a = 0; a < 3; ++a) {
            const double d = double(f.position[a]) - eye_local[a];
            d2 += d * d;
        }
        best = std::min(best, std::sqrt(d2) - double(radius_of_code[f.radius_code]));
    }
    // Rounding: a hair less than measured, never more.
    return std::max(0.0, best - std::abs(best) * 1e-9);
}

DrawnGeometry PointsFormat::drawn_geometry(const std::vector<DecodedPart>& parts, const std::array<double, 3>& eye) const {
    DrawnGeometry out;
    out.origin = eye;
    Mesh& mesh = out.mesh;
    bool all_colors = true, all_normals = true;
    for (const DecodedPart& p : parts) {
        const PackedSplats& s = points_node(*p.decoded).splats;
        all_colors &= s.has_colors;
        all_normals &= s.has_normals;
    }
    for (const DecodedPart& p : parts) {
        const PackedSplats& s = points_node(*p.decoded).splats;
        for (size_t i = 0; i < s.count; ++i) {
            const UnpackedSplat u = unpack_splat(s, i);
            Vec3d position;
            for (int a = 0; a < 3; ++a) position[a] = (s.origin[a] - eye[a]) + double(u.position[a]);
            mesh.positions.push_back(position);
            if (all_normals) mesh.normals.push_back({u.normal[0], u.normal[1], u.normal[2]});
            if (all_colors) mesh.colors.push_back({u.color[0], u.color[1], u.color[2]});
        }
    }
    return out;
}

Aabb PointsFormat::world_bounds() const {
    Aabb box;
    box.min = {meta_.bounds_min[0], meta_.bounds_min[1], meta_.bounds_min[2]};
    box.max = {meta_.bounds_max[0], meta_.bounds_max[1], meta_.bounds_max[2]};
    return box;
}

int PointsFormat::up_axis() const { return viewer_up_axis(up_axis_from_code(meta_.up_axis)); }

FormatSummary PointsFormat::summary() const {
    const PointsMeta& m = meta_;
    FormatSummary s;
    s.node_noun = "kd-tree nodes";
    s.primitive_noun = "points";
    int depth = 0;
    size_t leaves = 0;
    for (const HierarchyNode& n : hierarchy_.nodes()) {
        depth = std::max(depth, int(n.level));
        leaves += n.leaf;
    }
    s.levels_note = strprintf("deepest leaf at depth %d, %zu leaves", depth, leaves);
    s.lines.emplace_back("input", strprintf("%llu points; normals %s, colours %s, radii %s",
                                            (unsigned long long)m.input_points,
                                            (m.flags & kPointsMetaInputNormals) ? "from the input" : "estimated",
                                            (m.flags & kPointsMetaInputColors) ? "from the input" : "none",
                                            (m.flags & kPointsMetaInputRadii) ? "from the input" : "estimated"));
    double d2 = 0;
    for (int i = 0; i < 3; ++i) d2 += (m.bounds_max[i] - m.bounds_min[i]) * (m.bounds_max[i] - m.bounds_min[i]);
    s.lines.emplace_back("bounds", strprintf("[%.9g %.9g %.9g] - [%.9g %.9g %.9g]", m.bounds_min[0], m.bounds_min[1],
                                             m.bounds_min[2], m.bounds_max[0], m.bounds_max[1], m.bounds_max[2]));
    s.lines.emplace_back("diagonal", strprintf("%.9g", std::sqrt(d2)));
    s.lines.emplace_back("kd-tree", strprintf("%s split, at most %u points per node", point_split_rule_name(m.split),
                                              m.node_points));
    if (m.flags & kPointsMetaInputColors)
        s.lines.emplace_back("colours", strprintf("YCoCg, %u luma and %u chroma bits", unsigned(m.color_bits.luma),
                                                  unsigned(m.color_bits.chroma)));
    s.lines.emplace_back("up axis", up_axis_summary(up_axis_from_code(m.up_axis)));
    return s;
}

}  // namespace catpaq
