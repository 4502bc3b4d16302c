// Bad input: every reader must throw catpaq::Error naming the file and the problem, never crash,
// hang or return a wrong mesh. Each test writes a small broken file.
#include <gtest/gtest.h>

#include "mesh/io.h"
#include "test_util.h"

using namespace catpaq;
using catpaq::test::put_le;
using catpaq::test::read_fails;
using catpaq::test::write_file;

namespace {

const char* kPlyHeader =
    "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
    "element face 1\nproperty list uchar int vertex_indices\nend_header\n";

std::string binary_ply_header(int vertices, int faces) {
    return "ply\nformat binary_little_endian 1.0\nelement vertex " + std::to_string(vertices) +
           "\nproperty float x\nproperty float y\nproperty float z\nelement face " + std::to_string(faces) +
           "\nproperty list uchar int vertex_indices\nend_header\n";
}

// A valid binary PLY triangle; tests damage it.
std::string binary_ply_triangle(float x0 = 0, int32_t last_index = 2) {
    std::string file = binary_ply_header(3, 1);
    for (float c : {x0, 0.0f, 0.0f, 1.0f, 0.0f, 0.0f, 0.0f, 1.0f, 0.0f}) put_le(file, c);
    file += char(3);
    for (int32_t i : {0, 1, last_index}) put_le(file, i);
    return file;
}

std::string binary_stl(uint32_t declared, int written, float x0 = 0) {
    std::string file(80, ' ');
    put_le(file, declared);
    for (int t = 0; t < written; ++t) {
        for (float c : {0.0f, 0.0f, 1.0f, x0, 0.0f, 0.0f, 1.0f, 0.0f, 0.0f, 0.0f, 1.0f, 0.0f}) put_le(file, c);
        put_le(file, uint16_t(0));
    }
    return file;
}

const char* kStlFacet = "facet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\n";

}  // namespace

// --- files that are not there, or not meshes -------------------------------------------------

TEST(ReaderErrors, MissingFile) {
    EXPECT_TRUE(read_fails(test::scratch("does_not_exist.ply"), {"cannot open", "No such file"}));
    EXPECT_TRUE(read_fails(test::scratch("does_not_exist.obj"), {"cannot open"}));
    EXPECT_TRUE(read_fails(test::scratch("does_not_exist.xyz"), {"cannot open"}));
}

TEST(ReaderErrors, DirectoryInsteadOfFile) {
    EXPECT_TRUE(read_fails(test::scratch(""), {"directory"}));
}

TEST(ReaderErrors, UnknownFormat) {
    EXPECT_TRUE(read_fails(write_file("notes.txt", "hello, this is not a mesh\n"),
                           {"unknown mesh format (expected PLY, OBJ, OFF or STL)"}));
    EXPECT_TRUE(read_fails(write_file("empty.bin", ""), {"unknown mesh format"}));
}

// --- malformed headers ------------------------------------------------------------------------

TEST(ReaderErrors, PlyWithoutMagic) {
    EXPECT_TRUE(
        read_fails(write_file("magic.ply", "PLY\nformat ascii 1.0\nend_header\n"), {"not a PLY file", "header"}));
}

TEST(ReaderErrors, PlyMalformedHeaders) {
    const char* bad[] = {
        "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n",                        // no end_header
        "ply\nformat ebcdic 1.0\nelement vertex 0\nproperty float x\nend_header\n",             // unknown format
        "ply\nelement vertex 0\nproperty float x\nproperty float y\nproperty float z\nend_header\n",  // no format
        "ply\nformat ascii 1.0\nelement vertex many\nend_header\n",                             // bad count
        "ply\nformat ascii 1.0\nproperty float x\nend_header\n",                                // property first
        "ply\nformat ascii 1.0\nelement vertex 0\nproperty float32x x\nend_header\n",           // bad type
        "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\nend_header\n",  // no z
        "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\nproperty float z\n"
        "element face 0\nproperty list uchar int corners\nend_header\n",  // no vertex_indices
        "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\nproperty float y\nproperty float z\n"
        "element face 0\nproperty list float int vertex_indices\nend_header\n",  // float count type
        "ply\nformat ascii 1.0\nelement face 0\nproperty list uchar int vertex_indices\n"
        "element vertex 0\nproperty float x\nproperty float y\nproperty float z\nend_header\n",  // faces first
        "ply\nformat ascii 1.0\nmystery line\nend_header\n",  // unknown keyword
    };
    for (const char* header : bad) {
        SCOPED_TRACE(header);
        EXPECT_TRUE(read_fails(write_file("header.ply", header), {"malformed PLY header"}));
    }
}

TEST(ReaderErrors, PlyHeaderErrorsNameTheLine) {
    EXPECT_TRUE(read_fails(write_file("line.ply", "ply\nformat ascii 1.0\ncomment ok\nelement vertex x\nend_header\n"),
                           {"line 4", "bad element count"}));
}

TEST(ReaderErrors, OffMalformedHeaders) {
    EXPECT_TRUE(read_fails(write_file("header1.off", "OF\n3 1 0\n"), {"not an OFF file", "header"}));
    EXPECT_TRUE(read_fails(write_file("header2.off", "OFF\nthree 1 0\n"), {"malformed OFF header", "line 2"}));
    EXPECT_TRUE(read_fails(write_file("header3.off", "OFF\n3\n"), {"malformed OFF header"}));
    EXPECT_TRUE(read_fails(write_file("header4.off", "OFF\n"), {"malformed OFF header"}));
    EXPECT_TRUE(read_fails(write_file("header5.off", "4OFF\n1 0 0\n"), {"not supported"}));
    EXPECT_TRUE(read_fails(write_file("header6.off", "OFF BINARY\n"), {"binary OFF"}));
}

TEST(ReaderErrors, StlNeitherBinaryNorAscii) {
    EXPECT_TRUE(read_fails(write_file("short.stl", "facet"), {"not an STL file"}));
    EXPECT_TRUE(read_fails(write_file("nosolid.stl", std::string("xsolid name\n") + kStlFacet + "endsolid\n"),
                           {"not an STL file"}));
}

// --- truncation ---------------------------------------------------------------------------------

TEST(ReaderErrors, TruncatedBinaryPlyInTheFaces) {
    std::string file = binary_ply_triangle();
    file.resize(file.size() - 3);
    EXPECT_TRUE(read_fails(write_file("cut_faces.ply", file), {"truncated", "face 0 of 1"}));
}

TEST(ReaderErrors, TruncatedBinaryPlyInTheVertices) {
    std::string file = binary_ply_header(1000, 1);
    for (int i = 0; i < 600 * 3; ++i) put_le(file, 0.5f);
    EXPECT_TRUE(read_fails(write_file("cut_vertices.ply", file), {"truncated"}));
    // Counts far beyond the file size are rejected up front, before any allocation.
    EXPECT_TRUE(read_fails(write_file("huge_count.ply", binary_ply_header(2000000000, 2000000000)),
                           {"truncated", "2000000000 vertex"}));
}

TEST(ReaderErrors, TruncatedAsciiPly) {
    EXPECT_TRUE(read_fails(write_file("cut.ply", std::string(kPlyHeader) + "0 0 0\n1 0 0\n"),
                           {"truncated", "2 of 3 vertex"}));
    EXPECT_TRUE(read_fails(write_file("cut2.ply", std::string(kPlyHeader) + "0 0 0\n1 0 0\n0 1 0\n"),
                           {"truncated", "0 of 1 face"}));
    EXPECT_TRUE(read_fails(write_file("cut3.ply", std::string(kPlyHeader) + "0 0 0\n1 0 0\n0 1 0\n3 0 1\n"),
                           {"line 13", "too few values"}));
    EXPECT_TRUE(read_fails(write_file("huge.ply", "ply\nformat ascii 1.0\nelement vertex 3000000000\nproperty float x\n"
                                                  "property float y\nproperty float z\nend_header\n0 0 0\n"),
                           {"truncated", "3000000000 vertex"}));
}

TEST(ReaderErrors, TruncatedOff) {
    EXPECT_TRUE(read_fails(write_file("cut.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n"), {"truncated", "0 of 1 faces"}));
    EXPECT_TRUE(read_fails(write_file("cut2.off", "OFF\n30 10 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"),
                           {"truncated", "30 vertices"}));
    // Counts far beyond the file size are rejected before anything is allocated.
    EXPECT_TRUE(read_fails(write_file("huge.off", "OFF\n4000000000 4000000000 0\n0 0 0\n"), {"truncated"}));
}

TEST(ReaderErrors, TruncatedObjStatement) {
    EXPECT_TRUE(read_fails(write_file("cut.obj", "v 0 0 0\nv 1 0 0\nv 0 1"), {"line 3", "vertex 3 has 2 values"}));
}

TEST(ReaderErrors, TruncatedBinaryStl) {
    EXPECT_TRUE(read_fails(write_file("cut.stl", binary_stl(10, 9)), {"truncated", "10 triangles"}));
}

TEST(ReaderErrors, TruncatedAsciiStl) {
    std::string facet(kStlFacet);
    EXPECT_TRUE(read_fails(write_file("cut_ascii.stl", "solid x\n" + facet + facet.substr(0, 56)), {"truncated"}));
    EXPECT_TRUE(read_fails(write_file("no_end.stl", "solid x\n" + facet), {"truncated", "endsolid"}));
}

// --- non-finite coordinates -------------------------------------------------------------------

TEST(ReaderErrors, NanAndInfCoordinates) {
    EXPECT_TRUE(read_fails(write_file("nan.ply", std::string(kPlyHeader) + "0 0 0\nnan 0 0\n0 1 0\n3 0 1 2\n"),
                           {"line 11", "vertex 1 has a non-finite coordinate"}));
    EXPECT_TRUE(read_fails(write_file("inf.ply", std::string(kPlyHeader) + "0 0 0\n1 0 0\n0 -inf 0\n3 0 1 2\n"),
                           {"non-finite"}));
    EXPECT_TRUE(read_fails(write_file("nan_bin.ply", binary_ply_triangle(std::numeric_limits<float>::quiet_NaN())),
                           {"vertex 0 has a non-finite coordinate"}));
    EXPECT_TRUE(read_fails(write_file("inf_bin.ply", binary_ply_triangle(std::numeric_limits<float>::infinity())),
                           {"non-finite"}));
    EXPECT_TRUE(read_fails(write_file("nan.obj", "v 0 0 0\nv 1 NaN 0\nv 0 1 0\nf 1 2 3\n"), {"line 2", "non-finite"}));
    EXPECT_TRUE(
        read_fails(write_file("inf.off", "OFF\n3 1 0\n0 0 0\n1 0 inf\n0 1 0\n3 0 1 2\n"), {"line 4", "non-finite"}));
    EXPECT_TRUE(read_fails(write_file("nan.stl", binary_stl(1, 1, std::numeric_limits<float>::quiet_NaN())),
                           {"non-finite"}));
    EXPECT_TRUE(read_fails(
        write_file("inf.stl", "solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex inf 0 0\nvertex 0 1 0\n"
                              "endloop\nendfacet\nendsolid x\n"),
        {"line 5", "non-finite"}));
}

// In a file large enough to be decoded on all cores, the error still names the first bad
// vertex (the batch is decoded again in order to find it).
TEST(ReaderErrors, LargeBinaryFileNamesTheFirstBadVertex) {
    constexpr int kVertices = 60000;
    auto file_with = [](int bad_vertex, int bad_field) {
        std::string file = "ply\nformat binary_little_endian 1.0\nelement vertex " + std::to_string(kVertices) +
                           "\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\n"
                           "property float ny\nproperty float nz\nproperty float red\nproperty float green\n"
                           "property float blue\nelement face 0\nproperty list uchar int vertex_indices\nend_header\n";
        for (int v = 0; v < kVertices; ++v)
            for (int f = 0; f < 9; ++f) {
                const float value = f < 3 ? float(v) * 1e-3f : f < 6 ? (f == 5 ? 1.0f : 0.0f) : 0.5f;
                const bool bad = v == bad_vertex && f == bad_field;
                put_le(file, bad ? std::numeric_limits<float>::quiet_NaN() : value);
            }
        return file;
    };
    EXPECT_TRUE(read_fails(write_file("late_nan.ply", file_with(41234, 1)), {"vertex 41234 has a non-finite coordinate"}));
    EXPECT_TRUE(read_fails(write_file("late_nan_normal.ply", file_with(20001, 4)), {"vertex 20001 has a non-finite normal"}));
    EXPECT_TRUE(read_fails(write_file("late_nan_colour.ply", file_with(59999, 7)), {"vertex 59999 has a non-finite colour"}));
    // And a valid one reads whole (no faces: as a point cloud).
    PlyStream stream(write_file("late_none.ply", file_with(kVertices, 0)));
    Mesh points;
    while (stream.read_vertices(size_t(kVertices), points.positions, &points.normals, &points.colors) > 0) {
    }
    ASSERT_EQ(points.positions.size(), size_t(kVertices));
    EXPECT_EQ(points.positions[kVertices - 1][0], double(float(kVertices - 1) * 1e-3f));
    EXPECT_EQ(points.colors[kVertices - 1], (Rgb8{128, 128, 128}));
}

// --- indices out of range ---------------------------------------------------------------------

TEST(ReaderErrors, IndexOutOfRange) {
    EXPECT_TRUE(read_fails(write_file("range.ply", std::string(kPlyHeader) + "0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n"),
                           {"line 13", "vertex index 3, out of range"}));
    EXPECT_TRUE(read_fails(write_file("negative.ply", std::string(kPlyHeader) + "0 0 0\n1 0 0\n0 1 0\n3 0 -1 2\n"),
                           {"vertex index -1, out of range"}));
    EXPECT_TRUE(read_fails(write_file("range_bin.ply", binary_ply_triangle(0, 7)), {"face 0", "out of range"}));
    EXPECT_TRUE(read_fails(write_file("range.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 5\n"),
                           {"line 6", "out of range"}));
    EXPECT_TRUE(
        read_fails(write_file("range.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n"), {"line 4", "out of range"}));
    EXPECT_TRUE(read_fails(write_file("zero.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n"), {"index 0 is invalid"}));
}

TEST(ReaderErrors, ObjRelativeIndexBeforeTheFirstVertex) {
    EXPECT_TRUE(read_fails(write_file("relative.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -4\n"),
                           {"line 4", "relative vertex index -4 is out of range"}));
}

// --- faces with fewer than three vertices -----------------------------------------------------

TEST(ReaderErrors, FaceWithFewerThanThreeVertices) {
    EXPECT_TRUE(read_fails(write_file("two.ply", std::string(kPlyHeader) + "0 0 0\n1 0 0\n0 1 0\n2 0 1\n"),
                           {"face 0 has 2 vertices (fewer than 3)"}));
    std::string binary = binary_ply_header(3, 1);
    for (int i = 0; i < 9; ++i) put_le(binary, float(i));
    binary += char(2);
    put_le(binary, int32_t(0));
    put_le(binary, int32_t(1));
    EXPECT_TRUE(read_fails(write_file("two_bin.ply", binary), {"fewer than 3"}));
    EXPECT_TRUE(read_fails(write_file("two.obj", "v 0 0 0\nv 1 0 0\nf 1 2\n"), {"line 3", "fewer than 3"}));
    EXPECT_TRUE(
        read_fails(write_file("two.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n2 0 1\n"), {"line 6", "fewer than 3"}));
    EXPECT_TRUE(read_fails(write_file("two.stl", "solid x\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\n"
                                                 "endloop\nendfacet\nendsolid x\n"),
                           {"fewer than 3"}));
}

// --- counts that do not match the data --------------------------------------------------------

TEST(ReaderErrors, CountsDoNotMatchTheData) {
    // More faces than declared.
    std::string two_faces = std::string(kPlyHeader) + "0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 2 1 0\n";
    EXPECT_TRUE(read_fails(write_file("extra_face.ply", two_faces), {"counts", "do not match"}));
    // Binary: trailing bytes after the last element.
    EXPECT_TRUE(read_fails(write_file("extra_bytes.ply", binary_ply_triangle() + "garbage"), {"do not match"}));
    // A vertex line with more values than the header declares.
    EXPECT_TRUE(read_fails(write_file("wide.ply", std::string(kPlyHeader) + "0 0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"),
                           {"line 10", "more values than the header declares"}));
    // OFF: more data than declared, and a face listing fewer indices than its count.
    EXPECT_TRUE(read_fails(write_file("extra.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n3 2 1 0\n"),
                           {"line 7", "counts do not match"}));
    EXPECT_TRUE(read_fails(write_file("short_face.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n4 0 1 2\n"),
                           {"declares 4 vertices but lists 3"}));
    // Binary STL whose size disagrees with its triangle count (more data than declared).
    EXPECT_TRUE(read_fails(write_file("extra.stl", binary_stl(1, 2)), {"1 triangles"}));
}

// --- empty meshes -----------------------------------------------------------------------------

TEST(ReaderErrors, EmptyMesh) {
    EXPECT_TRUE(read_fails(write_file("points.ply",
                                      "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
                                      "property float z\nend_header\n0 0 0\n"),
                           {"empty mesh", "no triangles"}));
    EXPECT_TRUE(read_fails(write_file("empty.obj", "# nothing\nv 0 0 0\n"), {"no triangles"}));
    EXPECT_TRUE(read_fails(write_file("empty.off", "OFF\n0 0 0\n"), {"no triangles"}));
    EXPECT_TRUE(read_fails(write_file("empty.stl", binary_stl(0, 0)), {"no triangles"}));
    EXPECT_TRUE(read_fails(write_file("empty_ascii.stl", "solid x\nendsolid x\n"), {"no triangles"}));
}

// --- garbage never crashes --------------------------------------------------------------------

TEST(ReaderErrors, RandomBytesAreRejectedCleanly) {
    // Deterministic junk behind each format's magic: every read must end in catpaq::Error or
    // (rarely) a valid mesh, never a crash or a hang.
    uint64_t state = 12345;
    auto next = [&] { return (state = state * 6364136223846793005ull + 1442695040888963407ull) >> 33; };
    const std::string magics[] = {"ply\nformat binary_little_endian 1.0\nelement vertex 5\nproperty float x\n"
                                  "property float y\nproperty float z\nelement face 3\n"
                                  "property list uchar int vertex_indices\nend_header\n",
                                  kPlyHeader, "OFF\n5 3 0\n", "solid x\n", "v 1 2 3\n", ""};
    const char* names[] = {"junk_b.ply", "junk_a.ply", "junk.off", "junk.stl", "junk.obj", "junk.stl"};
    for (int round = 0; round < 200; ++round) {
        int kind = round % 6;
        std::string content = magics[kind];
        size_t length = next() % 300;
        for (size_t i = 0; i < length; ++i) {
            // Mostly printable digits and spaces for the text formats, raw bytes otherwise.
            content += round % 2 ? char(next()) : "0123456789 .-\n"[next() % 14];
        }
        std::string path = write_file(names[kind], content);
        try {
            read_mesh(path);
        } catch (const Error& e) {
            EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
        }
    }
}
