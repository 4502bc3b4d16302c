// Readers on small well-formed files, including the less common corners of each format.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>

#include "base/error.h"
#include "mesh/io.h"
#include "test_util.h"

using namespace catpaq;
using catpaq::test::put_be;
using catpaq::test::put_le;
using catpaq::test::write_file;
namespace fs = std::filesystem;

namespace {

const std::vector<uint32_t> kQuadAsTriangles = {0, 1, 2, 0, 2, 3};

}  // namespace

// ---------------------------------------------------------------------------------------------
// PLY

TEST(ReadPly, AsciiWithCommentsExtraPropertiesAndElements) {
    std::string path = write_file("extras.ply",
                                  "ply\n"
                                  "format ascii 1.0\n"
                                  "comment made by hand\n"
                                  "obj_info scanner 7\n"
                                  "element material 2\n"  // an element before the vertices
                                  "property list uchar float coefficients\n"
                                  "property int id\n"
                                  "element vertex 4\n"
                                  "property float x\n"
                                  "property float confidence\n"  // unknown: skipped
                                  "property float y\n"
                                  "property double z\n"
                                  "property uchar red\n"
                                  "property uchar green\n"
                                  "property uchar blue\n"
                                  "property uchar alpha\n"
                                  "element face 1\n"
                                  "property uchar flags\n"
                                  "property list uchar int vertex_indices\n"
                                  "property list uchar float texcoord\n"
                                  "element edge 1\n"  // an element after the faces
                                  "property int vertex1\n"
                                  "property int vertex2\n"
                                  "end_header\n"
                                  "3 0.1 0.2 0.3 1\n"
                                  "0 2\n"
                                  "0 0.9 0 0.5 10 20 30 255\n"
                                  "1 0.9 0 0.25 40 50 60 255\n"
                                  "1 0.9 1 0.125 70 80 90 0\n"
                                  "0 0.9 1 1e-3 100 110 120 1\n"
                                  "7 4 0 1 2 3 8 0 0 1 0 1 1 0 1\n"
                                  "0 1\n");
    Mesh mesh = read_mesh(path);
    EXPECT_EQ(mesh.positions, (std::vector<Vec3d>{{0, 0, 0.5}, {1, 0, 0.25}, {1, 1, 0.125}, {0, 1, 1e-3}}));
    EXPECT_EQ(mesh.colors, (std::vector<Rgb8>{{10, 20, 30}, {40, 50, 60}, {70, 80, 90}, {100, 110, 120}}));
    EXPECT_FALSE(mesh.has_normals());
    EXPECT_EQ(mesh.indices, kQuadAsTriangles);
}

TEST(ReadPly, BinaryWithMixedTypesFloatColoursAndNormals) {
    // x double, y int16, z float; normals not unit length (normalised on read); float colours.
    std::string header =
        "ply\nformat binary_little_endian 1.0\n"
        "element vertex 3\n"
        "property float64 x\nproperty int16 y\nproperty float32 z\n"
        "property float nx\nproperty float ny\nproperty float nz\n"
        "property float red\nproperty float green\nproperty float blue\n"
        "element face 1\n"
        "property list uint16 uint8 vertex_index\n"
        "end_header\n";
    std::string body;
    const double xs[3] = {0.5, 1e6 + 0.25, -3};
    const int16_t ys[3] = {-7, 0, 32000};
    const float zs[3] = {0.125f, -1.5f, 2};
    for (int v = 0; v < 3; ++v) {
        put_le(body, xs[v]);
        put_le(body, ys[v]);
        put_le(body, zs[v]);
        put_le(body, 0.0f), put_le(body, 0.0f), put_le(body, 2.0f);  // length 2
        put_le(body, 1.0f), put_le(body, 0.5f), put_le(body, 0.0f);
    }
    put_le(body, uint16_t(3));
    body += std::string{char(2), char(0), char(1)};
    Mesh mesh = read_mesh(write_file("mixed.ply", header + body));
    ASSERT_EQ(mesh.vertex_count(), 3u);
    EXPECT_EQ(mesh.positions[1], (Vec3d{1e6 + 0.25, 0, -1.5}));
    EXPECT_EQ(mesh.positions[2], (Vec3d{-3, 32000, 2}));
    EXPECT_EQ(mesh.normals[0], (Vec3f{0, 0, 1}));
    EXPECT_EQ(mesh.colors[0], (Rgb8{255, 128, 0}));
    EXPECT_EQ(mesh.indices, (std::vector<uint32_t>{2, 0, 1}));
}

TEST(ReadPly, BigEndianBinary) {
    std::string file =
        "ply\nformat binary_big_endian 1.0\n"
        "element vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
        "property uchar red\nproperty uchar green\nproperty uchar blue\n"
        "element face 2\nproperty list uchar int vertex_indices\nend_header\n";
    const float corners[4][3] = {{0, 0, 0}, {1.5f, 0, 0}, {1.5f, 2.25f, 0}, {0, 2.25f, -1e-3f}};
    for (int v = 0; v < 4; ++v) {
        for (float c : corners[v]) put_be(file, c);
        file += std::string{char(v), char(10 * v), char(255 - v)};
    }
    for (int f = 0; f < 2; ++f) {
        file += char(3);
        for (int32_t i : {0, 1 + f, 2 + f}) put_be(file, i);
    }
    Mesh mesh = read_mesh(write_file("big_endian.ply", file));
    ASSERT_EQ(mesh.vertex_count(), 4u);
    for (int v = 0; v < 4; ++v) {
        for (int k = 0; k < 3; ++k) EXPECT_EQ(mesh.positions[v][k], double(corners[v][k]));
        EXPECT_EQ(mesh.colors[v], (Rgb8{uint8_t(v), uint8_t(10 * v), uint8_t(255 - v)}));
    }
    EXPECT_EQ(mesh.indices, kQuadAsTriangles);
}

TEST(ReadPly, PolygonsAreFanTriangulated) {
    std::string path = write_file("polygons.ply",
                                  "ply\nformat ascii 1.0\nelement vertex 6\n"
                                  "property float x\nproperty float y\nproperty float z\n"
                                  "element face 2\nproperty list uchar uint vertex_indices\nend_header\n"
                                  "0 0 0\n1 0 0\n2 1 0\n1 2 0\n0 1 0\n-1 1 0\n"
                                  "5 0 1 2 3 4\n3 0 4 5\n");
    Mesh mesh = read_mesh(path);
    EXPECT_EQ(mesh.indices, (std::vector<uint32_t>{0, 1, 2, 0, 2, 3, 0, 3, 4, 0, 4, 5}));
}

TEST(ReadPly, CrlfLineEndingsAndBlankLines) {
    std::string path = write_file("crlf.ply",
                                  "ply\r\nformat ascii 1.0\r\nelement vertex 3\r\nproperty float x\r\n"
                                  "property float y\r\nproperty float z\r\nelement face 1\r\n"
                                  "property list uchar int vertex_indices\r\nend_header\r\n"
                                  "0 0 0\r\n\r\n1 0 0\r\n0 1 0\r\n3 0 1 2\r\n\r\n");
    Mesh mesh = read_mesh(path);
    EXPECT_EQ(mesh.triangle_count(), 1u);
    EXPECT_EQ(mesh.positions[1], (Vec3d{1, 0, 0}));
}

// ---------------------------------------------------------------------------------------------
// OBJ

TEST(ReadObj, AllCornerFormsNegativeIndicesAndPolygons) {
    std::string path = write_file("forms.obj",
                                  "# a comment\n"
                                  "mtllib thing.mtl\n"
                                  "o thing\n"
                                  "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0.5 0.5 1\n"
                                  "vt 0 0\nvt 1 0\nvt 1 1\n"
                                  "vn 0 0 1\n"
                                  "usemtl stone\n"
                                  "s off\n"
                                  "f 1 2 3\n"
                                  "f 1/1 3/3 4/2\n"
                                  "f 1//1 2//1 5//1\n"
                                  "f -4/1/1 -3/2/1 -1/3/1\n"  // relative: vertices 2, 3, 5
                                  "f 4 1 5 \\\n"              // continued on the next line
                                  "  3\n"
                                  "l 1 2\n");
    std::vector<std::string> dropped;
    Mesh mesh = read_mesh(path, &dropped);
    EXPECT_EQ(mesh.vertex_count(), 5u);
    EXPECT_EQ(mesh.indices, (std::vector<uint32_t>{0, 1, 2, 0, 2, 3, 0, 1, 4, 1, 2, 4, 3, 0, 4, 3, 4, 2}));
    // Per-corner normals (their indices do not follow the vertex indices) become per-vertex ones;
    // vertex 4 has none in any corner: computed from the faces.
    ASSERT_TRUE(mesh.has_normals());
    EXPECT_EQ(mesh.normals[0], (Vec3f{0, 0, 1}));
    EXPECT_FALSE(mesh.has_colors());
    std::string all;
    for (const std::string& d : dropped) all += d + "\n";
    EXPECT_NE(all.find("texture coordinates (3 'vt' statements, used by 6 face corners)"), std::string::npos) << all;
    EXPECT_NE(all.find("materials (2 'mtllib'/'usemtl' statements, library thing.mtl)"), std::string::npos) << all;
    EXPECT_NE(all.find("1 lines and points"), std::string::npos) << all;
    EXPECT_NE(all.find("normals for 1 vertices that no face corner gives one: computed"), std::string::npos) << all;
}

// Before, "vn" normals were used only when numbered like the vertices; an OBJ from a modelling
// tool (per-corner normals, "f v/vt/vn") lost them silently. A cube with hard edges: each
// vertex averages the normals of its three faces, and the reader says so.
TEST(ReadObj, PerCornerNormalsBecomePerVertexNormals) {
    std::string text;
    for (int i = 0; i < 8; ++i) text += strprintf("v %d %d %d\n", i & 1, (i >> 1) & 1, (i >> 2) & 1);
    text += "vn -1 0 0\nvn 1 0 0\nvn 0 -1 0\nvn 0 1 0\nvn 0 0 -1\nvn 0 0 1\n";
    // Faces as quads: x=0 (normal 1), x=1 (2), y=0 (3), y=1 (4), z=0 (5), z=1 (6).
    const int quads[6][4] = {{1, 5, 7, 3}, {2, 4, 8, 6}, {1, 2, 6, 5}, {3, 7, 8, 4}, {1, 3, 4, 2}, {5, 6, 8, 7}};
    for (int f = 0; f < 6; ++f)
        text += strprintf("f %d//%d %d//%d %d//%d %d//%d\n", quads[f][0], f + 1, quads[f][1], f + 1, quads[f][2], f + 1,
                          quads[f][3], f + 1);
    std::vector<std::string> dropped;
    Mesh mesh = read_mesh(write_file("hard_cube.obj", text), &dropped);
    ASSERT_TRUE(mesh.has_normals());
    const float c = float(1 / std::sqrt(3.0));
    EXPECT_NEAR(mesh.normals[0][0], -c, 1e-6);  // corner (0,0,0): faces x=0, y=0, z=0
    EXPECT_NEAR(mesh.normals[0][1], -c, 1e-6);
    EXPECT_NEAR(mesh.normals[0][2], -c, 1e-6);
    EXPECT_NEAR(mesh.normals[7][0], c, 1e-6);   // corner (1,1,1)
    ASSERT_EQ(dropped.size(), 1u);
    EXPECT_NE(dropped[0].find("8 vertices that differ between faces"), std::string::npos) << dropped[0];
}

// PLY face colours have no place in a per-vertex mesh: said, not silently dropped.
TEST(ReadPly, FaceColoursAndOtherPropertiesAreReportedAsDropped) {
    std::string path = write_file("face_colours.ply",
                                  "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                                  "property float z\nproperty float u\nproperty float v\n"
                                  "element face 1\nproperty list uchar int vertex_indices\nproperty uchar red\n"
                                  "property uchar green\nproperty uchar blue\nelement edge 2\nproperty int vertex1\n"
                                  "property int vertex2\nend_header\n0 0 0 0 0\n1 0 0 1 0\n0 1 0 0 1\n3 0 1 2 255 0 0\n"
                                  "0 1\n1 2\n");
    std::vector<std::string> dropped;
    Mesh mesh = read_mesh(path, &dropped);
    EXPECT_EQ(mesh.triangle_count(), 1u);
    std::string all;
    for (const std::string& d : dropped) all += d + "\n";
    EXPECT_NE(all.find("face colours (red, green, blue) of 1 faces"), std::string::npos) << all;
    EXPECT_NE(all.find("vertex properties u, v"), std::string::npos) << all;
    EXPECT_NE(all.find("2 'edge' elements"), std::string::npos) << all;
    // A plain file drops nothing.
    dropped.clear();
    Mesh plain;
    plain.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
    plain.indices = {0, 1, 2};
    write_ply((fs::path(path).parent_path() / "plain.ply").string(), plain);
    read_mesh((fs::path(path).parent_path() / "plain.ply").string(), &dropped);
    EXPECT_TRUE(dropped.empty()) << dropped[0];
}

TEST(ReadObj, MeshLabVertexColoursAndMatchingNormals) {
    std::string path = write_file("colours.obj",
                                  "v 0 0 0 1 0 0\nv 1 0 0 0 1 0\nv 0 1 0 0 0 0.5\n"
                                  "vn 0 0 2\nvn 0 0 1\nvn 0 0 1\n"
                                  "f 1//1 2//2 3//3\n");
    Mesh mesh = read_mesh(path);
    EXPECT_EQ(mesh.colors, (std::vector<Rgb8>{{255, 0, 0}, {0, 255, 0}, {0, 0, 128}}));
    ASSERT_TRUE(mesh.has_normals());
    EXPECT_EQ(mesh.normals[0], (Vec3f{0, 0, 1}));
}

// ---------------------------------------------------------------------------------------------
// OFF

TEST(ReadOff, CountsOnTheHeaderLineCommentsAndFaceColours) {
    std::string path = write_file("counts.off",
                                  "OFF 4 2 0 # counts here\n"
                                  "# a comment line\n"
                                  "0 0 0\n1 0 0\n\n1 1 0   # trailing comment\n0 1 0\n"
                                  "4 0 1 2 3 255 0 0\n"  // a face colour, ignored
                                  "3 0 2 1 0.5 0.5 0.5 1\n");
    Mesh mesh = read_mesh(path);
    EXPECT_EQ(mesh.vertex_count(), 4u);
    EXPECT_EQ(mesh.indices, (std::vector<uint32_t>{0, 1, 2, 0, 2, 3, 0, 2, 1}));
}

TEST(ReadOff, ColouredOffIntegerAndFloatColours) {
    Mesh ints = read_mesh(write_file("ints.off", "COFF\n3 1 0\n0 0 0 255 0 0 255\n1 0 0 0 128 0 255\n"
                                                 "0 1 0 0 0 7 255\n3 0 1 2\n"));
    EXPECT_EQ(ints.colors, (std::vector<Rgb8>{{255, 0, 0}, {0, 128, 0}, {0, 0, 7}}));
    Mesh floats = read_mesh(write_file("floats.off", "COFF\n3 1 0\n0 0 0 1.0 0.0 0.0 1.0\n1 0 0 0 0.5 0\n"
                                                     "0 1 0 0 0 1e0\n3 0 1 2\n"));
    EXPECT_EQ(floats.colors, (std::vector<Rgb8>{{255, 0, 0}, {0, 128, 0}, {0, 0, 255}}));
}

TEST(ReadOff, NormalsOff) {
    Mesh mesh = read_mesh(write_file("normals.off", "NOFF\n3 1 0\n0 0 0 0 0 1\n1 0 0 0 0 3\n0 1 0 0 0 0\n3 0 1 2\n"));
    ASSERT_TRUE(mesh.has_normals());
    EXPECT_EQ(mesh.normals[1], (Vec3f{0, 0, 1}));
    EXPECT_EQ(mesh.normals[2], (Vec3f{0, 0, 1}));  // a zero normal becomes +z
}

// ---------------------------------------------------------------------------------------------
// STL

TEST(ReadStl, AsciiCornersAreWelded) {
    std::string path = write_file("square.stl",
                                  "solid square\n"
                                  "  facet normal 0 0 1\n    outer loop\n"
                                  "      vertex 0 0 0\n      vertex 1 0 0\n      vertex 1 1 0\n"
                                  "    endloop\n  endfacet\n"
                                  "  facet normal 0 0 1\n    outer loop\n"
                                  "      vertex 0 0 -0.0\n      vertex 1 1 0\n      vertex 0 1 0\n"
                                  "    endloop\n  endfacet\n"
                                  "endsolid square\n");
    Mesh mesh = read_mesh(path);
    EXPECT_EQ(mesh.vertex_count(), 4u);  // -0.0 and 0.0 are one point
    EXPECT_EQ(mesh.indices, (std::vector<uint32_t>{0, 1, 2, 0, 2, 3}));
}

TEST(ReadStl, BinaryStartingWithSolidIsStillBinary) {
    std::string file = "solid but actually binary";
    file.resize(80, ' ');
    put_le(file, uint32_t(2));
    const float triangles[2][3][3] = {{{0, 0, 0}, {1, 0, 0}, {1, 1, 0}}, {{0, 0, 0}, {1, 1, 0}, {0, 1, 0}}};
    for (const auto& triangle : triangles) {
        for (int k = 0; k < 3; ++k) put_le(file, 0.0f);  // facet normal
        for (const auto& corner : triangle)
            for (float c : corner) put_le(file, c);
        put_le(file, uint16_t(0));
    }
    Mesh mesh = read_mesh(write_file("binary.stl", file));
    EXPECT_EQ(mesh.vertex_count(), 4u);
    EXPECT_EQ(mesh.indices, (std::vector<uint32_t>{0, 1, 2, 0, 2, 3}));
}

// ---------------------------------------------------------------------------------------------
// Format choice

TEST(ReadMesh, ExtensionIsCaseInsensitive) {
    Mesh mesh = read_mesh(write_file("upper.OFF", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"));
    EXPECT_EQ(mesh.triangle_count(), 1u);
}

TEST(ReadMesh, UnknownExtensionsAreSniffed) {
    const std::string triangle_ply =
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
        "element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
    EXPECT_EQ(read_mesh(write_file("sniff_ply.dat", triangle_ply)).triangle_count(), 1u);
    const std::string triangle_off = "# c\nOFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
    EXPECT_EQ(read_mesh(write_file("sniff_off", triangle_off)).triangle_count(), 1u);
    EXPECT_EQ(read_mesh(write_file("sniff_obj.txt", "# c\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")).triangle_count(), 1u);
    EXPECT_EQ(read_mesh(write_file("sniff_stl.mesh", "solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\n"
                                                     "vertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\nendsolid x\n"))
                  .triangle_count(),
              1u);
}
