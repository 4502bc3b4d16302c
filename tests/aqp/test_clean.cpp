// Input cleaning (aqp/clean.h): what it removes, splits and re-orients is counted, the result is an
// oriented two-manifold, and what cannot be made one is refused with a message.
#include <gtest/gtest.h>

#include <cmath>

#include "aqp/clean.h"
#include "base/error.h"
#include "mesh/generators.h"
#include "support.h"

using namespace catpaq;
using namespace catpaq::aqp;

namespace {

// Throws unless `mesh` cleans; returns the report.
CleanReport clean_report(const Mesh& mesh, CleanMesh* out = nullptr) {
    CleanReport r;
    CleanMesh c = clean_to_manifold(mesh, {}, &r);
    std::string why;
    EXPECT_TRUE(is_oriented_manifold(c.mesh, &why)) << why;
    EXPECT_EQ(c.source_vertex.size(), c.mesh.vertex_count());
    for (size_t v = 0; v < c.mesh.vertex_count(); ++v) EXPECT_EQ(c.mesh.positions[v], mesh.positions[c.source_vertex[v]]);
    if (out) *out = std::move(c);
    return r;
}

// The cleaned triangles in input vertex numbers.
std::vector<uint32_t> source_indices(const CleanMesh& c) {
    std::vector<uint32_t> out;
    for (uint32_t i : c.mesh.indices) out.push_back(c.source_vertex[i]);
    return out;
}

}  // namespace

TEST(AqpClean, ACleanClosedMeshPassesUnchanged) {
    Mesh sphere = make_sphere(2000, 3);
    CleanMesh c;
    CleanReport r = clean_report(sphere, &c);
    EXPECT_EQ(r.triangles, sphere.triangle_count());
    EXPECT_EQ(r.vertices, sphere.vertex_count());
    EXPECT_TRUE(r.summary().empty());
    EXPECT_EQ(r.genus, 0);
    EXPECT_EQ(r.border_edges, 0u);
    EXPECT_EQ(source_indices(c), sphere.indices);
}

TEST(AqpClean, GenusAndBordersAreCounted) {
    EXPECT_EQ(clean_report(make_torus(2000, 2)).genus, 1);
    CleanReport holes = clean_report(make_hard_case(HardCase::Holes));
    EXPECT_EQ(holes.border_edges, hard_case_border_edges(HardCase::Holes));
    EXPECT_EQ(holes.border_loops, 4u);
    EXPECT_EQ(holes.genus, 0);
}

TEST(AqpClean, DegenerateAndDuplicateTrianglesAreRemovedAndCounted) {
    // A box plus a repeated index, a single point, a collinear triple both ways, an exact
    // duplicate and a reversed duplicate (mesh/generators.h).
    CleanReport r = clean_report(make_hard_case(HardCase::DegenerateAndDuplicateTriangles));
    EXPECT_EQ(r.degenerate_triangles, 4u);
    EXPECT_EQ(r.duplicate_triangles, 2u);
    EXPECT_EQ(r.border_edges, 0u);
    EXPECT_EQ(r.components, 1u);
    EXPECT_FALSE(r.summary().empty());
}

TEST(AqpClean, ExactlyCoincidentVerticesAreWelded) {
    // Two triangles of a square that share no index but two positions: welding joins them.
    Mesh m;
    m.positions = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 0, 0}, {1, 1, 0}, {0, 1, 0}};
    m.indices = {0, 1, 2, 3, 4, 5};
    CleanMesh c;
    CleanReport r = clean_report(m, &c);
    EXPECT_EQ(r.welded_vertices, 2u);
    EXPECT_EQ(c.mesh.vertex_count(), 4u);
    EXPECT_EQ(r.border_edges, 4u);
}

// A UV sphere whose poles are rings of 40 vertices computed with sin(0) and sin(pi): the north
// ring coincides exactly, the south one spreads over 1.2e-16. Both are welded into one pole
// (edges under 1e-9 of the diagonal), so the sphere is one closed genus-0 surface; before, the
// south ring stayed a fan of needles that AQP's domain could not simplify. Two parallel
// sheets 1e-12 apart share no edge and stay apart.
TEST(AqpClean, VerticesAFewUlpsApartAlongAnEdgeAreWelded) {
    const int rows = 20, columns = 40;
    Mesh sphere;
    for (int j = 0; j <= rows; ++j)
        for (int i = 0; i < columns; ++i) {
            const double t = M_PI * j / rows, f = 2 * M_PI * i / columns;
            sphere.positions.push_back({std::sin(t) * std::cos(f), std::sin(t) * std::sin(f), std::cos(t)});
        }
    for (int j = 0; j < rows; ++j)
        for (int i = 0; i < columns; ++i) {
            const uint32_t a = uint32_t(j * columns + i), b = uint32_t(j * columns + (i + 1) % columns);
            sphere.indices.insert(sphere.indices.end(), {a, a + columns, b + columns, a, b + columns, b});
        }
    CleanMesh c;
    CleanReport r = clean_report(sphere, &c);
    EXPECT_EQ(r.welded_vertices, 2u * (columns - 1));
    EXPECT_EQ(r.components, 1u);
    EXPECT_EQ(r.border_edges, 0u);
    EXPECT_EQ(r.genus, 0);
    EXPECT_EQ(c.mesh.vertex_count(), size_t((rows - 1) * columns + 2));

    Mesh sheets;
    sheets.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1e-12}, {1, 0, 1e-12}, {0, 1, 1e-12}};
    sheets.indices = {0, 1, 2, 3, 5, 4};
    CleanReport apart = clean_report(sheets);
    EXPECT_EQ(apart.welded_vertices, 0u);
    EXPECT_EQ(apart.components, 2u);
}

TEST(AqpClean, NonManifoldEdgesAreSplitIntoManifoldPieces) {
    // Three sheets on one hinge and two boxes sharing an edge: 2 non-manifold edges.
    Mesh input = make_hard_case(HardCase::NonManifoldEdges);
    CleanMesh c;
    CleanReport r = clean_report(input, &c);
    EXPECT_EQ(r.nonmanifold_edges, 2u);
    EXPECT_GT(r.split_vertices, 0u);
    EXPECT_EQ(r.triangles, input.triangle_count());  // split, nothing removed
    // The first two sheets stay joined across the hinge, the third is cut loose; the boxes part.
    EXPECT_EQ(r.components, 4u);
    EXPECT_EQ(count_edges(c.mesh.indices).nonmanifold, 0u);
}

TEST(AqpClean, ABowtieVertexBecomesTwoVertices) {
    Mesh m;
    m.positions = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {-1, 0, 0}, {-1, -1, 0}};
    m.indices = {0, 1, 2, 0, 3, 4};  // two triangles touching only at vertex 0
    CleanMesh c;
    CleanReport r = clean_report(m, &c);
    EXPECT_EQ(r.nonmanifold_vertices, 1u);
    EXPECT_EQ(r.split_vertices, 1u);
    EXPECT_EQ(c.mesh.vertex_count(), 6u);
    EXPECT_EQ(r.components, 2u);
}

TEST(AqpClean, InconsistentOrientationIsRepairedTowardsTheMajority) {
    Mesh sphere = make_sphere(2000, 4);
    Mesh flipped = sphere;
    for (size_t t = 0; t < 10; ++t) std::swap(flipped.indices[3 * t * 7 + 1], flipped.indices[3 * t * 7 + 2]);
    CleanMesh c;
    CleanReport r = clean_report(flipped, &c);
    EXPECT_EQ(r.flipped_triangles, 10u);
    EXPECT_EQ(source_indices(c), sphere.indices);  // the outward orientation most triangles had
}

TEST(AqpClean, TinyComponentsAreDroppedAndCounted) {
    Mesh m = make_sphere(2000, 5);
    // A far away triangle, a millionth of the sphere's area.
    const uint32_t n = uint32_t(m.vertex_count());
    m.positions.insert(m.positions.end(), {{5, 5, 5}, {5.001, 5, 5}, {5, 5.001, 5}});
    m.normals.insert(m.normals.end(), 3, Vec3f{0, 0, 1});
    m.colors.insert(m.colors.end(), 3, Rgb8{1, 2, 3});
    m.indices.insert(m.indices.end(), {n, n + 1, n + 2});
    CleanMesh c;
    CleanReport r = clean_report(m, &c);
    EXPECT_EQ(r.dropped_components, 1u);
    EXPECT_EQ(r.dropped_component_triangles, 1u);
    EXPECT_EQ(r.unreferenced_vertices, 3u);
    EXPECT_EQ(c.mesh.triangle_count(), m.triangle_count() - 1);
    EXPECT_EQ(c.mesh.colors.size(), c.mesh.vertex_count());
}

TEST(AqpClean, ANonOrientableSurfaceIsRefusedWithAMessage) {
    try {
        clean_to_manifold(aqp::test::moebius_band(24), {});
        FAIL() << "a Moebius band was accepted";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("orientable"), std::string::npos) << e.what();
    }
}

TEST(AqpClean, EmptyAndAllDegenerateInputsAreRefusedWithAMessage) {
    Mesh empty;
    EXPECT_THROW(clean_to_manifold(empty, {}), Error);
    Mesh flat;
    flat.positions = {{0, 0, 0}, {1, 0, 0}, {2, 0, 0}};
    flat.indices = {0, 1, 2, 0, 0, 1};
    try {
        clean_to_manifold(flat, {});
        FAIL() << "a mesh of degenerate triangles was accepted";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("degenerate"), std::string::npos) << e.what();
    }
}

TEST(AqpClean, NonFiniteCoordinatesAreRefusedWithAMessage) {
    Mesh m = make_sphere(200, 1);
    m.positions[7][1] = std::nan("");
    try {
        clean_to_manifold(m, {});
        FAIL() << "a NaN coordinate was accepted";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("non-finite"), std::string::npos) << e.what();
    }
}
