// The out-of-core reduction (aqp/reduce.h): a closed surface stays closed and of the same genus,
// every output vertex is an input vertex with its attributes, the target is reached, the
// reported distance is the largest from an input vertex, the result does not
// depend on the threads, and an AQP dataset built from it keeps its bounds against the original.
#include <gtest/gtest.h>

#include <map>

#include "aqp/clean.h"
#include "aqp/reduce.h"
#include "base/error.h"
#include "catp/distance.h"
#include "mesh/generators.h"
#include "mesh/io.h"
#include "support.h"

using namespace catpaq;
using namespace catpaq::aqp;

namespace {

constexpr uint64_t kTarget = 20000;

struct Reduced {
    Mesh input;
    std::string path;
    Mesh out;
    ReduceReport report;
};

// A 120k-triangle scan-like blob (closed, genus 0, colours and normals) in blocks of 15k
// triangles: 8 blocks.
ReduceOptions options(unsigned threads = 0) {
    ReduceOptions o;
    o.target_triangles = kTarget;
    o.block_triangles = 15000;
    o.threads = threads;
    o.progress = false;
    return o;
}

const Reduced& scan() {
    static const Reduced r = [] {
        Reduced x;
        x.input = make_scan_like(120000, 5);
        x.path = (aqp::test::scratch_dir() / "reduce_scan.ply").string();
        write_ply(x.path, x.input);
        x.out = reduce_ply_out_of_core(x.path, options(), &x.report);
        return x;
    }();
    return r;
}

}  // namespace

TEST(AqpReduce, KeepsAClosedSurfaceClosedWithItsGenusAndReachesTheTarget) {
    const Reduced& r = scan();
    EXPECT_EQ(r.report.input_triangles, 120000u);
    EXPECT_GE(r.report.blocks, 4u);
    EXPECT_GE(r.report.round1_triangles, r.out.triangle_count());
    EXPECT_LE(r.out.triangle_count(), kTarget * 11 / 10);
    EXPECT_GE(r.out.triangle_count(), kTarget * 8 / 10);
    EXPECT_EQ(r.report.triangles, r.out.triangle_count());
    std::string why;
    EXPECT_TRUE(is_oriented_manifold(r.out, &why)) << why;
    const EdgeCounts e = count_edges(r.out.indices);
    EXPECT_EQ(e.border, 0u);
    // Euler characteristic 2: still a sphere.
    EXPECT_EQ(int64_t(r.out.vertex_count()) - int64_t(e.edges) + int64_t(r.out.triangle_count()), 2);
}

TEST(AqpReduce, EveryOutputVertexIsAnInputVertexWithItsAttributes) {
    const Reduced& r = scan();
    ASSERT_TRUE(r.out.has_colors() && r.out.has_normals());
    std::map<Vec3d, size_t> input;
    for (size_t v = 0; v < r.input.vertex_count(); ++v) input.emplace(r.input.positions[v], v);
    // The input file stores float positions (PLY written as float below 1e5).
    for (size_t v = 0; v < r.out.vertex_count(); ++v) {
        const auto it = input.find(r.out.positions[v]);
        ASSERT_NE(it, input.end()) << "vertex " << v;
        EXPECT_EQ(r.out.colors[v], r.input.colors[it->second]);
        for (int a = 0; a < 3; ++a) EXPECT_NEAR(r.out.normals[v][a], r.input.normals[it->second][a], 1e-6);
    }
}

TEST(AqpReduce, ReportsTheLargestDistanceOfAnInputVertexToTheResult) {
    const Reduced& r = scan();
    const SurfaceDistance to_out(r.out.positions, r.out.indices);
    double worst = 0;
    for (const Vec3d& p : r.input.positions) worst = std::max(worst, to_out.distance(p));
    EXPECT_GT(worst, 0.0);
    EXPECT_NEAR(r.report.vertex_distance, worst, 1e-12 * r.input.bounds().diagonal());
    // Small against the model: a hundredth of the diagonal at a sixth of the triangles.
    EXPECT_LT(worst, 0.01 * r.input.bounds().diagonal());
}

TEST(AqpReduce, TheResultDoesNotDependOnTheThreads) {
    const Reduced& r = scan();
    ReduceReport one;
    const Mesh single = reduce_ply_out_of_core(r.path, options(1), &one);
    EXPECT_EQ(single.indices, r.out.indices);
    EXPECT_EQ(single.positions, r.out.positions);
    EXPECT_EQ(one.vertex_distance, r.report.vertex_distance);
}

TEST(AqpReduce, ADatasetFromTheResultKeepsItsBoundsAgainstTheOriginal) {
    const Reduced& r = scan();
    AqpBuildOptions o;
    o.input_error = r.report.vertex_distance;
    const aqp::test::Built b = aqp::test::build(r.out, "reduced", o);
    for (const AqpLevelStats& l : b.report.levels) EXPECT_GE(l.max_error, r.report.vertex_distance);
    aqp::test::expect_bounds_hold(r.input, b.path, false);
}

// Projected scan coordinates (an offset of 1e7): the same reduction as at the origin, within
// rounding (simplify_mesh works relative to a vertex; the flips on differences).
TEST(AqpReduce, LargeOffsetsReduceAsAtTheOrigin) {
    const Reduced& r = scan();
    Mesh far = r.input;
    for (Vec3d& p : far.positions) p = {p[0] + 1e7, p[1] - 3e6, p[2] + 2e5};
    const std::string path = (aqp::test::scratch_dir() / "reduce_far.ply").string();
    write_ply(path, far);  // in double: coordinates above 1e5
    ReduceReport report;
    const Mesh out = reduce_ply_out_of_core(path, options(), &report);
    EXPECT_NEAR(double(out.triangle_count()), double(r.out.triangle_count()), 0.01 * double(r.out.triangle_count()));
    EXPECT_LT(report.vertex_distance, 2 * r.report.vertex_distance);
    std::string why;
    EXPECT_TRUE(is_oriented_manifold(out, &why)) << why;
    EXPECT_EQ(count_edges(out.indices).border, 0u);
}

// An open surface (the blob with its top cut away) keeps its border: one loop, no new holes.
TEST(AqpReduce, AnOpenSurfaceKeepsItsBorder) {
    Mesh open = scan().input;
    std::vector<uint32_t> kept;
    for (size_t t = 0; t < open.triangle_count(); ++t) {
        double y = 0;
        for (int k = 0; k < 3; ++k) y += open.positions[open.indices[3 * t + size_t(k)]][1] / 3;
        if (y < 1.0) kept.insert(kept.end(), &open.indices[3 * t], &open.indices[3 * t] + 3);
    }
    open.indices = kept;
    const std::string path = (aqp::test::scratch_dir() / "reduce_open.ply").string();
    write_ply(path, open);
    const Mesh out = reduce_ply_out_of_core(path, options());
    std::string why;
    EXPECT_TRUE(is_oriented_manifold(out, &why)) << why;
    const EdgeCounts e = count_edges(out.indices);
    EXPECT_GT(e.border, 0u);
    // Euler characteristic 1: a disc, as the input.
    EXPECT_EQ(int64_t(out.vertex_count()) - int64_t(e.edges) + int64_t(out.triangle_count()), 1);
    EXPECT_LT(e.border, count_edges(open.indices).border);  // the border is simplified too (sliding along itself)
}

TEST(AqpReduce, RefusesFilesWithoutFacesAndBudgetsTooSmall) {
    const std::string cloud = (aqp::test::scratch_dir() / "reduce_cloud.ply").string();
    Mesh points = make_sphere(500, 1);
    points.indices.clear();
    write_ply(cloud, points);
    EXPECT_THROW(reduce_ply_out_of_core(cloud, options()), Error);
    ReduceOptions tight = options();
    tight.memory_budget = 8 << 20;
    try {
        reduce_ply_out_of_core(scan().path, tight);
        FAIL() << "an 8 MiB budget was accepted";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("above the budget of 8 MiB"), std::string::npos) << e.what();
    }
}
