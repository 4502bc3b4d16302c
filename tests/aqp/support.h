#pragma once
// Shared by the AQP tests: building datasets into a scratch directory, small meshes, and the
// check that stored error bounds hold against the input.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <filesystem>
#include <string>

#include "aqp/build.h"
#include "aqp/dataset.h"
#include "aqp/verify.h"
#include "catp/distance.h"
#include "mesh/mesh.h"
#include "scratch_directory.h"

namespace catpaq::aqp::test {

inline std::filesystem::path scratch_dir() {
    static const catpaq::test::ScratchDirectory dir("catpaq_aqp_");
    return dir.path();
}

struct Built {
    std::string path;
    AqpBuildReport report;
};

// Builds `mesh` as scratch_dir()/NAME.cpq with `options` (progress off).
inline Built build(const Mesh& mesh, const std::string& name, AqpBuildOptions options = {}) {
    Built b;
    b.path = (scratch_dir() / (name + ".cpq")).string();
    options.progress = false;
    build_aqp_dataset(mesh, b.path, options, &b.report);
    return b;
}

// A triangle strip closed into a Moebius band: 2 * n triangles, not orientable.
inline Mesh moebius_band(int n) {
    Mesh m;
    for (int i = 0; i < n; ++i) {
        const double t = 2 * 3.14159265358979323846 * i / n;
        const double c = std::cos(t), s = std::sin(t), h = std::cos(t / 2) * 0.3, z = std::sin(t / 2) * 0.3;
        m.positions.push_back({(1 + h) * c, (1 + h) * s, z});
        m.positions.push_back({(1 - h) * c, (1 - h) * s, -z});
    }
    for (int i = 0; i < n; ++i) {
        uint32_t a = 2 * i, b = 2 * i + 1, c = 2 * ((i + 1) % n), d = 2 * ((i + 1) % n) + 1;
        if (i == n - 1) std::swap(c, d);  // the half twist
        m.indices.insert(m.indices.end(), {a, b, c, b, d, c});
    }
    return m;
}

// The patch's grid at `level` triangulated as drawn: cells split along (i,j)-(i+1,j+1).
inline void for_each_triangle(const AqpDataset& d, const PatchGrid& g, auto&& fn) {
    for (int j = 0; j + 1 < g.size; ++j)
        for (int i = 0; i + 1 < g.size; ++i) {
            const Vec3d a = d.world_position(g, g.index(i, j)), b = d.world_position(g, g.index(i + 1, j));
            const Vec3d c = d.world_position(g, g.index(i + 1, j + 1)), e = d.world_position(g, g.index(i, j + 1));
            fn(a, b, c);
            fn(a, c, e);
        }
}

// Points on every level surface (triangle centroids and edge midpoints: not samples, which the
// converter measured) are within their node's stored bound of the input; the input's vertices
// are within the level's largest bound of the level surface (its triangles, and the edges of
// those quantization flattened, which draw as lines). With `not_vacuous`, some point comes within
// a factor 4 of its node's bound at every level (the bound is a parametric distance: on a flat
// input it can be far above the true one; and a tile's is the largest of its patches', so only
// the patch that sets it can come close).
inline void expect_bounds_hold(const Mesh& input, const std::string& path, bool not_vacuous = true) {
    AqpDataset d(path);
    SurfaceDistance to_input(input.positions, input.indices);
    for (int l = 0; l <= d.finest_level(); ++l) {
        double level_bound = 0, worst_ratio = 0;
        for (uint32_t p = 0; p < d.patch_count(); ++p) {
            const double bound = d.entry(p, l).error;
            level_bound = std::max(level_bound, bound);
            const PatchGrid g = d.decode(p, l);
            for_each_triangle(d, g, [&](const Vec3d& a, const Vec3d& b, const Vec3d& c) {
                for (const Vec3d& x : {Vec3d{(a[0] + b[0] + c[0]) / 3, (a[1] + b[1] + c[1]) / 3, (a[2] + b[2] + c[2]) / 3},
                                       Vec3d{(a[0] + c[0]) / 2, (a[1] + c[1]) / 2, (a[2] + c[2]) / 2}}) {
                    const double e = to_input.distance(x);
                    worst_ratio = std::max(worst_ratio, e / bound);
                    ASSERT_LE(e, bound * (1 + 1e-6)) << "patch " << p << " level " << l;
                }
            });
        }
        const Mesh level = aqp_level_mesh(d, l, false);
        SurfaceDistance to_level(level.positions, level.indices);
        std::vector<std::pair<Vec3d, Vec3d>> edges;
        for (size_t t = 0; t < level.triangle_count(); ++t)
            for (int k = 0; k < 3; ++k)
                edges.push_back({level.positions[level.indices[3 * t + k]], level.positions[level.indices[3 * t + (k + 1) % 3]]});
        SegmentDistance to_level_edges(edges);
        double worst = 0;
        for (const Vec3d& v : input.positions)
            worst = std::max(worst, std::min(to_level.distance(v), to_level_edges.distance(v)));
        EXPECT_LE(worst, level_bound * (1 + 1e-6)) << "level " << l;
        if (not_vacuous) {
            EXPECT_GT(worst_ratio, 1.0 / 4) << "level " << l;
        }
    }
}

}  // namespace catpaq::aqp::test
