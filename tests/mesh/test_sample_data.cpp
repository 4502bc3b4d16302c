// The bundled sample model (see data/README.md).
#include <gtest/gtest.h>

#include "mesh/io.h"

using namespace catpaq;

TEST(SampleData, BunnyIsTheExpectedClosedMesh) {
    Mesh bunny = read_mesh(std::string(CATPAQ_SOURCE_DIR) + "/data/bunny.ply");
    EXPECT_EQ(bunny.vertex_count(), 37706u);
    EXPECT_EQ(bunny.triangle_count(), 75408u);
    EXPECT_TRUE(bunny.has_normals());
    EdgeCounts edges = count_edges(bunny.indices);
    EXPECT_EQ(edges.border, 0u);
    EXPECT_EQ(edges.nonmanifold, 0u);
    // Closed and of genus 0: V - E + F = 2.
    EXPECT_EQ(int64_t(bunny.vertex_count()) - int64_t(edges.edges) + int64_t(bunny.triangle_count()), 2);
}
