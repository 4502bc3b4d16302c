#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

#include "common_codec/barycentric.h"
#include "common_codec/packed_vertex.h"

using namespace catpaq;

TEST(Barycentric, PackUnpackIsABijectionOnAllValidWeights) {
    // Every index decodes to valid weights, and packing them gives the index back.
    for (uint32_t index = 0; index < kBaryIndexCount; ++index) {
        BaryWeights w;
        ASSERT_TRUE(bary_unpack(index, kBaryGrid, w));
        ASSERT_TRUE(w[0] >= 0 && w[1] >= 0 && w[2] >= 0 && w[3] >= 0) << index;
        ASSERT_EQ(w[0] + w[1] + w[2] + w[3], kBaryGrid);
        ASSERT_EQ(bary_pack(w), index);
    }
}

TEST(Barycentric, ThirtyBitIndexIsABijectionOnTheRgb18Grid) {
    // Every index near the table's block boundaries and the ends, and 20 million random ones.
    const uint32_t count = bary_index_count(kMaxIndexGrid);
    ASSERT_LE(count, 1u << 30);
    std::vector<uint32_t> indices = {0, 1, count - 1, count - 2};
    for (uint32_t block = 8192; block < count; block += 8192)
        for (uint32_t d : {block - 1, block, block + 1}) indices.push_back(d);
    std::mt19937_64 rng(11);
    for (int i = 0; i < 20000000; ++i) indices.push_back(uint32_t(rng() % count));
    for (uint32_t index : indices) {
        BaryWeights w;
        ASSERT_TRUE(bary_unpack(index, kMaxIndexGrid, w)) << index;
        ASSERT_TRUE(w[0] >= 0 && w[1] >= 0 && w[2] >= 0 && w[3] >= 0) << index;
        ASSERT_EQ(w[0] + w[1] + w[2] + w[3], kMaxIndexGrid);
        ASSERT_EQ(bary_pack(w), index);
    }
    BaryWeights w;
    EXPECT_FALSE(bary_unpack(count, kMaxIndexGrid, w));
}

TEST(Barycentric, IndicesBeyondTheGridAreRejected) {
    BaryWeights w;
    EXPECT_FALSE(bary_unpack(kBaryIndexCount, kBaryGrid, w));
    EXPECT_FALSE(bary_unpack(0xffffff, kBaryGrid, w));
    // A smaller grid uses the first indices of the same enumeration.
    EXPECT_TRUE(bary_unpack(bary_index_count(100) - 1, 100, w));
    EXPECT_EQ(w, (BaryWeights{0, 0, 0, 100}));
    EXPECT_FALSE(bary_unpack(bary_index_count(100), 100, w));
}

static std::array<LatticePoint, 4> sample_tet() {
    // A tetrahedron of the Kuhn subdivision of the cube [0,64]^3, canonical order.
    std::array<LatticePoint, 4> c = {LatticePoint{0, 0, 0}, {64, 0, 0}, {64, 64, 0}, {64, 64, 64}};
    canonical_order(c);
    return c;
}

TEST(Barycentric, QuantizationErrorIsBoundedByTheGridStepOnEveryGrid) {
    // The converter's precision guarantee: a quantized position is within longest edge / grid of
    // the point. Largest-remainder rounding moves weights by e_i (|e_i| < 1, summing to 0), so
    // the displacement is m (P - N) / grid with P, N points of the tetrahedron and m the total
    // positive change, at most 1 for four weights (the r largest fractions of four summing to r
    // round up: m <= r (4 - r) / 4).
    auto c = sample_tet();
    const double longest_edge = 64.0 * std::sqrt(3.0);
    for (int32_t grid : {kBaryGrid, 100, kMaxIndexGrid, kMaxWideGrid}) {
        std::mt19937_64 rng(7);
        std::uniform_real_distribution<double> u(0, 1);
        double max_err = 0;
        for (int i = 0; i < 200000; ++i) {
            double l[4] = {u(rng), u(rng), u(rng), u(rng)};
            double s = l[0] + l[1] + l[2] + l[3];
            double p[3] = {0, 0, 0};
            for (int k = 0; k < 4; ++k)
                for (int j = 0; j < 3; ++j) p[j] += l[k] / s * c[k][j];
            BaryWeights w = bary_quantize(p, c, 0xf, grid);
            ASSERT_EQ(w[0] + w[1] + w[2] + w[3], grid);
            std::array<int64_t, 3> exact = bary_integer_sum(w, c);
            double e2 = 0;
            for (int j = 0; j < 3; ++j) e2 += (double(exact[j]) / grid - p[j]) * (double(exact[j]) / grid - p[j]);
            max_err = std::max(max_err, std::sqrt(e2));
        }
        EXPECT_LT(max_err, longest_edge / grid) << "grid " << grid;
        std::printf("grid %5d: max quantization error %.5f lattice units = %.3f steps (edge %.1f)\n", grid, max_err,
                    max_err * grid / longest_edge, longest_edge);
    }
}

TEST(Barycentric, DecodeMatchesTheExactPositionToFloatPrecision) {
    // The two-sum float decode is the exact rational position, rounded, for every grid and far
    // anchors.
    std::mt19937_64 rng(9);
    std::uniform_int_distribution<int32_t> coord(0, 1 << 20);
    for (int32_t grid : {kBaryGrid, kMaxIndexGrid, kMaxWideGrid}) {
        for (int i = 0; i < 100000; ++i) {
            std::array<LatticePoint, 4> c;
            for (auto& p : c) p = {coord(rng), coord(rng), coord(rng)};
            const LatticePoint anchor{coord(rng), coord(rng), coord(rng)};
            BaryWeights w{0, int32_t(rng() % uint64_t(grid + 1)), 0, 0};
            w[2] = int32_t(rng() % uint64_t(grid - w[1] + 1));
            w[3] = int32_t(rng() % uint64_t(grid - w[1] - w[2] + 1));
            w[0] = grid - w[1] - w[2] - w[3];
            std::array<LatticePoint, 4> offsets;
            for (int k = 0; k < 4; ++k)
                for (int j = 0; j < 3; ++j) offsets[k][j] = c[k][j] - anchor[j];
            float q[3];
            bary_decode(w, offsets, 1.0f / float(grid), q);
            std::array<int64_t, 3> exact = bary_integer_sum(w, offsets);
            // Three roundings, of the high sum (at most grid x the largest offset, after the
            // exact x128), of the low sum (at most 4 x 127 x it) and of the result, plus the
            // scale's: bounded relative to the largest offset, which near the camera, where
            // tetrahedra are small, is about the distance to the anchor.
            int64_t largest = 1;
            for (const LatticePoint& o : offsets)
                for (int32_t x : o) largest = std::max<int64_t>(largest, std::llabs(int64_t(x)));
            for (int j = 0; j < 3; ++j) {
                const double truth = double(exact[j]) / grid;
                const double bound = std::ldexp(1.0, -24) * (double(largest) * (2.0 + 508.0 / grid) + 2.0 * std::fabs(truth));
                ASSERT_NEAR(q[j], truth, bound) << "grid " << grid;
            }
        }
    }
}

TEST(Barycentric, FaceRuleGivesZeroWeightOutsideTheSupport) {
    auto c = sample_tet();
    double p[3] = {0.3 * c[0][0] + 0.7 * c[2][0], 0.3 * c[0][1] + 0.7 * c[2][1], 0.3 * c[0][2] + 0.7 * c[2][2]};
    BaryWeights w = bary_quantize(p, c, 0b0101);  // on the edge C0-C2
    EXPECT_EQ(w[1], 0);
    EXPECT_EQ(w[3], 0);
    EXPECT_EQ(w[0] + w[2], kBaryGrid);
}

TEST(Barycentric, SharedFaceVertexDecodesBitIdenticallyFromBothTetrahedra) {
    // Two tetrahedra sharing the face {A, B, C}, with different fourth corners, in different
    // canonical positions. A point on the face must give the same integers for A, B, C and the
    // same decoded floats in both.
    LatticePoint A{0, 0, 0}, B{64, 0, 0}, C{64, 64, 0}, D1{64, 64, 64}, D2{0, -64, -32};
    std::array<LatticePoint, 4> t1 = {A, B, C, D1}, t2 = {D2, C, A, B};
    canonical_order(t1);
    canonical_order(t2);
    auto mask_for = [](const std::array<LatticePoint, 4>& t, const LatticePoint& d) {
        SupportMask m = 0;
        for (int i = 0; i < 4; ++i)
            if (t[i] != d) m |= SupportMask(1 << i);
        return m;
    };
    std::mt19937_64 rng(3);
    std::uniform_real_distribution<double> u(0, 1);
    for (int i = 0; i < 10000; ++i) {
        double a = u(rng), b = u(rng) * (1 - a);
        double p[3];
        for (int j = 0; j < 3; ++j) p[j] = a * A[j] + b * B[j] + (1 - a - b) * C[j];
        const int32_t grid = std::array<int32_t, 3>{kBaryGrid, kMaxIndexGrid, kMaxWideGrid}[size_t(i % 3)];
        BaryWeights w1 = bary_quantize(p, t1, mask_for(t1, D1), grid);
        BaryWeights w2 = bary_quantize(p, t2, mask_for(t2, D2), grid);
        auto weight_of = [](const std::array<LatticePoint, 4>& t, const BaryWeights& w, const LatticePoint& x) {
            for (int k = 0; k < 4; ++k)
                if (t[k] == x) return w[k];
            return -1;
        };
        ASSERT_EQ(weight_of(t1, w1, A), weight_of(t2, w2, A));
        ASSERT_EQ(weight_of(t1, w1, B), weight_of(t2, w2, B));
        ASSERT_EQ(weight_of(t1, w1, C), weight_of(t2, w2, C));
        ASSERT_EQ(weight_of(t1, w1, D1), 0);
        ASSERT_EQ(weight_of(t2, w2, D2), 0);
        const LatticePoint anchor{13, -7, 5};
        auto offsets = [&](const std::array<LatticePoint, 4>& t) {
            std::array<LatticePoint, 4> o;
            for (int k = 0; k < 4; ++k)
                for (int j = 0; j < 3; ++j) o[k][j] = t[k][j] - anchor[j];
            return o;
        };
        float q1[3], q2[3];
        bary_decode(w1, offsets(t1), 0.001953125f, q1);
        bary_decode(w2, offsets(t2), 0.001953125f, q2);
        for (int j = 0; j < 3; ++j) ASSERT_EQ(q1[j], q2[j]);
    }
}

TEST(PackedVertex, FieldsRoundTripThroughTheTwoWords) {
    PackedVertex v = PackedVertex::make(0xABCDEF, 0x1234, 10, 20, 30);
    EXPECT_EQ(v.position_index(), 0xABCDEFu);
    EXPECT_EQ(v.normal(), 0x1234);
    EXPECT_EQ(v.r(), 10);
    EXPECT_EQ(v.g(), 20);
    EXPECT_EQ(v.b(), 30);
    EXPECT_EQ(v.word0, 0x34ABCDEFu);
    EXPECT_EQ(v.word1, 0x1E140A12u);
}

TEST(PackedVertex, CorruptPositionIndexIsRejectedByTheDecoder) {
    VertexDecodeParams params;
    params.offsets = sample_tet();
    DecodedVertex out;
    EXPECT_FALSE(decode_packed_vertex(PackedVertex::make(0xffffff, 0, 0, 0, 0), params, out));
    EXPECT_TRUE(decode_packed_vertex(PackedVertex::make(0, 0, 0, 0, 0), params, out));
    params.layout = VertexLayout{VertexLayoutKind::Position48, 1000};
    EXPECT_FALSE(decode_packed_vertex(PackedVertex::from_payload(uint64_t(600) | (uint64_t(401) << 16), 0), params, out))
        << "weights summing above the grid";
    EXPECT_TRUE(decode_packed_vertex(PackedVertex::from_payload(uint64_t(600) | (uint64_t(400) << 16), 0), params, out));
}

TEST(PackedVertex, EveryLayoutRoundTripsWeightsNormalAndColour) {
    std::mt19937_64 rng(21);
    const VertexLayout layouts[] = {{VertexLayoutKind::Rgb24, kBaryGrid},
                                    {VertexLayoutKind::Rgb18, kMaxIndexGrid},
                                    {VertexLayoutKind::Position48, kMaxWideGrid},
                                    {VertexLayoutKind::Position48, 77}};
    for (const VertexLayout& layout : layouts) {
        ASSERT_TRUE(layout.valid());
        for (int i = 0; i < 100000; ++i) {
            const int32_t g = layout.grid;
            BaryWeights w{0, int32_t(rng() % uint64_t(g + 1)), 0, 0};
            w[2] = int32_t(rng() % uint64_t(g - w[1] + 1));
            w[3] = int32_t(rng() % uint64_t(g - w[1] - w[2] + 1));
            w[0] = g - w[1] - w[2] - w[3];
            const uint16_t normal = uint16_t(rng());
            const uint8_t rgb[3] = {uint8_t(rng()), uint8_t(rng()), uint8_t(rng())};
            PackedVertex v = pack_vertex(layout, w, normal, rgb);
            BaryWeights back;
            ASSERT_TRUE(vertex_weights(v, layout, back)) << layout.name();
            ASSERT_EQ(back, w) << layout.name();
            ASSERT_EQ(v.normal(), normal);
            if (!layout.has_color()) continue;
            float color[3];
            vertex_color(v, layout, color);
            // 8 bits exact; 6 bits within half a step of 1/63.
            const float tolerance = layout.color_bits() == 8 ? 0.0f : 0.5f / 63.0f + 1e-6f;
            for (int k = 0; k < 3; ++k) ASSERT_NEAR(color[k], rgb[k] / 255.0f, tolerance) << layout.name();
        }
    }
}

namespace {

// bary_quantize as first written: generic over the support size, always renormalising, floor,
// and largest remainder handed out one unit at a time. The library specialises per support
// size, skips the division by a sum of exactly 1 and ranks the fractions without branches; both
// must give the same weights for every input.
BaryWeights reference_quantize(const double p[3], const std::array<LatticePoint, 4>& c, SupportMask support) {
    double corners[4][3];
    const double* used[4];
    int index[4], k = 0;
    for (int i = 0; i < 4; ++i) {
        if (!(support & (1 << i))) continue;
        for (int j = 0; j < 3; ++j) corners[k][j] = double(c[size_t(i)][size_t(j)]);
        used[k] = corners[k];
        index[k++] = i;
    }
    auto sub = [](const double* a, const double* b, double r[3]) {
        for (int i = 0; i < 3; ++i) r[i] = a[i] - b[i];
    };
    auto dot = [](const double* a, const double* b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; };
    double out[4];
    if (k == 1) {
        out[0] = 1.0;
    } else if (k == 2) {
        double e[3], d[3];
        sub(used[1], used[0], e);
        sub(p, used[0], d);
        double t = dot(d, e) / dot(e, e);
        out[0] = 1.0 - t;
        out[1] = t;
    } else if (k == 3) {
        double e0[3], e1[3], d[3];
        sub(used[1], used[0], e0);
        sub(used[2], used[0], e1);
        sub(p, used[0], d);
        double d00 = dot(e0, e0), d01 = dot(e0, e1), d11 = dot(e1, e1);
        double d20 = dot(d, e0), d21 = dot(d, e1);
        double denom = d00 * d11 - d01 * d01;
        double v = (d11 * d20 - d01 * d21) / denom;
        double w = (d00 * d21 - d01 * d20) / denom;
        out[0] = 1.0 - v - w;
        out[1] = v;
        out[2] = w;
    } else {
        double e0[3], e1[3], e2[3], d[3];
        sub(used[1], used[0], e0);
        sub(used[2], used[0], e1);
        sub(used[3], used[0], e2);
        sub(p, used[0], d);
        auto det3 = [](const double* a, const double* b, const double* c) {
            return a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0]) +
                   a[2] * (b[0] * c[1] - b[1] * c[0]);
        };
        double det = det3(e0, e1, e2);
        double l1 = det3(d, e1, e2) / det;
        double l2 = det3(e0, d, e2) / det;
        double l3 = det3(e0, e1, d) / det;
        out[0] = 1.0 - l1 - l2 - l3;
        out[1] = l1;
        out[2] = l2;
        out[3] = l3;
    }
    if (k > 1) {
        double sum = 0.0;
        for (int i = 0; i < k; ++i) {
            if (!(out[i] > 0.0)) out[i] = 0.0;
            sum += out[i];
        }
        if (sum > 0.0) {
            for (int i = 0; i < k; ++i) out[i] /= sum;
        } else {
            for (int i = 0; i < k; ++i) out[i] = i == 0 ? 1.0 : 0.0;
        }
    }
    int32_t weight[4];
    double fraction[4];
    int32_t total = 0;
    for (int i = 0; i < k; ++i) {
        double scaled = out[i] * kBaryGrid;
        weight[i] = int32_t(std::floor(scaled));
        fraction[i] = scaled - weight[i];
        total += weight[i];
    }
    for (int remaining = kBaryGrid - total; remaining > 0; --remaining) {
        int best = 0;
        for (int i = 1; i < k; ++i)
            if (fraction[i] > fraction[best]) best = i;
        weight[best] += 1;
        fraction[best] = -1.0;
    }
    BaryWeights w{0, 0, 0, 0};
    for (int i = 0; i < k; ++i) w[size_t(index[i])] = weight[i];
    return w;
}

}  // namespace

TEST(Barycentric, QuantizeMatchesTheReferenceOnMillionsOfPoints) {
    std::mt19937_64 rng(17);
    std::uniform_real_distribution<double> u(0, 1);
    std::uniform_int_distribution<int32_t> coord(-(1 << 21), 1 << 21);
    size_t checked = 0;
    auto check = [&](const double p[3], const std::array<LatticePoint, 4>& c, SupportMask support) {
        ASSERT_EQ(bary_quantize(p, c, support), reference_quantize(p, c, support))
            << p[0] << " " << p[1] << " " << p[2] << " support " << int(support);
        ++checked;
    };
    for (int round = 0; round < 20000; ++round) {
        // Kuhn tetrahedra of cells of side 2^s at random lattice places (the converter's), and
        // random lattice tetrahedra (non-unit sums, ties between fractions).
        std::array<LatticePoint, 4> c;
        if (round % 2 == 0) {
            const int32_t side = 1 << (rng() % 20);
            const LatticePoint o = {coord(rng) & ~(side - 1), coord(rng) & ~(side - 1), coord(rng) & ~(side - 1)};
            int axis[3] = {0, 1, 2};
            std::shuffle(axis, axis + 3, rng);
            c[0] = o;
            for (int s = 0; s < 3; ++s) {
                c[size_t(s) + 1] = c[size_t(s)];
                c[size_t(s) + 1][size_t(axis[s])] += side;
            }
        } else {
            for (auto& corner : c) corner = {coord(rng) >> 8, coord(rng) >> 8, coord(rng) >> 8};
        }
        canonical_order(c);
        for (int i = 0; i < 100; ++i) {
            // A random support; the point in the simplex of the supporting corners (on a face,
            // edge or corner for smaller supports), on the 2^-32 grid as the clipper makes it,
            // or a simple dyadic combination (exact fractions, many ties), or slightly outside.
            const SupportMask support = SupportMask(1 + rng() % 15);
            double l[4] = {0, 0, 0, 0}, sum = 0;
            const int kind = int(rng() % 3);
            for (int k = 0; k < 4; ++k)
                if (support & (1 << k)) {
                    l[k] = kind == 1 ? double(rng() % 9) : u(rng) - (kind == 2 ? 0.05 : 0.0);
                    sum += l[k];
                }
            if (!(sum > 0)) continue;
            double p[3];
            for (int j = 0; j < 3; ++j) {
                double x = 0;
                for (int k = 0; k < 4; ++k) x += l[k] / sum * c[size_t(k)][size_t(j)];
                p[j] = kind == 1 ? x : std::ldexp(std::nearbyint(std::ldexp(x, 32)), -32);
            }
            check(p, c, support);
        }
    }
    EXPECT_GT(checked, 1900000u);
}
