// Point readers: the same points through every format, an independent LAS writer's file, and
// bad inputs refused with a message naming the file and the problem; PointFileReader's batches
// make the whole-file cloud, refuse the same files with the same messages, in bounded memory.
#include <gtest/gtest.h>

#include <malloc.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <functional>
#include <sstream>

#include "base/error.h"
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


// --- PointFileReader: streaming in batches ---------------------------------------------------

// Reads `path` through PointFileReader in batches of `max_points` and concatenates them, checking
// each batch's shape on the way: at most max_points, attributes the same for every batch.
PointCloud read_in_batches(const std::string& path, size_t max_points, PointReadInfo* info = nullptr) {
    PointFileReader reader(path);
    PointCloud all, batch;
    while (reader.next(batch, max_points)) {
        const size_t n = batch.size();
        EXPECT_TRUE(n >= 1 && n <= max_points) << n;
        EXPECT_EQ(batch.normals.size(), reader.has_normals() ? n : 0);
        EXPECT_EQ(batch.colors.size(), reader.has_colors() ? n : 0);
        EXPECT_EQ(batch.radii.size(), reader.has_radii() ? n : 0);
        all.positions.insert(all.positions.end(), batch.positions.begin(), batch.positions.end());
        all.normals.insert(all.normals.end(), batch.normals.begin(), batch.normals.end());
        all.colors.insert(all.colors.end(), batch.colors.begin(), batch.colors.end());
        all.radii.insert(all.radii.end(), batch.radii.begin(), batch.radii.end());
        EXPECT_EQ(reader.points_read(), all.size());
    }
    EXPECT_EQ(batch.size(), 0u);
    EXPECT_FALSE(reader.next(batch, max_points));  // stays exhausted
    if (reader.expected_points() != 0) {
        EXPECT_EQ(reader.expected_points(), all.size());
    }
    if (info) *info = reader.info();
    return all;
}

void expect_identical(const PointCloud& a, const PointCloud& b, const std::string& what) {
    EXPECT_EQ(a.size(), b.size()) << what;
    EXPECT_TRUE(a.positions == b.positions) << what;
    EXPECT_TRUE(a.normals == b.normals) << what;
    EXPECT_TRUE(a.colors == b.colors) << what;
    EXPECT_TRUE(a.radii == b.radii) << what;
}

// The message `call` throws (catpaq::Error), or "" if it does not throw.
std::string error_of(const std::function<void()>& call) {
    try {
        call();
    } catch (const Error& e) {
        return e.what();
    }
    return "";
}

// 2500 points (more than the largest batch tested) in projected coordinates, with colours and
// unit normals.
PointCloud streaming_cloud() {
    PointCloud cloud = test::sphere_cloud(2500, 10.0, {500000.0, 4000000.0, 10.0}, 7);
    for (const Vec3d& p : cloud.positions) {
        Vec3d d = {p[0] - 500000.0, p[1] - 4000000.0, p[2] - 10.0};
        cloud.normals.push_back({float(d[0] / 10), float(d[1] / 10), float(d[2] / 10)});
    }
    return cloud;
}

// One file per format and variant the readers know, all holding `cloud`'s points.
std::vector<std::string> files_of_every_format(const PointCloud& cloud) {
    std::vector<std::string> files;
    Mesh mesh;
    mesh.positions = cloud.positions;
    mesh.normals = cloud.normals;
    mesh.colors = cloud.colors;
    files.push_back(test::scratch("stream_binary.ply"));
    write_ply(files.back(), mesh, true);
    files.push_back(test::scratch("stream_ascii.ply"));
    write_ply(files.back(), mesh, false);
    std::string radius_ply = "ply\nformat ascii 1.0\nelement vertex 20\nproperty float x\nproperty float y\n"
                             "property float z\nproperty float radius\nend_header\n";
    for (int i = 0; i < 20; ++i) radius_ply += strprintf("%d %d %d %g\n", i, i * i, -i, 0.125 * i);
    files.push_back(test::write_text("stream_radius.ply", radius_ply));
    files.push_back(test::write_text("stream_colours.xyz", xyz_text(cloud, false)));
    std::ostringstream plain;
    plain.precision(17);
    plain << "# x y z only\n";
    for (const Vec3d& p : cloud.positions) plain << p[0] << ' ' << p[1] << ' ' << p[2] << "\n\n";
    files.push_back(test::write_text("stream_plain.xyz", plain.str()));
    // Two scans of 1500 and 1000 points (with intensity), the second count line mid-file.
    const std::string lines = xyz_text(cloud, true);
    size_t cut = 0;
    for (int i = 0; i < 1500; ++i) cut = lines.find('\n', cut) + 1;
    files.push_back(test::write_text("stream_two_scans.pts", "1500\n" + lines.substr(0, cut) + "1000\n" + lines.substr(cut)));
    for (int format : {0, 2, 3, 6, 7, 8}) {
        files.push_back(test::scratch("stream_format" + std::to_string(format) + ".las"));
        write_las(files.back(), cloud, format, 0.001);
    }
    std::string obj = "# a fan of triangles over the points\n";
    for (const Vec3d& p : cloud.positions) obj += strprintf("v %.17g %.17g %.17g\n", p[0], p[1], p[2]);
    for (size_t i = 2; i < cloud.size(); ++i) obj += strprintf("f 1 %zu %zu\n", i, i + 1);
    files.push_back(test::write_text("stream.obj", obj));
    files.push_back(std::string(CATPAQ_SOURCE_DIR) + "/tests/data/points/pig_points.las");  // all-black RGB
    return files;
}

TEST(PointFileReader, BatchesOfAnySizeMakeTheWholeFileCloudOfEveryFormat) {
    PointCloud cloud = streaming_cloud();
    for (const std::string& path : files_of_every_format(cloud)) {
        PointReadInfo whole_info;
        const PointCloud whole = read_point_cloud(path, &whole_info);
        for (size_t batch : {size_t(1), size_t(7), size_t(1000)}) {
            const std::string what = path + " in batches of " + std::to_string(batch);
            PointReadInfo info;
            expect_identical(read_in_batches(path, batch, &info), whole, what);
            EXPECT_EQ(info.format, whole_info.format) << what;
            EXPECT_EQ(info.dropped, whole_info.dropped) << what;
            EXPECT_EQ(info.z_up, whole_info.z_up) << what;
        }
    }
    // And the whole-file clouds hold what was written (LAS: to the millimetre), so the
    // comparison above is between right answers.
    EXPECT_TRUE(read_point_cloud(test::scratch("stream_binary.ply")).normals.size() == cloud.size());
    expect_same_points(cloud, read_point_cloud(test::scratch("stream_two_scans.pts")), 0.0);
    expect_same_points(cloud, read_point_cloud(test::scratch("stream_format7.las")), 0.5e-3 + 1e-9);
}

TEST(PointFileReader, TheHeaderAnnouncesAttributesAndCountsBeforeTheFirstBatch) {
    PointCloud cloud = streaming_cloud();
    files_of_every_format(cloud);
    PointFileReader ply(test::scratch("stream_binary.ply"));
    EXPECT_TRUE(ply.has_normals() && ply.has_colors() && !ply.has_radii());
    EXPECT_EQ(ply.expected_points(), cloud.size());
    PointFileReader xyz(test::scratch("stream_colours.xyz"));
    EXPECT_TRUE(xyz.has_colors() && !xyz.has_normals());
    EXPECT_EQ(xyz.expected_points(), 0u);  // text announces nothing
    PointFileReader pts(test::scratch("stream_two_scans.pts"));
    EXPECT_TRUE(pts.has_colors());
    EXPECT_EQ(pts.info().format, "PTS");
    EXPECT_EQ(pts.info().dropped, std::vector<std::string>{"intensity (not kept)"});
    PointFileReader las(test::scratch("stream_format0.las"));
    EXPECT_FALSE(las.has_colors());
    EXPECT_TRUE(las.info().z_up);
    EXPECT_EQ(las.expected_points(), cloud.size());
    PointFileReader obj(test::scratch("stream.obj"));
    EXPECT_EQ(obj.info().format, "OBJ mesh");
    EXPECT_EQ(obj.expected_points(), cloud.size());
    EXPECT_EQ(obj.points_read(), 0u);
}

// LAS colours are 16-bit; files whose colours all fit in 0..255 are kept as is, others scaled.
// The decision takes every record, so a large value in the last record scales the first batch.
TEST(PointFileReader, LasColoursAreScaledByAllRecordsNotByTheFirstBatch) {
    PointCloud cloud = streaming_cloud();
    std::string path = test::scratch("rgb8.las");
    write_las(path, cloud, 2, 0.001);
    std::string bytes = read_file(path);
    const size_t header = 227, record = 26, rgb = 20;
    auto set_rgb = [&](size_t i, uint16_t value) {
        for (int k = 0; k < 3; ++k) {
            bytes[header + i * record + rgb + 2 * k] = char(value & 0xff);
            bytes[header + i * record + rgb + 2 * k + 1] = char(value >> 8);
        }
    };
    for (size_t i = 0; i < cloud.size(); ++i) set_rgb(i, uint16_t(i % 256));
    std::string kept = test::write_text("rgb8_kept.las", bytes);
    set_rgb(cloud.size() - 1, 0xffff);
    std::string scaled = test::write_text("rgb8_scaled.las", bytes);
    for (size_t batch : {size_t(1), size_t(7), size_t(1000)}) {
        PointCloud a = read_in_batches(kept, batch), b = read_in_batches(scaled, batch);
        ASSERT_TRUE(a.has_colors() && b.has_colors());
        EXPECT_EQ(a.colors[200][0], 200);  // 8-bit values kept
        EXPECT_EQ(b.colors[200][0], 0);    // 200 >> 8: the file's colours are 16-bit
        EXPECT_EQ(b.colors.back()[0], 255);
        expect_identical(a, read_point_cloud(kept), kept);
        expect_identical(b, read_point_cloud(scaled), scaled);
    }
}

// A bad point far into the file is refused in whichever batch holds it, with the number it has
// in the file, and with the very message read_point_cloud gives.
TEST(PointFileReader, ErrorsInLaterBatchesNameFileGlobalPointsAndLines) {
    PointCloud cloud = streaming_cloud();
    std::string lines = xyz_text(cloud, false);
    size_t at = 0;
    for (int i = 0; i < 1499; ++i) at = lines.find('\n', at) + 1;  // line 1500 starts at `at`
    std::string nan_xyz = test::write_text("late_nan.xyz", lines.substr(0, at) + "1 nan 2 0 0 0\n" + lines.substr(at));
    std::string columns_xyz = test::write_text("late_columns.xyz", lines.substr(0, at) + "1 2 3\n" + lines.substr(at));
    std::string nan_pts = test::write_text("late_nan.pts", "2501\n" + lines.substr(0, at) + "1 2 inf 0 0 0\n" + lines.substr(at));

    // PLY: write_ply refuses non-finite points, so vertex 1500's z (doubles: |x| > 1e5) is patched.
    Mesh mesh;
    mesh.positions = cloud.positions;
    std::string ply_path = test::scratch("late_nan_source.ply");
    write_ply(ply_path, mesh, true);
    std::string ply_bytes = read_file(ply_path);
    const double inf = INFINITY;
    std::memcpy(&ply_bytes[ply_bytes.find("end_header\n") + 11 + 1500 * 24 + 16], &inf, 8);
    std::string nan_ply = test::write_text("late_nan.ply", ply_bytes);

    // LAS: scale 1e308 makes an integer coordinate of 2 overflow to infinity at record 1500.
    std::string las_path = test::scratch("late_inf.las");
    write_las(las_path, cloud, 0, 0.001);
    std::string bytes = read_file(las_path);
    const double huge = 1e308;
    std::memcpy(&bytes[131], &huge, 8);  // the x scale
    for (size_t i = 0; i < cloud.size(); ++i) std::memset(&bytes[227 + i * 20], 0, 4);
    bytes[227 + 1500 * 20] = 2;
    std::string inf_las = test::write_text("late_inf.las", bytes);

    const std::pair<std::string, std::vector<const char*>> cases[] = {
        {nan_xyz, {"late_nan.xyz", "line 1500", "non-finite"}},
        {columns_xyz, {"late_columns.xyz", "line 1500", "expected 6 numbers like the first point"}},
        {nan_pts, {"late_nan.pts", "line 1501", "non-finite"}},
        {nan_ply, {"late_nan.ply", "vertex 1500", "non-finite"}},
        {inf_las, {"late_inf.las", "point 1500", "non-finite"}},
    };
    for (const auto& [path, words] : cases) {
        const std::string whole = error_of([&] { read_point_cloud(path); });
        for (const char* word : words) EXPECT_NE(whole.find(word), std::string::npos) << whole << " lacks " << word;
        for (size_t batch : {size_t(1), size_t(7), size_t(1000)})
            EXPECT_EQ(error_of([&] { read_in_batches(path, batch); }), whole) << path << " in batches of " << batch;
    }
}

// Counts checked at the end (PTS scans, PLY vertices) and at open (LAS, empty files) refuse the
// same files through the streaming path, with read_point_cloud's message.
TEST(PointFileReader, CountsAndEmptyFilesAreRefusedThroughTheStreamingPath) {
    PointCloud cloud = streaming_cloud();
    const std::string lines = xyz_text(cloud, false);
    size_t cut = 0;
    for (int i = 0; i < 1500; ++i) cut = lines.find('\n', cut) + 1;
    // The second scan counts 1001 points and holds 1000; then one that holds one too many.
    std::string fewer = test::write_text("stream_fewer.pts", "1500\n" + lines.substr(0, cut) + "1001\n" + lines.substr(cut));
    std::string more = test::write_text("stream_more.pts", "1500\n" + lines.substr(0, cut) + "999\n" + lines.substr(cut));
    std::string zero = test::write_text("stream_zero.pts", "0\n\n0\n");
    std::string las = test::scratch("stream_short.las");
    write_las(las, cloud, 3, 0.001);
    std::string bytes = read_file(las);
    std::string cut_las = test::write_text("stream_short_cut.las", bytes.substr(0, bytes.size() - 1));
    Mesh mesh;
    mesh.positions = cloud.positions;
    std::string ply_path = test::scratch("stream_short.ply");
    write_ply(ply_path, mesh, true);
    std::string ply_bytes = read_file(ply_path);
    std::string short_ply = test::write_text("stream_short_cut.ply", ply_bytes.substr(0, ply_bytes.size() - 5));
    std::string comments = test::write_text("stream_comments.xyz", "# nothing\n\n# still nothing\n");

    const std::pair<std::string, std::vector<const char*>> cases[] = {
        {fewer, {"stream_fewer.pts", "truncated", "line 1502 counts 1001", "holds 1000"}},
        {more, {"stream_more.pts", "line 2502", "more points than the count on line 1502"}},
        {zero, {"stream_zero.pts", "no points"}},
        {cut_las, {"stream_short_cut.las", "truncated", "says 2500 points", "holds 2499"}},
        {short_ply, {"stream_short_cut.ply", "truncated"}},
        {comments, {"stream_comments.xyz", "no points"}},
        {test::write_text("stream_empty.xyz", ""), {"stream_empty.xyz", "empty"}},
        {test::write_text("stream_empty.pts", ""), {"stream_empty.pts", "empty"}},
        {test::write_text("stream_empty.las", ""), {"stream_empty.las", "empty"}},
        {test::write_text("stream_empty.ply", ""), {"stream_empty.ply"}},
        {test::scratch("stream_missing.las"), {"stream_missing.las", "no such file"}},
    };
    for (const auto& [path, words] : cases) {
        const std::string whole = error_of([&] { read_point_cloud(path); });
        for (const char* word : words) EXPECT_NE(whole.find(word), std::string::npos) << whole << " lacks " << word;
        for (size_t batch : {size_t(1), size_t(7), size_t(1000)})
            EXPECT_EQ(error_of([&] { read_in_batches(path, batch); }), whole) << path << " in batches of " << batch;
    }
}

// Bytes the heap holds (glibc: arenas and mmapped blocks). Under a sanitizer, whose allocator
// glibc does not see, it stays flat and the test below proves nothing (but does not fail).
size_t heap_in_use() {
    struct mallinfo2 m = mallinfo2();
    return m.uordblks + m.hblkhd;
}

// Streaming a file far larger than the readers' buffers never holds more than those buffers
// and a batch: the heap's peak while reading stays under half the file's size (the whole cloud
// would take more than the file).
TEST(PointFileReader, StreamingHoldsABatchAndBuffersNotTheFile) {
    std::vector<std::string> files;
    {
        // XYZ: 2M short lines, 23 MB; the line reader's buffer is 8 MiB.
        std::string text;
        text.reserve(size_t(25) << 20);
        for (int i = 0; i < 2000000; ++i) text += strprintf("%d %d %d\n", i % 1000, i % 997, i % 991);
        files.push_back(test::write_text("big.xyz", text));
    }
    {
        // LAS format 2 (RGB: the colour pre-scan reads every record too), 1M points, 26 MB;
        // PLY binary, 1M vertices with normals and colours, 27 MB.
        PointCloud cloud;
        Mesh mesh;
        for (int i = 0; i < 1000000; ++i) {
            cloud.positions.push_back({double(i % 1000), double(i % 997), double(i % 991)});
            cloud.colors.push_back({uint8_t(i), uint8_t(i >> 8), uint8_t(i >> 16)});
            mesh.normals.push_back({0.0f, 0.0f, 1.0f});
        }
        files.push_back(test::scratch("big.las"));
        write_las(files.back(), cloud, 2, 0.001);
        files.push_back(test::scratch("big.ply"));
        mesh.positions = std::move(cloud.positions);
        mesh.colors = std::move(cloud.colors);
        write_ply(files.back(), mesh, true);
    }
    for (const std::string& path : files) {
        const size_t file_size = std::filesystem::file_size(path);
        ASSERT_GT(file_size, size_t(20) << 20) << path;
        const size_t before = heap_in_use();
        size_t peak = 0, points = 0;
        {
            PointFileReader reader(path);
            PointCloud batch;
            while (reader.next(batch, 4096)) {
                points += batch.size();
                peak = std::max(peak, heap_in_use());
            }
        }
        EXPECT_EQ(points, path.ends_with(".xyz") ? 2000000u : 1000000u) << path;
        const size_t held = peak > before ? peak - before : 0;
        EXPECT_LT(held, file_size / 2) << path << ": " << held << " bytes held while streaming " << file_size;
        std::filesystem::remove(path);  // 20-30 MB each: not left in the scratch directory
    }
}

// read_point_sample: every point when the file holds no more than asked; else exactly that many,
// each an input point with its colour, none twice, the same on every run; from a PLY (count in
// the header) and from XYZ text (count unknown until the end).
TEST(PointReaders, ASampleHoldsInputPointsOnceAndIsTheSameEveryRun) {
    PointCloud cloud;
    for (int i = 0; i < 5000; ++i) {
        cloud.positions.push_back({double(i), double(i % 7), double(i % 13)});
        cloud.colors.push_back({uint8_t(i), uint8_t(i >> 8), 7});
    }
    Mesh mesh;
    mesh.positions = cloud.positions;
    mesh.colors = cloud.colors;
    const std::string ply = test::scratch("sample.ply");
    write_ply(ply, mesh);
    const std::string xyz = test::write_text("sample.xyz", xyz_text(cloud, false));
    for (const std::string& path : {ply, xyz}) {
        uint64_t total = 0;
        const PointCloud all = read_point_sample(path, 5000, nullptr, &total);
        EXPECT_EQ(total, 5000u);
        EXPECT_EQ(all.positions, cloud.positions) << path;
        const PointCloud sample = read_point_sample(path, 1000, nullptr, &total);
        EXPECT_EQ(total, 5000u);
        ASSERT_EQ(sample.size(), 1000u) << path;
        ASSERT_EQ(sample.colors.size(), 1000u);
        std::vector<bool> taken(5000, false);
        for (size_t k = 0; k < sample.size(); ++k) {
            const int i = int(sample.positions[k][0]);
            ASSERT_TRUE(i >= 0 && i < 5000 && sample.positions[k] == cloud.positions[size_t(i)]) << path;
            EXPECT_EQ(sample.colors[k], cloud.colors[size_t(i)]);
            EXPECT_FALSE(taken[size_t(i)]) << "point " << i << " twice";
            taken[size_t(i)] = true;
        }
        // Spread over the file, not its head: a uniform sample has points from each fifth.
        for (int fifth = 0; fifth < 5; ++fifth)
            EXPECT_GT(std::count(taken.begin() + fifth * 1000, taken.begin() + (fifth + 1) * 1000, true), 100);
        EXPECT_EQ(read_point_sample(path, 1000).positions, sample.positions);
    }
    EXPECT_THROW(read_point_sample(ply, 0), Error);
}

}  // namespace
}  // namespace catpaq
