// point_encode_bench: the point node encoder alone on a converted dataset's nodes, for A/B runs
// of encoder changes.
//
// Usage: point_encode_bench DATASET.cpq [--runs N]
//
// Decodes every node of a points dataset (what the converter encoded: its positions, normals,
// colours and radii), then times encode_point_node over all nodes, best of N runs in CPU time of
// the thread. The normals are the decoded ones turned slightly (the converter's normals are not
// on the octahedral grid, and exact grid normals would make the encoder's search trivial). A
// digest (checksum64 of every node's bytes) is printed: two builds whose digests agree wrote
// the same bytes, which encoder speed-ups must keep.

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "base/checksum.h"
#include "base/error.h"
#include "base/sysinfo.h"
#include "common_codec/octahedral.h"
#include "points/codec.h"
#include "points/dataset.h"

using namespace catpaq;

namespace {

struct Node {
    std::vector<double> positions;
    std::vector<float> normals, radii;
    std::vector<uint8_t> colors;
};

}  // namespace

int main(int argc, char** argv) try {
    std::string input;
    int runs = 5;
    for (int i = 1; i < argc; ++i) {
        std::string a = argv[i];
        if (a == "--runs" && i + 1 < argc) runs = std::atoi(argv[++i]);
        else if (a == "-h" || a == "--help") {
            std::printf("usage: point_encode_bench DATASET.cpq [--runs N]\n");
            return 0;
        } else input = a;
    }
    if (input.empty()) fail("usage: point_encode_bench DATASET.cpq [--runs N]");
    PointDataset dataset(input);
    std::vector<Node> nodes(dataset.node_count());
    DecodedPoints decoded;
    size_t points = 0;
    uint64_t turn = 1;
    for (size_t i = 0; i < nodes.size(); ++i) {
        const std::string problem = dataset.decode(i, decoded);
        if (!problem.empty()) fail("%s", problem.c_str());
        Node& node = nodes[i];
        node.positions.assign(decoded.positions.begin(), decoded.positions.end());
        node.colors = decoded.colors;
        node.radii = decoded.radii;
        for (uint16_t code : decoded.normals) {
            float d[3];
            oct_decode(code, d);
            for (float& c : d) {
                turn = turn * 6364136223846793005ull + 1442695040888963407ull;
                c += float(int32_t(turn >> 40) - (1 << 23)) * 0x1p-30f;  // up to 1/128 each
            }
            node.normals.insert(node.normals.end(), d, d + 3);
        }
        points += decoded.count;
    }
    PointEncodeSettings settings;
    settings.color_bits = dataset.meta().color_bits;
    uint64_t digest = 0;
    size_t bytes = 0;
    const double s = best_of(runs, [&] {
        digest = 0;
        bytes = 0;
        for (const Node& node : nodes) {
            PointSamplesView view;
            view.count = node.radii.size();
            view.positions = node.positions.data();
            view.normals = node.normals.empty() ? nullptr : node.normals.data();
            view.colors = node.colors.empty() ? nullptr : node.colors.data();
            view.radii = node.radii.data();
            const std::vector<uint8_t> out = encode_point_node(view, settings);
            digest = digest * 31 + checksum64(out.data(), out.size());
            bytes += out.size();
        }
    }, thread_cpu_seconds);
    std::printf("%s: %zu nodes, %zu points\n", input.c_str(), nodes.size(), points);
    std::printf("encode  %8.1f ms  %6.1f ns/point  %zu bytes  digest %016llx\n", s * 1e3, s * 1e9 / double(points), bytes,
                (unsigned long long)digest);
    return 0;
} catch (const std::exception& e) {
    std::fprintf(stderr, "point_encode_bench: %s\n", e.what());
    return 1;
}
