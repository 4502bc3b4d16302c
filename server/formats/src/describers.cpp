// The catalog's per-format part: each format's describer, and the list of them (the one place a
// new format's describer is registered).
#include "server_formats/describers.h"

#include <algorithm>

#include <nlohmann/json.hpp>

#include "catp/format.h"

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

}  // namespace

DatasetDescribers builtin_dataset_describers() { return {{ArchiveKind::Catp, describe_catp}}; }

}  // namespace catpaq
