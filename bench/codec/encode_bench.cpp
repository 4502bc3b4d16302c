// encode_bench: the converter's encoder side on real fragments, for A/B runs of encoder changes.
//
// Usage: encode_bench ARCHIVE.cpq [--runs N] [--only encode|normals|positions]
//
// Loads every fragment of a CATP archive (decoded with fragment_decode), then times
//   encode     fragment_encode over all fragments (the converter encodes each fragment once);
//   normals    oct_encode_precise over the decoded normals of all vertices, slightly perturbed
//              (quantize_fragment encodes one normal per vertex);
//   positions  bary_quantize + bary_pack over points spread in a Kuhn tetrahedron (mostly
//              interior, some on faces and edges as in the converter).
// Each figure is the best of N runs, in CPU time of the thread. A digest (XXH3 of all outputs) is printed per part: two
// builds whose digests agree produced the same bytes, which is what encoder speed-ups must keep.

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "base/checksum.h"
#include "base/error.h"
#include "base/sysinfo.h"
#include "catp/format.h"
#include "common_codec/archive.h"
#include "common_codec/barycentric.h"
#include "common_codec/fragment_codec.h"
#include "common_codec/octahedral.h"

using namespace catpaq;

namespace {

// Every fragment of a CATP archive, decoded (decode_diamond_node).
std::vector<FragmentMesh> load_fragments(const std::string& path) {
    ArchiveReader reader(path);
    std::vector<FragmentMesh> out;
    for (size_t e = 0; e < reader.entries().size(); ++e) {
        std::string error;
        const uint8_t* p = reader.node(e, &error);
        DiamondFragments node;
        if (p) error = decode_diamond_node(p, reader.entries()[e].size, std::nullopt, node);
        if (!error.empty()) fail("%s: node %zu: %s", path.c_str(), e, error.c_str());
        for (int s = 0; s < 8; ++s)
            if (node.slot_mask & (1 << s)) out.push_back(std::move(node.slots[s]));
    }
    return out;
}

}  // namespace

int main(int argc, char** argv) try {
    std::string input, only;
    int runs = 5;
    for (int i = 1; i < argc; ++i) {
        std::string a = argv[i];
        if (a == "--runs" && i + 1 < argc)
            runs = std::atoi(argv[++i]);
        else if (a == "--only" && i + 1 < argc)
            only = argv[++i];
        else if (a == "-h" || a == "--help") {
            std::printf("usage: encode_bench ARCHIVE.cpq [--runs N] [--only encode|normals|positions]\n");
            return 0;
        } else
            input = a;
    }
    if (input.empty()) fail("usage: encode_bench ARCHIVE.cpq [--runs N] [--only encode|normals|positions]");
    const std::vector<FragmentMesh> fragments = load_fragments(input);
    size_t triangles = 0, vertices = 0;
    for (const FragmentMesh& m : fragments) {
        triangles += m.triangle_count();
        vertices += m.vertices.size();
    }
    std::printf("%s: %zu fragments, %zu triangles, %zu vertices\n", input.c_str(), fragments.size(), triangles,
                vertices);

    if (only.empty() || only == "encode") {
        std::vector<uint8_t> out;
        uint64_t digest = 0;
        size_t bytes = 0;
        const double s = best_of(runs, [&] {
            digest = 0;
            bytes = 0;
            for (const FragmentMesh& m : fragments) {
                out.clear();
                fragment_encode(m, out);
                digest = digest * 31 + checksum64(out.data(), out.size());
                bytes += out.size();
            }
        }, thread_cpu_seconds);
        std::printf("encode     %8.1f ms  %6.2f Mtri/s  %zu bytes  digest %016llx\n", s * 1e3,
                    double(triangles) / s / 1e6, bytes, (unsigned long long)digest);
    }

    if (only.empty() || only == "normals") {
        // The decoded normals, each perturbed a little (the converter's normals are not on the grid).
        std::vector<std::array<float, 3>> normals;
        std::mt19937 rng(1);
        std::uniform_real_distribution<float> jitter(-0.01f, 0.01f);
        for (const FragmentMesh& m : fragments)
            for (const PackedVertex& v : m.vertices) {
                float d[3];
                oct_decode(v.normal(), d);
                normals.push_back({d[0] + jitter(rng), d[1] + jitter(rng), d[2] + jitter(rng)});
            }
        std::vector<uint16_t> codes(normals.size());
        const double s = best_of(runs, [&] {
            for (size_t i = 0; i < normals.size(); ++i)
                codes[i] = oct_encode_precise(normals[i][0], normals[i][1], normals[i][2]);
        }, thread_cpu_seconds);
        std::printf("normals    %8.1f ms  %6.1f ns/normal  digest %016llx\n", s * 1e3, s * 1e9 / double(normals.size()),
                    (unsigned long long)checksum64(codes.data(), codes.size() * 2));
    }

    if (only.empty() || only == "positions") {
        // A Kuhn tetrahedron of a 2^16 cell; points in it on the 2^-32 grid, 90% interior, the
        // rest on a face (3 corners) or an edge (2 corners), as the clipper produces them.
        std::array<LatticePoint, 4> c = {LatticePoint{0, 0, 0}, {65536, 0, 0}, {65536, 65536, 0}, {65536, 65536, 65536}};
        canonical_order(c);
        std::mt19937_64 rng(2);
        std::uniform_real_distribution<double> u(0, 1);
        struct Point {
            double p[3];
            SupportMask support;
        };
        std::vector<Point> points(vertices);
        for (Point& pt : points) {
            double l[4] = {u(rng), u(rng), u(rng), u(rng)};
            int kind = int(rng() % 10);
            pt.support = 0xf;
            if (kind == 0) {
                int zero = int(rng() % 4);
                l[zero] = 0;
                pt.support = SupportMask(0xf & ~(1 << zero));
            }
            double s = l[0] + l[1] + l[2] + l[3];
            for (int j = 0; j < 3; ++j) {
                double x = 0;
                for (int k = 0; k < 4; ++k) x += l[k] / s * c[size_t(k)][size_t(j)];
                pt.p[j] = std::ldexp(std::round(std::ldexp(x, 32)), -32);
            }
        }
        std::vector<uint32_t> index(points.size());
        const double s = best_of(runs, [&] {
            for (size_t i = 0; i < points.size(); ++i) index[i] = bary_pack(bary_quantize(points[i].p, c, points[i].support));
        }, thread_cpu_seconds);
        uint64_t unpacked = 0;  // sum of the weights, so the calls are not optimised away
        const double su = best_of(runs, [&] {
            unpacked = 0;
            for (size_t i = 0; i < points.size(); ++i) {
                BaryWeights w;
                bary_unpack(index[i], kBaryGrid, w);
                unpacked += uint64_t(w[1]) + uint64_t(w[2]) + uint64_t(w[3]);
            }
        }, thread_cpu_seconds);
        std::printf("positions  %8.1f ms  %6.1f ns/point  digest %016llx\n", s * 1e3, s * 1e9 / double(points.size()),
                    (unsigned long long)checksum64(index.data(), index.size() * 4));
        std::printf("unpack     %8.1f ms  %6.1f ns/index  sum %llu\n", su * 1e3, su * 1e9 / double(points.size()),
                    (unsigned long long)unpacked);
    }
    return 0;
} catch (const std::exception& e) {
    std::fprintf(stderr, "encode_bench: %s\n", e.what());
    return 1;
}
