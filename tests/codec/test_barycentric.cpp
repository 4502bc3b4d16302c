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
        ASSERT_TRUE(bary_unpack(index, w));
        ASSERT_TRUE(w[0] >= 0 && w[1] >= 0 && w[2] >= 0 && w[3] >= 0) << index;
        ASSERT_EQ(w[0] + w[1] + w[2] + w[3], kBaryGrid);
        ASSERT_EQ(bary_pack(w), index);
    }
}

TEST(Barycentric, IndicesBeyondTheGridAreRejected) {
    BaryWeights w;
    EXPECT_FALSE(bary_unpack(kBaryIndexCount, w));
    EXPECT_FALSE(bary_unpack(0xffffff, w));
}

static std::array<LatticePoint, 4> sample_tet() {
    // A tetrahedron of the Kuhn subdivision of the cube [0,64]^3, canonical order.
    std::array<LatticePoint, 4> c = {LatticePoint{0, 0, 0}, {64, 0, 0}, {64, 64, 0}, {64, 64, 64}};
    canonical_order(c);
    return c;
}

TEST(Barycentric, QuantizationErrorIsBoundedByTheGridStep) {
    auto c = sample_tet();
    std::mt19937_64 rng(7);
    std::uniform_real_distribution<double> u(0, 1);
    double max_err = 0;
    for (int i = 0; i < 200000; ++i) {
        double l[4] = {u(rng), u(rng), u(rng), u(rng)};
        double s = l[0] + l[1] + l[2] + l[3];
        double p[3] = {0, 0, 0};
        for (int k = 0; k < 4; ++k)
            for (int j = 0; j < 3; ++j) p[j] += l[k] / s * c[k][j];
        BaryWeights w = bary_quantize(p, c, 0xf);
        float q[3];
        bary_decode(w, c, {0, 0, 0}, 1.0f / kBaryGrid, q);
        double e = std::sqrt((q[0] - p[0]) * (q[0] - p[0]) + (q[1] - p[1]) * (q[1] - p[1]) + (q[2] - p[2]) * (q[2] - p[2]));
        max_err = std::max(max_err, e);
    }
    // Largest-remainder rounding moves each weight by less than one step, so the error is below
    // the sum of the corner distances from the centroid divided by the grid.
    double longest_edge = 64.0 * std::sqrt(3.0);
    EXPECT_LT(max_err, longest_edge / kBaryGrid);
    std::printf("max quantization error %.4f lattice units (edge %.1f, grid %d)\n", max_err, longest_edge, kBaryGrid);
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
        BaryWeights w1 = bary_quantize(p, t1, mask_for(t1, D1));
        BaryWeights w2 = bary_quantize(p, t2, mask_for(t2, D2));
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
        const std::array<int32_t, 3> anchor{kBaryGrid * 13, kBaryGrid * -7, kBaryGrid * 5};
        float q1[3], q2[3];
        bary_decode(w1, t1, anchor, 0.001953125f, q1);
        bary_decode(w2, t2, anchor, 0.001953125f, q2);
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
    auto c = sample_tet();
    DecodedVertex out;
    EXPECT_FALSE(decode_packed_vertex(PackedVertex::make(0xffffff, 0, 0, 0, 0), c, {0, 0, 0}, 1.0f, out));
    EXPECT_TRUE(decode_packed_vertex(PackedVertex::make(0, 0, 0, 0, 0), c, {0, 0, 0}, 1.0f, out));
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
