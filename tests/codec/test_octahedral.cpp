#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <random>

#include "common_codec/octahedral.h"

using namespace catpaq;

static double angle_degrees(const float a[3], const double b[3]) {
    double dot = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    dot = std::max(-1.0, std::min(1.0, dot));
    return std::acos(dot) * 180.0 / M_PI;
}

// Uniform random unit vectors (normalised Gaussians), deterministic seed.
static void random_unit(std::mt19937_64& rng, double v[3]) {
    std::normal_distribution<double> gauss;
    double len;
    do {
        for (int i = 0; i < 3; ++i) v[i] = gauss(rng);
        len = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    } while (len < 1e-9);
    for (int i = 0; i < 3; ++i) v[i] /= len;
}

TEST(Octahedral, PreciseEncoderMaxErrorBelowOneDegreeOverAMillionVectors) {
    std::mt19937_64 rng(12345);
    double max_precise = 0, sum_precise = 0, max_fast = 0;
    const int n = 1000000;
    for (int i = 0; i < n; ++i) {
        double v[3];
        random_unit(rng, v);
        float d[3];
        oct_decode(oct_encode_precise(float(v[0]), float(v[1]), float(v[2])), d);
        double e = angle_degrees(d, v);
        max_precise = std::max(max_precise, e);
        sum_precise += e;
        oct_decode(oct_encode_fast(float(v[0]), float(v[1]), float(v[2])), d);
        max_fast = std::max(max_fast, angle_degrees(d, v));
    }
    std::printf("octahedral 8+8: precise max %.4f deg, mean %.4f deg; fast max %.4f deg\n", max_precise,
                sum_precise / n, max_fast);
    EXPECT_LE(max_precise, 1.0);
    EXPECT_LE(sum_precise / n, 0.40);
    EXPECT_LE(max_precise, max_fast);  // the search never does worse than rounding
}

TEST(Octahedral, AxisAlignedNormalsDecodeExactly) {
    const float axes[6][3] = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
    for (auto& a : axes) {
        float d[3];
        oct_decode(oct_encode_precise(a[0], a[1], a[2]), d);
        for (int i = 0; i < 3; ++i) EXPECT_EQ(d[i], a[i]);
    }
}

TEST(Octahedral, EveryCodeDecodesToAUnitVector) {
    for (uint32_t code = 0; code < 65536; ++code) {
        float d[3];
        oct_decode(uint16_t(code), d);
        double len = std::sqrt(double(d[0]) * d[0] + double(d[1]) * d[1] + double(d[2]) * d[2]);
        ASSERT_NEAR(len, 1.0, 1e-6) << code;
    }
}

TEST(Octahedral, DegenerateInputsGiveAValidCode) {
    float d[3];
    oct_decode(oct_encode_precise(0, 0, 0), d);
    EXPECT_EQ(d[2], 1.0f);
    oct_decode(oct_encode_precise(NAN, 0, 0), d);
    EXPECT_TRUE(std::isfinite(d[0]) && std::isfinite(d[1]) && std::isfinite(d[2]));
}
