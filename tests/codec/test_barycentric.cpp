#include <gtest/gtest.h>

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
