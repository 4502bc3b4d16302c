// coarsen_bench: the steps that coarsening repeats for every diamond, timed one by one on
// diamond-sized pieces of a scan-like surface, single-threaded (thread CPU time, best of runs),
// so that a change to one step can be measured without the noise of a whole build.
//
// Steps, per gathered (input) triangle: simplify_mesh to half the triangles (no vertex locked: the
// piece is a closed surface, where a diamond locks its outer faces' vertices), the simplification
// error measurement (measured_simplification_error, both directions), and quantize + encode of
// the simplified mesh as one fragment. Each is also given relative to meshoptimizer's
// meshopt_simplify (to half, float positions) on the same piece in the same run, as this
// machine's speed drifts by a fifth from run to run.
//
// Usage: coarsen_bench [triangles per piece ...]   (default 4000 20000 60000)
#include <meshoptimizer.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include <tbb/global_control.h>

#include "../../catp/src/fragment_build.h"
#include "base/sysinfo.h"
#include "catp/simplify.h"
#include "common_codec/fragment_codec.h"
#include "mesh/generators.h"

using namespace catpaq;

namespace {

// A scan-like surface of about `triangles` triangles, scaled into the lattice box [1, 3]^3
// (positions on the converter's snapping grid are not needed for timing), as a WorkFragment
// with its lock flags (all clear).
struct Piece {
    WorkFragment gathered;
    std::vector<uint8_t> locked;
};

Piece make_piece(size_t triangles, uint64_t seed) {
    Mesh mesh = make_scan_like(triangles, seed);
    Bounds b = mesh.bounds();
    double extent = 0;
    for (int i = 0; i < 3; ++i) extent = std::max(extent, b.max[i] - b.min[i]);
    Piece piece;
    WorkFragment& f = piece.gathered;
    for (const Vec3d& p : mesh.positions) {
        Vec3d q;
        for (int i = 0; i < 3; ++i) q[i] = 1.0 + 2.0 * (p[i] - b.min[i]) / extent;
        f.positions.push_back(q);
    }
    f.normals = mesh.has_normals() ? mesh.normals : std::vector<Vec3f>(mesh.positions.size(), Vec3f{0, 0, 1});
    f.colors = mesh.has_colors() ? mesh.colors : std::vector<Rgb8>(mesh.positions.size(), Rgb8{200, 200, 200});
    f.indices = mesh.indices;
    piece.locked.assign(f.positions.size(), 0);
    return piece;
}

}  // namespace

int main(int argc, char** argv) {
    std::vector<size_t> sizes;
    for (int i = 1; i < argc; ++i) sizes.push_back(size_t(std::strtoull(argv[i], nullptr, 10)));
    if (sizes.empty()) sizes = {4000, 20000, 60000};
    const int kRuns = 7;
    // One thread: the measurement's two directions would otherwise run on two, and thread CPU
    // time would see one of them.
    tbb::global_control one_thread(tbb::global_control::max_allowed_parallelism, 1);
    std::printf("thread CPU time per gathered triangle (ns), best of %d; in brackets: relative to meshopt_simplify\n\n",
                kRuns);
    std::printf("%10s %10s %18s %18s %18s %18s\n", "triangles", "meshopt", "simplify", "measure", "encode", "sum");
    for (size_t n : sizes) {
        Piece piece = make_piece(n, 7);
        const WorkFragment& g = piece.gathered;
        const size_t triangles = g.indices.size() / 3;
        SimplifySettings settings;
        settings.target_triangles = triangles / 2;
        SimplifyResult simplified;
        const double t_simplify = best_of(kRuns, [&] {
            simplified = simplify_mesh(&g.positions[0][0], g.positions.size(), g.indices.data(), g.indices.size(),
                                       piece.locked.data(), settings);
        }, thread_cpu_seconds);
        double error = 0;
        const double t_measure = best_of(kRuns, [&] { error = measured_simplification_error(g, simplified.indices, &simplified.sources); },
                                         thread_cpu_seconds);
        WorkFragment out = g;
        out.indices = simplified.indices;
        // A tetrahedron around the piece's box [1, 3]^3 (x + y + z <= 12, all >= 0).
        const Tetrahedron tet = {{{0, 0, 0}, {12, 0, 0}, {0, 12, 0}, {0, 0, 12}}};
        std::vector<uint8_t> bytes;
        const double t_encode = best_of(kRuns, [&] {
            FragmentMesh mesh;
            quantize_fragment(out, tet, VertexLayout{}, mesh);
            bytes.clear();
            fragment_encode(mesh, bytes);
        }, thread_cpu_seconds);
        std::vector<float> floats;
        for (const Vec3d& p : g.positions) floats.insert(floats.end(), {float(p[0]), float(p[1]), float(p[2])});
        std::vector<uint32_t> kept(g.indices.size());
        const double t_meshopt = best_of(kRuns, [&] {
            meshopt_simplify(kept.data(), g.indices.data(), g.indices.size(), floats.data(), g.positions.size(),
                             3 * sizeof(float), triangles / 2 * 3, 1e-2f, 0, nullptr);
        }, thread_cpu_seconds);
        const double scale = 1e9 / double(triangles);
        auto column = [&](double t) { std::printf(" %10.1f (%5.2f)", t * scale, t / t_meshopt); };
        std::printf("%10zu %10.1f", triangles, t_meshopt * scale);
        for (double t : {t_simplify, t_measure, t_encode, t_simplify + t_measure + t_encode}) column(t);
        std::printf("   error %.3g, %zu bytes\n", error, bytes.size());
    }
    return 0;
}
