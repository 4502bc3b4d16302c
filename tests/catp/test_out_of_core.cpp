// The out-of-core converter: the memory budget changes where data lives, never the dataset;
// streamed PLY input gives the same dataset as the mesh in memory; bad input leaves nothing.
#include <gtest/gtest.h>
#include <tbb/parallel_for.h>

#include <filesystem>
#include <map>

#include "base/atomic_file.h"
#include "base/error.h"
#include "base/paged_array.h"
#include "catp/builder.h"
#include "common_codec/archive.h"
#include "mesh/generators.h"
#include "mesh/io.h"
#include "scratch_directory.h"

using namespace catpaq;
namespace fs = std::filesystem;

namespace {

// A directory per test, removed when the test ends.
struct TempDir {
    catpaq::test::ScratchDirectory dir{
        "catpaq_ooc_", std::string("_") + ::testing::UnitTest::GetInstance()->current_test_info()->name()};
    const fs::path path = dir.path();
    std::string file(const std::string& name) const { return (dir / name).string(); }
};

std::string bytes_of(const std::string& path) { return read_file(path); }

CatpBuildSettings quiet_settings(uint64_t budget = 0) {
    CatpBuildSettings s;
    s.progress = false;
    s.memory_budget = budget;
    return s;
}

// Node payloads by key: the geometry, independent of the header's input flags.
std::map<uint64_t, std::string> node_bytes(const std::string& path) {
    ArchiveReader archive(path);
    std::map<uint64_t, std::string> nodes;
    for (size_t i = 0; i < archive.entries().size(); ++i) {
        std::string error;
        const uint8_t* bytes = archive.node(i, &error);
        EXPECT_NE(bytes, nullptr) << error;
        if (bytes) nodes[archive.entries()[i].key] = std::string(bytes, bytes + archive.entries()[i].size);
    }
    return nodes;
}

}  // namespace

TEST(CatpOutOfCore, PagedArrayKeepsEveryRecordThroughEvictions) {
    TempDir dir;
    const uint64_t n = 100000;
    // Two pages fit the cache: nearly every access below evicts a page.
    PagedArray<uint64_t> paged(n, 2 * PagedArray<uint64_t>::kPageRecords * sizeof(uint64_t), dir.file("x"));
    std::vector<uint64_t> reference(n, 0);
    uint64_t state = 12345;
    for (int i = 0; i < 200000; ++i) {
        state = state * 6364136223846793005ull + 1442695040888963407ull;
        uint64_t at = (state >> 17) % n;
        if (i % 3 == 0) {
            paged.at_for_write(at) = state;
            reference[at] = state;
        } else {
            ASSERT_EQ(paged.at(at), reference[at]) << "record " << at << " after " << i << " operations";
        }
    }
    for (uint64_t at = 0; at < n; ++at) ASSERT_EQ(paged.at(at), reference[at]);
    EXPECT_GT(paged.bytes_spilled(), 0u);
}

TEST(CatpOutOfCore, PagedArrayResidentWritesFromManyThreadsAreWhatAtReads) {
    TempDir dir;
    const uint64_t n = 50000;
    PagedArray<uint64_t> paged(n, n * sizeof(uint64_t) * 2, dir.file("x"));
    for (uint64_t i = 0; i < n; ++i) paged.at_for_write(i) = i;
    ASSERT_TRUE(paged.resident());
    tbb::parallel_for(uint64_t(0), n, [&](uint64_t i) { paged.resident_at(i) = 3 * i + 1; });
    for (uint64_t i = 0; i < n; ++i) ASSERT_EQ(paged.at(i), 3 * i + 1) << "record " << i;
    EXPECT_EQ(paged.bytes_spilled(), 0u);
}

TEST(CatpOutOfCore, TheDatasetDoesNotDependOnTheMemoryBudget) {
    TempDir dir;
    Mesh mesh = make_scan_like(200000, 3);
    std::string input = dir.file("scan.ply");
    write_ply(input, mesh, true);
    CatpBuildReport roomy = build_catp_file(input, dir.file("roomy.cpq"), quiet_settings());
    // The smallest budget (4 MiB of data): the vertices (100k x 40 bytes) are paged, the
    // triangles spilled in many blocks, and most fragments go through scratch files.
    CatpBuildReport tight = build_catp_file(input, dir.file("tight.cpq"), quiet_settings(minimum_memory_budget()));
    EXPECT_EQ(roomy.bytes_spilled, 0u);
    EXPECT_GT(tight.bytes_spilled, 20u << 20) << "the tight build should have spilled its triangles";
    EXPECT_GT(tight.blocks, roomy.blocks);
    EXPECT_GT(tight.block_level, roomy.block_level);
    EXPECT_EQ(bytes_of(dir.file("roomy.cpq")), bytes_of(dir.file("tight.cpq")));
    // Nothing is left in the directory but the inputs and outputs (scratch files are anonymous).
    size_t files = 0;
    for (auto& entry : fs::directory_iterator(dir.path)) {
        (void)entry;
        files++;
    }
    EXPECT_EQ(files, 3u);
}

// Leaves follow the density, and a small budget asks for blocks finer than the sparse part's
// leaves: those gather their triangles from every block they were binned in, in input order,
// so the dataset is still the one a roomy budget makes.
TEST(CatpOutOfCore, AdaptiveLeavesAcrossBlocksGiveTheSameDataset) {
    TempDir dir;
    Mesh mesh = make_uneven_density(200000, 2);
    std::string input = dir.file("uneven.ply");
    write_ply(input, mesh, true);
    CatpBuildSettings settings = quiet_settings();
    settings.leaf_triangles = 200;
    CatpBuildReport roomy = build_catp_file(input, dir.file("roomy.cpq"), settings);
    settings.memory_budget = minimum_memory_budget();
    CatpBuildReport tight = build_catp_file(input, dir.file("tight.cpq"), settings);
    EXPECT_LT(roomy.coarsest_leaf_level, roomy.leaf_level) << "the leaves are at one level: the test proves nothing";
    EXPECT_EQ(roomy.leaves_across_blocks, 0u);
    EXPECT_GT(tight.leaves_across_blocks, 0u) << "no leaf crossed blocks: the test proves nothing";
    EXPECT_GT(tight.bytes_spilled, 0u);
    EXPECT_EQ(bytes_of(dir.file("roomy.cpq")), bytes_of(dir.file("tight.cpq")));
}

TEST(CatpOutOfCore, StreamedPlyGivesTheDatasetOfTheMeshInMemory) {
    TempDir dir;
    Mesh mesh = make_sphere(30000, 2);
    std::string input = dir.file("sphere.ply");
    write_ply(input, mesh, true);
    build_catp(read_mesh(input), dir.file("memory.cpq"), quiet_settings());
    build_catp_file(input, dir.file("streamed.cpq"), quiet_settings(minimum_memory_budget()));
    EXPECT_EQ(bytes_of(dir.file("memory.cpq")), bytes_of(dir.file("streamed.cpq")));
}

TEST(CatpOutOfCore, NormalsComputedWhileStreamingEqualComputeVertexNormals) {
    TempDir dir;
    Mesh mesh = make_torus(30000, 4);
    mesh.normals.clear();
    std::string input = dir.file("torus.ply");
    write_ply(input, mesh, true);
    // Streamed, normals computed by the converter from the file (with paged sums)...
    build_catp_file(input, dir.file("streamed.cpq"), quiet_settings(minimum_memory_budget()));
    // ... and in memory with the mesh module's normals.
    Mesh with_normals = read_mesh(input);
    with_normals.normals = compute_vertex_normals(with_normals);
    build_catp(with_normals, dir.file("memory.cpq"), quiet_settings());
    EXPECT_EQ(node_bytes(dir.file("streamed.cpq")), node_bytes(dir.file("memory.cpq")));
}

TEST(CatpOutOfCore, TruncatedPlyIsRefusedAndLeavesNothingBehind) {
    TempDir dir;
    Mesh mesh = make_sphere(20000, 1);
    std::string input = dir.file("sphere.ply");
    write_ply(input, mesh, true);
    std::string full = bytes_of(input);
    write_file_atomic(input, full.data(), full.size() - 1000);  // cut inside the face list
    std::string output = dir.file("out.cpq");
    try {
        build_catp_file(input, output, quiet_settings(minimum_memory_budget()));
        FAIL() << "a truncated file was accepted";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("sphere.ply"), std::string::npos) << e.what();
    }
    EXPECT_FALSE(fs::exists(output));
    size_t files = 0;
    for (auto& entry : fs::directory_iterator(dir.path)) {
        (void)entry;
        files++;
    }
    EXPECT_EQ(files, 1u) << "only the input may remain";
}

TEST(CatpOutOfCore, BudgetsBelowTheMinimumAreRefused) {
    TempDir dir;
    Mesh mesh = make_sphere(2000, 1);
    EXPECT_THROW(build_catp(mesh, dir.file("x.cpq"), quiet_settings(minimum_memory_budget() - 1)), Error);
    EXPECT_FALSE(fs::exists(dir.file("x.cpq")));
}

TEST(CatpOutOfCore, AMeshOfOnlyDegenerateTrianglesIsRefused) {
    TempDir dir;
    Mesh mesh;
    mesh.positions = {{0, 0, 0}, {1, 0, 0}, {2, 0, 0}, {0, 1, 0}};
    mesh.indices = {0, 1, 2, 0, 0, 3, 1, 1, 1};  // collinear, repeated index, a point
    try {
        build_catp(mesh, dir.file("x.cpq"), quiet_settings());
        FAIL() << "a mesh without area was accepted";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("has an area"), std::string::npos) << e.what();
    }
    EXPECT_FALSE(fs::exists(dir.file("x.cpq")));
}

TEST(CatpOutOfCore, AQuadPlyIsStreamedWithTheLevelsOfItsTriangles) {
    TempDir dir;
    // A 100 x 100 grid of quads: 10k polygons, 20k triangles.
    std::string input = dir.file("quads.ply");
    {
        std::string text;
        const int n = 100;
        text += "ply\nformat ascii 1.0\nelement vertex " + std::to_string((n + 1) * (n + 1)) +
                "\nproperty double x\nproperty double y\nproperty double z\nelement face " + std::to_string(n * n) +
                "\nproperty list uchar int vertex_indices\nend_header\n";
        for (int y = 0; y <= n; ++y)
            for (int x = 0; x <= n; ++x)
                text += std::to_string(x) + " " + std::to_string(y) + " " + std::to_string((x * y) % 7) + "\n";
        for (int y = 0; y < n; ++y)
            for (int x = 0; x < n; ++x) {
                int a = y * (n + 1) + x;
                text += "4 " + std::to_string(a) + " " + std::to_string(a + 1) + " " + std::to_string(a + n + 2) + " " +
                        std::to_string(a + n + 1) + "\n";
            }
        write_file_atomic(input, text.data(), text.size());
    }
    CatpBuildSettings settings = quiet_settings();
    settings.leaf_triangles = 1000;
    CatpBuildReport streamed = build_catp_file(input, dir.file("streamed.cpq"), settings);
    CatpBuildReport memory = build_catp(read_mesh(input), dir.file("memory.cpq"), settings);
    EXPECT_EQ(streamed.input_triangles, 20000u);
    EXPECT_EQ(streamed.leaf_level, memory.leaf_level);
    EXPECT_EQ(bytes_of(dir.file("streamed.cpq")), bytes_of(dir.file("memory.cpq")));
}
