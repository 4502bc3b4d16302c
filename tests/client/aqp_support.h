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

namespace catpaq::test {

enum class AqpModel { Sphere, Torus, Bunny };
inline const char* aqp_model_name(AqpModel m) { return m == AqpModel::Sphere ? "sphere" : m == AqpModel::Torus ? "torus" : "bunny"; }

// A scratch directory per process, removed at exit.
inline std::string aqp_scratch_dir() {
    struct Scratch {
        std::filesystem::path dir =
            std::filesystem::temp_directory_path() / ("catpaq_aqp_client_" + std::to_string(getpid()));
        Scratch() { std::filesystem::create_directories(dir); }
        ~Scratch() {
            std::error_code ignored;
            std::filesystem::remove_all(dir, ignored);
        }
    };
    static Scratch scratch;
    return scratch.dir.string();
}

// The input of a model: the sphere and torus are closed; the bunny (data/bunny.ply) has holes in its
// base, so its datasets have border patches.
inline Mesh aqp_model_mesh(AqpModel m) {
    if (m == AqpModel::Sphere) return make_sphere(6000, 3);
    if (m == AqpModel::Torus) return make_torus(6000, 5);
    return read_mesh(std::string(CATPAQ_SOURCE_DIR) + "/data/bunny.ply");
}

// An AQP dataset of the model, built on first use (finest level 4: patches of 17 x 17 samples).
inline const std::string& aqp_dataset_path(AqpModel m) {
    static std::map<AqpModel, std::string> paths;
    auto it = paths.find(m);
    if (it != paths.end()) return it->second;
    const std::string path = aqp_scratch_dir() + "/" + aqp_model_name(m) + ".cpq";
    aqp::AqpBuildOptions options;
    options.patch_level = 4;
    options.progress = false;
    aqp::build_aqp_dataset(aqp_model_mesh(m), path, options);
    return paths.emplace(m, path).first->second;
}

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

}  // namespace catpaq::test
