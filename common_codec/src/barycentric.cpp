#include "common_codec/barycentric.h"

#include <algorithm>
#include <cassert>
#include <cmath>

namespace catpaq {

// Enumeration: a = w1+w2+w3, b = w2+w3, c = w3, index = Tet(a) + Tri(b) + c.
static uint32_t tri(uint32_t b) { return b * (b + 1) / 2; }
static uint32_t tet(uint32_t a) { return a * (a + 1) * (a + 2) / 6; }

uint32_t bary_pack(const BaryWeights& w) {
    assert(w[0] >= 0 && w[1] >= 0 && w[2] >= 0 && w[3] >= 0);
    assert(w[0] + w[1] + w[2] + w[3] == kBaryGrid);
    uint32_t a = uint32_t(w[1] + w[2] + w[3]), b = uint32_t(w[2] + w[3]), c = uint32_t(w[3]);
    return tet(a) + tri(b) + c;
}

bool bary_unpack(uint32_t index, BaryWeights& w) {
    if (index >= kBaryIndexCount) return false;
    // Largest a with tet(a) <= index: estimate with a cube root, then correct (at most a
    // couple of steps). Mirrors bary_unpack() in shaders/catp_decode.glsl.
    uint32_t a = uint32_t(std::cbrt(6.0f * float(index)));
    if (a > uint32_t(kBaryGrid)) a = kBaryGrid;
    while (a > 0 && tet(a) > index) --a;
    while (a < uint32_t(kBaryGrid) && tet(a + 1) <= index) ++a;
    uint32_t rest = index - tet(a);
    uint32_t b = uint32_t(std::sqrt(2.0f * float(rest)));
    if (b > a) b = a;
    while (b > 0 && tri(b) > rest) --b;
    while (b < a && tri(b + 1) <= rest) ++b;
    uint32_t c = rest - tri(b);
    w = {int32_t(kBaryGrid - a), int32_t(a - b), int32_t(b - c), int32_t(c)};
    return true;
}

// Barycentric coordinates of p in the simplex spanned by k corners (k = 1..4), computed from
// those corners only. Coordinates are clamped to be non-negative and renormalised.
static void simplex_coordinates(const double p[3], const double* const corners[], int k, double out[]) {
    auto sub = [](const double* a, const double* b, double r[3]) {
        for (int i = 0; i < 3; ++i) r[i] = a[i] - b[i];
    };
    auto dot = [](const double* a, const double* b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; };
    if (k == 1) {
        out[0] = 1.0;
        return;
    }
    if (k == 2) {
        double e[3], d[3];
        sub(corners[1], corners[0], e);
        sub(p, corners[0], d);
        double t = dot(d, e) / dot(e, e);
        out[0] = 1.0 - t;
        out[1] = t;
    } else if (k == 3) {
        double e0[3], e1[3], d[3];
        sub(corners[1], corners[0], e0);
        sub(corners[2], corners[0], e1);
        sub(p, corners[0], d);
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
        sub(corners[1], corners[0], e0);
        sub(corners[2], corners[0], e1);
        sub(corners[3], corners[0], e2);
        sub(p, corners[0], d);
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
    double sum = 0.0;
    for (int i = 0; i < k; ++i) {
        if (!(out[i] > 0.0)) out[i] = 0.0;  // also maps NaN to 0
        sum += out[i];
    }
    if (sum > 0.0) {
        for (int i = 0; i < k; ++i) out[i] /= sum;
    } else {
        for (int i = 0; i < k; ++i) out[i] = i == 0 ? 1.0 : 0.0;
    }
}

BaryWeights bary_quantize(const double p[3], const std::array<LatticePoint, 4>& c, SupportMask support) {
    assert(support != 0 && support < 16);
    double corners[4][3];
    const double* used[4];
    int index[4], k = 0;
    for (int i = 0; i < 4; ++i) {
        if (!(support & (1 << i))) continue;
        for (int j = 0; j < 3; ++j) corners[k][j] = double(c[i][j]);
        used[k] = corners[k];
        index[k++] = i;
    }
    double lambda[4];
    simplex_coordinates(p, used, k, lambda);

    // Largest-remainder rounding to integers summing to kBaryGrid; ties go to the lower index.
    int32_t weight[4];
    double fraction[4];
    int32_t total = 0;
    for (int i = 0; i < k; ++i) {
        double scaled = lambda[i] * kBaryGrid;
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
    for (int i = 0; i < k; ++i) w[index[i]] = weight[i];
    return w;
}

std::array<int32_t, 3> bary_weighted_sum(const BaryWeights& w, const std::array<LatticePoint, 4>& c,
                                         const std::array<int32_t, 3>& anchor_times_grid) {
    std::array<int32_t, 3> s;
    for (int k = 0; k < 3; ++k) {
        // Exact in 32 bits for lattice coordinates below 2^22 (asserted by the lattice module);
        // computed in 64 bits here so a violated precondition cannot be undefined behaviour.
        int64_t sum = int64_t(w[0]) * c[0][k] + int64_t(w[1]) * c[1][k] + int64_t(w[2]) * c[2][k] +
                      int64_t(w[3]) * c[3][k] - anchor_times_grid[k];
        s[k] = int32_t(sum);
    }
    return s;
}

void bary_decode(const BaryWeights& w, const std::array<LatticePoint, 4>& c,
                 const std::array<int32_t, 3>& anchor_times_grid, float scale, float out[3]) {
    std::array<int32_t, 3> s = bary_weighted_sum(w, c, anchor_times_grid);
    for (int k = 0; k < 3; ++k) out[k] = float(s[k]) * scale;
}

std::array<int, 4> canonical_order(std::array<LatticePoint, 4>& corners) {
    std::array<int, 4> perm{0, 1, 2, 3};
    std::sort(perm.begin(), perm.end(), [&](int a, int b) { return corners[a] < corners[b]; });
    std::array<LatticePoint, 4> sorted;
    for (int i = 0; i < 4; ++i) sorted[i] = corners[perm[i]];
    corners = sorted;
    return perm;
}

}  // namespace catpaq
