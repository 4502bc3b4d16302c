// Error bounds of CATP datasets, measured against the original mesh by `verify`'s machinery:
// the stored (monotone) bound holds at every level, and the leaf level's distance to the original
// is within its quantization step.
#include <gtest/gtest.h>

#include <filesystem>

#include "catp/builder.h"
#include "catp/verify.h"
#include "mesh/generators.h"
#include "mesh/io.h"

using namespace catpaq;
namespace fs = std::filesystem;

namespace {

std::string build_to_temp(const Mesh& mesh, const std::string& name, size_t leaf_triangles, int leaf_level = -1) {
    fs::path dir = fs::temp_directory_path() / ("catpaq_errors_" + std::to_string(getpid()));
    fs::create_directories(dir);
    std::string path = (dir / (name + ".cpq")).string();
    CatpBuildSettings settings;
    settings.leaf_triangles = leaf_triangles;
    settings.leaf_level = leaf_level;
    settings.progress = false;
    build_catp(mesh, path, settings);
    return path;
}

void expect_bounds_hold(const Mesh& mesh, const std::string& path) {
    VerifySettings settings;
    settings.samples_per_level = 20000;
    VerifyReport r = verify_catp(path, &mesh, settings);
    EXPECT_TRUE(r.ok()) << (r.problems.empty() ? "" : r.problems[0]);
    EXPECT_GT(r.faces_checked, 0u);
    const VerifyLevel* leaf = nullptr;
    for (const VerifyLevel& l : r.levels) {
        if (!l.diamonds) continue;
        leaf = &l;
        ASSERT_GE(l.distance_to_original_max, 0.0);
        // The stored error bounds the distance of the level's surface from the original.
        EXPECT_LE(l.distance_to_original_max, l.stored_error) << "level " << l.level;
        EXPECT_LE(l.distance_from_original_max, l.stored_error * 1.5) << "level " << l.level;
        EXPECT_GE(l.stored_error, l.quantization_step * 0.999) << "level " << l.level;
    }
    ASSERT_NE(leaf, nullptr);
    // At full resolution only quantization separates the surface from the original.
    EXPECT_LE(leaf->distance_to_original_max, leaf->quantization_step);
}

}  // namespace

TEST(CatpErrors, StoredBoundsHoldAtEveryLevelOfASphere) {
    Mesh mesh = make_sphere(30000, 9);
    expect_bounds_hold(mesh, build_to_temp(mesh, "sphere", 300));
}

TEST(CatpErrors, StoredBoundsHoldAtEveryLevelOfAScanLikeSurface) {
    Mesh mesh = make_scan_like(60000, 2);
    expect_bounds_hold(mesh, build_to_temp(mesh, "scan", 500));
}

TEST(CatpErrors, StoredBoundsHoldAtEveryLevelOfTheBunny) {
    Mesh mesh = read_mesh(std::string(CATPAQ_SOURCE_DIR) + "/data/bunny.ply");
    expect_bounds_hold(mesh, build_to_temp(mesh, "bunny", 1500));
}

TEST(CatpErrors, HardCasesPassVerifyAndKeepTheirBounds) {
    for (HardCase c : kAllHardCases) {
        SCOPED_TRACE(hard_case_name(c));
        Mesh mesh = make_hard_case(c, 1);
        std::string path = build_to_temp(mesh, hard_case_name(c), 200, 7);
        VerifySettings settings;
        settings.samples_per_level = 5000;
        VerifyReport r = verify_catp(path, &mesh, settings);
        EXPECT_EQ(r.checksum_failures + r.corrupt_nodes + r.bad_flags + r.monotonicity_violations, 0u);
        // The local face check assumes a closed manifold; open and non-manifold inputs are
        // checked globally by the crack tests (border edges only on the original border).
        if (count_border_edges(mesh.indices) == 0 && c != HardCase::NonManifoldEdges) {
            EXPECT_EQ(r.face_mismatches, 0u) << (r.problems.empty() ? "" : r.problems[0]);
        }
        for (const VerifyLevel& l : r.levels) {
            if (l.diamonds && l.distance_to_original_max >= 0) {
                EXPECT_LE(l.distance_to_original_max, l.stored_error) << "level " << l.level;
            }
        }
    }
}
