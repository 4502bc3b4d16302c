#pragma once
// Shared by the AQP client tests: AQP datasets of closed models built once per process (with
// aqp::build_aqp_dataset), opened as the client opens them (DatasetPrefix -> AqpFormat), and
// the nodes' bytes.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "aqp/build.h"
#include "aqp/dataset.h"
#include "aqp_client/aqp_format.h"
#include "mesh/generators.h"
#include "mesh/io.h"
#include "scratch_directory.h"

namespace catpaq::test {

enum class AqpModel { Sphere, Torus, Bunny };
inline const char* aqp_model_name(AqpModel m) { return m == AqpModel::Sphere ? "sphere" : m == AqpModel::Torus ? "torus" : "bunny"; }

// A scratch directory per process, removed at exit.
inline std::string aqp_scratch_dir() {
    static const ScratchDirectory dir("catpaq_aqp_client_");
    return dir.string();
}

// The input of a model: the sphere and torus are closed; the bunny (data/bunny.ply) has holes in its
// base, so its datasets have border patches.
inline Mesh aqp_model_mesh(AqpModel m) {
    if (m == AqpModel::Sphere) return make_sphere(6000, 3);
    if (m == AqpModel::Torus) return make_torus(6000, 5);
    return read_mesh(std::string(CATPAQ_SOURCE_DIR) + "/data/bunny.ply");
}

// An AQP dataset of the model, built on first use (finest level 4: patches of 17 x 17 samples),
// with the default tiles (several patches per node at coarse levels) or, `untiled`, one patch
// per node at every level (tile_samples 0): the renderer tests draw any per-patch levels with it.
inline const std::string& aqp_dataset_path(AqpModel m, bool untiled = false) {
    static std::map<std::pair<AqpModel, bool>, std::string> paths;
    auto it = paths.find({m, untiled});
    if (it != paths.end()) return it->second;
    const std::string path = aqp_scratch_dir() + "/" + aqp_model_name(m) + (untiled ? "_untiled" : "") + ".cpq";
    aqp::AqpBuildOptions options;
    options.patch_level = 4;
    options.progress = false;
    if (untiled) options.tile_samples = 0;
    aqp::build_aqp_dataset(aqp_model_mesh(m), path, options);
    return paths.emplace(std::make_pair(m, untiled), path).first->second;
}
inline const std::string& aqp_untiled_dataset_path(AqpModel m) { return aqp_dataset_path(m, true); }

inline std::vector<uint8_t> read_file_bytes(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    return std::vector<uint8_t>(std::istreambuf_iterator<char>(in), {});
}

// The dataset opened as the client opens it, with the whole file's bytes at hand.
struct OpenedAqp {
    std::vector<uint8_t> file;
    std::unique_ptr<AqpFormat> format;
    const uint8_t* node_bytes(uint32_t node) const { return file.data() + format->hierarchy().node(node).payload_offset; }
    size_t node_size(uint32_t node) const { return format->hierarchy().node(node).payload_bytes; }
};
inline OpenedAqp open_aqp(const std::string& path) {
    OpenedAqp o;
    o.file = read_file_bytes(path);
    o.format = std::make_unique<AqpFormat>(DatasetPrefix::parse(o.file.data(), o.file.size(), path));
    return o;
}

// Decodes `node` the way the session does: through its chain of coarser levels.
inline std::shared_ptr<const DecodedNode> decode_chain(const OpenedAqp& o, uint32_t node) {
    const HierarchyNode& n = o.format->hierarchy().node(node);
    std::shared_ptr<const DecodedNode> out;
    std::string problem;
    if (n.decode_parent == kNoNode) {
        problem = o.format->decode(node, o.node_bytes(node), o.node_size(node), out);
    } else {
        std::shared_ptr<const DecodedNode> parent = decode_chain(o, n.decode_parent);
        problem = o.format->decode_with_parent(node, *parent, o.node_bytes(node), o.node_size(node), out);
    }
    EXPECT_EQ(problem, "") << "node " << n.key;
    return out;
}

// Every node decoded, by hierarchy index (nodes come coarse to fine, so a node's decode parent
// is decoded before it).
inline std::vector<std::shared_ptr<const DecodedNode>> decode_all(const OpenedAqp& o) {
    const Hierarchy& h = o.format->hierarchy();
    std::vector<std::shared_ptr<const DecodedNode>> out(h.size());
    for (uint32_t i = 0; i < h.size(); ++i) {
        const HierarchyNode& n = h.node(i);
        const std::string problem =
            n.decode_parent == kNoNode
                ? o.format->decode(i, o.node_bytes(i), o.node_size(i), out[i])
                : o.format->decode_with_parent(i, *out[n.decode_parent], o.node_bytes(i), o.node_size(i), out[i]);
        EXPECT_EQ(problem, "") << "node " << n.key;
    }
    return out;
}

// The node (tile) holding a patch at a level.
inline uint32_t patch_node(const OpenedAqp& o, uint32_t patch, int level) {
    const aqp::AqpMeta& meta = o.format->meta();
    return o.format->hierarchy().find(aqp::aqp_node_key(meta.tile_of(patch, level), level));
}

// A patch's grid in a decoded tile (a test failure, and the first grid, when it has none).
inline const aqp::PatchGrid& patch_grid(const DecodedNode& tile, uint32_t patch) {
    const std::vector<aqp::PatchGrid>& grids = aqp_grids(tile);
    for (const aqp::PatchGrid& g : grids)
        if (g.patch == patch) return g;
    ADD_FAILURE() << "the tile does not hold patch " << patch;
    return grids.front();
}

// A node holding one patch's grid of a decoded tile: drawn_geometry over any per-patch levels,
// not only the ones a cut of tiles can give.
inline std::shared_ptr<const DecodedNode> single_patch_node(const DecodedNode& tile, uint32_t patch) {
    auto out = std::make_shared<AqpNode>();
    out->grids.push_back(patch_grid(tile, patch));
    return out;
}

}  // namespace catpaq::test
