// The benchmark's LAS/LAZ writer (bench/points/laz_writer.h), checked against an independent
// decoder: laz-perf (hobuinc's LASzip implementation, WebAssembly, npm laz-perf@0.0.7) run by
// scripts/report/laz_decode.mjs must return every point record we wrote, bit for bit, for clouds
// that reach every path of the format: several chunks, one point, none, colours and none, grey
// colours, every flag and attribute changing, coordinates across the whole int32 range. The
// uncompressed LAS from the same writer reads back through our own reader to the same points.
// node and laz-perf are part of the test setup (scripts/setup.sh --tests): missing, the tests
// fail saying so; they do not skip.
#include <gtest/gtest.h>

#include <climits>

#include "laz_writer.h"
#include "mesh/generators.h"
#include "points/point_cloud.h"
#include "points/sampling.h"
#include "support.h"

namespace catpaq {
namespace {

using laz::LasLayout;
using laz::LasPoint;

std::string records_of(const std::vector<LasPoint>& points, bool colors) {
    std::string out;
    for (const LasPoint& p : points) laz::append_las_record(p, colors, out);
    return out;
}

// A scan-like surface sampled at random (the benchmark's kind of cloud), quantized to 1 mm with
// the offset at the minimum; colours from the surface.
std::vector<LasPoint> scan_points(size_t count, LasLayout& layout) {
    const PointCloud cloud = sample_surface(make_scan_like(count / 2, 7), count, 11, false, true);
    const Bounds bounds = cloud.bounds();
    for (int a = 0; a < 3; ++a) {
        layout.scale[a] = 0.001;
        layout.offset[a] = bounds.min[a];
    }
    return laz::quantize_points(cloud.positions, cloud.colors, layout);
}

// Points whose every field changes now and then, so that each of POINT10's and RGB12's models
// is used: returns r of n for all r, n in 0..7 (the unusual pairs share contexts), flags,
// intensity, classes, scan angles across the sign, user data, source IDs, colours grey (r = g =
// b) or not, bytes changing alone; coordinates jumping across the whole int32 range (differences
// that wrap, correctors of every bit length, -2^31 itself).
std::vector<LasPoint> every_field_points(size_t count) {
    std::vector<LasPoint> points(count);
    uint64_t state = 99;
    int32_t x = 0, y = 0, z = 0;
    for (size_t i = 0; i < count; ++i) {
        LasPoint& p = points[i];
        const uint64_t r = test::next_random(state);
        const int jump = int(r % 16);
        if (jump == 0) {  // anywhere
            x = int32_t(uint32_t(test::next_random(state)));
            y = int32_t(uint32_t(test::next_random(state)));
            z = int32_t(uint32_t(test::next_random(state)));
        } else if (jump == 1) {  // the extremes
            x = (r >> 8) & 1 ? INT32_MIN : INT32_MAX;
            y = (r >> 9) & 1 ? INT32_MIN : INT32_MAX;
            z = (r >> 10) & 1 ? INT32_MIN : 0;
        } else {  // a small step, sometimes of a larger scale
            const int shift = int((r >> 12) % 24);
            x += int32_t(int64_t((r >> 20) % 41) - 20) << (jump < 8 ? 0 : shift % 12);
            y += int32_t(int64_t((r >> 28) % 41) - 20) << (jump < 8 ? 0 : shift % 12);
            z += int32_t(int64_t((r >> 36) % 17) - 8) << (jump < 12 ? 0 : shift);
        }
        p.x = x;
        p.y = y;
        p.z = z;
        const uint64_t f = test::next_random(state);
        p.return_number = uint8_t(f % 8 < 5 ? 1 : f % 8);
        p.number_of_returns = uint8_t((f >> 3) % 8 < 4 ? 1 : (f >> 3) % 8);
        p.scan_direction = (f >> 6) & 1;
        p.edge_of_flight_line = ((f >> 7) % 8) == 0;
        p.intensity = (f >> 10) % 4 ? uint16_t(1000 + (f >> 12) % 64) : uint16_t(f >> 16);
        p.classification = (f >> 32) % 8 ? 2 : uint8_t(f >> 35);
        p.scan_angle_rank = int8_t((f >> 40) % 6 ? -3 : int((f >> 43) % 181) - 90);
        p.user_data = (f >> 48) % 16 ? 0 : uint8_t(f >> 52);
        p.point_source_id = (f >> 56) % 32 ? 7 : uint16_t(f >> 20);
        const uint64_t c = test::next_random(state);
        const uint16_t grey = uint16_t(c >> 8);
        switch (c % 5) {
            case 0: std::fill(std::begin(p.rgb), std::end(p.rgb), grey); break;
            case 1: p.rgb[0] = uint16_t(c >> 16), p.rgb[1] = uint16_t(c >> 32), p.rgb[2] = uint16_t(c >> 48); break;
            case 2:  // only one byte of one channel changes
                if (i) std::copy(std::begin(points[i - 1].rgb), std::end(points[i - 1].rgb), p.rgb);
                p.rgb[(c >> 3) % 3] ^= uint16_t(((c >> 5) & 1 ? 0xFF00 : 0x00FF) & (c >> 24));
                break;
            default:  // 8-bit colours as 16 (v * 257), as the benchmark writes them
                for (int k = 0; k < 3; ++k) p.rgb[k] = uint16_t(((c >> (8 * k + 8)) & 0xFF) * 257);
        }
    }
    return points;
}

// node, the script and laz-perf; missing, a failure saying what to install.
bool find_decoder(laz::LazPerfDecoder& decoder) {
    try {
        decoder = laz::find_lazperf_decoder(CATPAQ_SOURCE_DIR);
        return true;
    } catch (const Error& e) {
        ADD_FAILURE() << "the LAZ check cannot run: " << e.what();
        return false;
    }
}

struct Case {
    explicit Case(std::string case_name = "") : name(std::move(case_name)) {}
    std::string name;
    std::vector<LasPoint> points;
    LasLayout layout;
    uint32_t chunk_points = laz::kDefaultChunkPoints;
};

std::vector<Case> cases() {
    std::vector<Case> all;
    Case scan("scan");
    scan.points = scan_points(120000, scan.layout);  // 3 chunks of LASzip's default 50000
    all.push_back(scan);
    Case plain = scan;  // format 0, smaller chunks, the last one short
    plain.name = "scan_no_colours";
    plain.layout.colors = false;
    plain.points.resize(23456);
    plain.chunk_points = 5000;
    all.push_back(plain);
    Case one("one_point");
    one.points = {scan.points[17]};
    one.layout = scan.layout;
    all.push_back(one);
    Case two("two_points");
    two.points = {scan.points[17], scan.points[18]};
    two.layout = scan.layout;
    all.push_back(two);
    Case chunk_of_one = two;  // every chunk a single raw point
    chunk_of_one.name = "chunks_of_one";
    chunk_of_one.chunk_points = 1;
    all.push_back(chunk_of_one);
    Case empty("empty");
    all.push_back(empty);
    Case fields("every_field");
    fields.points = every_field_points(60000);
    fields.chunk_points = 20000;
    all.push_back(fields);
    Case far = scan;  // a projected-coordinate scan: offsets of 1e7, 0.1 mm steps
    far.name = "large_offsets";
    far.points.resize(30000);
    for (int a = 0; a < 3; ++a) {
        far.layout.scale[a] = 0.0001;
        far.layout.offset[a] = 1e7 + 12345.678 * a;
    }
    for (LasPoint& p : far.points) p.x = p.x * 10 + 7, p.y = p.y * 10 - 3, p.z *= 10;
    all.push_back(far);
    return all;
}

// Every case written as LAZ, decoded by laz-perf: the same count, format and record length,
// and the same record bytes as our records. A case that fails names its first differing point.
TEST(LazWriter, LazPerfDecodesEveryPointBitForBit) {
    laz::LazPerfDecoder decoder;
    if (!find_decoder(decoder)) return;  // a failure, not a skip
    for (const Case& c : cases()) {
        SCOPED_TRACE(c.name);
        const std::string path = test::scratch(c.name + ".laz");
        const laz::LasFileSummary summary = laz::write_las_file(path, c.points, c.layout, true, c.chunk_points);
        EXPECT_EQ(summary.chunks, (c.points.size() + c.chunk_points - 1) / c.chunk_points);
        laz::DecodedLas decoded;
        try {
            decoded = laz::decode_with_lazperf(decoder, path, test::scratch(c.name + ".records"));
        } catch (const Error& e) {
            ADD_FAILURE() << e.what();
            continue;
        }
        EXPECT_EQ(decoded.points, c.points.size());
        EXPECT_EQ(decoded.format, c.layout.colors ? 2 : 0);
        EXPECT_EQ(size_t(decoded.record_length), laz::las_record_length(c.layout.colors));
        const std::string expected = records_of(c.points, c.layout.colors);
        ASSERT_EQ(decoded.records.size(), expected.size());
        const size_t length = laz::las_record_length(c.layout.colors);
        for (size_t i = 0; i < c.points.size(); ++i)
            if (decoded.records.compare(i * length, length, expected, i * length, length) != 0) {
                ADD_FAILURE() << "point " << i << " of " << c.points.size() << " decodes differently";
                break;
            }
    }
}

// The comparison above can fail: a LAZ file with one byte changed inside its second chunk
// decodes to other points (or laz-perf refuses it).
TEST(LazWriter, ACorruptedChunkDecodesDifferently) {
    laz::LazPerfDecoder decoder;
    if (!find_decoder(decoder)) return;  // a failure, not a skip
    LasLayout layout;
    const std::vector<LasPoint> points = scan_points(12000, layout);
    std::string bytes = laz::encode_laz(points, layout, 5000);
    const std::string expected = records_of(points, true);
    const std::string good = test::write_text("good.laz", bytes);
    EXPECT_EQ(laz::decode_with_lazperf(decoder, good, test::scratch("good.records")).records, expected);
    // The second chunk starts about 5000 / 12000 of the way through the point data.
    const size_t at = bytes.size() * 6 / 10;
    bytes[at] = char(bytes[at] ^ 0x10);
    const std::string bad = test::write_text("bad.laz", bytes);
    try {
        EXPECT_NE(laz::decode_with_lazperf(decoder, bad, test::scratch("bad.records")).records, expected);
    } catch (const Error& e) {
        SUCCEED() << "laz-perf refused it: " << e.what();
    }
}

// The uncompressed LAS of the same writer reads back through our reader (read_las and
// PointFileReader): the coordinates integer * scale + offset exactly, colours v * 257 back to v.
TEST(LazWriter, UncompressedLasReadsBackThroughOurReader) {
    LasLayout layout;
    const PointCloud cloud = sample_surface(make_scan_like(4000, 3), 9000, 5, false, true);
    const Bounds bounds = cloud.bounds();
    for (int a = 0; a < 3; ++a) {
        layout.scale[a] = 0.0005;
        layout.offset[a] = bounds.min[a] + 1000.0;  // above the points: negative integers
    }
    const std::vector<LasPoint> points = laz::quantize_points(cloud.positions, cloud.colors, layout);
    for (bool colors : {true, false}) {
        SCOPED_TRACE(colors ? "format 2" : "format 0");
        layout.colors = colors;
        const std::string path = test::scratch(colors ? "rgb.las" : "plain.las");
        const laz::LasFileSummary summary = laz::write_las_file(path, points, layout, false);
        EXPECT_EQ(summary.point_bytes, points.size() * laz::las_record_length(colors));
        PointReadInfo info;
        const PointCloud back = read_las(path, &info);
        EXPECT_EQ(info.format, std::string("LAS 1.2 format ") + (colors ? "2" : "0"));
        ASSERT_EQ(back.size(), points.size());
        ASSERT_EQ(back.has_colors(), colors);
        size_t differing = 0;
        for (size_t i = 0; i < points.size(); ++i) {
            const int32_t v[3] = {points[i].x, points[i].y, points[i].z};
            for (int a = 0; a < 3; ++a) differing += back.positions[i][a] != v[a] * layout.scale[a] + layout.offset[a];
            if (colors) differing += back.colors[i] != cloud.colors[i];
            // and within half a step of the input
            for (int a = 0; a < 3; ++a) EXPECT_NEAR(back.positions[i][a], cloud.positions[i][a], 0.5 * layout.scale[a] + 1e-6);
        }
        EXPECT_EQ(differing, 0u);
        PointFileReader reader(path);
        EXPECT_EQ(reader.expected_points(), points.size());
        EXPECT_EQ(reader.has_colors(), colors);
    }
}

// What LAS cannot hold is refused with a message saying what.
TEST(LazWriter, RefusesWhatLasCannotHold) {
    LasLayout layout;
    std::vector<LasPoint> points(3);
    points[1].return_number = 8;
    EXPECT_TRUE(test::fails_with([&] { laz::encode_laz(points, layout); }, {"point 1", "return 8 of 1", "3 bits"}));
    points[1].return_number = 1;
    EXPECT_TRUE(test::fails_with([&] { laz::encode_laz(points, layout, 0); }, {"chunk", "at least one point"}));
    layout.scale[1] = 0;
    EXPECT_TRUE(test::fails_with([&] { laz::encode_laz(points, layout); }, {"scale 0", "positive"}));
    layout.scale[1] = 0.001;
    EXPECT_TRUE(test::fails_with([&] { laz::quantize_points({{0, 0, 0}, {0, 3e6, 0}}, {}, layout); },
                                 {"point 1", "2^31 steps"}));
    EXPECT_TRUE(test::fails_with([&] { laz::quantize_points({{0, 0, NAN}}, {}, layout); }, {"point 0", "2^31 steps"}));
}

}  // namespace
}  // namespace catpaq
