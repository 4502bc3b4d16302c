// The catalog's per-format part: each format's describer, and the list of them (the one place a
// new format's describer is registered).
#include "server_formats/describers.h"

#include <algorithm>

#include <nlohmann/json.hpp>

#include "aqp/format.h"
#include "catp/format.h"
#include "points/format.h"

namespace catpaq {

namespace {

// CATP: the world bounds and the decoded metadata (docs/http-api.md, "catp").
std::string describe_catp(const ArchiveHeader&, const std::vector<uint8_t>& meta_bytes, DatasetDescription& out) {
    CatpMeta meta;
    std::string problem = decode_catp_meta(meta_bytes.data(), meta_bytes.size(), meta);
    if (!problem.empty()) return problem;
    out.has_bounds = true;
    std::copy(meta.bounds_min, meta.bounds_min + 3, out.bounds_min.begin());
    std::copy(meta.bounds_max, meta.bounds_max + 3, out.bounds_max.begin());
    nlohmann::json details{{"lattice_bits", meta.lattice_bits},
                           {"origin", {meta.origin[0], meta.origin[1], meta.origin[2]}},
                           {"cell", meta.cell},
                           {"leaf_level", meta.leaf_level},
                           {"flags", meta.flags},
                           {"input_vertices", meta.input_vertices},
                           {"input_triangles", meta.input_triangles},
                           {"default_rgb", meta.default_rgb}};
    out.details_json = details.dump();
    return "";
}

// AQP: the world bounds of the samples and the decoded metadata without the per-patch tables
// (docs/http-api.md, "aqp"; a client reads those from the prefix).
std::string describe_aqp(const ArchiveHeader&, const std::vector<uint8_t>& meta_bytes, DatasetDescription& out) {
    aqp::AqpMeta meta;
    std::string problem = aqp::decode_aqp_meta(meta_bytes.data(), meta_bytes.size(), meta);
    if (!problem.empty()) return problem;
    out.has_bounds = true;
    std::copy(meta.bounds_min, meta.bounds_min + 3, out.bounds_min.begin());
    std::copy(meta.bounds_max, meta.bounds_max + 3, out.bounds_max.begin());
    nlohmann::json details{{"patch_level", meta.patch_level},
                           {"patches", meta.patches.size()},
                           {"base_vertices", meta.base_vertices},
                           {"base_triangles", meta.base_triangles},
                           {"border_edges", meta.border_edges},
                           {"colors", meta.has_colors()},
                           {"origin", {meta.origin[0], meta.origin[1], meta.origin[2]}},
                           {"step", meta.step},
                           {"precision", meta.precision},
                           {"up_axis", meta.up_axis},
                           {"input_vertices", meta.input_vertices},
                           {"input_triangles", meta.input_triangles}};
    nlohmann::json tiles = nlohmann::json::array();  // patches per node, by level
    for (int l = 0; l <= int(meta.patch_level); ++l) tiles.push_back(uint64_t(1) << (2 * meta.shift(l)));
    details["tile_patches"] = tiles;
    out.details_json = details.dump();
    return "";
}

// Points: the world bounds of the input and the decoded metadata without the per-node table.
std::string describe_points(const ArchiveHeader&, const std::vector<uint8_t>& meta_bytes, DatasetDescription& out) {
    PointsMeta meta;
    std::string problem = decode_points_meta(meta_bytes.data(), meta_bytes.size(), meta);
    if (!problem.empty()) return problem;
    out.has_bounds = true;
    std::copy(meta.bounds_min, meta.bounds_min + 3, out.bounds_min.begin());
    std::copy(meta.bounds_max, meta.bounds_max + 3, out.bounds_max.begin());
    nlohmann::json details{{"input_points", meta.input_points},
                           {"node_points", meta.node_points},
                           {"nodes", meta.nodes.size()},
                           {"split", point_split_rule_name(meta.split)},
                           {"flags", meta.flags},
                           {"origin", {meta.origin[0], meta.origin[1], meta.origin[2]}},
                           {"up_axis", meta.up_axis}};
    out.details_json = details.dump();
    return "";
}

}  // namespace

DatasetDescribers builtin_dataset_describers() {
    return {{ArchiveKind::Catp, describe_catp}, {ArchiveKind::Aqp, describe_aqp}, {ArchiveKind::Points, describe_points}};
}

}  // namespace catpaq
