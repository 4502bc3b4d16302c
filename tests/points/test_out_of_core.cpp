// The point converter out of core (points/builder.h, points/src/out_of_core.h): the top of the
// tree decided by passes over scratch files, the rest chunk by chunk, gives the very dataset the
// in-core converter writes, for every chunk size.
#include <gtest/gtest.h>

#include "base/atomic_file.h"
#include "points/builder.h"
#include "support.h"

namespace catpaq {
namespace {

PointsBuildSettings quiet(size_t node_points = 512) {
    PointsBuildSettings settings;
    settings.node_points = node_points;
    settings.progress = false;
    return settings;
}

// Builds `cloud` in core and with each chunk size; every dataset must be byte-identical.
void expect_same_for_chunk_sizes(const PointCloud& cloud, PointsBuildSettings settings, std::initializer_list<size_t> chunks,
                                 const std::string& name) {
    const std::string in_core = test::scratch(name + "_in_core.cpq");
    const PointsBuildReport reference = build_points(cloud, in_core, settings);
    EXPECT_FALSE(reference.out_of_core);
    const std::string expected = read_file(in_core);
    for (size_t chunk : chunks) {
        settings.chunk_points = chunk;
        // A tiny budget leaves the split passes 2 MiB of histograms: a level of more than two
        // nodes takes 11-bit digits (three passes a value) instead of 16-bit ones.
        settings.memory_budget = chunk % 2 ? 1 : 0;
        const std::string path = test::scratch(name + "_chunks_" + std::to_string(chunk) + ".cpq");
        const PointsBuildReport report = build_points(cloud, path, settings);
        EXPECT_TRUE(report.out_of_core);
        if (chunk < cloud.size()) {
            EXPECT_GT(report.chunks, 1u) << "chunks of " << chunk;
            EXPECT_GE(report.split_passes, 3u);
        }
        EXPECT_EQ(report.nodes, reference.nodes);
        EXPECT_TRUE(read_file(path) == expected) << name << ": chunks of " << chunk << " points give another dataset";
    }
}

TEST(PointsOutOfCore, GivesTheInCoreDatasetForEveryChunkSize) {
    const PointCloud cloud = test::sphere_cloud(40000, 1.0, {0.3, -0.2, 0.1}, 11);
    expect_same_for_chunk_sizes(cloud, quiet(), {2048, 2049, 5000, 17000, 40000}, "sphere");
}

TEST(PointsOutOfCore, GivesTheInCoreDatasetWithTheMidpointRule) {
    const PointCloud cloud = test::sphere_cloud(30000, 1.0, {0, 0, 0}, 12);
    PointsBuildSettings settings = quiet();
    settings.split = PointSplitRule::Midpoint;
    expect_same_for_chunk_sizes(cloud, settings, {2048, 2049, 9000}, "midpoint");
}

// Scanner coordinates are quantized: many points share a coordinate, so splits by rank must
// break ties the same way (by input index) in the passes and in core; duplicates too.
TEST(PointsOutOfCore, GivesTheInCoreDatasetWhenCoordinatesTie) {
    PointCloud cloud = test::sphere_cloud(30000, 1.0, {0, 0, 0}, 13);
    for (Vec3d& p : cloud.positions)
        for (int a = 0; a < 3; ++a) p[a] = std::round(p[a] * 16) / 16;
    for (size_t i = 0; i < 3000; ++i) {
        cloud.positions.push_back(cloud.positions[i * 7]);
        cloud.colors.push_back(cloud.colors[i]);
    }
    // Radii given: coincident points need no estimate.
    cloud.radii.assign(cloud.size(), 0.05f);
    expect_same_for_chunk_sizes(cloud, quiet(), {2048, 2049, 6000}, "ties");
}

TEST(PointsOutOfCore, GivesTheInCoreDatasetWithInputNormalsAndRadiiFarFromTheOrigin) {
    PointCloud cloud = test::sphere_cloud(25000, 2.0, {4.5e6, -3.2e6, 1e7}, 14);
    for (size_t i = 0; i < cloud.size(); ++i) {
        Vec3f n;
        for (int a = 0; a < 3; ++a) n[a] = float(cloud.positions[i][a] - (a == 0 ? 4.5e6 : a == 1 ? -3.2e6 : 1e7)) / 2.0f;
        cloud.normals.push_back(n);
        cloud.radii.push_back(0.01f + 0.001f * float(i % 5));
    }
    expect_same_for_chunk_sizes(cloud, quiet(), {2048, 11000}, "offset");
}

// Degenerate clouds split mostly by rank (planes leave a side empty, or there is no extent to
// split): on a line, on a plane, and all at one point (with radii, which need no estimate).
TEST(PointsOutOfCore, GivesTheInCoreDatasetOnALineOnAPlaneAndAtOnePoint) {
    PointCloud line, plane, point;
    uint64_t state = 17;
    for (size_t i = 0; i < 20000; ++i) {
        const double t = test::random_unit(state), u = test::random_unit(state);
        line.positions.push_back({1 + 2 * t, 1 + 2 * t, 1 + 2 * t});
        plane.positions.push_back({t, u, 0.5});
        point.positions.push_back({3, -2, 7});
    }
    point.radii.assign(point.size(), 0.01f);
    expect_same_for_chunk_sizes(line, quiet(), {2048, 2049}, "line");
    expect_same_for_chunk_sizes(plane, quiet(), {2048, 2049}, "plane");
    expect_same_for_chunk_sizes(point, quiet(), {2048, 2049}, "point");
}

// A budget below the in-core estimate converts out of core (tests/tools: CliFormats.
// PointsBeyondTheMemoryBudgetConvertOutOfCoreWithinIt), unless it is too small even for that.
TEST(PointsOutOfCore, ABudgetTooSmallEvenOutOfCoreIsRefusedBeforeAnythingIsWritten) {
    const PointCloud cloud = test::sphere_cloud(20000, 1.0, {0, 0, 0}, 15);
    PointsBuildSettings settings = quiet();
    settings.memory_budget = points_memory_estimate(cloud.size()) - 1;
    const std::string path = test::scratch("budget.cpq");
    const std::string need = "20000 points need about " + std::to_string(points_memory_estimate(20000) >> 20) + " MiB in core";
    EXPECT_TRUE(test::fails_with([&] { build_points(cloud, path, settings); }, {need.c_str(), "needs at least 48 MiB"}));
    EXPECT_FALSE(std::filesystem::exists(path));
    settings.memory_budget = points_memory_estimate(cloud.size());  // fits: in core
    EXPECT_FALSE(build_points(cloud, path, settings).out_of_core);
}

// A text file announces no count: its points are read in core until they stop fitting the
// budget, then moved to the store and the rest streamed there; the dataset is the in-core one.
TEST(PointsOutOfCore, ATextFileMovesOutOfCoreWhenItsPointsStopFittingTheBudget) {
    const PointCloud cloud = test::sphere_cloud(600000, 1.0, {10, 20, 30}, 16);
    std::string text;
    text.reserve(cloud.size() * 60);
    char line[128];
    for (size_t i = 0; i < cloud.size(); ++i) {
        const Vec3d& p = cloud.positions[i];
        const Rgb8& c = cloud.colors[i];
        std::snprintf(line, sizeof line, "%.17g %.17g %.17g %u %u %u\n", p[0], p[1], p[2], c[0], c[1], c[2]);
        text += line;
    }
    const std::string input = test::write_text("budget.xyz", text);
    PointsBuildSettings settings = quiet(4096);
    const std::string in_core = test::scratch("budget_text_in_core.cpq"), out = test::scratch("budget_text.cpq");
    EXPECT_FALSE(build_points(read_point_cloud(input), in_core, settings).out_of_core);
    settings.memory_budget = kPointsMinimumBudget;  // below the 600k points' 49 MiB
    const PointsBuildReport report = build_points_file(input, out, settings);
    EXPECT_TRUE(report.out_of_core);
    EXPECT_EQ(report.input_points, cloud.size());
    EXPECT_TRUE(read_file(out) == read_file(in_core));
}

}  // namespace
}  // namespace catpaq
