// Cross-check: OpenMesh's readers and ours agree on files we write (PLY ascii and binary) and on
// an OFF file written here, for a generated sphere.
#include <gtest/gtest.h>

#include <OpenMesh/Core/IO/MeshIO.hh>
#include <OpenMesh/Core/Mesh/TriMesh_ArrayKernelT.hh>
#include <cstdio>

#include "mesh/generators.h"
#include "mesh/io.h"
#include "test_util.h"

using namespace catpaq;
using OpenMeshTriangles = OpenMesh::TriMesh_ArrayKernelT<>;

namespace {

std::string write_off(const std::string& name, const Mesh& mesh) {
    std::string text = "OFF\n" + std::to_string(mesh.vertex_count()) + " " + std::to_string(mesh.triangle_count());
    text += " 0\n";
    char line[128];
    for (const Vec3d& p : mesh.positions) {
        std::snprintf(line, sizeof line, "%.9g %.9g %.9g\n", p[0], p[1], p[2]);
        text += line;
    }
    for (size_t t = 0; t < mesh.triangle_count(); ++t) {
        std::snprintf(line, sizeof line, "3 %u %u %u\n", mesh.indices[3 * t], mesh.indices[3 * t + 1],
                      mesh.indices[3 * t + 2]);
        text += line;
    }
    return test::write_file(name, text);
}

void expect_agreement(const std::string& path) {
    SCOPED_TRACE(path);
    OpenMeshTriangles reference;
    ASSERT_TRUE(OpenMesh::IO::read_mesh(reference, path));
    Mesh ours = read_mesh(path);
    ASSERT_EQ(ours.vertex_count(), reference.n_vertices());
    ASSERT_EQ(ours.triangle_count(), reference.n_faces());
    size_t mismatches = 0;
    for (auto vertex : reference.vertices()) {
        const auto& p = reference.point(vertex);
        const Vec3d& q = ours.positions[size_t(vertex.idx())];
        for (int k = 0; k < 3; ++k)
            if (float(q[k]) != p[k]) ++mismatches;  // OpenMesh stores float: compare at float precision
    }
    EXPECT_EQ(mismatches, 0u);
    // Same triangles, up to the rotation of corners OpenMesh may apply.
    size_t different = 0;
    for (auto face : reference.faces()) {
        std::array<uint32_t, 3> theirs;
        int k = 0;
        for (auto vertex : reference.fv_range(face)) theirs[k++] = uint32_t(vertex.idx());
        const uint32_t* mine = &ours.indices[3 * size_t(face.idx())];
        bool same = false;
        for (int r = 0; r < 3; ++r)
            same |= theirs[0] == mine[r] && theirs[1] == mine[(r + 1) % 3] && theirs[2] == mine[(r + 2) % 3];
        different += !same;
    }
    EXPECT_EQ(different, 0u);
}

}  // namespace

TEST(OpenMeshCrossCheck, PlyAsciiPlyBinaryAndOff) {
    Mesh sphere = make_sphere(5000, 11);
    std::string ascii = test::scratch("openmesh_ascii.ply"), binary = test::scratch("openmesh_binary.ply");
    write_ply(ascii, sphere, false);
    write_ply(binary, sphere, true);
    expect_agreement(ascii);
    expect_agreement(binary);
    expect_agreement(write_off("openmesh.off", sphere));
}
