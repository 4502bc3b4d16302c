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

// The precise encoder as first written: four scalar oct_decode calls and a search keeping the
// first strictly better candidate. The library decodes the four candidates at once with SSE and
// picks the first maximum without branches; both must give the same code for every input.
static uint16_t reference_precise(float x, float y, float z) {
    auto sign_not_zero = [](float v) { return v < 0.0f ? -1.0f : 1.0f; };
    auto clamp127 = [](float f) {
        int c = int(f);
        return c < -127 ? -127 : (c > 127 ? 127 : c);
    };
    auto pack = [](int cu, int cv) { return uint16_t(uint8_t(int8_t(cu)) | (uint16_t(uint8_t(int8_t(cv))) << 8)); };
    float u = 0.0f, v = 0.0f;
    float l1 = std::fabs(x) + std::fabs(y) + std::fabs(z);
    if (l1 > 0.0f && std::isfinite(l1)) {
        u = x / l1;
        v = y / l1;
        if (z < 0.0f) {
            float fu = (1.0f - std::fabs(v)) * sign_not_zero(u);
            float fv = (1.0f - std::fabs(u)) * sign_not_zero(v);
            u = fu;
            v = fv;
        }
    }
    float len = std::sqrt(x * x + y * y + z * z);
    if (!(len > 0.0f) || !std::isfinite(len)) return pack(0, 0);
    float nx = x / len, ny = y / len, nz = z / len;
    int base_u = clamp127(std::floor(u * 127.0f)), base_v = clamp127(std::floor(v * 127.0f));
    uint16_t best = pack(base_u, base_v);
    float best_dot = -2.0f;
    for (int du = 0; du <= 1; ++du) {
        for (int dv = 0; dv <= 1; ++dv) {
            uint16_t code = pack(clamp127(float(base_u + du)), clamp127(float(base_v + dv)));
            float d[3];
            oct_decode(code, d);
            float dot = d[0] * nx + d[1] * ny + d[2] * nz;
            if (dot > best_dot) {
                best_dot = dot;
                best = code;
            }
        }
    }
    return best;
}

TEST(Octahedral, PreciseEncoderMatchesTheScalarSearchOnEightMillionVectors) {
    std::mt19937_64 rng(99);
    std::uniform_real_distribution<float> coord(-1.0f, 1.0f), tiny(-1e-6f, 1e-6f);
    std::uniform_int_distribution<int> code(-127, 127);
    size_t checked = 0;
    auto check = [&](float x, float y, float z) {
        ASSERT_EQ(oct_encode_precise(x, y, z), reference_precise(x, y, z)) << x << " " << y << " " << z;
        ++checked;
    };
    for (int i = 0; i < 2000000; ++i) {
        // Unit and non-unit vectors in every octant.
        double v[3];
        random_unit(rng, v);
        check(float(v[0]), float(v[1]), float(v[2]));
        check(coord(rng) * 1000.0f, coord(rng) * 1000.0f, coord(rng) * 1e-3f);
        // Near the decoded directions of codes (ties between candidates), near the fold
        // (z ~ 0) and near the axes.
        float d[3];
        oct_decode(uint16_t(uint8_t(int8_t(code(rng))) | (uint8_t(int8_t(code(rng))) << 8)), d);
        check(d[0] + tiny(rng), d[1] + tiny(rng), d[2] + tiny(rng));
        check(coord(rng), coord(rng), tiny(rng));
    }
    // Special values: zeros of both signs, axes, huge, tiny, infinite and NaN components.
    const float specials[] = {0.0f, -0.0f, 1.0f, -1.0f, 1e-38f, -1e-38f, 1e38f, -1e38f, INFINITY, -INFINITY, NAN};
    for (float x : specials)
        for (float y : specials)
            for (float z : specials) check(x, y, z);
    EXPECT_EQ(checked, 8000000u + 11u * 11u * 11u);
}

TEST(Octahedral, BatchEncoderMatchesTheSingleEncoderForEveryInput) {
    // oct_encode_precise_batch (four vectors per SSE step) against one call per vector:
    // the kinds of vectors of the test above, shuffled so every kind meets every lane, then
    // every triple of special values at every lane position, and arrays of every length up to
    // 9 (the scalar tail).
    std::mt19937_64 rng(2024);
    std::uniform_real_distribution<float> coord(-1.0f, 1.0f), tiny(-1e-6f, 1e-6f);
    std::uniform_int_distribution<int> code(-127, 127);
    std::vector<float> xyz;
    auto add = [&](float x, float y, float z) { xyz.insert(xyz.end(), {x, y, z}); };
    for (int i = 0; i < 1000000; ++i) {
        switch (rng() % 5) {
        case 0: {
            double v[3];
            random_unit(rng, v);
            add(float(v[0]), float(v[1]), float(v[2]));
            break;
        }
        case 1: add(coord(rng) * 1000.0f, coord(rng) * 1000.0f, coord(rng) * 1e-3f); break;
        case 2: {
            float d[3];
            oct_decode(uint16_t(uint8_t(int8_t(code(rng))) | (uint8_t(int8_t(code(rng))) << 8)), d);
            add(d[0] + tiny(rng), d[1] + tiny(rng), d[2] + tiny(rng));
            break;
        }
        case 3: add(coord(rng), coord(rng), tiny(rng)); break;
        default: {  // exact decoded directions (ties) and axis-aligned vectors of any length
            float d[3];
            oct_decode(uint16_t(uint8_t(int8_t(code(rng))) | (uint8_t(int8_t(code(rng))) << 8)), d);
            const float s = float(1 + rng() % 3);
            if (rng() % 2) add(d[0] * s, d[1] * s, d[2] * s);
            else add(float(int(rng() % 3) - 1) * s, float(int(rng() % 3) - 1) * s, float(int(rng() % 3) - 1) * s);
        }
        }
    }
    const float specials[] = {0.0f, -0.0f, 1.0f, -1.0f, 1e-38f, -1e-38f, 1e-30f, 1e38f, -1e38f, INFINITY, -INFINITY, NAN};
    for (int lane = 0; lane < 4; ++lane)
        for (float x : specials)
            for (float y : specials)
                for (float z : specials) {
                    for (int k = 0; k < lane; ++k) add(coord(rng), coord(rng), coord(rng));
                    add(x, y, z);
                    for (int k = lane + 1; k < 4; ++k) add(coord(rng), coord(rng), coord(rng));
                }
    const size_t n = xyz.size() / 3;
    std::vector<uint16_t> codes(n);
    oct_encode_precise_batch(xyz.data(), n, codes.data());
    for (size_t i = 0; i < n; ++i)
        ASSERT_EQ(codes[i], oct_encode_precise(xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]))
            << i << ": " << xyz[3 * i] << " " << xyz[3 * i + 1] << " " << xyz[3 * i + 2];
    for (size_t count = 0; count <= 9; ++count) {
        std::vector<uint16_t> some(count + 1, 0xabcd);
        oct_encode_precise_batch(xyz.data() + 3 * 12345, count, some.data());
        for (size_t i = 0; i < count; ++i) ASSERT_EQ(some[i], codes[12345 + i]) << count;
        ASSERT_EQ(some[count], 0xabcd);  // nothing written past the end
    }
}
