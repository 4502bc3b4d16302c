// Point readers: the same points through every format, an independent LAS writer's file, and
// bad inputs refused with a message naming the file and the problem.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <sstream>

#include "mesh/io.h"
#include "points/point_cloud.h"
#include "support.h"

namespace catpaq {
namespace {

// Points on a millimetre grid far from the origin (as scans in projected coordinates are), so
// that text with 3 decimals and LAS with scale 0.001 hold them exactly as doubles round them.
PointCloud grid_cloud() {
    PointCloud cloud;
    for (int i = 0; i < 40; ++i) {
        double x = 500000.0 + 0.001 * (i * 37 % 1000), y = 4000000.0 + 0.001 * (i * 53 % 1000), z = 10.0 + 0.001 * i;
        cloud.positions.push_back({x, y, z});
        cloud.colors.push_back({uint8_t(i * 6), uint8_t(255 - i), uint8_t(i * i % 256)});
    }
    return cloud;
}

std::string xyz_text(const PointCloud& cloud, bool intensity) {
    std::ostringstream out;
    out.precision(17);
    for (size_t i = 0; i < cloud.size(); ++i) {
        out << cloud.positions[i][0] << ' ' << cloud.positions[i][1] << ' ' << cloud.positions[i][2];
        if (intensity) out << ' ' << 0.5;
        out << ' ' << int(cloud.colors[i][0]) << ' ' << int(cloud.colors[i][1]) << ' ' << int(cloud.colors[i][2]) << '\n';
    }
    return out.str();
}

void expect_same_points(const PointCloud& a, const PointCloud& b, double tolerance) {
    ASSERT_EQ(a.size(), b.size());
    for (size_t i = 0; i < a.size(); ++i) {
        for (int k = 0; k < 3; ++k) EXPECT_NEAR(a.positions[i][k], b.positions[i][k], tolerance) << i;
        if (a.has_colors() && b.has_colors()) {
            for (int k = 0; k < 3; ++k) EXPECT_EQ(a.colors[i][k], b.colors[i][k]) << i;
        }
    }
}

TEST(PointReaders, PlyXyzPtsAndLasReadTheSamePoints) {
    PointCloud cloud = grid_cloud();
    Mesh mesh;
    mesh.positions = cloud.positions;
    mesh.colors = cloud.colors;
    std::string ply = test::scratch("same.ply");
    write_ply(ply, mesh, true);
    std::string xyz = test::write_text("same.xyz", xyz_text(cloud, false));
    std::string pts = test::write_text("same.pts", std::to_string(cloud.size()) + "\n" + xyz_text(cloud, true));
    std::string las = test::scratch("same.las");
    write_las(las, cloud, 3, 0.001);

    PointReadInfo info;
    PointCloud from_ply = read_point_cloud(ply, &info);
    EXPECT_EQ(info.format, "PLY");
    expect_same_points(cloud, from_ply, 0.0);  // doubles (|x| > 1e5 is written as double)
    expect_same_points(cloud, read_point_cloud(xyz), 0.0);
    PointReadInfo pts_info;
    expect_same_points(cloud, read_point_cloud(pts, &pts_info), 0.0);
    EXPECT_EQ(pts_info.format, "PTS");
    ASSERT_EQ(pts_info.dropped.size(), 1u);  // the intensity column
    PointReadInfo las_info;
    PointCloud from_las = read_point_cloud(las, &las_info);
    EXPECT_EQ(las_info.format, "LAS 1.2 format 3");
    EXPECT_TRUE(las_info.z_up);
    expect_same_points(cloud, from_las, 0.5e-3 + 1e-9);  // integer millimetres
}

TEST(PointReaders, LasPointFormats0To3And6To8RoundTrip) {
    PointCloud cloud = grid_cloud();
    for (int format : {0, 1, 2, 3, 6, 7, 8}) {
        std::string path = test::scratch("format" + std::to_string(format) + ".las");
        write_las(path, cloud, format, 0.001);
        PointReadInfo info;
        PointCloud back = read_las(path, &info);
        EXPECT_EQ(info.format, std::string("LAS 1.") + (format >= 6 ? "4" : "2") + " format " + std::to_string(format));
        const bool has_rgb = format == 2 || format == 3 || format == 7 || format == 8;
        EXPECT_EQ(back.has_colors(), has_rgb) << format;
        expect_same_points(cloud, back, 0.5e-3 + 1e-9);
    }
}

TEST(PointReaders, LasWrittenByLibLasReadsAsItsHeaderSays) {
    // tests/data/points/pig_points.las: LAS 1.2, format 3, 468 points, written by libLAS 1.8.1.
    PointReadInfo info;
    PointCloud cloud = read_point_cloud(std::string(CATPAQ_SOURCE_DIR) + "/tests/data/points/pig_points.las", &info);
    EXPECT_EQ(info.format, "LAS 1.2 format 3");
    ASSERT_EQ(cloud.size(), 468u);
    EXPECT_FALSE(cloud.has_colors());  // its RGB fields are all zero
    // The header's bounds (max x, min x, max y, min y, max z, min z) hold every point and are
    // reached, within a scale step (about 1e-9).
    const double header_min[3] = {-0.28540000319480896, -0.23811699450016022, -0.5016670227050781};
    const double header_max[3] = {0.28481000661849976, 0.23883600533008575, 0.5015980005264282};
    Bounds b = cloud.bounds();
    for (int a = 0; a < 3; ++a) {
        EXPECT_NEAR(b.min[a], header_min[a], 2e-9);
        EXPECT_NEAR(b.max[a], header_max[a], 2e-9);
    }
    // The first point, decoded independently from the file's bytes (integer * scale + offset).
    EXPECT_NEAR(cloud.positions[0][0], 0.17518299820932004, 1e-12);
    EXPECT_NEAR(cloud.positions[0][1], 0.07026900344903608, 1e-12);
    EXPECT_NEAR(cloud.positions[0][2], -0.003253000332826994, 1e-12);
}

TEST(PointReaders, PlyRadiiNormalsAndColoursAreKept) {
    std::string path = test::write_text("radius.ply",
                                        "ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
                                        "property float z\nproperty float nx\nproperty float ny\nproperty float nz\n"
                                        "property uchar red\nproperty uchar green\nproperty uchar blue\n"
                                        "property float radius\nproperty float intensity\nend_header\n"
                                        "0 0 0 0 0 1 10 20 30 0.5 1\n1 2 3 1 0 0 40 50 60 0.25 2\n");
    PointReadInfo info;
    PointCloud cloud = read_point_cloud(path, &info);
    ASSERT_EQ(cloud.size(), 2u);
    ASSERT_TRUE(cloud.has_radii() && cloud.has_normals() && cloud.has_colors());
    EXPECT_EQ(cloud.radii[1], 0.25f);
    EXPECT_EQ(cloud.normals[1][0], 1.0f);
    EXPECT_EQ(cloud.colors[1][2], 60);
    ASSERT_EQ(info.dropped.size(), 1u);
    EXPECT_NE(info.dropped[0].find("intensity"), std::string::npos);
    EXPECT_EQ(info.dropped[0].find("radius"), std::string::npos);
}

TEST(PointReaders, MeshVerticesAreReadAsPoints) {
    std::string path = test::write_text("tri.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n");
    PointReadInfo info;
    PointCloud cloud = read_point_cloud(path, &info);
    EXPECT_EQ(cloud.size(), 3u);
    EXPECT_EQ(info.format, "OFF mesh");
}

TEST(PointReaders, NonFiniteCoordinatesAreRefused) {
    std::string xyz = test::write_text("nan.xyz", "0 0 0\n1 nan 2\n");
    EXPECT_TRUE(test::fails_with([&] { read_point_cloud(xyz); }, {"nan.xyz", "line 2", "non-finite"}));
    std::string inf = test::write_text("inf.pts", "1\n0 inf 0\n");
    EXPECT_TRUE(test::fails_with([&] { read_point_cloud(inf); }, {"inf.pts", "non-finite"}));
    std::string ply = test::write_text("nan.ply", "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n"
                                                  "property float y\nproperty float z\nend_header\n0 nan 0\n");
    EXPECT_TRUE(test::fails_with([&] { read_point_cloud(ply); }, {"nan.ply", "non-finite"}));
    PointCloud cloud = grid_cloud();
    cloud.positions[3][1] = NAN;
    EXPECT_TRUE(test::fails_with([&] { validate_point_cloud(cloud, "cloud"); }, {"point 3", "non-finite"}));
}

TEST(PointReaders, EmptyFilesAreRefused) {
    for (const char* name : {"empty.xyz", "empty.pts", "empty.las", "empty.ply"}) {
        std::string path = test::write_text(name, "");
        EXPECT_TRUE(test::fails_with([&] { read_point_cloud(path); }, {name})) << name;
    }
    std::string comments = test::write_text("comments.xyz", "# nothing\n\n");
    EXPECT_TRUE(test::fails_with([&] { read_point_cloud(comments); }, {"comments.xyz", "no points"}));
    std::string zero = test::write_text("zero.ply", "ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\n"
                                                    "property float y\nproperty float z\nend_header\n");
    EXPECT_TRUE(test::fails_with([&] { read_point_cloud(zero); }, {"zero.ply", "no vertices"}));
}

TEST(PointReaders, CountsThatDisagreeWithTheDataAreRefused) {
    std::string fewer = test::write_text("fewer.pts", "3\n0 0 0\n1 1 1\n");
    EXPECT_TRUE(test::fails_with([&] { read_point_cloud(fewer); }, {"fewer.pts", "truncated", "counts 3", "holds 2"}));
    std::string more = test::write_text("more.pts", "1\n0 0 0\n1 1 1\n");
    EXPECT_TRUE(test::fails_with([&] { read_point_cloud(more); }, {"more.pts", "more points than the count"}));

    PointCloud cloud = grid_cloud();
    std::string las = test::scratch("short.las");
    write_las(las, cloud, 1, 0.001);
    std::string bytes = read_file(las);
    std::string cut = test::write_text("short_cut.las", bytes.substr(0, bytes.size() - 10));
    EXPECT_TRUE(test::fails_with([&] { read_point_cloud(cut); }, {"short_cut.las", "truncated", "says 40 points", "holds 39"}));

    std::string ply = test::write_text("short.ply", "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n"
                                                    "property float y\nproperty float z\nend_header\n0 0 0\n1 1 1\n");
    EXPECT_TRUE(test::fails_with([&] { read_point_cloud(ply); }, {"short.ply", "truncated"}));
}

TEST(PointReaders, MalformedLinesAreRefusedWithTheirNumber) {
    std::string columns = test::write_text("columns.xyz", "0 0 0\n1 1 1 5 5 5\n");
    EXPECT_TRUE(test::fails_with([&] { read_point_cloud(columns); }, {"columns.xyz", "line 2", "expected 3 numbers"}));
    std::string word = test::write_text("word.xyz", "0 0 zero\n");
    EXPECT_TRUE(test::fails_with([&] { read_point_cloud(word); }, {"word.xyz", "line 1", "'zero'"}));
    std::string colour = test::write_text("colour.xyz", "0 0 0 300 0 0\n");
    EXPECT_TRUE(test::fails_with([&] { read_point_cloud(colour); }, {"colour.xyz", "0..255"}));
    std::string nocount = test::write_text("nocount.pts", "0 0 0\n");
    EXPECT_TRUE(test::fails_with([&] { read_point_cloud(nocount); }, {"nocount.pts", "point count"}));
}

TEST(PointReaders, LazAndForeignFilesAreRefused) {
    PointCloud cloud = grid_cloud();
    std::string las = test::scratch("laz.las");
    write_las(las, cloud, 3, 0.001);
    std::string bytes = read_file(las);
    bytes[104] = char(3 | 0x80);  // the LAZ convention: compressed point format
    std::string laz = test::write_text("compressed.laz", bytes);
    EXPECT_TRUE(test::fails_with([&] { read_point_cloud(laz); }, {"compressed.laz", "LAZ"}));
    std::string notlas = test::write_text("not.las", std::string(300, 'x'));
    EXPECT_TRUE(test::fails_with([&] { read_point_cloud(notlas); }, {"not.las", "LASF"}));
    std::string version = bytes;
    version[25] = 9;
    std::string v19 = test::write_text("v19.las", version);
    EXPECT_TRUE(test::fails_with([&] { read_point_cloud(v19); }, {"v19.las", "version 1.9"}));
    std::string unknown = test::write_text("cloud.e57", "x");
    EXPECT_TRUE(test::fails_with([&] { read_point_cloud(unknown); }, {"cloud.e57", "unknown point file type"}));
    EXPECT_TRUE(test::fails_with([&] { read_point_cloud(test::scratch("missing.xyz")); }, {"missing.xyz", "no such file"}));
}

}  // namespace
}  // namespace catpaq
