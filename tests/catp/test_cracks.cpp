// Crack-freeness, topologically: every conforming cut of a closed model, decoded exactly as the
// vertex shader does and welded by exact position, is closed (no border edges).
#include <gtest/gtest.h>

#include <filesystem>
#include <set>

#include "base/error.h"
#include "catp/builder.h"
#include "crack_check.h"
#include "mesh/generators.h"
#include "mesh/io.h"
#include "scratch_directory.h"

using namespace catpaq;
namespace fs = std::filesystem;

namespace {

const fs::path& scratch_dir() {
    static const catpaq::test::ScratchDirectory dir("catpaq_cracks_");
    return dir.path();
}

struct Built {
    std::string path;
    CatpBuildReport report;
};

Built build(const Mesh& mesh, const std::string& name, size_t leaf_triangles, int leaf_level = -1,
            LayoutChoice layout = LayoutChoice::Auto, bool centred = false) {
    Built b;
    b.path = (scratch_dir() / (name + ".cpq")).string();
    CatpBuildSettings settings;
    settings.leaf_triangles = leaf_triangles;
    settings.leaf_level = leaf_level;
    settings.layout = layout;
    settings.progress = false;
    settings.centred_placement = centred;
    b.report = build_catp(mesh, b.path, settings);
    return b;
}

// Checks the finest cut, the coarsest, and `trials` random cuts of both kinds; returns how many
// cuts mixed at least two levels.
int expect_every_cut_closed(const std::string& path, int trials, size_t expected_border = 0) {
    CatpFile file(path);
    std::unordered_map<uint64_t, DiamondFragments> cache;
    std::mt19937_64 rng(42);
    int mixed = 0;
    RefinedSet none;
    test::CutTopology coarsest = test::cut_topology(file, none, cache);
    EXPECT_EQ(coarsest.border_edges, expected_border) << "coarsest cut";
    EXPECT_GT(coarsest.triangles, 0u);
    RefinedSet all;
    for (const ArchiveEntry& e : file.index().entries())
        if (!(e.flags & kCatpLeafFlag)) all.refine(DiamondId{e.key});
    test::CutTopology finest = test::cut_topology(file, all, cache);
    EXPECT_EQ(finest.border_edges, expected_border) << "finest cut";
    for (int t = 0; t < trials; ++t) {
        RefinedSet cut = test::random_cut(file.index(), rng, t % 2 == 1);
        test::CutTopology topo = test::cut_topology(file, cut, cache);
        EXPECT_EQ(topo.border_edges, expected_border) << "random cut " << t << " (" << topo.fragments << " fragments, levels "
                                                      << topo.min_level << ".." << topo.max_level << ")";
        mixed += topo.max_level > topo.min_level;
    }
    return mixed;
}

}  // namespace

TEST(CatpCracks, EveryCutOfAClosedSphereIsClosed) {
    Built b = build(make_sphere(40000, 3), "sphere", 200);
    ASSERT_GE(b.report.leaf_level, 6);
    int mixed = expect_every_cut_closed(b.path, 40);
    EXPECT_GT(mixed, 10);  // the random cuts really mix levels
}

TEST(CatpCracks, EveryCutIsClosedInEveryVertexLayout) {
    const Mesh sphere = make_sphere(30000, 4);
    for (LayoutChoice layout : {LayoutChoice::Rgb24, LayoutChoice::Rgb18, LayoutChoice::Position48}) {
        Built b = build(sphere, "sphere_layout" + std::to_string(int(layout)), 200, -1, layout);
        SCOPED_TRACE(b.report.layout.name());
        EXPECT_GT(expect_every_cut_closed(b.path, 20), 5);
    }
}

TEST(CatpCracks, EveryCutOfAClosedTorusIsClosed) {
    Built b = build(make_torus(40000, 5), "torus", 200);
    int mixed = expect_every_cut_closed(b.path, 40);
    EXPECT_GT(mixed, 10);
}

// Leaves deep enough for the dense sphere (the largest leaf is bounded, not only the mean) leave
// the sparse blob in small fragments far below its own density: cuts still close both surfaces.
TEST(CatpCracks, EveryCutOfAnUnevenDensityMeshIsClosed) {
    Mesh mesh = make_uneven_density(40000, 2);
    Built b = build(mesh, "uneven", 200);
    int mixed = expect_every_cut_closed(b.path, 30);
    EXPECT_GT(mixed, 10);
}

TEST(CatpCracks, EveryCutOfTheBunnyIsClosed) {
    Mesh bunny = read_mesh(std::string(CATPAQ_SOURCE_DIR) + "/data/bunny.ply");
    Built b = build(bunny, "bunny", 1000);
    expect_every_cut_closed(b.path, 30);
}

// In both placements: centred, as the cases are built (geometry on the lattice planes of every
// level), and the default, shifted off them.
TEST(CatpCracks, HardCasesAreCrackFreeOrRefused) {
    for (bool centred : {true, false})
    for (HardCase c : kAllHardCases) {
        Mesh mesh = make_hard_case(c, 1);
        SCOPED_TRACE(std::string(hard_case_name(c)) + (centred ? ", centred" : ", shifted"));
        size_t border = count_border_edges(mesh.indices);
        Built b;
        try {
            // A deep leaf level, so many lattice planes, edges and corners cut the model.
            b = build(mesh, hard_case_name(c), 200, 7, LayoutChoice::Auto, centred);
        } catch (const Error& e) {
            ADD_FAILURE() << "refused: " << e.what();
            continue;
        }
        if (border == 0 && c != HardCase::NonManifoldEdges && c != HardCase::DegenerateAndDuplicateTriangles) {
            EXPECT_GT(expect_every_cut_closed(b.path, 30), 5);
            continue;
        }
        // Open or non-manifold: every border edge of every cut lies on the original border
        // (within the largest stored error: coarse levels may slide the border along itself).
        CatpFile file(b.path);
        double tolerance = 0;
        for (const ArchiveEntry& e : file.index().entries()) tolerance = std::max(tolerance, double(e.error));
        std::unordered_map<uint64_t, DiamondFragments> cache;
        std::mt19937_64 rng(11);
        RefinedSet all;
        for (const ArchiveEntry& e : file.index().entries())
            if (!(e.flags & kCatpLeafFlag)) all.refine(DiamondId{e.key});
        EXPECT_EQ(test::border_edges_off_original_border(file, all, mesh, tolerance, cache), 0u) << "finest cut";
        EXPECT_EQ(test::border_edges_off_original_border(file, RefinedSet{}, mesh, tolerance, cache), 0u) << "coarsest";
        for (int t = 0; t < 20; ++t) {
            RefinedSet cut = test::random_cut(file.index(), rng, t % 2 == 1);
            EXPECT_EQ(test::border_edges_off_original_border(file, cut, mesh, tolerance, cache), 0u) << "random cut " << t;
        }
    }
}

// Leaves follow the density: on a mesh whose density varies a hundredfold they sit at several
// levels (a cut of the hierarchy, so every cut of the dataset is still closed), and the dataset
// is smaller than with every leaf at the dense part's level.
TEST(CatpCracks, AdaptiveLeavesSitAtSeveralLevelsAndEveryCutIsClosed) {
    Mesh mesh = make_uneven_density(200000, 2);
    Built adaptive = build(mesh, "uneven_adaptive", 200);
    CatpFile file(adaptive.path);
    std::set<int> leaf_levels;
    for (const ArchiveEntry& e : file.index().entries())
        if (e.flags & kCatpLeafFlag) leaf_levels.insert(e.level);
    ASSERT_GE(leaf_levels.size(), 2u) << "the leaves are at one level: the test proves nothing";
    EXPECT_EQ(*leaf_levels.rbegin(), adaptive.report.leaf_level);
    EXPECT_GT(expect_every_cut_closed(adaptive.path, 30), 10);
    Built uniform = build(mesh, "uneven_uniform", 200, adaptive.report.leaf_level);
    EXPECT_LT(adaptive.report.file_bytes * 3, uniform.report.file_bytes * 2)
        << "adaptive " << adaptive.report.file_bytes << " bytes, uniform " << uniform.report.file_bytes;
}
