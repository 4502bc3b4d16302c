#include "common_codec/octahedral.h"

#include <array>
#include <cmath>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace catpaq {

// Each axis is a signed 8-bit integer c in [-127, 127] mapped to c/127, so 0 and +-1 are exact
// and axis-aligned normals decode exactly. The byte holds c as two's complement.

static float sign_not_zero(float v) { return v < 0.0f ? -1.0f : 1.0f; }

// float(int8_t(byte)) / 127.0f for every byte: the same values as the division (IEEE division is
// correctly rounded however it is done), looked up by oct_decode and the precise encoder.
static const std::array<float, 256>& axis_values() {
    static const std::array<float, 256> table = [] {
        std::array<float, 256> t{};
        for (int b = 0; b < 256; ++b) t[size_t(b)] = float(int8_t(uint8_t(b))) / 127.0f;
        return t;
    }();
    return table;
}

// Projects a vector to the unfolded octahedron square [-1,1]^2.
// Inlined: the call cost 8% of oct_encode_precise (encode_bench).
static inline __attribute__((always_inline)) void project(float x, float y, float z, float& u, float& v) {
    float l1 = std::fabs(x) + std::fabs(y) + std::fabs(z);
    if (!(l1 > 0.0f) || !std::isfinite(l1)) { u = 0.0f; v = 0.0f; return; }  // zero/NaN -> +z
    u = x / l1;
    v = y / l1;
    if (z < 0.0f) {
        float fu = (1.0f - std::fabs(v)) * sign_not_zero(u);
        float fv = (1.0f - std::fabs(u)) * sign_not_zero(v);
        u = fu;
        v = fv;
    }
}

static uint16_t pack(int cu, int cv) { return uint16_t(uint8_t(int8_t(cu)) | (uint16_t(uint8_t(int8_t(cv))) << 8)); }

static int clamp127(float f) {
    int c = int(f);
    return c < -127 ? -127 : (c > 127 ? 127 : c);
}

uint16_t oct_encode_fast(float x, float y, float z) {
    float u, v;
    project(x, y, z, u, v);
    return pack(clamp127(std::nearbyint(u * 127.0f)), clamp127(std::nearbyint(v * 127.0f)));
}

// The first k of the four candidates (cu[k], cv[k]) with the largest dot product
// oct_decode(pack(cu[k], cv[k])) . n. The SSE path decodes the four at once with exactly the
// float operations of oct_decode and of the dot product, each rounded as the scalar code rounds
// it (no fused multiply-add: the project builds with -ffp-contract=off), so the dot products are
// bit-identical; it then takes the first lane equal to the maximum, which is what the scalar
// search (first strictly greater wins) keeps, without its unpredictable branches. The scalar
// loop is the reference and the fallback.
static int best_candidate(const int cu[4], const int cv[4], float nx, float ny, float nz) {
    const std::array<float, 256>& axis = axis_values();
#if defined(__SSE2__)
    const __m128 u = _mm_setr_ps(axis[uint8_t(cu[0])], axis[uint8_t(cu[1])], axis[uint8_t(cu[2])], axis[uint8_t(cu[3])]);
    const __m128 v = _mm_setr_ps(axis[uint8_t(cv[0])], axis[uint8_t(cv[1])], axis[uint8_t(cv[2])], axis[uint8_t(cv[3])]);
    const __m128 sign = _mm_set1_ps(-0.0f), one = _mm_set1_ps(1.0f), zero = _mm_setzero_ps();
    const __m128 abs_u = _mm_andnot_ps(sign, u), abs_v = _mm_andnot_ps(sign, v);
    const __m128 z = _mm_sub_ps(_mm_sub_ps(one, abs_u), abs_v);
    // Lower hemisphere: x = (1 - |v|) * sign_not_zero(u); multiplying by -1 flips the sign bit.
    const __m128 fx = _mm_xor_ps(_mm_sub_ps(one, abs_v), _mm_and_ps(_mm_cmplt_ps(u, zero), sign));
    const __m128 fy = _mm_xor_ps(_mm_sub_ps(one, abs_u), _mm_and_ps(_mm_cmplt_ps(v, zero), sign));
    const __m128 fold = _mm_cmplt_ps(z, zero);
    const __m128 x = _mm_or_ps(_mm_and_ps(fold, fx), _mm_andnot_ps(fold, u));
    const __m128 y = _mm_or_ps(_mm_and_ps(fold, fy), _mm_andnot_ps(fold, v));
    const __m128 len = _mm_sqrt_ps(_mm_add_ps(_mm_add_ps(_mm_mul_ps(x, x), _mm_mul_ps(y, y)), _mm_mul_ps(z, z)));
    const __m128 dx = _mm_div_ps(x, len), dy = _mm_div_ps(y, len), dz = _mm_div_ps(z, len);
    const __m128 d = _mm_add_ps(_mm_add_ps(_mm_mul_ps(dx, _mm_set1_ps(nx)), _mm_mul_ps(dy, _mm_set1_ps(ny))),
                                _mm_mul_ps(dz, _mm_set1_ps(nz)));
    __m128 m = _mm_max_ps(d, _mm_shuffle_ps(d, d, _MM_SHUFFLE(2, 3, 0, 1)));
    m = _mm_max_ps(m, _mm_shuffle_ps(m, m, _MM_SHUFFLE(1, 0, 3, 2)));
    return __builtin_ctz(unsigned(_mm_movemask_ps(_mm_cmpeq_ps(d, m))));  // no NaN: a lane matches
#else
    (void)axis;
    int best = 0;
    float best_dot = -2.0f;
    for (int k = 0; k < 4; ++k) {
        float d[3];
        oct_decode(pack(cu[k], cv[k]), d);
        const float dot = d[0] * nx + d[1] * ny + d[2] * nz;
        if (dot > best_dot) {
            best_dot = dot;
            best = k;
        }
    }
    return best;
#endif
}

uint16_t oct_encode_precise(float x, float y, float z) {
    float u, v;
    project(x, y, z, u, v);
    float len = std::sqrt(x * x + y * y + z * z);
    if (!(len > 0.0f) || !std::isfinite(len)) return pack(0, 0);
    float nx = x / len, ny = y / len, nz = z / len;
    const int base_u = clamp127(std::floor(u * 127.0f)), base_v = clamp127(std::floor(v * 127.0f));
    const int up_u = base_u < 127 ? base_u + 1 : 127, up_v = base_v < 127 ? base_v + 1 : 127;
    // The four quantized neighbours, in the order the first best is kept.
    const int cu[4] = {base_u, base_u, up_u, up_u}, cv[4] = {base_v, up_v, base_v, up_v};
    const int best = best_candidate(cu, cv, nx, ny, nz);
    return pack(cu[best], cv[best]);
}

void oct_decode(uint16_t code, float out[3]) {
    // Mirrors oct_decode() in shaders/catp_decode.glsl.
    const std::array<float, 256>& axis = axis_values();
    float u = axis[code & 0xff];
    float v = axis[code >> 8];
    float z = 1.0f - std::fabs(u) - std::fabs(v);
    float x = u, y = v;
    if (z < 0.0f) {
        x = (1.0f - std::fabs(v)) * sign_not_zero(u);
        y = (1.0f - std::fabs(u)) * sign_not_zero(v);
    }
    float len = std::sqrt(x * x + y * y + z * z);
    out[0] = x / len;
    out[1] = y / len;
    out[2] = z / len;
}

}  // namespace catpaq
