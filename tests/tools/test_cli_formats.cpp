// The catpaq tool on the AQP and point formats: convert --format aqp|points with the table and
// --json reports, verify dispatching to each format's checks (passing on a faithful original,
// failing on a moved one), and the options of one format refused by name for another.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include <nlohmann/json.hpp>

#include "base/atomic_file.h"
#include "base/child_process.h"
#include "cli_support.h"
#include "common_codec/archive.h"
#include "mesh/generators.h"
#include "mesh/io.h"
#include "points/builder.h"
#include "points/sampling.h"

using namespace catpaq;
using namespace catpaq::cli_test;

namespace {

void write_xyz(const fs::path& path, const PointCloud& cloud) {
    std::ofstream out(path);
    out.precision(17);
    for (const Vec3d& p : cloud.positions) out << p[0] << ' ' << p[1] << ' ' << p[2] << '\n';
}

Mesh translated(Mesh m, double dx) {
    for (Vec3d& p : m.positions) p[0] += dx;
    return m;
}

}  // namespace

// convert --format aqp writes an AQP dataset, reports cleaning and levels as JSON, and verify
// --mesh measures every level within its stored bound against the original.
TEST(CliFormats, AqpConvertsReportsJsonAndVerifiesAgainstTheOriginal) {
    fs::path in = scratch() / "aqp_sphere.ply", out = scratch() / "aqp_sphere.cpq";
    write_ply(in.string(), make_sphere(8000, 5));
    ToolRun c = run("convert " + in.string() + " -o " + out.string() + " --format aqp --json --quiet", true);
    ASSERT_EQ(c.status, 0) << c.output;
    const nlohmann::json report = nlohmann::json::parse(c.output);
    EXPECT_EQ(report.at("format"), "aqp");
    EXPECT_EQ(report.at("clean").at("dropped_components").get<size_t>(), 0u);
    EXPECT_EQ(report.at("clean").at("genus").get<int>(), 0);
    EXPECT_TRUE(report.at("domain").at("bijective").get<bool>());
    const int k = report.at("patch_level").get<int>();
    ASSERT_EQ(report.at("levels").size(), size_t(k + 1));
    EXPECT_EQ(report.at("output").at("bytes").get<uint64_t>(), fs::file_size(out));
    EXPECT_EQ(ArchiveReader(out.string()).header().kind, ArchiveKind::Aqp);

    ToolRun v = run("verify " + out.string() + " --mesh " + in.string() + " --samples 3000 --quiet");
    EXPECT_EQ(v.status, 0) << v.output;
    EXPECT_NE(v.output.find("shared edges and corners ok"), std::string::npos) << v.output;
    EXPECT_NE(v.output.find("level->original max"), std::string::npos) << v.output;
    EXPECT_NE(v.output.find("verify: OK"), std::string::npos) << v.output;
    // The up axis convert records (default y, as for CATP), which viewers use.
    EXPECT_NE(run("info " + out.string()).output.find("up axis:   y"), std::string::npos) << run("info " + out.string()).output;
    ASSERT_EQ(run("convert " + in.string() + " -o " + out.string() + " --format aqp --up -z --quiet").status, 0);
    EXPECT_NE(run("info " + out.string()).output.find("up axis:   -z"), std::string::npos) << run("info " + out.string()).output;
}

// Against an original moved by far more than the coarsest bound, verify fails naming the level.
TEST(CliFormats, AqpVerifyFailsAgainstAMovedOriginal) {
    fs::path in = scratch() / "aqp_moved.ply", moved = scratch() / "aqp_moved_by.ply", out = scratch() / "aqp_moved.cpq";
    const Mesh sphere = make_sphere(4000, 2);
    write_ply(in.string(), sphere);
    write_ply(moved.string(), translated(sphere, 0.5));
    ASSERT_EQ(run("convert " + in.string() + " -o " + out.string() + " --format aqp --quiet").status, 0);
    ToolRun v = run("verify " + out.string() + " --mesh " + moved.string() + " --samples 2000 --quiet");
    EXPECT_EQ(v.status, 1) << v.output;
    EXPECT_NE(v.output.find("above its stored bound"), std::string::npos) << v.output;
    EXPECT_NE(v.output.find("verify: FAILED"), std::string::npos) << v.output;
}

// convert --format points on an XYZ file; verify finds every input point within each depth's
// bound of a splat, and fails when one input point is moved away.
TEST(CliFormats, PointsConvertAndVerifyEveryInputPointIsCovered) {
    fs::path in = scratch() / "cloud.xyz", moved = scratch() / "cloud_moved.xyz", out = scratch() / "cloud.cpq";
    PointCloud cloud = sample_surface(make_sphere(4000, 3), 30000, 9, false, false);
    write_xyz(in, cloud);
    ToolRun c = run("convert " + in.string() + " -o " + out.string() +
                           " --format points --node-points 2000 --json --quiet", true);
    ASSERT_EQ(c.status, 0) << c.output;
    const nlohmann::json report = nlohmann::json::parse(c.output);
    EXPECT_EQ(report.at("format"), "points");
    EXPECT_EQ(report.at("input").at("points").get<size_t>(), 30000u);
    EXPECT_TRUE(report.at("normals_estimated").get<bool>());
    EXPECT_LE(report.at("worst_error_to_radius").get<double>(), 0.25 + 1e-9);
    EXPECT_GT(report.at("levels").size(), 2u);

    ToolRun v = run("verify " + out.string() + " --mesh " + in.string() + " --quiet");
    EXPECT_EQ(v.status, 0) << v.output;
    EXPECT_NE(v.output.find("leaves hold the input ok"), std::string::npos) << v.output;
    EXPECT_NE(v.output.find("verify: OK"), std::string::npos) << v.output;

    cloud.positions[12345][2] += 10.0;  // the sphere's radius is about 1
    write_xyz(moved, cloud);
    ToolRun f = run("verify " + out.string() + " --mesh " + moved.string() + " --quiet");
    EXPECT_EQ(f.status, 1) << f.output;
    EXPECT_NE(f.output.find("1 input points are farther than the bound"), std::string::npos) << f.output;
}

// A dataset whose first frame needs more than a first request's 64 KiB (the prefix lists every
// node: here 100,000 points in nodes of at most 16) gets a warning naming the option that makes fewer
// nodes; with the default node size it does not.
TEST(CliFormats, ConvertWarnsWhenTheFirstFrameExceedsSixtyFourKiB) {
    fs::path in = scratch() / "cloud_small_nodes.xyz", out = scratch() / "cloud_small_nodes.cpq";
    write_xyz(in, sample_surface(make_sphere(4000, 3), 100000, 9, false, false));
    ToolRun small = run("convert " + in.string() + " -o " + out.string() + " --format points --node-points 16 --quiet");
    ASSERT_EQ(small.status, 0) << small.output;
    EXPECT_NE(small.output.find("over the 64 KiB of a first request; larger nodes (--node-points) make fewer"),
              std::string::npos)
        << small.output;
    ToolRun fine = run("convert " + in.string() + " -o " + out.string() + " --format points --quiet");
    ASSERT_EQ(fine.status, 0) << fine.output;
    EXPECT_EQ(fine.output.find("64 KiB"), std::string::npos) << fine.output;
}

// verify --mesh at a million units from the origin, on a cloud 2e-5 wide (cells of 1e-7; a
// sphere's vertices, some on its axes, exactly 1e6): every
// input point is still found beside its splat. (Its grid divided world coordinates by the cell in
// doubles, and the cell of p + cell came out as p's own: 174 of 10002 points were reported
// uncovered.) Clouds wider or narrower than the converter's single-precision distances hold are
// refused with a message.
TEST(CliFormats, PointsVerifyFarFromTheOriginAndExtremeExtentsAreRefused) {
    fs::path in = scratch() / "far_cloud.xyz", out = scratch() / "far_cloud.cpq";
    PointCloud cloud;
    for (const Vec3d& p : make_sphere(20000, 1).positions)
        cloud.positions.push_back({1e6 + 1e-5 * p[0], 1e6 + 1e-5 * p[1], 1e6 + 1e-5 * p[2]});
    write_xyz(in, cloud);
    ToolRun c = run("convert " + in.string() + " -o " + out.string() + " --format points --quiet");
    ASSERT_EQ(c.status, 0) << c.output;
    ToolRun v = run("verify " + out.string() + " --mesh " + in.string() + " --quiet");
    EXPECT_EQ(v.status, 0) << v.output;
    EXPECT_NE(v.output.find("verify: OK"), std::string::npos) << v.output;

    for (double scale : {1e30, 1e-30}) {
        fs::path extreme = scratch() / "extreme_cloud.xyz", extreme_out = scratch() / "extreme_cloud.cpq";
        PointCloud e = sample_surface(make_sphere(400, 3), 2000, 13, false, false);
        for (Vec3d& p : e.positions)
            for (double& x : p) x *= scale;
        write_xyz(extreme, e);
        ToolRun r = run("convert " + extreme.string() + " -o " + extreme_out.string() + " --format points --quiet");
        EXPECT_EQ(r.status, 1) << r.output;
        EXPECT_NE(r.output.find("rescale the coordinates"), std::string::npos) << r.output;
        expect_nothing_written(extreme_out);
    }
}

// A mesh becomes a point dataset from its vertices (saying that its faces are left out), or from
// points sampled on its surface.
TEST(CliFormats, PointsFromAMeshTakeItsVerticesOrSurfaceSamples) {
    fs::path in = scratch() / "points_mesh.ply", out = scratch() / "points_mesh.cpq";
    const Mesh sphere = make_sphere(6000, 4);
    write_ply(in.string(), sphere);
    ToolRun vertices = run("convert " + in.string() + " -o " + out.string() + " --format points --quiet");
    ASSERT_EQ(vertices.status, 0) << vertices.output;
    EXPECT_NE(vertices.output.find("left out: " + std::to_string(sphere.triangle_count()) + " faces"), std::string::npos)
        << vertices.output;
    ToolRun sampled = run("convert " + in.string() + " -o " + out.string() +
                                 " --format points --surface-samples 7000 --json --quiet", true);
    ASSERT_EQ(sampled.status, 0) << sampled.output;
    EXPECT_EQ(nlohmann::json::parse(sampled.output).at("input").at("points").get<size_t>(), 7000u);
}

// An option of one format given to another is refused by name before anything is read or
// written; so are unknown formats.
TEST(CliFormats, OptionsOfAnotherFormatAreRefusedByName) {
    fs::path in = scratch() / "refuse.ply", out = scratch() / "refuse.cpq";
    write_ply(in.string(), make_sphere(500, 1));
    expect_failure("convert " + in.string() + " -o " + out.string() + " --format aqp --vertex-layout rgb24",
                   "--vertex-layout applies to --format catp, not aqp");
    expect_failure("convert " + in.string() + " -o " + out.string() + " --node-points 100",
                   "--node-points applies to --format points, not catp");
    expect_failure("convert " + in.string() + " -o " + out.string() + " --format points --precision 0.1e",
                   "--precision applies to --format catp and aqp, not points");
    expect_failure("convert " + in.string() + " -o " + out.string() + " --format quads",
                   "unknown --format 'quads' (available: catp, aqp, points)");
    expect_failure("convert " + in.string() + " -o " + out.string() + " --format points --split halves",
                   "--split: 'halves' is not one of balanced, midpoint");
    expect_nothing_written(out);
}

// The point converter works in core: a cloud whose estimate exceeds --memory is refused with
// the estimate and the budget, and nothing is written; under a budget that holds it converts.
// A cloud whose in-core estimate exceeds the budget converts out of core, within the budget, to
// the dataset the in-core converter writes; a budget too small even for that is refused.
TEST(CliFormats, PointsBeyondTheMemoryBudgetConvertOutOfCoreWithinIt) {
    fs::path in = scratch() / "budget.ply", out = scratch() / "budget.cpq", in_core = scratch() / "budget_in_core.cpq";
    write_ply(in.string(), make_sphere(1300000, 3));  // 650,002 vertices: about 62 MiB estimated in core
    expect_failure("convert " + in.string() + " -o " + out.string() + " --format points --memory 9M",
                   "650002 points need about " + std::to_string(points_memory_estimate(650002) >> 20) +
                       " MiB in core, more than the memory budget of 9 MiB, and out of core the point converter needs at "
                       "least 48 MiB");
    expect_nothing_written(out);
    ToolRun whole = run("convert " + in.string() + " -o " + in_core.string() + " --format points --memory 4G --json --quiet", true);
    ASSERT_EQ(whole.status, 0) << whole.output;
    EXPECT_FALSE(nlohmann::json::parse(whole.output).at("out_of_core").get<bool>());
    ToolRun ok = run("convert " + in.string() + " -o " + out.string() + " --format points --memory 48M --json --quiet", true);
    ASSERT_EQ(ok.status, 0) << ok.output;
    const nlohmann::json j = nlohmann::json::parse(ok.output);
    EXPECT_EQ(j.at("memory_estimate").get<uint64_t>(), points_memory_estimate(650002));
    EXPECT_TRUE(j.at("out_of_core").get<bool>());
    EXPECT_GT(j.at("chunks").get<size_t>(), 1u);
    EXPECT_LE(j.at("peak_rss").get<uint64_t>(), uint64_t(48) << 20);
    EXPECT_TRUE(read_file(out.string()) == read_file(in_core.string())) << "out of core wrote another dataset";
}

// In core, a point conversion's peak resident memory, as the kernel measured it (wait4), stays
// within points_memory_estimate: the figure that decides whether a cloud is converted in core
// under --memory. 3M samples with colours, normals and radii estimated: the estimate is 202 MiB.
// Before the partition's allocations were reordered (the input's doubles, the permuted doubles
// and the float copy were resident together) the peak was about 67 bytes a point, 212 MiB here.
TEST(CliFormats, PointsInCorePeakStaysWithinTheEstimate) {
    constexpr size_t kPoints = 3000000;
    fs::path in = scratch() / "peak.ply", out = scratch() / "peak.cpq";
    {
        const PointCloud cloud = sample_surface(make_scan_like(kPoints / 2, 7), kPoints, 11, false, true);
        Mesh mesh;
        mesh.positions = cloud.positions;
        mesh.colors = cloud.colors;
        write_ply(in.string(), mesh);
    }
    const uint64_t estimate = points_memory_estimate(kPoints);
    ChildRun r = run_measured({std::string(CATPAQ_BINARY_DIR) + "/apps/catpaq", "convert", in.string(), "-o", out.string(),
                               "--format", "points", "--memory", std::to_string(estimate), "--json", "--quiet"},
                              (scratch() / "peak.txt").string());
    ASSERT_EQ(r.status, 0) << r.output;
    EXPECT_FALSE(nlohmann::json::parse(r.output).at("out_of_core").get<bool>());
    EXPECT_LE(r.peak_bytes, estimate) << "peak " << (r.peak_bytes >> 20) << " MiB, estimate " << (estimate >> 20) << " MiB";
    fs::remove(in);
    fs::remove(out);
}

// A PLY mesh above AQP's in-core estimate is reduced out of core to what fits, converted within
// the budget (the peak from the kernel), and the dataset's bounds hold against the original file.
TEST(CliFormats, AqpReducesAMeshAboveTheBudgetOutOfCoreAndStaysWithinIt) {
    fs::path in = scratch() / "aqp_large.ply", out = scratch() / "aqp_large.cpq";
    write_ply(in.string(), make_scan_like(400000, 3));  // in core: about 200 MiB
    const uint64_t budget = uint64_t(150) << 20;
    ChildRun r = run_measured({std::string(CATPAQ_BINARY_DIR) + "/apps/catpaq", "convert", in.string(), "-o", out.string(),
                               "--format", "aqp", "--memory", "150M", "--json", "--quiet"},
                              (scratch() / "aqp_large.txt").string());
    ASSERT_EQ(r.status, 0) << r.output;
    const nlohmann::json report = nlohmann::json::parse(r.output);
    const nlohmann::json& reduction = report.at("reduction");
    ASSERT_FALSE(reduction.is_null());
    EXPECT_EQ(reduction.at("input_triangles").get<uint64_t>(), 400000u);
    EXPECT_EQ(report.at("input").at("triangles").get<uint64_t>(), 400000u);
    EXPECT_LT(reduction.at("triangles").get<uint64_t>(), 400000u * 3 / 4);
    EXPECT_GT(reduction.at("triangles").get<uint64_t>(), 400000u / 4);  // not far below what fits
    EXPECT_EQ(report.at("clean").at("triangles").get<uint64_t>(), reduction.at("triangles").get<uint64_t>());
    EXPECT_LE(r.peak_bytes, budget) << "peak " << (r.peak_bytes >> 20) << " MiB";
    ToolRun v = run("verify " + out.string() + " --mesh " + in.string() + " --samples 20000");
    EXPECT_EQ(v.status, 0) << v.output;
    EXPECT_NE(v.output.find("verify: OK"), std::string::npos) << v.output;
    fs::remove(in);
    fs::remove(out);
}

// A point cloud whose reconstruction would exceed the budget is sampled uniformly to what fits
// (the file read once), reconstructed and converted within the budget; a PLY without faces is
// such a cloud.
TEST(CliFormats, AqpSamplesAPointCloudAboveTheBudgetAndStaysWithinIt) {
    fs::path in = scratch() / "aqp_big_cloud.ply", out = scratch() / "aqp_big_cloud.cpq";
    {
        const PointCloud cloud = sample_surface(make_scan_like(60000, 4), 60000, 5, true, false);
        Mesh mesh;
        mesh.positions = cloud.positions;
        mesh.normals = cloud.normals;
        write_ply(in.string(), mesh);
    }
    const uint64_t budget = uint64_t(120) << 20;
    ChildRun r = run_measured({std::string(CATPAQ_BINARY_DIR) + "/apps/catpaq", "convert", in.string(), "-o", out.string(),
                               "--format", "aqp", "--memory", "120M", "--json", "--quiet"},
                              (scratch() / "aqp_big_cloud.txt").string());
    ASSERT_EQ(r.status, 0) << r.output;
    // The warning that says the cloud was sampled (stderr), then the report.
    EXPECT_NE(r.output.find("60000 points need about"), std::string::npos) << r.output;
    const nlohmann::json poisson = nlohmann::json::parse(r.output.substr(r.output.find('{'))).at("poisson");
    EXPECT_EQ(poisson.at("file_points").get<uint64_t>(), 60000u);
    const uint64_t kept = poisson.at("input_points").get<uint64_t>();
    EXPECT_LT(kept, 30000u);
    EXPECT_GT(kept, 10000u);
    EXPECT_EQ(poisson.at("normals_estimated").get<uint64_t>(), 0u);  // the file's normals came along
    EXPECT_LE(r.peak_bytes, budget) << "peak " << (r.peak_bytes >> 20) << " MiB";
    EXPECT_EQ(ArchiveReader(out.string()).header().kind, ArchiveKind::Aqp);
    fs::remove(in);
    fs::remove(out);
}

// What AQP cannot map is refused with a message and leaves nothing behind: a mesh without
// triangles, and a memory budget below the converter's estimate.
TEST(CliFormats, AqpRefusesWhatItCannotConvertAndWritesNothing) {
    fs::path in = scratch() / "aqp_refused.ply", cloud = scratch() / "aqp_cloud.ply", out = scratch() / "aqp_refused.cpq";
    write_ply(in.string(), make_sphere(20000, 1));
    // A PLY without faces is a point cloud (reconstructed first): ten points are too few.
    Mesh points_only = make_sphere(200, 1);
    points_only.indices.clear();
    points_only.positions.resize(10);
    points_only.normals.clear();
    points_only.colors.clear();
    write_ply(cloud.string(), points_only);
    ToolRun none = run("convert " + cloud.string() + " -o " + out.string() + " --format aqp --quiet");
    EXPECT_EQ(none.status, 1) << none.output;
    EXPECT_NE(none.output.find("at least 16 points"), std::string::npos) << none.output;
    ToolRun budget = run("convert " + in.string() + " -o " + out.string() + " --format aqp --memory 1M --quiet");
    EXPECT_EQ(budget.status, 1) << budget.output;
    EXPECT_NE(budget.output.find("above the budget of 1 MiB"), std::string::npos) << budget.output;
    // Too few faces to be worth a reduction: the in-core estimate is what is asked for.
    fs::path small = scratch() / "aqp_refused_small.ply";
    write_ply(small.string(), make_sphere(5000, 1));
    ToolRun tiny = run("convert " + small.string() + " -o " + out.string() + " --format aqp --memory 40M --quiet");
    EXPECT_EQ(tiny.status, 1) << tiny.output;
    EXPECT_NE(tiny.output.find("AQP converts in core"), std::string::npos) << tiny.output;
    expect_nothing_written(out);
    // A PLY's face count is enough to refuse, before the mesh is read: this one's first vertex is
    // NaN, which reading it would report (a large mesh would take the memory and the time first).
    fs::path early_in = scratch() / "aqp_early.ply";
    std::string file = "ply\nformat binary_little_endian 1.0\nelement vertex 30000\nproperty float x\nproperty float y\n"
                       "property float z\nelement face 30000\nproperty list uchar int vertex_indices\nend_header\n";
    auto put = [&file](auto value) { file.append(reinterpret_cast<const char*>(&value), sizeof value); };  // little-endian host
    for (int v = 0; v < 30000; ++v)
        for (int k = 0; k < 3; ++k) put(v == 0 && k == 0 ? std::numeric_limits<float>::quiet_NaN() : float(v % 7 + k));
    for (int f = 0; f < 30000; ++f) {
        file += char(3);
        for (int32_t i : {0, 1, 2}) put(i);
    }
    write_text(early_in, file);
    ToolRun early = run("convert " + early_in.string() + " -o " + out.string() + " --format aqp --memory 40M --quiet");
    EXPECT_EQ(early.status, 1) << early.output;
    EXPECT_NE(early.output.find("30000 triangles"), std::string::npos) << early.output;
    EXPECT_NE(early.output.find("above the budget of 40 MiB"), std::string::npos) << early.output;
    EXPECT_EQ(early.output.find("non-finite"), std::string::npos) << early.output;
    expect_nothing_written(out);
}

// A point cloud given to convert --format aqp becomes a closed surface by Poisson reconstruction
// (normals estimated when the file has none), reported in the JSON, and then an AQP dataset.
TEST(CliFormats, AqpFromAPointCloudReconstructsAClosedSurfaceFirst) {
    fs::path in = scratch() / "aqp_cloud.xyz", out = scratch() / "aqp_cloud.cpq";
    write_xyz(in, sample_surface(make_sphere(4000, 3), 6000, 11, false, false));
    ToolRun c = run("convert " + in.string() + " -o " + out.string() + " --format aqp --json --quiet", true);
    ASSERT_EQ(c.status, 0) << c.output;
    const nlohmann::json report = nlohmann::json::parse(c.output);
    EXPECT_EQ(report.at("poisson").at("input_points").get<size_t>(), 6000u);
    EXPECT_EQ(report.at("poisson").at("normals_estimated").get<size_t>(), 6000u);
    EXPECT_GT(report.at("poisson").at("triangles").get<size_t>(), 1000u);
    EXPECT_EQ(report.at("clean").at("border_edges").get<size_t>(), 0u);
    EXPECT_EQ(report.at("clean").at("components").get<size_t>(), 1u);
    EXPECT_EQ(ArchiveReader(out.string()).header().kind, ArchiveKind::Aqp);
    ToolRun v = run("verify " + out.string() + " --quiet");
    EXPECT_EQ(v.status, 0) << v.output;
}

// An open cloud (a height field: a terrain) is refused by convert --format aqp at once, saying
// why and what to use instead; nothing is written. (The surface mesher ran for minutes on it.)
TEST(CliFormats, AqpRefusesAnOpenCloudQuickly) {
    fs::path in = scratch() / "aqp_terrain.xyz", out = scratch() / "aqp_terrain.cpq";
    PointCloud terrain;
    for (int j = 0; j < 60; ++j)
        for (int i = 0; i < 60; ++i) {
            const double x = i / 59.0, y = j / 59.0;
            terrain.positions.push_back({x, y, 0.1 * (x * x + y) + 0.01 * std::sin(20 * x)});
        }
    write_xyz(in, terrain);
    ToolRun c = run("convert " + in.string() + " -o " + out.string() + " --format aqp --quiet");
    EXPECT_EQ(c.status, 1) << c.output;
    EXPECT_NE(c.output.find("do not enclose a volume"), std::string::npos) << c.output;
    EXPECT_NE(c.output.find("--format points"), std::string::npos) << c.output;
    expect_nothing_written(out);
}

// A point dataset converted by the tool renders headless to the tolerance; its statistics count
// the points drawn (and no triangles).
TEST(CliFormats, PointDatasetsRenderAndCountThePointsDrawn) {
    fs::path in = scratch() / "render_cloud.xyz", out = scratch() / "render_cloud.cpq", stats = scratch() / "points.jsonl";
    write_xyz(in, sample_surface(make_sphere(4000, 3), 40000, 12, false, false));
    ASSERT_EQ(run("convert " + in.string() + " -o " + out.string() + " --format points --node-points 2000 --quiet").status, 0);
    ToolRun r = run("render " + out.string() + " --orbit 2 --size 160x120 --tolerance 2 --stats " + stats.string() +
                    " --out " + (scratch() / "points_frames").string());
    ASSERT_EQ(r.status, 0) << r.output;
    std::ifstream lines(stats);
    std::string line;
    int frames = 0;
    while (std::getline(lines, line)) {
        const nlohmann::json j = nlohmann::json::parse(line);
        EXPECT_EQ(j.at("triangles").get<uint64_t>(), 0u) << line;
        EXPECT_GT(j.at("points").get<uint64_t>(), 1000u) << line;
        EXPECT_TRUE(j.at("tolerance_met").get<bool>()) << line;
        ++frames;
    }
    EXPECT_EQ(frames, 2);
    EXPECT_TRUE(fs::exists(scratch() / "points_frames" / "frame_0001.png"));
}
