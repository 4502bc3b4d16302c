// The node codec: round trips within the stated bounds, and bad bytes give errors, never crashes.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>

#include "base/checksum.h"
#include "common_codec/octahedral.h"
#include "points/codec.h"
#include "support.h"
// The encoder's private Rice helpers (rice_bits against the scalar rice_cost).
#include "../../points/src/rice.h"

namespace catpaq {
namespace {

// GoldenBytesOfASmallNode: recorded from the encoder of format version 3 (version 2: 95 bytes,
// checksum 12957350842320211667; version 1: 152 bytes, four interleaved Rice lanes per stream).
constexpr size_t kGoldenSize = 95;
constexpr uint64_t kGoldenChecksum = 4545968190027558109ull;

// The same node as written by the encoder of format version 2 (before blocks of zeros), which
// the decoder still reads: datasets converted before version 3 stay readable.
constexpr uint8_t kGoldenVersion2[95] = {
    0x43, 0x50, 0x50, 0x4e, 0x02, 0x03, 0x08, 0x09, 0x04, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00,
    0x00, 0x00, 0x00, 0x00, 0x00, 0x3a, 0xcd, 0x13, 0x3e, 0x00, 0x00, 0x00, 0x3f, 0x00, 0x00, 0x00, 0x3e, 0x3b, 0x0a,
    0x93, 0x3c, 0x03, 0x55, 0x70, 0x0d, 0x01, 0x03, 0x06, 0x00, 0x01, 0x07, 0x04, 0x00, 0x06, 0x23, 0x02, 0x00, 0xe0,
    0xf7, 0x05, 0x07, 0x04, 0x00, 0x00, 0x0f, 0x06, 0x52, 0x01, 0x3e, 0xf0, 0x57, 0x09, 0x1e, 0xfc, 0xfb, 0xf7, 0xb7,
    0x0e, 0x08, 0x92, 0x01, 0x00, 0xfc, 0xfb, 0xfe, 0x00, 0x43, 0x08, 0xdc, 0xb8, 0x20, 0x5e, 0x6c, 0x6a, 0xac, 0x6d};

struct Node {
    std::vector<double> positions;
    std::vector<float> normals, radii;
    std::vector<uint8_t> colors;
    PointSamplesView view() const {
        PointSamplesView v;
        v.count = radii.size();
        v.positions = positions.data();
        v.normals = normals.empty() ? nullptr : normals.data();
        v.colors = colors.empty() ? nullptr : colors.data();
        v.radii = radii.data();
        return v;
    }
};

// A patch of a wavy surface: n points, varied radii, smooth normals and colours, around `offset`.
Node make_node(size_t n, uint64_t seed, double offset = 0.0) {
    Node node;
    uint64_t state = seed;
    for (size_t i = 0; i < n; ++i) {
        double x = test::random_unit(state), y = test::random_unit(state);
        double z = 0.05 * std::sin(6 * x) * std::cos(5 * y);
        node.positions.insert(node.positions.end(), {offset + x, offset + y, offset + z});
        float nx = float(-0.3 * std::cos(6 * x)), ny = float(0.25 * std::sin(5 * y)), nz = 1.0f;
        float length = std::sqrt(nx * nx + ny * ny + nz * nz);
        node.normals.insert(node.normals.end(), {nx / length, ny / length, nz / length});
        node.colors.insert(node.colors.end(), {uint8_t(255 * x), uint8_t(255 * y), uint8_t(test::next_random(state) & 255)});
        node.radii.push_back(float(0.01 + 0.01 * test::random_unit(state)));
    }
    return node;
}

double distance(const float* decoded, const double* input) {
    double d2 = 0;
    for (int a = 0; a < 3; ++a) d2 += (double(decoded[a]) - input[a]) * (double(decoded[a]) - input[a]);
    return std::sqrt(d2);
}

TEST(PointCodec, RoundTripKeepsEveryAttributeWithinTheStatedBounds) {
    Node node = make_node(3000, 1);
    std::vector<uint32_t> order;
    DecodedPoints out;
    PointEncodeStats stats;
    std::vector<uint8_t> bytes = encode_point_node(node.view(), PointEncodeSettings{}, &order, nullptr, &stats);
    ASSERT_EQ(decode_point_node(bytes.data(), bytes.size(), out), "");
    ASSERT_EQ(out.count, 3000u);
    EXPECT_EQ(out.flags, kPointHasNormals | kPointHasColors);
    // The order is a permutation.
    std::vector<uint32_t> sorted = order;
    std::sort(sorted.begin(), sorted.end());
    for (uint32_t i = 0; i < 3000; ++i) ASSERT_EQ(sorted[i], i);
    const double min_radius = *std::min_element(node.radii.begin(), node.radii.end());
    EXPECT_LE(out.position_error, 0.25 * min_radius);
    EXPECT_GE(double(out.position_error), stats.position_error);
    for (size_t i = 0; i < out.count; ++i) {
        const uint32_t k = order[i];
        EXPECT_LE(distance(&out.positions[3 * i], &node.positions[3 * k]), out.position_error);
        // Radii are never smaller than the input's grown by the position error: decoded splats
        // cover the input splats.
        EXPECT_GE(double(out.radii[i]), double(node.radii[k]) + distance(&out.positions[3 * i], &node.positions[3 * k]));
        EXPECT_LE(out.radii[i], node.radii[k] + 0.25 * min_radius + out.position_error + 1e-6);
        EXPECT_EQ(out.normals[i], oct_encode_precise(node.normals[3 * k], node.normals[3 * k + 1], node.normals[3 * k + 2]));
        for (int c = 0; c < 3; ++c) EXPECT_EQ(out.colors[3 * i + c], node.colors[3 * k + c]);  // lossless by default
    }
    // Scan-like patches compress: well under the raw 31 bytes per point.
    EXPECT_LT(double(bytes.size()) / 3000, 6.0);
}

TEST(PointCodec, EncoderDecodesItsOwnOutputForTheCaller) {
    Node node = make_node(500, 2);
    DecodedPoints from_encoder, from_decoder;
    std::vector<uint8_t> bytes = encode_point_node(node.view(), PointEncodeSettings{}, nullptr, &from_encoder);
    ASSERT_EQ(decode_point_node(bytes.data(), bytes.size(), from_decoder), "");
    EXPECT_EQ(from_encoder.positions, from_decoder.positions);
    EXPECT_EQ(from_encoder.radii, from_decoder.radii);
    EXPECT_EQ(from_encoder.normals, from_decoder.normals);
}

TEST(PointCodec, ReducedColourPrecisionStaysWithinItsStepsAndShrinksTheNode) {
    Node node = make_node(2000, 3);
    DecodedPoints out;
    std::vector<uint32_t> order;
    std::vector<uint8_t> lossless = encode_point_node(node.view(), PointEncodeSettings{});
    std::vector<uint8_t> bytes = encode_point_node(node.view(), PointEncodeSettings{ColorBits{5, 6}}, &order);
    ASSERT_EQ(decode_point_node(bytes.data(), bytes.size(), out), "");
    int worst = 0;
    for (size_t i = 0; i < out.count; ++i)
        for (int c = 0; c < 3; ++c) worst = std::max(worst, std::abs(int(out.colors[3 * i + c]) - int(node.colors[3 * order[i] + c])));
    // Luma steps of 8 and chroma steps of 8: each RGB channel within Y/2 + (Co or Cg)/2 + the
    // other's rounding, at most 12 (measured: the luma search keeps it near 8).
    EXPECT_LE(worst, 12);
    EXPECT_LT(bytes.size(), lossless.size());
}

TEST(PointCodec, NodesWithoutNormalsOrColoursAndSinglePointsRoundTrip) {
    Node node = make_node(1, 4);
    node.normals.clear();
    node.colors.clear();
    DecodedPoints out;
    std::vector<uint8_t> bytes = encode_point_node(node.view(), PointEncodeSettings{});
    ASSERT_EQ(decode_point_node(bytes.data(), bytes.size(), out), "");
    EXPECT_EQ(out.count, 1u);
    EXPECT_EQ(out.flags, 0);
    EXPECT_TRUE(out.normals.empty());
    EXPECT_TRUE(out.colors.empty());
    EXPECT_LE(distance(&out.positions[0], &node.positions[0]), out.position_error);
}

TEST(PointCodec, LargeResidualsAndEscapesRoundTrip) {
    // Tiny radii on a unit patch: a fine grid, so position deltas take Rice parameters past the
    // decoder's specialized ones (0-7), and outliers among them escape.
    Node node = make_node(1500, 10);
    for (float& r : node.radii) r = 1e-6f;
    for (size_t i = 0; i < 1500; i += 97) node.positions[3 * i + 2] += 0.5;  // outliers
    std::vector<uint32_t> order;
    DecodedPoints out;
    std::vector<uint8_t> bytes = encode_point_node(node.view(), PointEncodeSettings{}, &order);
    ASSERT_EQ(decode_point_node(bytes.data(), bytes.size(), out), "");
    ASSERT_EQ(out.count, 1500u);
    for (size_t i = 0; i < out.count; ++i) {
        ASSERT_LE(distance(&out.positions[3 * i], &node.positions[3 * order[i]]), out.position_error) << i;
        for (int c = 0; c < 3; ++c) ASSERT_EQ(out.colors[3 * i + c], node.colors[3 * order[i] + c]);
    }
}

TEST(PointCodec, RiceBitsEqualsTheSumOfRiceCosts) {
    // rice_bits (four values at a time, escapes without branches) against rice_cost summed, for
    // every k on blocks of every length up to two blocks: small values, values around every
    // escape threshold, and values of every width up to 2^32 - 1 (escape prefixes up to 30, and
    // the excesses from 2^24 up, whose float conversion the SIMD path must not round up).
    using namespace points_detail;
    uint64_t state = 7;
    std::vector<uint32_t> values(2 * kRiceBlock);
    auto check = [&](size_t n, const char* what) {
        for (uint32_t k = 0; k <= kRiceMaxK; ++k) {
            uint64_t expected = 0;
            for (size_t i = 0; i < n; ++i) expected += rice_cost(values[i], k);
            ASSERT_EQ(rice_bits(values.data(), n, k), expected) << what << " n " << n << " k " << k;
        }
    };
    for (int round = 0; round < 3000; ++round) {
        const size_t n = size_t(test::next_random(state) % (values.size() + 1));
        const int kind = round % 4;
        for (uint32_t& v : values) {
            const uint64_t r = test::next_random(state);
            if (kind == 0) v = uint32_t(r % 64);
            else if (kind == 1) v = uint32_t(r) >> (r >> 59);  // every width
            else if (kind == 2) {  // near 2^m: escape thresholds (8 << k) and float rounding edges
                const uint32_t m = uint32_t(r >> 32) % 33;
                const int64_t near = (m == 32 ? int64_t(1) << 32 : int64_t(1) << m) + int64_t(r % 9) - 4;
                v = uint32_t(std::clamp<int64_t>(near, 0, UINT32_MAX));
            } else v = uint32_t(r);
        }
        check(n, "random");
    }
    for (uint32_t edge : {0u, 1u, 7u, 8u, 9u, 0xffffffu, 0x1000000u, 0x3ffffffu, 0x4000000u, 0x4000020u, 0x7fffffffu,
                          0x80000000u, 0xfffffff7u, 0xfffffff8u, 0xffffffffu}) {
        std::fill(values.begin(), values.end(), edge);
        check(values.size(), "constant");
        check(kRiceBlock - 1, "constant");
    }
}

TEST(PointCodec, FullPrecisionColourSearchKeepsTheLosslessLumaForEveryColour) {
    // The encoder's quantize_color skips its search for the luma at full precision (8-bit luma,
    // 9-bit chroma) and keeps the YCoCg-R luma: what the search (copied here from
    // points/src/codec.cpp, with the colour transform) keeps for every RGB colour.
    auto clamp_byte = [](int v) { return v < 0 ? 0 : v > 255 ? 255 : v; };
    for (int r = 0; r < 256; ++r)
        for (int g = 0; g < 256; ++g)
            for (int b = 0; b < 256; ++b) {
                const int co = r - b, t = b + (co >> 1), cg = g - t, y = t + (cg >> 1);
                int best_y = y, best_error = INT32_MAX;
                for (int dy = -1; dy <= 1; ++dy) {
                    const int yq = y + dy;
                    if (yq < 0 || yq > 256) continue;
                    const int tt = std::min(yq, 255) - (cg >> 1), gg = cg + tt, bb = tt - (co >> 1), rr = bb + co;
                    const int error = std::max({std::abs(clamp_byte(rr) - r), std::abs(clamp_byte(gg) - g),
                                                std::abs(clamp_byte(bb) - b)});
                    if (error < best_error) best_error = error, best_y = yq;
                }
                ASSERT_EQ(best_y, y) << r << " " << g << " " << b;
            }
}

TEST(PointCodec, GridRoundingEqualsNearbyintOnTheGridsRange) {
    // quantize_positions rounds a coordinate clamped to [0, 2^24 - 1] as (t + 2^52) - 2^52
    // (copied here) where it called std::nearbyint: equal on integers, halves (ties to even),
    // their neighbours and random values over the range, and on the clamped special values.
    auto rounded = [](double t) { return (t + 0x1p52) - 0x1p52; };
    const double top = double((1u << 24) - 1);
    uint64_t state = 11;
    auto check = [&](double t) {
        const double c = std::clamp(t, 0.0, top);
        ASSERT_EQ(rounded(c), std::clamp(std::nearbyint(t), 0.0, top)) << t;
    };
    for (uint32_t i = 0; i <= (1u << 24); i += (i < 4096 ? 1 : 997)) {
        for (double t : {double(i), i + 0.5, i - 0.5})
            for (double u : {t, std::nextafter(t, -1.0), std::nextafter(t, 1e300)}) check(u);
    }
    for (int i = 0; i < 1000000; ++i) check((test::random_unit(state) * 1.2 - 0.1) * double(1u << 24));
    for (double t : {-0.0, -0.4, -1e300, 1e300, double(INFINITY), -double(INFINITY), 0x1p60}) check(t);
}

TEST(PointCodec, BaselineAndAvx2KernelsDecodeAlike) {
    // The decoder picks its SIMD kernels at run time: both must give the same points, on small
    // residuals (specialized Rice parameters), large ones and escapes, at every colour precision.
    std::vector<std::vector<uint8_t>> nodes;
    for (uint64_t seed = 20; seed < 26; ++seed) {
        Node node = make_node(1000 + 300 * seed, seed);
        if (seed % 2) for (float& r : node.radii) r *= 1e-4f;
        for (size_t i = 0; i < node.radii.size(); i += 61) node.positions[3 * i + 1] += 0.3;
        const uint8_t luma = uint8_t(1 + seed % 8), chroma = uint8_t(1 + (seed * 3) % 9);
        nodes.push_back(encode_point_node(node.view(), PointEncodeSettings{ColorBits{luma, chroma}}));
        nodes.push_back(encode_point_node(node.view(), PointEncodeSettings{}));
    }
    const bool had_avx2 = use_point_decoder_avx2(true);
    for (const std::vector<uint8_t>& bytes : nodes) {
        DecodedPoints baseline, fast;
        use_point_decoder_avx2(false);
        ASSERT_EQ(decode_point_node(bytes.data(), bytes.size(), baseline), "");
        use_point_decoder_avx2(true);
        ASSERT_EQ(decode_point_node(bytes.data(), bytes.size(), fast), "");
        EXPECT_EQ(baseline.positions, fast.positions);
        EXPECT_EQ(baseline.normals, fast.normals);
        EXPECT_EQ(baseline.colors, fast.colors);
        EXPECT_EQ(baseline.radii, fast.radii);
    }
    use_point_decoder_avx2(had_avx2);
}

TEST(PointCodec, CoincidentPointsRoundTrip) {
    Node node = make_node(200, 5);
    for (size_t i = 0; i < 200; ++i)
        for (int a = 0; a < 3; ++a) node.positions[3 * i + a] = node.positions[a];
    DecodedPoints out;
    std::vector<uint8_t> bytes = encode_point_node(node.view(), PointEncodeSettings{});
    ASSERT_EQ(decode_point_node(bytes.data(), bytes.size(), out), "");
    for (size_t i = 0; i < out.count; ++i) EXPECT_LE(distance(&out.positions[3 * i], &node.positions[0]), out.position_error);
}

TEST(PointCodec, FarFromTheOriginKeepsTheBoundRelativeToTheLocalOrigin) {
    // Positions are relative to the dataset origin; a node far from it (1e3 units, small radii)
    // still meets its bound, with float rounding measured into position_error.
    Node node = make_node(1000, 6, 1000.0);
    DecodedPoints out;
    std::vector<uint32_t> order;
    std::vector<uint8_t> bytes = encode_point_node(node.view(), PointEncodeSettings{}, &order);
    ASSERT_EQ(decode_point_node(bytes.data(), bytes.size(), out), "");
    for (size_t i = 0; i < out.count; ++i)
        EXPECT_LE(distance(&out.positions[3 * i], &node.positions[3 * order[i]]), out.position_error);
}

Node make_golden_node() {
    Node node;
    node.positions = {0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 1};
    node.normals = {0, 0, 1, 0, 0, 1, 1, 0, 0, 0, 1, 0};
    node.colors = {255, 0, 0, 0, 255, 0, 0, 0, 255, 10, 20, 30};
    node.radii = {0.5f, 0.5f, 0.75f, 1.0f};
    return node;
}

// Every attribute of two decodes, bit for bit.
void expect_same_points(const DecodedPoints& a, const DecodedPoints& b) {
    EXPECT_EQ(a.count, b.count);
    EXPECT_EQ(a.flags, b.flags);
    EXPECT_EQ(a.positions, b.positions);
    EXPECT_EQ(a.normals, b.normals);
    EXPECT_EQ(a.colors, b.colors);
    EXPECT_EQ(a.radii, b.radii);
    EXPECT_EQ(a.position_error, b.position_error);
    EXPECT_EQ(a.grid_step, b.grid_step);
}

TEST(PointCodec, GoldenBytesOfASmallNode) {
    // The byte layout of docs/formats/points.md: a change of format must change the version.
    Node node = make_golden_node();
    std::vector<uint8_t> bytes = encode_point_node(node.view(), PointEncodeSettings{});
    ASSERT_GE(bytes.size(), 48u);
    EXPECT_EQ(std::string(reinterpret_cast<const char*>(bytes.data()), 4), "CPPN");
    EXPECT_EQ(bytes[4], kPointNodeVersion);
    EXPECT_EQ(bytes[5], kPointHasNormals | kPointHasColors);
    EXPECT_EQ(bytes[6], 8);
    EXPECT_EQ(bytes[7], 9);
    EXPECT_EQ(bytes[8], 4);
    EXPECT_EQ(bytes.size(), kGoldenSize);
    EXPECT_EQ(checksum64(bytes.data(), bytes.size()), kGoldenChecksum);
}

TEST(PointCodec, Version2GoldenBytesStillDecodeToTheVersion3Points) {
    // Datasets written before version 3 stay readable, and decode to what the current encoder's
    // node decodes to.
    DecodedPoints old_points, new_points;
    ASSERT_EQ(decode_point_node(kGoldenVersion2, sizeof(kGoldenVersion2), old_points), "");
    Node node = make_golden_node();
    PointEncodeSettings v2;
    v2.version = 2;
    EXPECT_EQ(encode_point_node(node.view(), v2), std::vector<uint8_t>(std::begin(kGoldenVersion2), std::end(kGoldenVersion2)));
    std::vector<uint8_t> bytes = encode_point_node(node.view(), PointEncodeSettings{});
    ASSERT_EQ(decode_point_node(bytes.data(), bytes.size(), new_points), "");
    expect_same_points(old_points, new_points);
}

TEST(PointCodec, EveryVersionDecodesToIdenticalPoints) {
    // Versions differ in how the streams are coded, never in what they decode to: nodes of many
    // sizes (partial last blocks), colour precisions, grey (all chroma deltas zero: blocks of
    // zeros), constant radii, escapes and missing attributes.
    for (uint64_t seed = 40; seed < 52; ++seed) {
        Node node = make_node(1 + 397 * (seed - 40), seed);
        if (seed % 3 == 0)
            for (size_t i = 0; i < node.colors.size(); i += 3) node.colors[i + 1] = node.colors[i + 2] = node.colors[i];
        if (seed % 4 == 1) std::fill(node.radii.begin(), node.radii.end(), 0.015f);
        if (seed % 5 == 2) node.normals.clear();
        if (seed % 5 == 3) node.colors.clear();
        for (size_t i = 0; i < node.radii.size(); i += 97) node.positions[3 * i + 2] += 0.2;
        PointEncodeSettings settings{ColorBits{uint8_t(1 + seed % 8), uint8_t(1 + seed % 9)}};
        DecodedPoints reference;
        for (uint8_t version = kPointNodeOldestVersion; version <= kPointNodeVersion; ++version) {
            settings.version = version;
            std::vector<uint8_t> bytes = encode_point_node(node.view(), settings);
            EXPECT_EQ(bytes[4], version);
            DecodedPoints out;
            ASSERT_EQ(decode_point_node(bytes.data(), bytes.size(), out), "") << int(version);
            if (version == kPointNodeOldestVersion) reference = out;
            else expect_same_points(reference, out);
        }
    }
}

TEST(PointCodec, BlocksOfZerosShrinkGreyNodes) {
    // Grey points have zero Co and Cg deltas throughout: version 3 codes such blocks by their
    // parameter alone, where version 2 spent a bit per value (two bits per point).
    Node node = make_node(4000, 53);
    for (size_t i = 0; i < node.colors.size(); i += 3) node.colors[i + 1] = node.colors[i + 2] = node.colors[i];
    PointEncodeSettings v2;
    v2.version = 2;
    const size_t old_size = encode_point_node(node.view(), v2).size();
    const size_t new_size = encode_point_node(node.view(), PointEncodeSettings{}).size();
    EXPECT_LE(double(new_size), double(old_size) - 0.95 * 2 * 4000 / 8);  // 984 bytes less (measured)
}

TEST(PointCodec, RunsOfZerosLongerThanAnEscapeAreRejectedWithAValidChecksum) {
    // The decoder reads the quotient string as the positions of its one bits modulo 256: runs
    // of 9 to 255 zeros must fail the quotient check, and longer ones (which would alias to
    // short quotients) the check for two zero bytes in a row. A node of one block: the first
    // stream's parameter takes a byte, and its quotients start at body byte 1.
    Node node = make_node(100, 11);
    const std::vector<uint8_t> bytes = encode_point_node(node.view(), PointEncodeSettings{});
    constexpr size_t kQuotients = 40 + 1;
    DecodedPoints out;
    for (size_t zeros : {2, 3, 8, 33, 40}) {
        std::vector<uint8_t> bad = bytes;
        ASSERT_LT(kQuotients + zeros, bad.size() - 8);
        std::fill(bad.begin() + ptrdiff_t(kQuotients), bad.begin() + ptrdiff_t(kQuotients + zeros), 0);
        if (zeros == 2) bad[kQuotients + 2] = 0x01;  // a run of 16 zeros, then a one bit
        const uint64_t sum = checksum64(bad.data(), bad.size() - 8);
        std::memcpy(bad.data() + bad.size() - 8, &sum, 8);
        EXPECT_NE(decode_point_node(bad.data(), bad.size(), out), "") << zeros;
    }
}

TEST(PointCodec, EveryTruncationIsRejected) {
    for (uint8_t version = kPointNodeOldestVersion; version <= kPointNodeVersion; ++version) {
        Node node = make_node(700, 7);
        for (size_t i = 0; i < node.colors.size(); i += 6) node.colors[i + 1] = node.colors[i + 2] = node.colors[i];
        PointEncodeSettings settings;
        settings.version = version;
        std::vector<uint8_t> bytes = encode_point_node(node.view(), settings);
        DecodedPoints out;
        for (size_t size = 0; size < bytes.size(); ++size) {
            std::vector<uint8_t> part(bytes.begin(), bytes.begin() + ptrdiff_t(size));  // exact-size heap copy (ASan)
            EXPECT_NE(decode_point_node(part.data(), part.size(), out), "") << size;
        }
    }
}

TEST(PointCodec, CorruptBytesAreRejected) {
    Node node = make_node(700, 8);
    std::vector<uint8_t> bytes = encode_point_node(node.view(), PointEncodeSettings{});
    DecodedPoints out;
    for (size_t at = 0; at < bytes.size(); at += 3) {
        std::vector<uint8_t> bad = bytes;
        bad[at] ^= uint8_t(1 + at % 255);
        EXPECT_NE(decode_point_node(bad.data(), bad.size(), out), "") << at;
    }
}

TEST(PointCodec, CorruptStreamsWithAValidChecksumNeverCrash) {
    // The checksum catches accidents; a forged node (checksum recomputed) must still decode
    // safely: an error, or some points, but no read outside the bytes (run under ASan in CI).
    // Both versions, and a node with blocks of zeros (grey), whose forged parameters change
    // which values the quotient string holds.
    Node node = make_node(700, 9), grey = make_node(900, 10);
    for (size_t i = 0; i < grey.colors.size(); i += 3) grey.colors[i + 1] = grey.colors[i + 2] = grey.colors[i];
    PointEncodeSettings v2;
    v2.version = 2;
    const std::vector<uint8_t> originals[3] = {encode_point_node(node.view(), PointEncodeSettings{}),
                                               encode_point_node(node.view(), v2),
                                               encode_point_node(grey.view(), PointEncodeSettings{})};
    DecodedPoints out;
    uint64_t state = 99;
    size_t rejected = 0, trials = 0;
    const bool had_avx2 = use_point_decoder_avx2(true);
    for (int trial = 0; trial < 6000; ++trial) {
        use_point_decoder_avx2(trial % 2 == 0);  // both kernels (where the CPU has AVX2)
        const std::vector<uint8_t>& bytes = originals[trial / 2 % 3];
        std::vector<uint8_t> bad = bytes;
        size_t flips = 1 + test::next_random(state) % 4;
        for (size_t f = 0; f < flips; ++f) bad[8 + test::next_random(state) % (bad.size() - 16)] ^= uint8_t(1 + test::next_random(state) % 255);
        uint64_t sum = checksum64(bad.data(), bad.size() - 8);
        std::memcpy(bad.data() + bad.size() - 8, &sum, 8);
        std::string problem = decode_point_node(bad.data(), bad.size(), out);
        ++trials;
        if (!problem.empty()) ++rejected;
        else EXPECT_EQ(out.positions.size(), 3 * out.count);
    }
    use_point_decoder_avx2(had_avx2);
    // Many forged nodes break a structural check (stream lengths, counts, header values):
    // about half of these (measured).
    EXPECT_GT(rejected, trials / 3);
}

TEST(PointCodec, RandomBytesAreRejected) {
    DecodedPoints out;
    uint64_t state = 5;
    for (int trial = 0; trial < 2000; ++trial) {
        std::vector<uint8_t> bytes(test::next_random(state) % 300);
        for (uint8_t& b : bytes) b = uint8_t(test::next_random(state));
        if (bytes.size() >= 4 && trial % 2)
            std::memcpy(bytes.data(), trial % 4 == 1 ? "CPPN\x02" : "CPPN\x03", std::min<size_t>(5, bytes.size()));
        EXPECT_NE(decode_point_node(bytes.data(), bytes.size(), out), "");
    }
}

}  // namespace
}  // namespace catpaq
