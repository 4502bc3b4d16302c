// AQP behind the format seam: the (tile, level) hierarchy, decoding tiles against their coarser
// level, measuring them, their drawn (stitched) geometry and what `info` says.
#include "aqp_client/aqp_format.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "aqp/dataset.h"
#include "aqp_client/stitch.h"
#include "base/error.h"
#include "mesh/up_axis.h"
#include "common_codec/octahedral.h"

namespace catpaq {

namespace {

using aqp::AqpMeta;
using aqp::PatchGrid;

// The largest coordinate, per axis, of any sample on the quantization grid.
std::array<uint64_t, 3> grid_extent(const AqpMeta& meta) {
    std::array<uint64_t, 3> out{0, 0, 0};
    for (const aqp::AqpPatchInfo& p : meta.patches)
        for (int a = 0; a < 3; ++a) out[size_t(a)] = std::max(out[size_t(a)], uint64_t(p.origin[size_t(a)]) + p.extent[size_t(a)]);
    return out;
}

// The squared distance from p to triangle abc (Ericson, Real-Time Collision Detection 5.1.5).
double point_triangle_distance2(const Vec3d& p, const Vec3d& a, const Vec3d& b, const Vec3d& c) {
    auto sub = [](const Vec3d& x, const Vec3d& y) { return Vec3d{x[0] - y[0], x[1] - y[1], x[2] - y[2]}; };
    auto dot = [](const Vec3d& x, const Vec3d& y) { return x[0] * y[0] + x[1] * y[1] + x[2] * y[2]; };
    auto at = [&](const Vec3d& x) { const Vec3d d = sub(p, x); return dot(d, d); };
    const Vec3d ab = sub(b, a), ac = sub(c, a), ap = sub(p, a);
    const double d1 = dot(ab, ap), d2 = dot(ac, ap);
    if (d1 <= 0 && d2 <= 0) return at(a);
    const Vec3d bp = sub(p, b);
    const double d3 = dot(ab, bp), d4 = dot(ac, bp);
    if (d3 >= 0 && d4 <= d3) return at(b);
    const double vc = d1 * d4 - d3 * d2;
    if (vc <= 0 && d1 >= 0 && d3 <= 0) {
        const double v = d1 / (d1 - d3);
        return at({a[0] + v * ab[0], a[1] + v * ab[1], a[2] + v * ab[2]});
    }
    const Vec3d cp = sub(p, c);
    const double d5 = dot(ab, cp), d6 = dot(ac, cp);
    if (d6 >= 0 && d5 <= d6) return at(c);
    const double vb = d5 * d2 - d1 * d6;
    if (vb <= 0 && d2 >= 0 && d6 <= 0) {
        const double w = d2 / (d2 - d6);
        return at({a[0] + w * ac[0], a[1] + w * ac[1], a[2] + w * ac[2]});
    }
    const double va = d3 * d6 - d5 * d4;
    if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
        const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return at({b[0] + w * (c[0] - b[0]), b[1] + w * (c[1] - b[1]), b[2] + w * (c[2] - b[2])});
    }
    const double denom = 1 / (va + vb + vc), v = vb * denom, w = vc * denom;
    return at({a[0] + ab[0] * v + ac[0] * w, a[1] + ab[1] * v + ac[1] * w, a[2] + ab[2] * v + ac[2] * w});
}

}  // namespace

Hierarchy build_aqp_hierarchy(const AqpMeta& meta, const std::vector<ArchiveEntry>& entries) {
    if (std::string e = aqp::check_aqp_index(meta, entries); !e.empty()) fail("%s", e.c_str());
    Hierarchy h;
    // Entries are sorted by (level, key) = (level, tile) (check_aqp_index), and nodes are added
    // in that order, so node index = entry index = aqp_entry_index(tile, level).
    for (size_t e = 0; e < entries.size(); ++e) {
        const ArchiveEntry& entry = entries[e];
        const uint32_t tile = aqp::aqp_key_tile(entry.key);
        const int level = aqp::aqp_key_level(entry.key);
        const double error = std::isfinite(entry.error) ? std::max(0.0, double(entry.error)) : -1.0;
        if (error < 0) fail("index entry %zu has a bad error bound", e);
        const uint32_t first = meta.first_patch(tile, level), count = meta.tile_patches(tile, level);
        Aabb box;
        for (uint32_t p = first; p < first + count; ++p) box.extend(aqp_patch_box(meta, p));
        const uint32_t n = h.add_node(entry.key, uint16_t(level), error, box, true);
        HierarchyNode& node = h.mutable_node(n);
        node.entry = uint32_t(e);
        node.payload_offset = entry.offset;
        node.payload_bytes = entry.size;
        node.checksum = entry.checksum;
        node.flags = entry.flags;
        node.primitives = count * (uint32_t(2) << (2 * level));  // 2 (n - 1)^2 grid triangles, n - 1 = 2^level
        HierarchyPart part;
        part.id = 0;
        part.primitives = node.primitives;
        if (level > 0) {
            const uint32_t parent = uint32_t(aqp::aqp_entry_index(meta, meta.tile_of(first, level - 1), level - 1));
            h.add_parent(n, parent);
            part.parent = parent;
            node.decode_parent = parent;
        }
        node.parts.push_back(part);
    }
    h.finalize();
    return h;
}

Aabb aqp_patch_box(const AqpMeta& meta, uint32_t patch) {
    Aabb box;
    const aqp::AqpPatchInfo& p = meta.patches[patch];
    for (int a = 0; a < 3; ++a) {
        box.min[size_t(a)] = meta.world(patch, a, 0);
        box.max[size_t(a)] = meta.world(patch, a, p.extent[size_t(a)]);
    }
    return box;
}

const std::vector<PatchGrid>& aqp_grids(const DecodedNode& node) {
    const auto* a = dynamic_cast<const AqpNode*>(&node);
    if (!a) fail("a node of another format given to AQP");
    return a->grids;
}

uint64_t aqp_gpu_bytes(int level, bool colors) {
    const uint64_t side = (uint64_t(1) << level) + 1;
    return side * side * (colors ? 12 : 8);
}

std::array<int64_t, 3> aqp_frame_anchor(const AqpMeta& meta, const std::array<double, 3>& eye) {
    const std::array<uint64_t, 3> extent = grid_extent(meta);
    std::array<int64_t, 3> anchor{0, 0, 0};
    for (int a = 0; a < 3; ++a) {
        double g = std::nearbyint((eye[size_t(a)] - meta.origin[a]) / meta.step);
        if (!(g >= 0)) g = 0;  // also NaN
        if (g > double(extent[size_t(a)])) g = double(extent[size_t(a)]);
        anchor[size_t(a)] = int64_t(g);
    }
    return anchor;
}

AqpFormat::AqpFormat(const DatasetPrefix& prefix) {
    if (std::string e = aqp::decode_aqp_meta(prefix.meta.data(), prefix.meta.size(), meta_); !e.empty())
        fail("'%s': AQP metadata: %s", prefix.source.c_str(), e.c_str());
    // Positions relative to the frame's anchor go to the GPU as 32-bit integers.
    for (uint64_t e : grid_extent(meta_))
        if (e >= (uint64_t(1) << 31))
            fail("'%s': the quantization grid spans %llu steps, more than the renderer's 2^31", prefix.source.c_str(),
                 (unsigned long long)e);
    try {
        hierarchy_ = build_aqp_hierarchy(meta_, prefix.entries);
    } catch (const Error& e) {
        fail("'%s': %s", prefix.source.c_str(), e.what());
    }
}

std::string AqpFormat::node_tile_level(uint32_t node, uint32_t& tile, int& level) const {
    if (node >= hierarchy_.size()) return "no such node";
    const uint64_t key = hierarchy_.node(node).key;
    tile = aqp::aqp_key_tile(key);
    level = aqp::aqp_key_level(key);
    return "";
}

std::string AqpFormat::decode(uint32_t node, const uint8_t* data, size_t size, std::shared_ptr<const DecodedNode>& out) const {
    uint32_t tile = 0;
    int level = 0;
    if (std::string e = node_tile_level(node, tile, level); !e.empty()) return e;
    if (level > 0)
        return strprintf("tile %u level %d is stored as a difference from level %d, which was not given", tile, level,
                         level - 1);
    auto decoded = std::make_shared<AqpNode>();
    if (std::string e = aqp::decode_tile_node(data, size, meta_.first_patch(tile, 0), meta_.tile_patches(tile, 0), 0,
                                              meta_.node_layout(), {}, decoded->grids, meta_.tile_patch_info(tile, 0));
        !e.empty())
        return e;
    account(*decoded);
    out = std::move(decoded);
    return "";
}

std::string AqpFormat::decode_with_parent(uint32_t node, const DecodedNode& parent, const uint8_t* data, size_t size,
                                          std::shared_ptr<const DecodedNode>& out) const {
    uint32_t tile = 0;
    int level = 0;
    if (std::string e = node_tile_level(node, tile, level); !e.empty()) return e;
    const auto* coarser = dynamic_cast<const AqpNode*>(&parent);
    const uint32_t first = meta_.first_patch(tile, level), count = meta_.tile_patches(tile, level);
    // The parent tile holds this tile's patches, one level down.
    std::vector<const PatchGrid*> coarser_grids;
    if (level > 0 && coarser && !coarser->grids.empty() && coarser->grids[0].level == level - 1 &&
        coarser->grids[0].patch <= first && first + count <= coarser->grids[0].patch + coarser->grids.size())
        for (uint32_t p = first; p < first + count; ++p) coarser_grids.push_back(&coarser->grids[p - coarser->grids[0].patch]);
    if (coarser_grids.empty())
        return strprintf("tile %u level %d: the parent given is not the tile holding its patches one level down", tile, level);
    auto decoded = std::make_shared<AqpNode>();
    if (std::string e = aqp::decode_tile_node(data, size, first, count, level, meta_.node_layout(), coarser_grids, decoded->grids);
        !e.empty())
        return e;
    account(*decoded);
    out = std::move(decoded);
    return "";
}

void AqpFormat::account(AqpNode& node) const {
    node.bytes = {};
    uint32_t primitives = 0;
    for (const PatchGrid& g : node.grids) {
        node.bytes.cpu += g.position.size() * sizeof(g.position[0]) + g.normal.size() * sizeof(g.normal[0]) +
                          g.color.size() * sizeof(g.color[0]);
        node.bytes.gpu += aqp_gpu_bytes(g.level, meta_.has_colors());
        primitives += uint32_t(2 * (g.size - 1) * (g.size - 1));
        // The box of the samples, clamped to the patch's box (the hierarchy's): a corrupt sample
        // beyond the extent must not make data_bounds leave it (the converter guarantees it does not).
        std::array<uint16_t, 3> lo{65535, 65535, 65535}, hi{0, 0, 0};
        for (const auto& p : g.position)
            for (int a = 0; a < 3; ++a) {
                lo[size_t(a)] = std::min(lo[size_t(a)], p[size_t(a)]);
                hi[size_t(a)] = std::max(hi[size_t(a)], p[size_t(a)]);
            }
        const aqp::AqpPatchInfo& info = meta_.patches[g.patch];
        Aabb box;
        for (int a = 0; a < 3; ++a) {
            const uint16_t top = info.extent[size_t(a)];
            box.min[size_t(a)] = meta_.world(g.patch, a, std::min(lo[size_t(a)], top));
            box.max[size_t(a)] = meta_.world(g.patch, a, std::min(hi[size_t(a)], top));
        }
        node.data_bounds.extend(box);
    }
    node.part_primitives = {primitives};
}

std::optional<double> AqpFormat::data_distance(uint32_t node, const DecodedNode& decoded, const std::array<double, 3>& eye) const {
    (void)node;
    double best = std::numeric_limits<double>::infinity();
    for (const PatchGrid& g : aqp_grids(decoded)) best = std::min(best, grid_distance(g, eye));
    if (!std::isfinite(best)) return std::nullopt;
    // A hair less than measured, never more (rounding).
    return std::max(0.0, best * (1 - 1e-9) - meta_.step * 1e-6);
}

double AqpFormat::grid_distance(const PatchGrid& g, const std::array<double, 3>& eye) const {
    const int n = g.size;
    if (n < 2) return std::numeric_limits<double>::infinity();
    auto world = [&](int i, int j) {
        const auto& q = g.position[g.index(i, j)];
        return Vec3d{meta_.world(g.patch, 0, q[0]), meta_.world(g.patch, 1, q[1]), meta_.world(g.patch, 2, q[2])};
    };
    double best2 = std::numeric_limits<double>::infinity();
    // Cells off the border ring are drawn as they are.
    for (int j = 1; j + 2 < n; ++j)
        for (int i = 1; i + 2 < n; ++i) {
            const Vec3d a = world(i, j), b = world(i + 1, j), c = world(i + 1, j + 1), d = world(i, j + 1);
            best2 = std::min({best2, point_triangle_distance2(eye, a, b, c), point_triangle_distance2(eye, a, c, d)});
        }
    // The border ring: a stitched triangle there joins samples of the first two rows along one
    // edge, or near a corner of the two edges meeting there (a sample of the second row can be
    // snapped along the perpendicular edge), so it lies in the box of those rows.
    auto strip_box = [&](int e, Aabb& box) {
        for (int t = 0; t < n; ++t)
            for (int r = 0; r < std::min(2, n); ++r) {
                const int i = e == 0 || e == 2 ? t : (e == 1 ? n - 1 - r : r);
                const int j = e == 1 || e == 3 ? t : (e == 0 ? r : n - 1 - r);
                box.extend(world(i, j));
            }
    };
    std::array<Aabb, 4> strips;
    for (int e = 0; e < 4; ++e) strip_box(e, strips[size_t(e)]);
    for (int e = 0; e < 4; ++e) {
        Aabb corner = strips[size_t(e)];
        corner.extend(strips[size_t((e + 1) % 4)]);
        const double d = corner.distance_to(eye);
        best2 = std::min(best2, d * d);
    }
    return std::sqrt(best2);
}

DrawnGeometry AqpFormat::drawn_geometry(const std::vector<DecodedPart>& parts, const std::array<double, 3>& eye) const {
    const std::array<int64_t, 3> anchor = aqp_frame_anchor(meta_, eye);
    DrawnGeometry out;
    for (int a = 0; a < 3; ++a) out.origin[size_t(a)] = meta_.origin[a] + double(anchor[size_t(a)]) * meta_.step;
    // Every drawn patch's level, for the edge levels.
    std::vector<int> drawn_level(meta_.patches.size(), -1);
    std::vector<const PatchGrid*> grids;
    for (const DecodedPart& p : parts) {
        const auto* node = dynamic_cast<const AqpNode*>(p.decoded);
        if (!node) continue;
        for (const PatchGrid& g : node->grids) {
            if (g.patch >= meta_.patches.size()) continue;
            drawn_level[g.patch] = std::max(drawn_level[g.patch], g.level);
            grids.push_back(&g);
        }
    }
    const float step = float(meta_.step);
    Mesh& mesh = out.mesh;
    for (const PatchGrid* g : grids) {
        if (drawn_level[g->patch] != g->level) continue;  // the patch drawn twice: its finer level wins
        const std::array<int, 4> edges = edge_levels(meta_, g->patch, g->level, [&](uint32_t q) { return drawn_level[q]; });
        const aqp::AqpPatchInfo& info = meta_.patches[g->patch];
        const uint32_t base = uint32_t(mesh.positions.size());
        for (size_t s = 0; s < g->position.size(); ++s) {
            // As the vertex shader: the integer offset from the anchor, then one float multiply.
            Vec3d p;
            for (int a = 0; a < 3; ++a) {
                const int32_t d = int32_t(int64_t(info.origin[size_t(a)]) + g->position[s][size_t(a)] - anchor[size_t(a)]);
                p[size_t(a)] = double(float(d) * step);
            }
            mesh.positions.push_back(p);
            float normal[3];
            oct_decode(g->normal[s], normal);
            mesh.normals.push_back({normal[0], normal[1], normal[2]});
            if (meta_.has_colors()) mesh.colors.push_back(g->color[s]);
        }
        for (uint32_t v : stitched_triangles(g->level, edges)) mesh.indices.push_back(base + v);
    }
    return out;
}

Aabb AqpFormat::world_bounds() const {
    Aabb box;
    box.min = {meta_.bounds_min[0], meta_.bounds_min[1], meta_.bounds_min[2]};
    box.max = {meta_.bounds_max[0], meta_.bounds_max[1], meta_.bounds_max[2]};
    return box;
}

int AqpFormat::up_axis() const { return viewer_up_axis(up_axis_from_code(meta_.up_axis)); }

FormatSummary AqpFormat::summary() const {
    const AqpMeta& m = meta_;
    FormatSummary s;
    s.node_noun = "tiles";
    s.primitive_noun = "samples";
    s.levels_note = strprintf("finest level %u: patches of %u x %u samples", m.patch_level, (1u << m.patch_level) + 1,
                              (1u << m.patch_level) + 1);
    s.lines.emplace_back("input", strprintf("%llu vertices, %llu triangles; colours %s", (unsigned long long)m.input_vertices,
                                            (unsigned long long)m.input_triangles, m.has_colors() ? "from the input" : "none"));
    s.lines.emplace_back("domain", strprintf("%zu quad patches over %u base triangles (%u base vertices, %u border edges)",
                                             m.patches.size(), m.base_triangles, m.base_vertices, m.border_edges));
    std::string tiles;
    for (int l = 0; l <= int(m.patch_level); ++l)
        tiles += strprintf("%s%u", l ? " " : "", 1u << (2 * m.shift(l)));
    s.lines.emplace_back("tiles", "patches per tile by level, coarse to fine: " + tiles);
    double d2 = 0;
    for (int i = 0; i < 3; ++i) d2 += (m.bounds_max[i] - m.bounds_min[i]) * (m.bounds_max[i] - m.bounds_min[i]);
    s.lines.emplace_back("bounds", strprintf("[%.9g %.9g %.9g] - [%.9g %.9g %.9g]", m.bounds_min[0], m.bounds_min[1],
                                             m.bounds_min[2], m.bounds_max[0], m.bounds_max[1], m.bounds_max[2]));
    s.lines.emplace_back("diagonal", strprintf("%.9g", std::sqrt(d2)));
    std::string precision = strprintf("%.6g (step %.6g)", m.precision, m.step);
    if (m.mean_edge > 0) precision += strprintf(", %.3g mean input edges of %.6g", m.precision / m.mean_edge, m.mean_edge);
    s.lines.emplace_back("precision", precision);
    s.lines.emplace_back("up axis", up_axis_summary(up_axis_from_code(m.up_axis)));
    return s;
}

}  // namespace catpaq
