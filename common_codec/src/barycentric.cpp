#include "common_codec/barycentric.h"

#include <algorithm>
#include <cassert>
#include <cmath>

namespace catpaq {

// Enumeration: a = w1+w2+w3, b = w2+w3, c = w3, index = Tet(a) + Tri(b) + c.
static constexpr uint32_t tri(uint32_t b) { return b * (b + 1) / 2; }
static constexpr uint32_t tet(uint32_t a) { return uint32_t(uint64_t(a) * (a + 1) * (a + 2) / 6); }

// Inverting index = tet(a) + tri(b) + c by table, for every grid of the enumeration (up to
// kMaxIndexGrid). tet and tri run to kMaxIndexGrid + 1, sentinels above every valid index and
// every valid rest (index - tet(a) < tri(a + 1)). Per block of 2^kBlockBits indices
// (2^kRestBlockBits rests), a_of_block (b_of_block) is the largest a with tet(a) (b with tri(b))
// at or below the block's first value. A block is narrower than the gap to the next number once
// a >= 127 (b >= 64), so one step from the block's value is then exact. This replaced std::cbrt
// and std::sqrt estimates, 8x slower in encode_bench (the encoder unpacks every vertex of every
// fragment).
struct UnpackTables {
    static constexpr int kBlockBits = 13, kRestBlockBits = 6;
    std::array<uint32_t, kMaxIndexGrid + 2> tet{}, tri{};
    std::array<uint16_t, (catpaq::tet(kMaxIndexGrid + 1) >> kBlockBits) + 1> a_of_block{};
    std::array<uint16_t, (catpaq::tri(kMaxIndexGrid + 1) >> kRestBlockBits) + 1> b_of_block{};
    constexpr UnpackTables() {
        for (uint32_t a = 0; a < tet.size(); ++a) {
            tet[a] = catpaq::tet(a);
            tri[a] = catpaq::tri(a);
        }
        uint32_t a = 0, b = 0;
        for (uint32_t block = 0; block < a_of_block.size(); ++block) {
            while (tet[a + 1] <= block << kBlockBits) ++a;
            a_of_block[block] = uint16_t(a);
        }
        for (uint32_t block = 0; block < b_of_block.size(); ++block) {
            while (tri[b + 1] <= block << kRestBlockBits) ++b;
            b_of_block[block] = uint16_t(b);
        }
    }
};
static constexpr UnpackTables kUnpack{};
static_assert(kUnpack.tet[kBaryGrid + 1] == kBaryIndexCount);
static_assert(kUnpack.tet[kMaxIndexGrid + 1] <= (1u << 30), "the Rgb18 layout's index must fit 30 bits");

uint32_t bary_pack(const BaryWeights& w) {
    assert(w[0] >= 0 && w[1] >= 0 && w[2] >= 0 && w[3] >= 0);
    assert(w[1] + w[2] + w[3] <= kMaxIndexGrid);
    uint32_t a = uint32_t(w[1] + w[2] + w[3]), b = uint32_t(w[2] + w[3]), c = uint32_t(w[3]);
    return tet(a) + tri(b) + c;
}

bool bary_unpack(uint32_t index, int32_t grid, BaryWeights& w) {
    assert(grid >= 1 && grid <= kMaxIndexGrid);
    if (index >= bary_index_count(grid)) return false;
    // Largest a with tet(a) <= index: the block's a, then one step without a branch and more
    // only near the first corner (the sentinel stops the loop). Gives the same
    // weights as bary_unpack() in shaders/catp_decode.glsl, which starts from a cube root.
    uint32_t a = kUnpack.a_of_block[index >> UnpackTables::kBlockBits];
    a += uint32_t(kUnpack.tet[a + 1] <= index);
    while (kUnpack.tet[a + 1] <= index) [[unlikely]]
        ++a;
    const uint32_t rest = index - kUnpack.tet[a];
    // Largest b with tri(b) <= rest, the same way; it is at most a since rest < tri(a + 1).
    uint32_t b = kUnpack.b_of_block[rest >> UnpackTables::kRestBlockBits];
    b += uint32_t(kUnpack.tri[b + 1] <= rest);
    while (kUnpack.tri[b + 1] <= rest) [[unlikely]]
        ++b;
    uint32_t c = rest - kUnpack.tri[b];
    w = {grid - int32_t(a), int32_t(a - b), int32_t(b - c), int32_t(c)};
    return true;
}

// Barycentric coordinates of p in the simplex spanned by K corners (K = 1..4), computed from
// those corners only. Coordinates are clamped to be non-negative and renormalised. K is a
// template parameter so that every loop unrolls (no branch depends on the support).
template <int K>
static void simplex_coordinates(const double p[3], const double* const corners[], double out[]) {
    auto sub = [](const double* a, const double* b, double r[3]) {
        for (int i = 0; i < 3; ++i) r[i] = a[i] - b[i];
    };
    auto dot = [](const double* a, const double* b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; };
    if constexpr (K == 1) {
        out[0] = 1.0;
        return;
    } else if constexpr (K == 2) {
        double e[3], d[3];
        sub(corners[1], corners[0], e);
        sub(p, corners[0], d);
        double t = dot(d, e) / dot(e, e);
        out[0] = 1.0 - t;
        out[1] = t;
    } else if constexpr (K == 3) {
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
    for (int i = 0; i < K; ++i) {
        out[i] = out[i] > 0.0 ? out[i] : 0.0;  // also maps NaN to 0
        sum += out[i];
    }
    if (sum == 1.0) {
        // Dividing by exactly 1 changes nothing; skipping it shortens the function's longest
        // latency chain, and the sum is exactly 1 for nearly every point (all of those tried in a
        // Kuhn tetrahedron, 88% in random tetrahedra).
    } else if (sum > 0.0) {
        for (int i = 0; i < K; ++i) out[i] /= sum;
    } else {
        for (int i = 0; i < K; ++i) out[i] = i == 0 ? 1.0 : 0.0;
    }
}

// Largest-remainder rounding of K coordinates (>= 0, summing to about 1) to integer weights
// summing to `grid`; ties go to the lower index.
template <int K>
static void round_to_grid(const double lambda[], int32_t grid, int32_t weight[]) {
    double fraction[K];
    int32_t total = 0;
    for (int i = 0; i < K; ++i) {
        const double scaled = lambda[i] * grid;
        weight[i] = int32_t(scaled);  // scaled >= 0: truncation is floor
        fraction[i] = scaled - weight[i];
        total += weight[i];
    }
    const int remaining = grid - total;
    if (remaining <= K) [[likely]] {
        // The `remaining` first coordinates in the order (fraction descending, index ascending)
        // get one more each: the result of handing them out one at a time to the first largest
        // fraction, without that loop's unpredictable branches (the costliest part of
        // bary_quantize, in perf). More than K cannot remain: the fractions sum to less than K.
#pragma GCC unroll 4
        for (int i = 0; i < K; ++i) {
            int rank = 0;
#pragma GCC unroll 4
            for (int j = 0; j < K; ++j) rank += j < i ? fraction[j] >= fraction[i] : fraction[j] > fraction[i];
            weight[i] += rank < remaining;
        }
    } else {
        for (int left = remaining; left > 0; --left) {
            int best = 0;
            for (int i = 1; i < K; ++i)
                if (fraction[i] > fraction[best]) best = i;
            weight[best] += 1;
            fraction[best] = -1.0;
        }
    }
}

// bary_quantize for a support of K corners.
template <int K>
static BaryWeights quantize_on_support(const double p[3], const std::array<LatticePoint, 4>& c, SupportMask support,
                                       int32_t grid) {
    double corners[K][3];
    const double* used[K] = {};
    int index[K] = {}, k = 0;
    for (int i = 0; i < 4; ++i) {
        if (!(support & (1 << i))) continue;
        for (int j = 0; j < 3; ++j) corners[k][j] = double(c[size_t(i)][size_t(j)]);
        used[k] = corners[k];
        index[k++] = i;
    }
    double lambda[K];
    simplex_coordinates<K>(p, used, lambda);
    int32_t weight[K];
    round_to_grid<K>(lambda, grid, weight);
    if constexpr (K == 4) {
        // Built whole: scattering into w then returning it stalls on store forwarding.
        return {weight[0], weight[1], weight[2], weight[3]};
    } else {
        BaryWeights w{0, 0, 0, 0};
        for (int i = 0; i < K; ++i) w[size_t(index[i])] = weight[i];
        return w;
    }
}

BaryWeights bary_quantize(const double p[3], const std::array<LatticePoint, 4>& c, SupportMask support, int32_t grid) {
    assert(support != 0 && support < 16);
    assert(grid >= 1 && grid <= kMaxWideGrid);
    // Corners per support mask (std::popcount is a library call without a popcnt instruction).
    static constexpr uint8_t kCorners[16] = {0, 1, 1, 2, 1, 2, 2, 3, 1, 2, 2, 3, 2, 3, 3, 4};
    switch (kCorners[support & 15]) {
        case 4: return quantize_on_support<4>(p, c, support, grid);
        case 3: return quantize_on_support<3>(p, c, support, grid);
        case 2: return quantize_on_support<2>(p, c, support, grid);
        default: return quantize_on_support<1>(p, c, support, grid);
    }
}

std::array<int64_t, 3> bary_integer_sum(const BaryWeights& w, const std::array<LatticePoint, 4>& c) {
    std::array<int64_t, 3> s;
    for (int k = 0; k < 3; ++k)
        s[k] = int64_t(w[0]) * c[0][k] + int64_t(w[1]) * c[1][k] + int64_t(w[2]) * c[2][k] + int64_t(w[3]) * c[3][k];
    return s;
}

void bary_decode(const BaryWeights& w, const std::array<LatticePoint, 4>& offsets, float scale, float out[3]) {
    for (int k = 0; k < 3; ++k) {
        // The shader's two 32-bit sums (exact there for |offsets| <= 2^20 and weights summing
        // below 2^14), computed in 64 bits so that a violated precondition is not undefined
        // behaviour here.
        int64_t high = 0, low = 0;
        for (int i = 0; i < 4; ++i) {
            high += int64_t(w[i] >> 7) * offsets[i][k];
            low += int64_t(w[i] & 127) * offsets[i][k];
        }
        out[k] = (float(int32_t(high)) * 128.0f + float(int32_t(low))) * scale;
    }
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
