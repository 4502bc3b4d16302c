// CATP behind the format seam: decoding diamonds, measuring them, their drawn geometry and what
// `info` says about a CATP dataset.
#include "catp_client/catp_format.h"

#include <algorithm>
#include <cmath>

#include "base/error.h"
#include "catp/distance.h"
#include "catp/lattice.h"
#include "common_codec/packed_vertex.h"

namespace catpaq {

const DiamondFragments& catp_fragments(const DecodedNode& node) {
    const auto* catp = dynamic_cast<const CatpNode*>(&node);
    if (!catp) fail("a node of another format given to CATP");
    return catp->fragments;
}

LatticePoint catp_frame_anchor(const CatpMeta& meta, const std::array<double, 3>& eye) {
    LatticePoint anchor{};
    for (int i = 0; i < 3; ++i) {
        double l = std::nearbyint((eye[size_t(i)] - meta.origin[i]) / meta.cell);
        if (!(l >= 0)) l = 0;  // also NaN
        if (l > kLatticeSize) l = kLatticeSize;
        anchor[size_t(i)] = int32_t(l);
    }
    return anchor;
}

CatpFormat::CatpFormat(const DatasetPrefix& prefix)
    : index_(prefix.header, prefix.meta, prefix.entries, prefix.source), hierarchy_(build_catp_hierarchy(index_)) {}

std::string CatpFormat::decode(uint32_t node, const uint8_t* data, size_t size,
                               std::shared_ptr<const DecodedNode>& out) const {
    auto decoded = std::make_shared<CatpNode>();
    std::string problem = decode_diamond_node(data, size, meta().layout, decoded->fragments);
    if (!problem.empty()) return problem;
    account(hierarchy_.node(node), *decoded);
    out = std::move(decoded);
    return "";
}

std::string CatpFormat::decode_part(uint32_t node, size_t part, const uint8_t* data, size_t size,
                                    std::shared_ptr<const DecodedNode>& out) const {
    const HierarchyNode& n = hierarchy_.node(node);
    if (!n.fetch_parts || part >= n.parts.size()) return "no such part";
    const int slot = n.parts[part].id;
    auto decoded = std::make_shared<CatpNode>();
    FragmentMesh& fragment = decoded->fragments.slots[size_t(slot)];
    const FragmentStatus status = fragment_decode(data, size, fragment);
    if (status != FragmentStatus::Ok) return strprintf("slot %d: fragment %s", slot, fragment_status_name(status));
    if (fragment.layout != meta().layout)
        return strprintf("slot %d: fragment in the %s layout with grid %d, the dataset's is %s with grid %d", slot,
                         fragment.layout.name(), fragment.layout.grid, meta().layout.name(), meta().layout.grid);
    decoded->fragments.slot_mask = uint8_t(1u << slot);
    account(n, *decoded);
    out = std::move(decoded);
    return "";
}

void CatpFormat::account(const HierarchyNode& n, CatpNode& decoded) const {
    for (const HierarchyPart& part : n.parts) {
        const FragmentMesh& fragment = decoded.fragments.slots[part.id];
        decoded.part_primitives.push_back(uint32_t(fragment.triangle_count()));
        decoded.bytes.cpu += fragment.vertices.size() * sizeof(PackedVertex) + fragment.indices.size() * 4;
        if (fragment.indices.empty()) continue;  // FragmentStore::upload is not called for it
        decoded.bytes.gpu += fragment.vertices.size() * sizeof(PackedVertex) +
                             fragment.indices.size() * (fragment.vertices.size() < 65536 ? 2 : 4);
    }
    decoded.data_bounds = data_bounds(n, decoded.fragments);
}

// The box of a node's decoded vertices (world): where its geometry really is, for the cut
// engine's projected errors (the hierarchy's box also covers the descendants).
Aabb CatpFormat::data_bounds(const HierarchyNode& node, const DiamondFragments& fragments) const {
    const CatpMeta& meta = index_.meta();
    Aabb box;
    std::vector<std::array<int64_t, 3>> exact;
    DiamondInfo info = diamond_info(DiamondId{node.key});
    for (const HierarchyPart& part : node.parts) {
        const FragmentMesh& fragment = fragments.slots[part.id];
        if (fragment.indices.empty() || !decode_fragment_integer_positions(fragment, info, int(part.id), exact)) continue;
        for (const auto& p : exact) {
            std::array<double, 3> world;
            for (int k = 0; k < 3; ++k) world[k] = meta.origin[k] + double(p[k]) / meta.layout.grid * meta.cell;
            box.extend(world);
        }
    }
    if (box.empty()) return box;
    // Rounding: a hair larger, never smaller, than the decoded positions.
    double slack = meta.cell * 1e-6;
    for (int k = 0; k < 3; ++k) {
        box.min[k] -= slack + std::abs(box.min[k]) * 1e-12;
        box.max[k] += slack + std::abs(box.max[k]) * 1e-12;
    }
    return box;
}

// The distance from the eye to the triangles of a resident node (all its parts: a superset of
// what it draws), measured on the CPU from the decoded vertices.
std::optional<double> CatpFormat::data_distance(uint32_t node, const DecodedNode& decoded,
                                                const std::array<double, 3>& eye) const {
    const DiamondFragments& fragments = catp_fragments(decoded);
    const HierarchyNode& n = hierarchy_.node(node);
    const CatpMeta& meta = index_.meta();
    DiamondInfo info = diamond_info(DiamondId{n.key});
    std::vector<std::array<int64_t, 3>> exact;
    std::vector<std::array<double, 3>> world;
    double best2 = INFINITY;
    for (const HierarchyPart& part : n.parts) {
        const FragmentMesh& fragment = fragments.slots[part.id];
        if (fragment.indices.empty() || !decode_fragment_integer_positions(fragment, info, int(part.id), exact)) continue;
        world.resize(exact.size());
        for (size_t v = 0; v < exact.size(); ++v)
            for (int k = 0; k < 3; ++k) world[v][k] = meta.origin[k] + double(exact[v][k]) / meta.layout.grid * meta.cell;
        for (size_t t = 0; t + 2 < fragment.indices.size(); t += 3)
            best2 = std::min(best2, point_triangle_distance2(eye, world[fragment.indices[t]], world[fragment.indices[t + 1]],
                                                             world[fragment.indices[t + 2]]));
    }
    if (!std::isfinite(best2)) return std::nullopt;
    // Decoding rounds: a hair less than measured, never more.
    return std::max(0.0, std::sqrt(best2) * (1 - 1e-9) - meta.cell * 1e-6);
}

DrawnGeometry CatpFormat::drawn_geometry(const std::vector<DecodedPart>& parts, const std::array<double, 3>& eye) const {
    const CatpMeta& meta = index_.meta();
    const LatticePoint anchor = catp_frame_anchor(meta, eye);
    DrawnGeometry out;
    for (int k = 0; k < 3; ++k) out.origin[size_t(k)] = meta.origin[k] + double(anchor[size_t(k)]) * meta.cell;
    Mesh& mesh = out.mesh;
    std::vector<uint32_t> remap;
    for (const DecodedPart& p : parts) {
        if (p.part >= 8) continue;
        const FragmentMesh& frag = catp_fragments(*p.decoded).slots[p.part];
        const uint64_t key = hierarchy_.node(p.node).key;
        // The shader's inputs with positions in world units relative to the anchor.
        const VertexDecodeParams params = slot_decode_params(meta, diamond_info(DiamondId{key}), int(p.part), anchor, meta.cell);
        remap.assign(frag.vertices.size(), kNoNode);
        for (size_t i = 0; i < frag.vertices.size(); ++i) {
            DecodedVertex d;
            if (!decode_packed_vertex(frag.vertices[i], params, d)) continue;
            remap[i] = uint32_t(mesh.positions.size());
            mesh.positions.push_back({d.position[0], d.position[1], d.position[2]});
            mesh.normals.push_back({d.normal[0], d.normal[1], d.normal[2]});
            mesh.colors.push_back({uint8_t(std::lround(d.color[0] * 255.0f)), uint8_t(std::lround(d.color[1] * 255.0f)),
                                   uint8_t(std::lround(d.color[2] * 255.0f))});
        }
        for (size_t t = 0; t + 2 < frag.indices.size(); t += 3) {
            uint32_t a = frag.indices[t], b = frag.indices[t + 1], c = frag.indices[t + 2];
            if (a >= remap.size() || b >= remap.size() || c >= remap.size()) continue;
            if (remap[a] == kNoNode || remap[b] == kNoNode || remap[c] == kNoNode) continue;
            mesh.indices.insert(mesh.indices.end(), {remap[a], remap[b], remap[c]});
        }
    }
    return out;
}

Aabb CatpFormat::world_bounds() const {
    const CatpMeta& m = index_.meta();
    Aabb box;
    box.min = {m.bounds_min[0], m.bounds_min[1], m.bounds_min[2]};
    box.max = {m.bounds_max[0], m.bounds_max[1], m.bounds_max[2]};
    return box;
}

int CatpFormat::up_axis() const { return viewer_up_axis(index_.meta().up); }

FormatSummary CatpFormat::summary() const {
    const CatpMeta& m = index_.meta();
    FormatSummary s;
    s.node_noun = "diamonds";
    s.primitive_noun = "triangles";
    s.levels_note = strprintf("leaf level %u", unsigned(m.leaf_level));
    s.lines.emplace_back("input", strprintf("%llu vertices, %llu triangles; colours %s, normals %s",
                                            (unsigned long long)m.input_vertices, (unsigned long long)m.input_triangles,
                                            (m.flags & 1) ? "from the input" : "none (one default colour)",
                                            (m.flags & 2) ? "from the input" : "computed"));
    double d2 = 0;
    for (int i = 0; i < 3; ++i) d2 += (m.bounds_max[i] - m.bounds_min[i]) * (m.bounds_max[i] - m.bounds_min[i]);
    s.lines.emplace_back("bounds", strprintf("[%.9g %.9g %.9g] - [%.9g %.9g %.9g]", m.bounds_min[0], m.bounds_min[1],
                                             m.bounds_min[2], m.bounds_max[0], m.bounds_max[1], m.bounds_max[2]));
    s.lines.emplace_back("diagonal", strprintf("%.9g", std::sqrt(d2)));
    s.lines.emplace_back("vertices", strprintf("%s layout, grid %d", m.layout.name(), m.layout.grid));
    if (m.precision > 0) {
        std::string precision = strprintf("%.6g", m.precision);
        if (m.mean_edge > 0) precision += strprintf(" (%.3g mean input edges of %.6g)", m.precision / m.mean_edge, m.mean_edge);
        s.lines.emplace_back("precision", precision);
    }
    s.lines.emplace_back("up axis", up_axis_summary(m.up));
    return s;
}

}  // namespace catpaq
