// write_ply round trips, PlyStream chunking, and the binary reading speed.
#include <gtest/gtest.h>

#include <chrono>
#include <cstdio>
#include <ctime>
#include <filesystem>

#include "base/atomic_file.h"
#include "mesh/generators.h"
#include "mesh/io.h"
#include "test_util.h"

using namespace catpaq;
using catpaq::test::put_be;
using catpaq::test::scratch;

namespace {

void expect_same_mesh(const Mesh& a, const Mesh& b) {
    EXPECT_EQ(a.positions, b.positions);
    EXPECT_EQ(a.normals, b.normals);
    EXPECT_EQ(a.colors, b.colors);
    EXPECT_EQ(a.indices, b.indices);
}

std::string header_of(const std::string& path) {
    std::string text = read_file(path);
    return text.substr(0, text.find("end_header"));
}

}  // namespace

TEST(WritePly, BinaryRoundTripIsExact) {
    Mesh sphere = make_sphere(3000, 5);
    std::string path = scratch("round_trip.ply");
    write_ply(path, sphere);
    EXPECT_NE(header_of(path).find("format binary_little_endian 1.0"), std::string::npos);
    EXPECT_NE(header_of(path).find("property float x"), std::string::npos);
    expect_same_mesh(read_mesh(path), sphere);
}

TEST(WritePly, AsciiRoundTripIsExact) {
    // Shortest round-trip formatting: ascii reads back to the same bits as well.
    Mesh torus = make_torus(2000, 9);
    std::string path = scratch("round_trip_ascii.ply");
    write_ply(path, torus, false);
    EXPECT_NE(header_of(path).find("format ascii 1.0"), std::string::npos);
    expect_same_mesh(read_mesh(path), torus);
}

TEST(WritePly, LargeCoordinatesAreWrittenAsDouble) {
    Mesh far = make_hard_case(HardCase::FarFromOrigin);
    for (bool binary : {true, false}) {
        std::string path = scratch(binary ? "far.ply" : "far_ascii.ply");
        write_ply(path, far, binary);
        EXPECT_NE(header_of(path).find("property double x"), std::string::npos);
        expect_same_mesh(read_mesh(path), far);
    }
}

TEST(WritePly, GeometryOnlyMesh) {
    Mesh mesh;
    mesh.positions = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};
    mesh.indices = {0, 1, 2};
    std::string path = scratch("bare.ply");
    write_ply(path, mesh);
    EXPECT_EQ(header_of(path).find("nx"), std::string::npos);
    EXPECT_EQ(header_of(path).find("red"), std::string::npos);
    expect_same_mesh(read_mesh(path), mesh);
}

TEST(WritePly, InvalidMeshIsRefusedAndNothingIsWritten) {
    Mesh mesh;
    mesh.positions = {{0, 0, 0}};
    mesh.indices = {0, 0, 1};
    std::string path = scratch("refused.ply");
    std::filesystem::remove(path);
    EXPECT_THROW(write_ply(path, mesh), Error);
    EXPECT_FALSE(std::filesystem::exists(path));
}

// Large files are decoded on all cores in batches (read_ply.cpp, parse_vertices_parallel), small
// ones on one: both sizes, both byte orders read back every vertex as written, in order.
TEST(WritePly, BinaryRoundTripIsExactOnAllCores) {
    Mesh sphere = make_sphere(200000, 5);  // 100,002 vertices: several parallel batches
    ASSERT_GT(sphere.vertex_count(), 3 * 16384u);
    std::string path = scratch("round_trip_large.ply");
    write_ply(path, sphere);
    expect_same_mesh(read_mesh(path), sphere);
}

TEST(WritePly, ReadsBackWithBigEndianWrittenByHand) {
    // The same sphere written big-endian by hand (double positions, reordered properties,
    // an extra per-face property) reads back identically, small and large.
    for (size_t triangles : {500, 100000}) {
        SCOPED_TRACE(triangles);
        Mesh sphere = make_sphere(triangles, 2);
        std::string file = "ply\nformat binary_big_endian 1.0\nelement vertex " + std::to_string(sphere.vertex_count()) +
                           "\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n"
                           "property double x\nproperty double y\nproperty double z\n"
                           "property float nx\nproperty float ny\nproperty float nz\n"
                           "element face " + std::to_string(sphere.triangle_count()) +
                           "\nproperty list uchar uint vertex_indices\nproperty ushort material\nend_header\n";
        for (size_t v = 0; v < sphere.vertex_count(); ++v) {
            for (uint8_t c : sphere.colors[v]) file += char(c);
            for (double c : sphere.positions[v]) put_be(file, c);
            for (float c : sphere.normals[v]) put_be(file, c);
        }
        for (size_t t = 0; t < sphere.triangle_count(); ++t) {
            file += char(3);
            for (int k = 0; k < 3; ++k) put_be(file, sphere.indices[3 * t + k]);
            put_be(file, uint16_t(t));
        }
        expect_same_mesh(read_mesh(test::write_file("sphere_be.ply", file)), sphere);
    }
}

TEST(PlyStream, ChunkedReadsMatchWholeReads) {
    Mesh sphere = make_sphere(1000, 4);
    for (bool binary : {true, false}) {
        std::string path = scratch(binary ? "stream.ply" : "stream_ascii.ply");
        write_ply(path, sphere, binary);
        PlyStream stream(path);
        EXPECT_EQ(stream.vertex_count(), sphere.vertex_count());
        EXPECT_EQ(stream.face_count(), sphere.triangle_count());
        EXPECT_TRUE(stream.has_normals());
        EXPECT_TRUE(stream.has_colors());
        Mesh mesh;
        size_t calls = 0;
        while (size_t n = stream.read_vertices(7, mesh.positions, &mesh.normals, &mesh.colors)) {
            EXPECT_LE(n, 7u);
            ++calls;
        }
        EXPECT_EQ(calls, (sphere.vertex_count() + 6) / 7);
        while (stream.read_faces(13, mesh.indices) > 0) {
        }
        EXPECT_EQ(stream.read_vertices(10, mesh.positions, nullptr, nullptr), 0u);
        stream.finish();
        expect_same_mesh(mesh, sphere);
    }
}

TEST(PlyStream, FacesWithoutReadingVertices) {
    Mesh sphere = make_sphere(200, 4);
    for (bool binary : {true, false}) {
        std::string path = scratch(binary ? "faces_only.ply" : "faces_only_ascii.ply");
        write_ply(path, sphere, binary);
        PlyStream stream(path);
        std::vector<uint32_t> indices;
        EXPECT_EQ(stream.read_faces(size_t(-1), indices), sphere.triangle_count());
        EXPECT_EQ(indices, sphere.indices);
        stream.finish();
    }
}

TEST(PlyStream, PositionsOnlyFromAFileWithAttributes) {
    Mesh sphere = make_sphere(100, 4);
    std::string path = scratch("positions_only.ply");
    write_ply(path, sphere);
    PlyStream stream(path);
    std::vector<Vec3d> positions;
    stream.read_vertices(size_t(-1), positions, nullptr, nullptr);
    EXPECT_EQ(positions, sphere.positions);
}

TEST(PlyStream, HeaderErrorsThrowFromTheConstructor) {
    std::string path = test::write_file("stream_bad.ply", "ply\nformat ascii 2.0\nend_header\n");
    EXPECT_TRUE(test::fails_with([&] { PlyStream stream(path); }, path, {"malformed PLY header"}));
}

TEST(PlyPerformance, BinaryReadingSpeed) {
    // A 2M-triangle sphere (about 50 MB); the file is in the page cache, so this measures parsing.
    Mesh sphere = make_sphere(2'000'000, 1);
    std::string path = scratch("speed.ply");
    write_ply(path, sphere);
    double megabytes = double(std::filesystem::file_size(path)) / 1e6;
    read_mesh(path);  // warm the cache
    auto cpu_seconds = [] {
        timespec t;
        clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
        return double(t.tv_sec) + 1e-9 * double(t.tv_nsec);
    };
    auto wall_start = std::chrono::steady_clock::now();
    double cpu_start = cpu_seconds();
    Mesh mesh = read_mesh(path);
    double cpu = cpu_seconds() - cpu_start;
    double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - wall_start).count();
    EXPECT_EQ(mesh.triangle_count(), sphere.triangle_count());
    std::printf("[ speed    ] binary PLY: %.1f MB in %.3f s CPU (%.0f MB/s), %.3f s wall (%.0f MB/s)\n", megabytes, cpu,
                megabytes / cpu, wall, megabytes / wall);
    // CPU time, so a busy shared machine does not fail the test; the floor catches an accidental
    // per-value slow path (iostreams, virtual calls), not noise. Sanitizers slow parsing ~4x.
#if defined(__SANITIZE_ADDRESS__)
    const double floor_mb_per_s = 25.0;
#else
    const double floor_mb_per_s = 100.0;
#endif
    EXPECT_GT(megabytes / cpu, floor_mb_per_s);
    std::filesystem::remove(path);
}
