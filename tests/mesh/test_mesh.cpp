#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "base/error.h"
#include "mesh/mesh.h"

using namespace catpaq;

namespace {

Mesh tetrahedron() {
    Mesh mesh;
    mesh.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
    mesh.indices = {0, 2, 1, 0, 1, 3, 1, 2, 3, 0, 3, 2};  // outward
    return mesh;
}

}  // namespace

TEST(Bounds, EmptyAndDiagonal) {
    Bounds bounds;
    EXPECT_TRUE(bounds.empty());
    EXPECT_EQ(bounds.diagonal(), 0.0);
    bounds.add({1, 2, 3});
    EXPECT_FALSE(bounds.empty());
    EXPECT_EQ(bounds.diagonal(), 0.0);
    bounds.add({4, 6, 3});
    EXPECT_DOUBLE_EQ(bounds.diagonal(), 5.0);
}

TEST(Mesh, BoundsCoverAllPositions) {
    Mesh mesh = tetrahedron();
    mesh.positions.push_back({-2, 0.5, 7});
    Bounds bounds = mesh.bounds();
    EXPECT_EQ(bounds.min, (Vec3d{-2, 0, 0}));
    EXPECT_EQ(bounds.max, (Vec3d{1, 1, 7}));
}

TEST(ValidateMesh, AcceptsAValidMesh) { EXPECT_NO_THROW(validate_mesh(tetrahedron(), "tet")); }

TEST(ValidateMesh, RejectsEachBrokenInvariant) {
    auto expect_error = [](const Mesh& mesh, const char* word) {
        try {
            validate_mesh(mesh, "thing.ply");
            ADD_FAILURE() << "expected an error about " << word;
        } catch (const Error& e) {
            EXPECT_NE(std::string(e.what()).find("thing.ply"), std::string::npos) << e.what();
            EXPECT_NE(std::string(e.what()).find(word), std::string::npos) << e.what();
        }
    };
    Mesh nan = tetrahedron();
    nan.positions[2][1] = std::numeric_limits<double>::quiet_NaN();
    expect_error(nan, "non-finite");
    Mesh inf = tetrahedron();
    inf.positions[0][0] = std::numeric_limits<double>::infinity();
    expect_error(inf, "non-finite");
    Mesh range = tetrahedron();
    range.indices[4] = 4;
    expect_error(range, "out of range");
    Mesh ragged = tetrahedron();
    ragged.indices.push_back(0);
    expect_error(ragged, "multiple of 3");
    Mesh normals = tetrahedron();
    normals.normals.resize(3);
    expect_error(normals, "normals");
    Mesh colors = tetrahedron();
    colors.colors.resize(5);
    expect_error(colors, "colours");
}

TEST(VertexNormals, AreAreaWeightedUnitVectors) {
    Mesh mesh = tetrahedron();
    std::vector<Vec3f> normals = compute_vertex_normals(mesh);
    ASSERT_EQ(normals.size(), 4u);
    for (const Vec3f& n : normals) EXPECT_NEAR(std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]), 1.0, 1e-6);
    // Vertex 0 touches the three axis-aligned faces (each area 1/2): the normal is (-1,-1,-1)/sqrt(3).
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(normals[0][k], -1.0 / std::sqrt(3.0), 1e-6);
    // Vertex 1 touches faces with weighted normals -z, -y and (1,1,1): they sum to +x.
    EXPECT_NEAR(normals[1][0], 1.0, 1e-6);
    EXPECT_NEAR(normals[1][1], 0.0, 1e-6);
    EXPECT_NEAR(normals[1][2], 0.0, 1e-6);
}

TEST(VertexNormals, IsolatedVerticesGetPlusZ) {
    Mesh mesh = tetrahedron();
    mesh.positions.push_back({5, 5, 5});
    std::vector<Vec3f> normals = compute_vertex_normals(mesh);
    EXPECT_EQ(normals[4], (Vec3f{0, 0, 1}));
}

TEST(EdgeCounts, ClosedOpenAndNonManifold) {
    Mesh mesh = tetrahedron();
    EdgeCounts closed = count_edges(mesh.indices);
    EXPECT_EQ(closed.edges, 6u);
    EXPECT_EQ(closed.border, 0u);
    EXPECT_EQ(closed.manifold, 6u);
    EXPECT_EQ(closed.nonmanifold, 0u);
    EXPECT_EQ(closed.misoriented, 0u);
    EXPECT_EQ(count_border_edges(mesh.indices), 0u);

    std::vector<uint32_t> open(mesh.indices.begin(), mesh.indices.begin() + 9);  // one face removed
    EXPECT_EQ(count_border_edges(open), 3u);

    std::vector<uint32_t> fin = mesh.indices;
    fin.insert(fin.end(), {0, 1, 3});  // a duplicate of face 1 makes three of its edges non-manifold
    EdgeCounts counts = count_edges(fin);
    EXPECT_EQ(counts.nonmanifold, 3u);
    EXPECT_EQ(counts.border, 0u);

    std::vector<uint32_t> flipped = mesh.indices;
    std::swap(flipped[1], flipped[2]);  // one face reversed: its three edges are misoriented
    EXPECT_EQ(count_edges(flipped).misoriented, 3u);

    // A repeated index contributes no self edge; the other two corners still form an edge.
    EdgeCounts degenerate = count_edges({0, 0, 1});
    EXPECT_EQ(degenerate.edges, 1u);
    EXPECT_EQ(degenerate.manifold, 1u);  // 0-1 traversed once each way
}
