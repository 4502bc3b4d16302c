// The catalog's per-format part (server_formats/describers.h): every format of this build is
// described from its real metadata, with its world bounds; metadata of another format is refused
// with a reason rather than misread.
#include <gtest/gtest.h>

#include <filesystem>

#include <nlohmann/json.hpp>

#include "aqp/build.h"
#include "common_codec/archive.h"
#include "mesh/generators.h"
#include "points/builder.h"
#include "points/sampling.h"
#include "scratch_directory.h"
#include "server_formats/describers.h"

using namespace catpaq;
namespace fs = std::filesystem;

namespace {

fs::path scratch(const std::string& name) {
    static const catpaq::test::ScratchDirectory dir("catpaq_describers_");
    return dir / name;
}

// Describes the dataset at `path` with this build's describer of its kind.
nlohmann::json describe(const std::string& path, DatasetDescription& out) {
    ArchiveReader reader(path);
    const DatasetDescribers describers = builtin_dataset_describers();
    auto it = describers.find(reader.header().kind);
    EXPECT_NE(it, describers.end()) << archive_kind_name(reader.header().kind);
    if (it == describers.end()) return {};
    const std::string problem = it->second(reader.header(), reader.meta(), out);
    EXPECT_EQ(problem, "");
    return nlohmann::json::parse(out.details_json);
}

void expect_bounds_hold(const DatasetDescription& d, const Bounds& inside, double slack) {
    ASSERT_TRUE(d.has_bounds);
    for (int a = 0; a < 3; ++a) {
        EXPECT_LE(d.bounds_min[a], inside.min[a] + slack) << a;
        EXPECT_GE(d.bounds_max[a], inside.max[a] - slack) << a;
        EXPECT_LT(d.bounds_max[a] - d.bounds_min[a], (inside.max[a] - inside.min[a]) * 1.1 + slack) << a;
    }
}

}  // namespace

TEST(Describers, AqpDatasetsAreDescribedWithTheirBoundsAndPatchLayout) {
    const Mesh sphere = make_sphere(4000);
    const std::string path = scratch("sphere_aqp.cpq").string();
    aqp::AqpBuildOptions options;
    options.progress = false;
    aqp::AqpBuildReport report;
    aqp::build_aqp_dataset(sphere, path, options, &report);
    DatasetDescription d;
    const nlohmann::json details = describe(path, d);
    expect_bounds_hold(d, sphere.bounds(), 2 * report.precision);
    EXPECT_EQ(details.at("patches").get<size_t>(), report.patches);
    EXPECT_EQ(details.at("patch_level").get<int>(), report.patch_level);
    EXPECT_EQ(details.at("input_triangles").get<size_t>(), sphere.triangle_count());
    EXPECT_EQ(details.at("colors").get<bool>(), sphere.has_colors());
    // Patches per node, by level: level l's node count in the report is the patches over that.
    const nlohmann::json& tiles = details.at("tile_patches");
    ASSERT_EQ(tiles.size(), size_t(report.patch_level) + 1);
    for (int l = 0; l <= report.patch_level; ++l) {
        const size_t per_tile = tiles[size_t(l)].get<size_t>();
        EXPECT_EQ(report.levels[size_t(l)].nodes, (report.patches + per_tile - 1) / per_tile) << l;
    }
    EXPECT_GT(tiles[0].get<size_t>(), 1u);
}

TEST(Describers, PointDatasetsAreDescribedWithTheirBoundsAndNodeCount) {
    const Mesh sphere = make_sphere(4000);
    const std::string path = scratch("sphere_points.cpq").string();
    PointsBuildSettings settings;
    settings.progress = false;
    settings.node_points = 1000;
    PointCloud cloud = sample_surface(sphere, 20000, 3, true, false);
    const Bounds cloud_bounds = cloud.bounds();
    const PointsBuildReport report = build_points(std::move(cloud), path, settings);
    DatasetDescription d;
    const nlohmann::json details = describe(path, d);
    expect_bounds_hold(d, cloud_bounds, 1e-9);
    EXPECT_EQ(details.at("nodes").get<size_t>(), report.nodes);
    EXPECT_EQ(details.at("input_points").get<size_t>(), 20000u);
    EXPECT_EQ(details.at("split").get<std::string>(), "balanced");
}

TEST(Describers, MetadataOfAnotherFormatIsRefusedWithAReason) {
    const Mesh sphere = make_sphere(2000);
    const std::string path = scratch("refused_points.cpq").string();
    PointsBuildSettings settings;
    settings.progress = false;
    build_points(sample_surface(sphere, 3000, 3, true, false), path, settings);
    ArchiveReader reader(path);
    const DatasetDescribers describers = builtin_dataset_describers();
    for (ArchiveKind other : {ArchiveKind::Catp, ArchiveKind::Aqp}) {
        DatasetDescription d;
        const std::string problem = describers.at(other)(reader.header(), reader.meta(), d);
        EXPECT_NE(problem, "") << archive_kind_name(other);
        EXPECT_FALSE(d.has_bounds) << archive_kind_name(other);
    }
}
