#include "common_codec/octahedral.h"

#include <cmath>

namespace catpaq {

// Each axis is a signed 8-bit integer c in [-127, 127] mapped to c/127, so 0 and +-1 are exact
// and axis-aligned normals decode exactly. The byte holds c as two's complement.

static float sign_not_zero(float v) { return v < 0.0f ? -1.0f : 1.0f; }

// Projects a vector to the unfolded octahedron square [-1,1]^2.
static void project(float x, float y, float z, float& u, float& v) {
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

uint16_t oct_encode_precise(float x, float y, float z) {
    float u, v;
    project(x, y, z, u, v);
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
            if (dot > best_dot) { best_dot = dot; best = code; }
        }
    }
    return best;
}

void oct_decode(uint16_t code, float out[3]) {
    // Mirrors oct_decode() in shaders/catp_decode.glsl.
    float u = float(int8_t(uint8_t(code & 0xff))) / 127.0f;
    float v = float(int8_t(uint8_t(code >> 8))) / 127.0f;
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
