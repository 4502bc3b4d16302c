// Packing decoded point nodes into GPU splats of 8 bytes, or 6 without colours
// (points_client/splat_layout.h).
#include "points_client/splat_layout.h"

#include <algorithm>
#include <cmath>

#include "common_codec/octahedral.h"

namespace catpaq {

namespace {

constexpr uint32_t kPositionLevels[3] = {2047, 2047, 1023};  // 11, 11, 10 bits
constexpr int kPositionShift[3] = {0, 11, 22};
// The radius decode runs through the shader's exp2, which may be a few ulps off: every radius
// is padded by this relative margin so the GPU's splat still covers the decoded one.
constexpr double kRadiusMargin = 1e-5;

float sign_not_zero(float v) { return v >= 0 ? 1.0f : -1.0f; }

uint32_t quantize6(float v) {  // [-1, 1] -> 0..63
    long q = std::lround((double(v) * 0.5 + 0.5) * 63.0);
    return uint32_t(std::clamp(q, 0L, 63L));
}

}  // namespace

namespace {

// The 6+6-bit code of every 8+8-bit normal code: a table (128 KiB, built once) instead of a
// decode and an encode per splat, which took most of the packing time.
const std::vector<uint16_t>& oct8_to_oct6() {
    static const std::vector<uint16_t> table = [] {
        std::vector<uint16_t> t(65536);
        for (uint32_t code = 0; code < 65536; ++code) {
            float n[3];
            oct_decode(uint16_t(code), n);
            t[code] = uint16_t(oct6_encode(n));
        }
        return t;
    }();
    return table;
}

}  // namespace

uint32_t oct6_encode(const float n[3]) {
    float l1 = std::abs(n[0]) + std::abs(n[1]) + std::abs(n[2]);
    if (!(l1 > 0)) return quantize6(0) | quantize6(0) << 6;  // no direction: +z
    float x = n[0] / l1, y = n[1] / l1;
    if (n[2] < 0) {  // fold the lower half over the upper
        float fx = (1 - std::abs(y)) * sign_not_zero(x), fy = (1 - std::abs(x)) * sign_not_zero(y);
        x = fx, y = fy;
    }
    return quantize6(x) | quantize6(y) << 6;
}

void oct6_decode(uint32_t code, float out[3]) {
    float x = float(code & 63u) / 63.0f * 2.0f - 1.0f;
    float y = float((code >> 6) & 63u) / 63.0f * 2.0f - 1.0f;
    float z = 1.0f - std::abs(x) - std::abs(y);
    if (z < 0) {
        float fx = (1 - std::abs(y)) * sign_not_zero(x), fy = (1 - std::abs(x)) * sign_not_zero(y);
        x = fx, y = fy;
    }
    float l = std::sqrt(x * x + y * y + z * z);
    out[0] = x / l, out[1] = y / l, out[2] = z / l;
}

PackedSplats pack_splats(const DecodedPoints& points, const double dataset_origin[3]) {
    PackedSplats out;
    const size_t n = points.count;
    out.count = n;
    out.has_normals = (points.flags & kPointHasNormals) != 0;
    out.has_colors = (points.flags & kPointHasColors) != 0;
    out.stride = out.has_colors ? kSplatBytesWithColor : kSplatBytesWithoutColor;
    out.radius_bits = out.has_colors ? 5 : 4;
    const size_t halves = out.stride / 2;
    out.halves.assign(halves * n, 0);
    if (n == 0) return out;

    // Position grid over the tight box of the centres.
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (size_t i = 0; i < n; ++i)
        for (int a = 0; a < 3; ++a) {
            lo[a] = std::min(lo[a], double(points.positions[3 * i + a]));
            hi[a] = std::max(hi[a], double(points.positions[3 * i + a]));
        }
    for (int a = 0; a < 3; ++a) {
        out.origin[a] = dataset_origin[a] + lo[a];
        out.step[a] = float((hi[a] - lo[a]) / kPositionLevels[a]);
    }
    double inverse_step[3];
    for (int a = 0; a < 3; ++a) inverse_step[a] = out.step[a] > 0 ? 1.0 / double(out.step[a]) : 0.0;
    double error2 = 0;
    for (size_t i = 0; i < n; ++i) {
        uint32_t word = 0;
        double d2 = 0;
        for (int a = 0; a < 3; ++a) {
            const double p = points.positions[3 * i + a];
            uint32_t q = 0;
            if (out.step[a] > 0)  // (p - lo) / step >= 0: truncating x + 0.5 rounds
                q = std::min(uint32_t((p - lo[a]) * inverse_step[a] + 0.5), kPositionLevels[a]);
            // What the shader computes (float product), relative to the node origin.
            const double packed = lo[a] + double(float(q) * out.step[a]);
            d2 += (packed - p) * (packed - p);
            word |= q << kPositionShift[a];
        }
        error2 = std::max(error2, d2);
        out.halves[halves * i] = uint16_t(word);
        out.halves[halves * i + 1] = uint16_t(word >> 16);
    }
    // Rounding of origin + lo in double is far below the float grid; a relative hair covers it.
    out.position_error = float(std::sqrt(error2) * (1 + 1e-6));

    // Radii, grown by the position error, on a logarithmic scale over the node's range.
    double rmin = INFINITY, rmax = 0;
    for (size_t i = 0; i < n; ++i) {
        const double r = double(points.radii[i]) + out.position_error;
        rmin = std::min(rmin, r);
        rmax = std::max(rmax, r);
    }
    out.radius_base = float(rmin * (1 + kRadiusMargin));
    const int codes = 1 << out.radius_bits;
    double log2_step = std::log2(rmax * (1 + 2 * kRadiusMargin) / out.radius_base) / (codes - 1);
    out.radius_log2_step = float(std::max(log2_step * (1 + 1e-6), 1.0 / 256));
    // The radius of every code, as the shader computes it (exact exp2 here; the margin covers the
    // GPU's): a splat takes the first code at least its radius (a table search, no log per point).
    double code_radius[32];
    for (int c = 0; c < codes; ++c) code_radius[c] = double(out.radius_base) * std::exp2(double(c) * out.radius_log2_step);
    const uint16_t* normal_codes = oct8_to_oct6().data();
    for (size_t i = 0; i < n; ++i) {
        const double r = (double(points.radii[i]) + out.position_error) * (1 + kRadiusMargin);
        const long code = std::min(long(std::lower_bound(code_radius, code_radius + codes, r) - code_radius), long(codes - 1));
        uint32_t word = uint32_t(code) << 12;
        if (out.has_normals) word |= normal_codes[points.normals[i]];
        if (out.has_colors) {
            const uint8_t* c = &points.colors[3 * i];
            for (int k = 0; k < 3; ++k) word |= ((uint32_t(c[k]) * 31 + 127) / 255) << (17 + 5 * k);
        }
        out.halves[halves * i + 2] = uint16_t(word);
        if (halves == 4) out.halves[halves * i + 3] = uint16_t(word >> 16);
        out.max_radius = std::max(out.max_radius, float(code_radius[code]));
    }
    return out;
}

SplatFields splat_fields(const PackedSplats& splats, size_t i) {
    SplatFields f;
    const size_t halves = splats.stride / 2;
    const uint16_t* h = &splats.halves[halves * i];
    const uint32_t w0 = uint32_t(h[0]) | uint32_t(h[1]) << 16;
    for (int a = 0; a < 3; ++a) f.position[a] = float((w0 >> kPositionShift[a]) & kPositionLevels[a]) * splats.step[a];
    const uint32_t w1 = uint32_t(h[2]) | (halves == 4 ? uint32_t(h[3]) << 16 : 0u);  // the 5-bit code crosses halves
    f.radius_code = (w1 >> 12) & ((1u << splats.radius_bits) - 1);
    return f;
}

UnpackedSplat unpack_splat(const PackedSplats& splats, size_t i) {
    UnpackedSplat s;
    const size_t halves = splats.stride / 2;
    const uint16_t* h = &splats.halves[halves * i];
    const uint32_t w1 = uint32_t(h[2]) | (halves == 4 ? uint32_t(h[3]) << 16 : 0u);
    const SplatFields f = splat_fields(splats, i);
    s.position = f.position;
    s.radius = splats.radius_base * std::exp2(float(f.radius_code) * splats.radius_log2_step);
    if (splats.has_normals) oct6_decode(w1 & 0xfffu, s.normal.data());
    for (int k = 0; k < 3; ++k)
        s.color[k] = splats.has_colors ? uint8_t(std::lround(float((w1 >> (17 + 5 * k)) & 31u) * 255.0f / 31.0f)) : 0;
    return s;
}

}  // namespace catpaq
