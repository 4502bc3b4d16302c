// The node codec (points/codec.h): quantization, Morton order, delta + zigzag residuals, and
// block-adaptive Rice codes on four lanes (rice.h). Byte layout: docs/formats/points.md.
#include "points/codec.h"

#include <algorithm>
#include <array>
#include <cassert>
#include <cmath>
#include <cstring>
#include <utility>

#include "base/bytes.h"
#include "base/checksum.h"
#include "base/error.h"
#include "common_codec/octahedral.h"
#include "rice.h"

#ifdef __SSE2__
#include <emmintrin.h>
#endif
// AVX2 kernels compiled alongside the baseline ones and chosen at run time (GCC's target pragma).
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__)
#define CATPAQ_POINTS_AVX2 1
#include <immintrin.h>
#else
#define CATPAQ_POINTS_AVX2 0
#endif

namespace catpaq {

using namespace points_detail;

namespace {

constexpr size_t kHeaderSize = 40;
constexpr size_t kChecksumSize = 8;
constexpr size_t kMaxPoints = size_t(1) << 24;
constexpr uint32_t kMaxGridBits = 24;   // per axis: q < 2^24 is exact in float
constexpr uint32_t kMortonBits = 21;    // per axis in the 63-bit sort key

// ---------------------------------------------------------------------------------------------
// Shared by both sides

// The decoded position of grid coordinate q: the decoder's exact float operations.
__attribute__((always_inline)) inline float grid_position(float origin, float step, uint32_t q) { return origin + float(q) * step; }

__attribute__((always_inline)) inline float radius_value(float base, float step, float pad, uint32_t q) { return (base + float(q) * step) + pad; }

// YCoCg-R (lossless for 8-bit RGB) with Co and Cg offset to be non-negative (0..510).
struct Ycocg {
    int y, co, cg;
};
inline Ycocg to_ycocg(int r, int g, int b) {
    int co = r - b;
    int t = b + (co >> 1);
    int cg = g - t;
    return {t + (cg >> 1), co + 255, cg + 255};
}
__attribute__((always_inline)) inline uint8_t clamp_byte(int v) { return uint8_t(v < 0 ? 0 : v > 255 ? 255 : v); }
__attribute__((always_inline)) inline void from_ycocg(int y, int co, int cg, uint8_t* rgb) {
    co -= 255;
    cg -= 255;
    int t = y - (cg >> 1);
    int g = cg + t;
    int b = t - (co >> 1);
    int r = b + co;
    rgb[0] = clamp_byte(r);
    rgb[1] = clamp_byte(g);
    rgb[2] = clamp_byte(b);
}
// Quantized colour components back to full range (the decoder's operations).
__attribute__((always_inline)) inline void dequantize_color(uint32_t yq, uint32_t coq, uint32_t cgq, int luma_shift, int chroma_shift, uint8_t* rgb) {
    int y = std::min(int(yq << luma_shift), 255);
    int co = std::min(int(coq << chroma_shift), 510);
    int cg = std::min(int(cgq << chroma_shift), 510);
    from_ycocg(y, co, cg, rgb);
}

float round_down(double v) {
    float f = float(v);
    return double(f) > v ? std::nextafter(f, -INFINITY) : f;
}
float round_up(double v) {
    float f = float(v);
    return double(f) < v ? std::nextafter(f, INFINITY) : f;
}

uint64_t spread_bits21(uint64_t x) {  // 21 bits -> every third bit of 63
    x &= 0x1fffff;
    x = (x | x << 32) & 0x1f00000000ffffULL;
    x = (x | x << 16) & 0x1f0000ff0000ffULL;
    x = (x | x << 8) & 0x100f00f00f00f00fULL;
    x = (x | x << 4) & 0x10c30c30c30c30c3ULL;
    x = (x | x << 2) & 0x1249249249249249ULL;
    return x;
}

// ---------------------------------------------------------------------------------------------
// Encoder

// Bits of block parameter k after a block with parameter `previous` (the first block has
// previous = kNoPrevious): "0" the same k, "10s" one less (s = 0) or one more (s = 1), "11"
// and k in 5 bits; the first block's k is 5 bits. Neighbouring blocks mostly share k: this
// took the parameters from 5 bits per block to about 2.
constexpr uint32_t kNoPrevious = 64;
uint32_t parameter_bits(uint32_t previous, uint32_t k) {
    if (previous == kNoPrevious) return 5;
    if (k == previous) return 1;
    if (k + 1 == previous || k == previous + 1) return 3;
    return 7;
}
void put_parameter(BitWriter& w, uint32_t previous, uint32_t k) {
    if (previous == kNoPrevious) w.put(k, 5);
    else if (k == previous) w.put(0, 1);
    else if (k + 1 == previous || k == previous + 1) w.put(1u | (k > previous ? 4u : 0u), 3);
    else w.put(3u | k << 2, 7);
}

// Chooses the block's parameter (docs/formats/points.md, "Block parameters"): from version 3 on,
// 0 for a block of zeros, else the Rice parameter k plus one; in version 2, k. k is the cheapest
// (values and parameter code) among those near log2 of the mean.
uint32_t choose_parameter(const uint32_t* values, size_t n, uint32_t previous, bool zero_blocks) {
    uint64_t sum = 0;
    for (size_t i = 0; i < n; ++i) sum += values[i];
    // A block of zeros costs its parameter only, where a Rice code spends a bit per value: the
    // chroma of grey or evenly coloured points is such blocks throughout (a quarter of a byte
    // per point on points_bench's scan).
    if (zero_blocks && sum == 0) return 0;
    const uint32_t offset = zero_blocks ? 1 : 0;
    uint32_t guess = n ? bit_width32(uint32_t(std::min<uint64_t>(sum / n, UINT32_MAX))) : 0;
    uint32_t lo = guess > 2 ? guess - 2 : 0, hi = std::min(guess + 1, kRiceMaxK - offset);
    lo = std::min(lo, hi);
    uint32_t best_k = lo;
    uint64_t best = UINT64_MAX;
    for (uint32_t k = lo; k <= hi; ++k) {
        const uint64_t cost = parameter_bits(previous, k + offset) + rice_bits(values, n, k);
        if (cost < best) best = cost, best_k = k;
    }
    return best_k + offset;
}

// The low bits of a full block in the vertical layout: value i is the (i / 4)-th k-bit field of
// lane i % 4, a little-endian string of 32-bit words stored interleaved (word j of lane l at
// word 4j + l), 16k bytes in all.
void put_vertical_block(std::vector<uint8_t>& out, const uint32_t* values, uint32_t k) {
    // One spare row of words: a field's spill past the last word is zero but still written.
    // Only the 4k + 4 words the block uses are cleared: the whole array's 512-byte memset per
    // block was 3% of put_stream's samples (point_encode_bench 343 -> 341 ms).
    uint32_t words[4 * kRiceMaxK + 4];
    if (k == 0) return;
    std::memset(words, 0, sizeof(uint32_t) * 4 * (size_t(k) + 1));
    const uint32_t mask = k >= 32 ? UINT32_MAX : (uint32_t(1) << k) - 1;
    // The four lanes' m-th fields share their bit offset m k: each step packs four values with
    // the same shifts (a loop the compiler turns into SIMD), where a value at a time was most
    // of the stream writer's instructions.
    for (uint32_t m = 0; m < kRiceBlock / 4; ++m) {
        const uint32_t bit = m * k, j = bit >> 5, shift = bit & 31;
        uint32_t* low = words + 4 * j;
        for (uint32_t lane = 0; lane < 4; ++lane) low[lane] |= (values[4 * m + lane] & mask) << shift;
        if (shift + k > 32)
            for (uint32_t lane = 0; lane < 4; ++lane) low[4 + lane] |= (values[4 * m + lane] & mask) >> (32 - shift);
    }
    // Appended whole, bytes in little-endian order (a push_back per byte cost more than the
    // packing above).
    const size_t at = out.size(), bytes = 16 * size_t(k);
    out.resize(at + bytes);
    uint8_t* to = out.data() + at;
    for (size_t w = 0; w < 4 * size_t(k); ++w)
        for (int b = 0; b < 4; ++b) to[4 * w + size_t(b)] = uint8_t(words[w] >> (8 * b));
}

// An escape's excess quotient e in the Exp-Golomb code of escape_cost.
void put_escape(BitWriter& w, uint32_t e) {
    const uint32_t n = escape_prefix(e);
    w.put(uint64_t(1) << n, n + 1);
    w.put((uint64_t(e) >> kEscapeOrder) + 1, n);  // put keeps the n low bits: the top bit goes
    w.put(e, kEscapeOrder);
}

// The encoder's work space for streams, reused from stream to stream.
struct StreamBuffers {
    BitWriter parameters, unary, partial, exceptions;
    std::vector<uint8_t> low;
};

// Writes one stream (docs/formats/points.md, "Streams"): the blocks' parameters, the unary quotients, the low bits (full blocks vertical, then the partial block
// packed) and the escaped values' high bits.
void put_stream(ByteWriter& out, const std::vector<uint32_t>& values, bool zero_blocks, StreamBuffers& s) {
    const size_t n = values.size();
    s.parameters.clear();
    s.unary.clear();
    s.partial.clear();
    s.exceptions.clear();
    s.low.clear();
    uint32_t previous = kNoPrevious;
    for (size_t first = 0; first < n; first += kRiceBlock) {
        const size_t end = std::min(n, first + kRiceBlock);
        const uint32_t parameter = choose_parameter(values.data() + first, end - first, previous, zero_blocks);
        put_parameter(s.parameters, previous, parameter);
        previous = parameter;
        if (zero_blocks && parameter == 0) continue;  // no quotients, low bits or exceptions
        const uint32_t k = zero_blocks ? parameter - 1 : parameter;
        // The unary codes gathered in a local word and handed to the writer 32 bits at a time:
        // a put per value kept the writer's state in memory (most of the stream's time).
        uint64_t word = 0;
        uint32_t bits = 0;  // below 32 between values
        for (size_t i = first; i < end; ++i) {
            const uint32_t q = values[i] >> k, capped = std::min(q, kRiceEscape);
            word |= (uint64_t(1) << capped) << bits;
            bits += capped + 1;
            if (bits >= 32) {
                s.unary.put(word, 32);
                word >>= 32;
                bits -= 32;
            }
            if (q >= kRiceEscape) put_escape(s.exceptions, q - kRiceEscape);
        }
        s.unary.put(word, bits);
        if (end - first == kRiceBlock) put_vertical_block(s.low, values.data() + first, k);
        else
            for (size_t i = first; i < end; ++i) s.partial.put(values[i], k);
    }
    for (BitWriter* part : {&s.parameters, &s.unary}) {
        std::vector<uint8_t>& bytes = part->finish();
        out.raw(bytes.data(), bytes.size());
    }
    out.raw(s.low.data(), s.low.size());
    for (BitWriter* part : {&s.partial, &s.exceptions}) {
        std::vector<uint8_t>& bytes = part->finish();
        out.raw(bytes.data(), bytes.size());
    }
}

struct Grid {
    float origin[3];
    float step;
};

// A grid whose rounding moves a point by at most `max_error` (step * sqrt(3) / 2), unless the
// node is so large for its radii that 2^24 steps per axis cannot reach that (then coarser: the
// radius pad still covers the measured error).
Grid choose_grid(const PointSamplesView& points, double max_error) {
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (size_t i = 0; i < points.count; ++i)
        for (int a = 0; a < 3; ++a) {
            lo[a] = std::min(lo[a], points.positions[3 * i + a]);
            hi[a] = std::max(hi[a], points.positions[3 * i + a]);
        }
    Grid grid;
    double extent = 0;
    for (int a = 0; a < 3; ++a) {
        grid.origin[a] = round_down(lo[a]);
        extent = std::max(extent, hi[a] - double(grid.origin[a]));
    }
    double step = 2.0 * max_error / std::sqrt(3.0);
    step = std::max(step, extent / double((1u << kMaxGridBits) - 2));
    if (!(step > 0)) step = std::max(max_error, 1e-30);
    grid.step = round_down(step);
    if (!(grid.step > 0)) grid.step = std::numeric_limits<float>::denorm_min();
    return grid;
}

// std::nearbyint(t) for 0 <= t <= 2^52, inline: t + 2^52 has no fraction bits left, so the sum
// is t rounded to an integer in the current rounding mode (as nearbyint rounds) and the
// subtraction is exact. Without SSE4.1 in the baseline, std::nearbyint is a libm call.
__attribute__((always_inline)) inline double nearbyint_nonnegative(double t) {
    constexpr double kNoFraction = 0x1p52;
    return (t + kNoFraction) - kNoFraction;
}

// Grid coordinates of every point (3 per point): each coordinate rounded to the nearest grid
// index and clamped to the grid. Clamped first, then rounded: the same indices as rounding
// first (the bounds are integers and rounding is monotonic; NaN stays NaN either way), and the
// rounding stays in nearbyint_nonnegative's range. The libm call per coordinate took 8% of the
// encoder's time (point_encode_bench 316 -> 305 ms).
std::vector<uint32_t> quantize_positions(const PointSamplesView& points, const Grid& grid) {
    std::vector<uint32_t> q(3 * points.count);
    const double top = double((1u << kMaxGridBits) - 1);
    size_t i = 0;
#ifdef __SSE2__
    // Two points per step, their six coordinates as the pairs (x0 y0) (z0 x1) (y1 z1), with the
    // same operations, two at a time: the divisions were the loop's time, and a divpd costs
    // about what a divsd does (point_encode_bench 249 -> 244 ms). The clamp is max then min,
    // which maps NaN to 0, the index the scalar loop's conversion of NaN gives.
    const double origin[3] = {double(grid.origin[0]), double(grid.origin[1]), double(grid.origin[2])};
    const __m128d origin_xy = _mm_setr_pd(origin[0], origin[1]), origin_zx = _mm_setr_pd(origin[2], origin[0]);
    const __m128d origin_yz = _mm_setr_pd(origin[1], origin[2]);
    const __m128d step = _mm_set1_pd(double(grid.step)), zero = _mm_setzero_pd(), last = _mm_set1_pd(top);
    const __m128d no_fraction = _mm_set1_pd(0x1p52);
    auto indices = [&](const double* at, __m128d from) {  // two coordinates -> two int32 (low half)
        const __m128d t = _mm_div_pd(_mm_sub_pd(_mm_loadu_pd(at), from), step);
        const __m128d clamped = _mm_min_pd(_mm_max_pd(t, zero), last);
        return _mm_cvttpd_epi32(_mm_sub_pd(_mm_add_pd(clamped, no_fraction), no_fraction));
    };
    for (; i + 2 <= points.count; i += 2) {
        const double* p = points.positions + 3 * i;
        uint32_t* to = q.data() + 3 * i;
        _mm_storel_epi64(reinterpret_cast<__m128i*>(to), indices(p, origin_xy));
        _mm_storel_epi64(reinterpret_cast<__m128i*>(to + 2), indices(p + 2, origin_zx));
        _mm_storel_epi64(reinterpret_cast<__m128i*>(to + 4), indices(p + 4, origin_yz));
    }
#endif
    for (; i < points.count; ++i)
        for (int a = 0; a < 3; ++a) {
            const double t = (points.positions[3 * i + a] - double(grid.origin[a])) / double(grid.step);
            q[3 * i + a] = uint32_t(nearbyint_nonnegative(std::clamp(t, 0.0, top)));
        }
    return q;
}

// The points' order along the Morton curve of their cells (the coarsest 21 bits per axis).
void morton_order(const std::vector<uint32_t>& q, std::vector<uint32_t>& order) {
    const size_t n = q.size() / 3;
    uint32_t largest = 0;
    for (uint32_t v : q) largest = std::max(largest, v);
    const uint32_t shift = bit_width32(largest) > kMortonBits ? bit_width32(largest) - kMortonBits : 0;
    auto key = [&](size_t i) {
        return spread_bits21(q[3 * i] >> shift) | spread_bits21(q[3 * i + 1] >> shift) << 1 |
               spread_bits21(q[3 * i + 2] >> shift) << 2;
    };
    // The keys are below 2^key_bits and the indices below 2^index_bits.
    const uint32_t key_bits = 3 * std::min(bit_width32(largest), kMortonBits);
    const uint32_t index_bits = bit_width32(uint32_t(n - 1));
    if (n >= 256 && key_bits + index_bits <= 64) {
        // By key, ties by index, as the sort of (key, index) pairs below: each point as one
        // 64-bit item, its key above its index, in a stable LSD radix sort of the key bits in
        // 11-bit digits (a digit every key shares skipped) from the index order, so that only
        // the key's digits are counted and half the bytes move. Keys of up to 52 bits (17 per
        // axis) fit beside a 4096-point node's indices; the 1M scan's nodes have 21 to 30.
        // Measured: point_encode_bench 266 -> 248 ms (8-bit digits 251 ms, 12-bit 254 ms).
        constexpr uint32_t kDigitBits = 11;
        constexpr size_t kBuckets = size_t(1) << kDigitBits;
        const uint32_t digits = (key_bits + kDigitBits - 1) / kDigitBits;
        std::vector<uint64_t> items(n), scratch(n);
        std::vector<uint32_t> counts(size_t(digits) * kBuckets, 0);
        for (size_t i = 0; i < n; ++i) {
            const uint64_t k = key(i);
            items[i] = k << index_bits | i;
            for (uint32_t d = 0; d < digits; ++d) ++counts[d * kBuckets + ((k >> (kDigitBits * d)) & (kBuckets - 1))];
        }
        for (uint32_t d = 0; d < digits; ++d) {
            uint32_t* c = &counts[d * kBuckets];
            const uint32_t at = index_bits + kDigitBits * d;
            if (c[(items[0] >> at) & (kBuckets - 1)] == n) continue;
            uint32_t sum = 0;
            for (size_t v = 0; v < kBuckets; ++v) {
                const uint32_t count = c[v];
                c[v] = sum;
                sum += count;
            }
            for (uint64_t item : items) scratch[c[(item >> at) & (kBuckets - 1)]++] = item;
            items.swap(scratch);
        }
        order.resize(n);
        const uint64_t index_mask = (uint64_t(1) << index_bits) - 1;
        for (size_t i = 0; i < n; ++i) order[i] = uint32_t(items[i] & index_mask);
        return;
    }
    std::vector<std::pair<uint64_t, uint32_t>> keys(n);
    for (size_t i = 0; i < n; ++i) keys[i] = {key(i), uint32_t(i)};
    if (n < 256) {
        std::sort(keys.begin(), keys.end());
    } else {
        // By key, ties by index, as the sort of the pairs: a stable LSD radix sort on the key
        // in 11-bit digits (a digit every key shares skipped) from the index order. The
        // comparison sort's branches mispredicted (1.4% of the conversion's time).
        constexpr int kDigitBits = 11, kDigits = 6;  // 66 bits, for the 63 of a key
        constexpr size_t kBuckets = size_t(1) << kDigitBits;
        std::vector<uint32_t> counts(kDigits * kBuckets, 0);
        for (const auto& k : keys)
            for (int d = 0; d < kDigits; ++d) ++counts[size_t(d) * kBuckets + ((k.first >> (kDigitBits * d)) & (kBuckets - 1))];
        std::vector<std::pair<uint64_t, uint32_t>> scratch(n);
        for (int d = 0; d < kDigits; ++d) {
            uint32_t* c = &counts[size_t(d) * kBuckets];
            const int at = kDigitBits * d;
            if (c[(keys[0].first >> at) & (kBuckets - 1)] == n) continue;
            uint32_t sum = 0;
            for (size_t v = 0; v < kBuckets; ++v) {
                const uint32_t count = c[v];
                c[v] = sum;
                sum += count;
            }
            for (const auto& k : keys) scratch[c[(k.first >> at) & (kBuckets - 1)]++] = k;
            keys.swap(scratch);
        }
    }
    order.resize(n);
    for (size_t i = 0; i < n; ++i) order[i] = keys[i].second;
}

// Appends the zigzagged deltas of values[order[i] * stride + offset] as one stream.
struct StreamWriter {
    ByteWriter& out;
    const std::vector<uint32_t>& order;
    bool zero_blocks;  // version 3 on
    std::vector<uint32_t> residuals;
    StreamBuffers buffers;

    template <class Value>
    size_t put_deltas(Value value) {  // value(input index) -> int32
        int32_t previous = 0;
        residuals.resize(order.size());
        for (size_t i = 0; i < order.size(); ++i) {
            int32_t v = value(order[i]);
            residuals[i] = zigzag(v - previous);
            previous = v;
        }
        size_t before = out.size();
        put_stream(out, residuals, zero_blocks, buffers);
        return out.size() - before;
    }
};

// The quantized Y, Co, Cg of an RGB colour: chroma to the nearest step, then the luma (of the
// nearest and its neighbours) that best restores RGB given that chroma.
std::array<uint32_t, 3> quantize_color(const uint8_t* rgb, int luma_shift, int chroma_shift) {
    Ycocg c = to_ycocg(rgb[0], rgb[1], rgb[2]);
    // At full precision (the default) the search below keeps Y itself, so it is skipped: YCoCg-R
    // is lossless, so Y restores RGB exactly, and the search keeps the first least error, where
    // only Y - 1 comes before Y. Y - 1 moves every channel down by one before the clamp to
    // 0..255, which hides that only for black, whose Y - 1 is skipped. (Checked for all 2^24
    // colours: tests/points/test_codec.cpp.) The search's three decodes per point were a third
    // of encode_point_node's own samples on the 1M scan (point_encode_bench 341 -> 316 ms).
    if (luma_shift == 0 && chroma_shift == 0) return {uint32_t(c.y), uint32_t(c.co), uint32_t(c.cg)};
    auto nearest = [](int v, int shift, int top) {
        return uint32_t(std::min((v + (shift ? 1 << (shift - 1) : 0)) >> shift, top >> shift));
    };
    const uint32_t co = nearest(c.co, chroma_shift, 510), cg = nearest(c.cg, chroma_shift, 510);
    const uint32_t y0 = nearest(c.y, luma_shift, 255);
    uint32_t best_y = y0;
    int best_error = INT32_MAX;
    for (int dy = -1; dy <= 1; ++dy) {
        int y = int(y0) + dy;
        if (y < 0 || y > (255 >> luma_shift) + 1) continue;
        uint8_t back[3];
        dequantize_color(uint32_t(y), co, cg, luma_shift, chroma_shift, back);
        int error = 0;
        for (int k = 0; k < 3; ++k) error = std::max(error, std::abs(int(back[k]) - int(rgb[k])));
        if (error < best_error) best_error = error, best_y = uint32_t(y);
    }
    return {best_y, co, cg};
}

// The smallest radius grid index whose decoded value (before the pad) is at least r: rounded up
// so splats never shrink, then stepped up while the decoder's float arithmetic falls short.
int32_t quantize_radius(double r, float base, float step) {
    double t = std::ceil((r - double(base)) / double(step));
    int32_t v = int32_t(std::clamp(t, 0.0, double(1 << 30)));
    while (radius_value(base, step, 0.0f, uint32_t(v)) < float(r) && v < (1 << 30)) ++v;
    return v;
}

// The smallest of n radii, as a double. Out of line, as is largest_error: inlined into the
// encoder, GCC kept the running minimum and maximum in stack slots, a store and a load on the
// chain from point to point (together 17% of encode_point_node's own samples; out of line,
// point_encode_bench 272 -> 266 ms).
// Taken among the floats and then widened: exact and order-keeping, so the same double as the
// minimum of the widened radii.
__attribute__((noinline)) double smallest_radius(const float* radii, size_t n) {
    float smallest = INFINITY;
    for (size_t i = 0; i < n; ++i) smallest = std::min(smallest, radii[i]);
    return smallest;
}
__attribute__((noinline)) double largest_error(const std::vector<double>& error) {
    double worst = 0;
    for (double e : error) worst = std::max(worst, e);
    return worst;
}

// Decodes the node in `out` (its checksum and pad not yet set), measures every point's
// position error against the input, then sets the pad so that every decoded splat covers its
// input splat grown by that error, and seals the node with its checksum. `decoded` receives
// the final decode.
//
// The node is decoded once, with a pad of 0: the pad changes nothing but the radii, which the
// decoder computes as radius_value(b, t, e, q) = (b + q t) + e in float arithmetic, and
// (b + q t) + 0 is (b + q t) itself; so the radii under any pad are the pad-0 radii plus the
// pad, the same float additions the decoder makes. (This saved a second decode and checksum
// of every node: 2% of the conversion.)
void seal_node(ByteWriter& out, size_t pad_at, size_t body_end, const PointSamplesView& points,
               const std::vector<uint32_t>& order, DecodedPoints& decoded, PointEncodeStats& stats) {
    const size_t n = points.count;
    auto seal = [&](float pad) {
        uint32_t pad_bits;
        std::memcpy(&pad_bits, &pad, 4);
        out.patch_u32(pad_at, pad_bits);
        out.patch_u64(body_end, checksum64(out.bytes().data(), body_end));
    };
    seal(0.0f);
    {
        std::string problem = decode_point_node(out.bytes().data(), out.size(), decoded);
        assert(problem.empty() && "the encoder's own output must decode");
        (void)problem;
    }
    std::vector<double> error(n);
    for (size_t i = 0; i < n; ++i) {
        const double* p = points.positions + 3 * order[i];
        double d2 = 0;
        for (int a = 0; a < 3; ++a) d2 += (double(decoded.positions[3 * i + a]) - p[a]) * (double(decoded.positions[3 * i + a]) - p[a]);
        error[i] = std::sqrt(d2);
    }
    const double worst = largest_error(error);
    stats.position_error = worst;
    float pad = round_up(worst);
    float largest_radius = 0;
    for (float r : decoded.radii) largest_radius = std::max(largest_radius, r);
    for (int attempt = 0;; ++attempt) {
        double deficit = 0;
        for (size_t i = 0; i < n; ++i)
            deficit = std::max(deficit, double(points.radii[order[i]]) + error[i] - double(decoded.radii[i] + pad));
        if (deficit <= 0) break;
        assert(attempt < 16);
        // A deficit far below a float step of the radius is lost when the decoder adds the pad
        // (float(r + pad) == r): after 8 such steps, grow by that step too (a single point a
        // little off its grid origin asserted here; nodes that met the bound sooner keep their bytes).
        const double step = attempt >= 8 ? double(largest_radius) * 0x1p-23 : 0.0;
        pad = round_up(double(pad) + deficit * (1.0 + 1e-6) + step);
    }
    seal(pad);
    for (float& r : decoded.radii) r += pad;
    decoded.position_error = pad;
}

}  // namespace

std::vector<uint8_t> encode_point_node(const PointSamplesView& points, const PointEncodeSettings& settings,
                                       std::vector<uint32_t>* order_out, DecodedPoints* decoded_out,
                                       PointEncodeStats* stats_out) {
    const size_t n = points.count;
    assert(n >= 1 && n < kMaxPoints);
    assert(points.positions && points.radii);
    const ColorBits& color_bits = settings.color_bits;
    assert(color_bits.luma >= 1 && color_bits.luma <= 8 && color_bits.chroma >= 1 && color_bits.chroma <= 9);
    assert(settings.error_fraction > 0 && settings.error_fraction <= 1);
    for (size_t i = 0; i < n; ++i) assert(std::isfinite(points.radii[i]) && points.radii[i] > 0);
    const double min_radius = smallest_radius(points.radii, n);
    const Grid grid = choose_grid(points, min_radius * settings.error_fraction);
    const std::vector<uint32_t> q = quantize_positions(points, grid);
    std::vector<uint32_t> local_order;
    std::vector<uint32_t>& order = order_out ? *order_out : local_order;
    morton_order(q, order);

    const bool has_normals = points.normals != nullptr, has_colors = points.colors != nullptr;
    const float radius_base = round_down(min_radius);
    float radius_step = round_down(min_radius * settings.error_fraction);
    if (!(radius_step > 0)) radius_step = std::numeric_limits<float>::denorm_min();

    // Header; the position error (radius pad) is patched once measured.
    ByteWriter out;
    // Room for the usual node (about 4 bytes a point), so the streams rarely regrow it.
    out.bytes().reserve(kHeaderSize + kChecksumSize + 8 * n);
    out.raw(kPointNodeMagic, 4);
    assert(settings.version >= kPointNodeOldestVersion && settings.version <= kPointNodeVersion);
    out.u8(settings.version);
    out.u8(uint8_t((has_normals ? kPointHasNormals : 0) | (has_colors ? kPointHasColors : 0)));
    out.u8(color_bits.luma);
    out.u8(color_bits.chroma);
    out.u32(uint32_t(n));
    for (int a = 0; a < 3; ++a) out.f32(grid.origin[a]);
    out.f32(grid.step);
    out.f32(radius_base);
    out.f32(radius_step);
    const size_t pad_at = out.size();
    out.f32(0.0f);
    assert(out.size() == kHeaderSize);

    PointEncodeStats stats;
    stats.min_radius = min_radius;
    stats.bytes_header = kHeaderSize + kChecksumSize;
    StreamWriter streams{out, order, settings.version >= 3, {}, {}};
    for (int a = 0; a < 3; ++a)
        stats.bytes_position += streams.put_deltas([&](uint32_t i) { return int32_t(q[3 * i + a]); });
    if (has_normals) {
        // Four normals per SSE step (point_encode_bench 305 -> 270 ms).
        std::vector<uint16_t> codes(n);
        oct_encode_precise_batch(points.normals, n, codes.data());
        // Octahedral coordinates wrap modulo 256: a delta is the signed byte difference.
        for (int c = 0; c < 2; ++c) {
            int32_t running = 0;
            stats.bytes_normal += streams.put_deltas([&](uint32_t i) {
                int v = (codes[i] >> (8 * c)) & 0xff;
                running += int8_t(uint8_t(v - (running & 0xff)));
                return running;
            });
        }
    }
    if (has_colors) {
        const int luma_shift = 8 - color_bits.luma, chroma_shift = 9 - color_bits.chroma;
        std::vector<std::array<uint32_t, 3>> quantized(n);
        for (size_t i = 0; i < n; ++i) quantized[i] = quantize_color(points.colors + 3 * i, luma_shift, chroma_shift);
        for (int c = 0; c < 3; ++c)
            stats.bytes_color += streams.put_deltas([&](uint32_t i) { return int32_t(quantized[i][size_t(c)]); });
    }
    stats.bytes_radius += streams.put_deltas(
        [&](uint32_t i) { return quantize_radius(points.radii[i], radius_base, radius_step); });
    const size_t body_end = out.size();
    out.u64(0);

    DecodedPoints local_decoded;
    seal_node(out, pad_at, body_end, points, order, decoded_out ? *decoded_out : local_decoded, stats);
    if (stats_out) *stats_out = stats;
    return std::move(out.bytes());
}

// ---------------------------------------------------------------------------------------------
// Decoder

namespace {

// The one bits of a byte of the unary string (bits least significant first): their bit
// indices (0-7) in the bytes of kOnesAt[byte], kOnesCount[byte] of them. A quotient is the
// distance between two one bits less one, so the string decodes to the positions of its one
// bits (modulo 256, a byte each) and the quotients follow in a separate SIMD pass. Measured:
// the earlier table of quotients carried the zeros after a byte's last one bit into the next
// byte's first quotient, a dependency from byte to byte, and its loop took a quarter of the
// decoder's time; with positions, the only dependency is the output pointer.
struct OnesTables {
    uint64_t at[256];
    uint8_t count[256];
};
constexpr OnesTables make_ones_tables() {
    OnesTables t{};
    for (uint32_t byte = 0; byte < 256; ++byte) {
        uint32_t count = 0;
        for (uint32_t bit = 0; bit < 8; ++bit)
            if (byte >> bit & 1) t.at[byte] |= uint64_t(bit) << (8 * count++);
        t.count[byte] = uint8_t(count);
    }
    return t;
}
constexpr OnesTables kOnes = make_ones_tables();
constexpr uint64_t kEveryByte = 0x0101010101010101ull;

// Appends the one bits' positions of the byte at `p`, whose bits are at 8b .. 8b + 7 of the
// string: `base` is 8b modulo 256 in every byte (the indices below 8 and a multiple of 8 below
// 256 carry nothing into each other).
__attribute__((always_inline)) inline void put_ones(uint32_t byte, uint64_t base, uint8_t*& out) {
    const uint64_t at = kOnes.at[byte] + base;
    std::memcpy(out, &at, 8);
    out += kOnes.count[byte];
}

// Decodes the n unary quotients at the start of [cursor, end) into q[0, n), through the
// positions (modulo 256) of the string's one bits in ones[0, n); ones[-1] must be writable and
// both arrays need 64 bytes of slack after n. Advances cursor past the string (which ends at its
// n-th one bit's byte).
//
// Positions modulo 256 give exact differences for runs of zeros below 256; a longer run would
// alias to a short quotient, so the quotients plus their one bits must add up to the position
// of the n-th one bit (a sum the quotient pass keeps by the way; measured: checking the bytes
// for long runs took a tenth of this loop). Runs of 9 to 255 zeros give quotients above
// kRiceEscape, which the block decoders reject.
const char* get_unary(const uint8_t*& cursor, const uint8_t* end, size_t n, uint8_t* ones, uint8_t* q) {
    const uint8_t* const start = cursor;
    const uint8_t* p = start;
    uint8_t* out = ones;
    uint8_t* const out_end = ones + n;
    ones[-1] = 0xff;  // the one bit "before" the string, at position -1
    uint64_t base = 0;  // 8b mod 256 for the first byte b of the next word
    // Eight bytes per step while they cannot hold the n-th one bit (at most 64 values).
    while (out_end - out > 64 && end - p >= 8) {
        uint64_t w;
        std::memcpy(&w, p, 8);
        if constexpr (std::endian::native == std::endian::big) w = __builtin_bswap64(w);
        p += 8;
        for (uint32_t j = 0; j < 8; ++j) put_ones(uint32_t(w >> (8 * j)) & 0xff, base + 8 * j * kEveryByte, out);
        base = (base + 64 * kEveryByte) & (0xc0 * kEveryByte);  // the carries out of each byte masked off
    }
    for (; out < out_end; base += 8 * kEveryByte) {
        if (p == end) return "truncated unary string";
        put_ones(*p++, base & (0xf8 * kEveryByte), out);  // 8b mod 256: the carries masked off
    }
    if (out != out_end) return "unary string has too many values";
    if (n == 0) return nullptr;
    uint64_t total = 0;  // the quotients' sum
    size_t i = 0;
#ifdef __SSE2__
    const __m128i one = _mm_set1_epi8(1), zero = _mm_setzero_si128();
    __m128i sums = zero;
    for (; i + 16 <= n; i += 16) {
        const __m128i here = _mm_loadu_si128(reinterpret_cast<const __m128i*>(ones + i));
        const __m128i before = _mm_loadu_si128(reinterpret_cast<const __m128i*>(ones + i - 1));
        const __m128i quotients = _mm_sub_epi8(_mm_sub_epi8(here, before), one);
        _mm_storeu_si128(reinterpret_cast<__m128i*>(q + i), quotients);
        sums = _mm_add_epi64(sums, _mm_sad_epu8(quotients, zero));
    }
    alignas(16) uint64_t halves[2];
    _mm_store_si128(reinterpret_cast<__m128i*>(halves), sums);
    total = halves[0] + halves[1];
#endif
    for (; i < n; ++i) {
        q[i] = uint8_t(ones[i] - ones[i - 1] - 1);
        total += q[i];
    }
    // The n-th one bit is in the last byte read, at the index its position has modulo 8.
    const uint64_t last = 8 * uint64_t(p - start - 1) + (ones[n - 1] & 7);
    if (total + n != last + 1) return "unary run too long";
    cursor = p;
    return nullptr;
}

// The k-bit field i (< kRiceBlock) of a full block's vertical low bits (put_vertical_block).
__attribute__((always_inline)) inline uint32_t vertical_field(const uint8_t* words, size_t i, uint32_t k) {
    const uint32_t bit = uint32_t(i / 4) * k, j = bit >> 5;
    const uint8_t* at = words + 4 * (4 * j + i % 4);
    uint32_t w0, w1;
    std::memcpy(&w0, at, 4);
    std::memcpy(&w1, at + 16, 4);
    const uint64_t two = uint64_t(w0) | uint64_t(w1) << 32;
    return uint32_t((two >> (bit & 31)) & ((uint64_t(1) << k) - 1));
}

// Where a stream's parts are while its blocks are decoded.
struct StreamParts {
    const uint8_t* low;      // the current full block's low bits
    BitReader partial;       // the partial block's low bits
    BitReader exceptions;    // escaped values' excess quotients
};

// Decodes the count values of a block one at a time, their quotients at `quotients`: the partial block, blocks with escapes
// and builds without SSE2. Running sums continue from `running`.
const char* get_block_scalar(StreamParts& s, const uint8_t* quotients, size_t count, uint32_t k, bool full,
                             uint32_t& running, uint32_t* sums) {
    for (size_t i = 0; i < count; ++i) {
        const uint32_t low = full ? vertical_field(s.low, i, k) : s.partial.get(k);
        const uint32_t q = quotients[i];
        uint32_t v;
        uint64_t escaped;
        if (q < kRiceEscape) v = (q << k) | low;
        else if (q == kRiceEscape && s.exceptions.escape_quotient(escaped)) v = uint32_t(escaped << k) | low;
        else return q == kRiceEscape ? "bad escape" : "unary run too long";
        running += uint32_t(unzigzag(v));
        sums[i] = running;
    }
    return nullptr;
}

#ifdef __SSE2__
// Bit i of mask set where the quotient q[i] (i < kRiceBlock) is kRiceEscape; false if some
// quotient is above it (a run of zeros too long).
inline bool escape_mask(const uint8_t* q, uint64_t mask[2]) {
    const __m128i below = _mm_set1_epi8(char(kRiceEscape - 1)), escape = _mm_set1_epi8(char(kRiceEscape));
    __m128i top = _mm_setzero_si128();
    for (int half = 0; half < 2; ++half) {
        uint64_t bits = 0;
        for (int c = 0; c < 4; ++c) {
            const __m128i q16 = _mm_loadu_si128(reinterpret_cast<const __m128i*>(q + 64 * half + 16 * c));
            const uint32_t plain = uint32_t(_mm_movemask_epi8(_mm_cmpeq_epi8(_mm_max_epu8(q16, below), below)));
            bits |= uint64_t(~plain & 0xffff) << (16 * c);
            top = _mm_max_epu8(top, q16);
        }
        mask[half] = bits;
    }
    return _mm_movemask_epi8(_mm_cmpeq_epi8(_mm_max_epu8(top, escape), escape)) == 0xffff;
}

// The escaped values of a block (mask from escape_mask): each one's excess quotient, shifted by
// k, into extra[i], which a block kernel adds to the value it decodes ((8 + e) << k | low is
// (8 << k | low) + (e << k) modulo 2^32). False on a bad excess code. Done ahead of the block
// (measured: patching escapes inside the kernel, through memory and a call, made the compiler
// rebuild the kernel's constants at every step, and half the blocks hold an escape).
inline bool take_escapes(BitReader& exceptions, const uint64_t mask[2], uint32_t k, uint32_t* extra) {
    bool ok = true;
    for (int half = 0; half < 2; ++half)
        for (uint64_t bits = mask[half]; bits; bits &= bits - 1) {
            uint64_t q = 0;
            ok &= exceptions.escape_quotient(q);
            extra[64 * half + uint32_t(__builtin_ctzll(bits))] = uint32_t((q - kRiceEscape) << k);
        }
    return ok;
}
// Zeroes what take_escapes wrote.
inline void clear_escapes(const uint64_t mask[2], uint32_t* extra) {
    for (int half = 0; half < 2; ++half)
        for (uint64_t bits = mask[half]; bits; bits &= bits - 1) extra[64 * half + uint32_t(__builtin_ctzll(bits))] = 0;
}

// Unzigzag of four values, their running sums continuing from carry (all four lanes hold the
// previous sum), stored at `sums`; carry becomes the last sum. The carry chain is one add per
// step: the group's own total is broadcast before the carry joins.
__attribute__((always_inline)) inline void store_running_sums(__m128i v, __m128i& carry, uint32_t* sums) {
    __m128i d = _mm_xor_si128(_mm_srli_epi32(v, 1), _mm_srai_epi32(_mm_slli_epi32(v, 31), 31));
    d = _mm_add_epi32(d, _mm_slli_si128(d, 4));
    d = _mm_add_epi32(d, _mm_slli_si128(d, 8));
    _mm_storeu_si128(reinterpret_cast<__m128i*>(sums), _mm_add_epi32(d, carry));
    carry = _mm_add_epi32(carry, _mm_shuffle_epi32(d, 0xff));
}

// The four quotients at q as 32-bit lanes.
__attribute__((always_inline)) inline __m128i load_quotients(const uint8_t* q) {
    int32_t q4;
    std::memcpy(&q4, q, 4);
    const __m128i zero = _mm_setzero_si128();
    return _mm_unpacklo_epi16(_mm_unpacklo_epi8(_mm_cvtsi32_si128(q4), zero), zero);
}

// Decodes a full block four values per step: the vertical layout puts values 4m .. 4m + 3 at
// the same bit offset of the four word lanes, so one shift pair extracts their low bits; then
// the quotient, the escapes' excess (take_escapes), unzigzag and the running sum (a prefix sum
// in the register). Quotients are checked beforehand (escape_mask).
//
// K is the block's Rice parameter as a constant, the 32 steps unrolled: every shift and offset
// is then an immediate (measured: the generic loop spent half its instructions computing
// them). The parameters measured on scans are 0-6; larger ones take the generic loop (K = -1).
template <int K>
void get_block_sse2(const uint8_t* low, const uint8_t* q, const uint32_t* extra, uint32_t k_runtime, uint32_t& running,
                    uint32_t* sums) {
    const uint32_t k = K >= 0 ? uint32_t(K) : k_runtime;
    const __m128i mask = _mm_set1_epi32(int32_t((uint64_t(1) << k) - 1));
    const __m128i k_count = _mm_cvtsi32_si128(int(k));
    __m128i carry = _mm_set1_epi32(int32_t(running));
    auto step = [&](uint32_t m) __attribute__((always_inline)) {
        const uint32_t bit = m * k, j = bit >> 5, shift = bit & 31;
        __m128i field = _mm_setzero_si128();
        if (k > 0) {
            field = _mm_srl_epi32(_mm_loadu_si128(reinterpret_cast<const __m128i*>(low + 16 * j)), _mm_cvtsi32_si128(int(shift)));
            // A shift by 32 gives zero: the second word adds nothing when the field is in the first.
            if (K < 0 || shift + k > 32)
                field = _mm_or_si128(field, _mm_sll_epi32(_mm_loadu_si128(reinterpret_cast<const __m128i*>(low + 16 * j + 16)),
                                                          _mm_cvtsi32_si128(int(32 - shift))));
            field = _mm_and_si128(field, mask);
        }
        __m128i v = _mm_or_si128(_mm_sll_epi32(load_quotients(q + 4 * m), k_count), field);
        v = _mm_add_epi32(v, _mm_loadu_si128(reinterpret_cast<const __m128i*>(extra + 4 * m)));
        store_running_sums(v, carry, sums + 4 * m);
    };
    if constexpr (K >= 0) {
        [&]<uint32_t... M>(std::integer_sequence<uint32_t, M...>) __attribute__((always_inline)) {
            (step(M), ...);
        }(std::make_integer_sequence<uint32_t, kRiceBlock / 4>{});
    } else {
        for (uint32_t m = 0; m < kRiceBlock / 4; ++m) step(m);
    }
    running = uint32_t(_mm_cvtsi128_si32(carry));
}

#if CATPAQ_POINTS_AVX2
#pragma GCC push_options
#pragma GCC target("avx2")
// get_block_sse2 eight values per step, for CPUs with AVX2 (chosen at run time: the build
// targets baseline x86-64). Steps m and m + 1 of the four-lane layout share one 256-bit
// register, each half shifted by its own offset (variable shifts); the running sum spans the
// two halves. Measured: the SSE2 block loop was half the decoder's instructions.
template <int K>
void get_block_avx2(const uint8_t* low, const uint8_t* q, const uint32_t* extra, uint32_t& running, uint32_t* sums) {
    constexpr uint32_t k = uint32_t(K);
    const __m256i mask = _mm256_set1_epi32(int32_t((uint64_t(1) << k) - 1));
    const __m256i last = _mm256_set1_epi32(7);
    __m256i carry = _mm256_set1_epi32(int32_t(running));
    // 16 bytes of lane words at word row j0 (low half) and j1 (high half).
    auto rows = [&](uint32_t j0, uint32_t j1) __attribute__((always_inline)) {
        const __m128i* at = reinterpret_cast<const __m128i*>(low);
        if (j1 == j0) return _mm256_broadcastsi128_si256(_mm_loadu_si128(at + j0));
        if (j1 == j0 + 1) return _mm256_loadu_si256(reinterpret_cast<const __m256i*>(at + j0));
        return _mm256_inserti128_si256(_mm256_castsi128_si256(_mm_loadu_si128(at + j0)), _mm_loadu_si128(at + j1), 1);
    };
    auto step = [&](uint32_t m) __attribute__((always_inline)) {  // values 4m .. 4m + 7
        __m256i field = _mm256_setzero_si256();
        if (k > 0) {
            const uint32_t bit0 = m * k, bit1 = bit0 + k;
            const uint32_t j0 = bit0 >> 5, j1 = bit1 >> 5, s0 = bit0 & 31, s1 = bit1 & 31;
            field = _mm256_srlv_epi32(rows(j0, j1), _mm256_setr_epi32(s0, s0, s0, s0, s1, s1, s1, s1));
            // Counts of 32 give zero: the next word adds nothing where the field is in the first.
            if (s0 + k > 32 || s1 + k > 32)
                field = _mm256_or_si256(field, _mm256_sllv_epi32(rows(j0 + 1, j1 + 1),
                                                                 _mm256_setr_epi32(32 - s0, 32 - s0, 32 - s0, 32 - s0,
                                                                                   32 - s1, 32 - s1, 32 - s1, 32 - s1)));
            field = _mm256_and_si256(field, mask);
        }
        const __m256i quotient = _mm256_cvtepu8_epi32(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(q + 4 * m)));
        __m256i v = _mm256_or_si256(_mm256_slli_epi32(quotient, int(k)), field);
        v = _mm256_add_epi32(v, _mm256_loadu_si256(reinterpret_cast<const __m256i*>(extra + 4 * m)));
        __m256i d = _mm256_xor_si256(_mm256_srli_epi32(v, 1), _mm256_srai_epi32(_mm256_slli_epi32(v, 31), 31));
        d = _mm256_add_epi32(d, _mm256_slli_si256(d, 4));  // prefix sums within each half
        d = _mm256_add_epi32(d, _mm256_slli_si256(d, 8));
        // The low half's total into the high half.
        d = _mm256_add_epi32(d, _mm256_permute2x128_si256(_mm256_shuffle_epi32(d, 0xff), _mm256_shuffle_epi32(d, 0xff), 0x08));
        _mm256_storeu_si256(reinterpret_cast<__m256i*>(sums + 4 * m), _mm256_add_epi32(d, carry));
        carry = _mm256_add_epi32(carry, _mm256_permutevar8x32_epi32(d, last));
    };
    [&]<uint32_t... M>(std::integer_sequence<uint32_t, M...>) __attribute__((always_inline)) {
        (step(2 * M), ...);
    }(std::make_integer_sequence<uint32_t, kRiceBlock / 8>{});
    running = uint32_t(_mm_cvtsi128_si32(_mm256_castsi256_si128(carry)));
}
#pragma GCC pop_options

// Whether the AVX2 kernels run: the CPU (and OS) has AVX2 and no test switched them off.
// __builtin_cpu_init first: this runs among the static constructors.
bool g_use_avx2 = (__builtin_cpu_init(), __builtin_cpu_supports("avx2"));
#endif

// get_block_sse2 (or get_block_avx2) for the block's parameter k.
void get_block_any_k(const uint8_t* low, const uint8_t* q, const uint32_t* extra, uint32_t k, uint32_t& running,
                     uint32_t* sums) {
#if CATPAQ_POINTS_AVX2
    if (g_use_avx2) {
        switch (k) {
            case 0: return get_block_avx2<0>(low, q, extra, running, sums);
            case 1: return get_block_avx2<1>(low, q, extra, running, sums);
            case 2: return get_block_avx2<2>(low, q, extra, running, sums);
            case 3: return get_block_avx2<3>(low, q, extra, running, sums);
            case 4: return get_block_avx2<4>(low, q, extra, running, sums);
            case 5: return get_block_avx2<5>(low, q, extra, running, sums);
            case 6: return get_block_avx2<6>(low, q, extra, running, sums);
            case 7: return get_block_avx2<7>(low, q, extra, running, sums);
            default: break;
        }
    }
#endif
    switch (k) {
        case 0: return get_block_sse2<0>(low, q, extra, k, running, sums);
        case 1: return get_block_sse2<1>(low, q, extra, k, running, sums);
        case 2: return get_block_sse2<2>(low, q, extra, k, running, sums);
        case 3: return get_block_sse2<3>(low, q, extra, k, running, sums);
        case 4: return get_block_sse2<4>(low, q, extra, k, running, sums);
        case 5: return get_block_sse2<5>(low, q, extra, k, running, sums);
        case 6: return get_block_sse2<6>(low, q, extra, k, running, sums);
        case 7: return get_block_sse2<7>(low, q, extra, k, running, sums);
        default: return get_block_sse2<-1>(low, q, extra, k, running, sums);
    }
}
#endif

// Positions from the three axes' running sums: p[3i + a] = origin[a] + float(q mod 2^24) * step,
// the float operations of grid_position (no fused multiply-add), four points per step with the
// axes transposed into x y z order in registers. GCC vectorized this loop only partly: it was a
// fifth of the decoder's time.
void positions_from_sums(const uint32_t* const sums[3], size_t n, const float origin[3], float step, float* p) {
    const uint32_t grid_mask = (1u << kMaxGridBits) - 1;
    size_t i = 0;
#ifdef __SSE2__
    const __m128i mask = _mm_set1_epi32(int32_t(grid_mask));
    const __m128 step4 = _mm_set1_ps(step);
    __m128 o[3];
    for (int a = 0; a < 3; ++a) o[a] = _mm_set1_ps(origin[a]);
    for (; i + 4 <= n; i += 4) {
        __m128 c[3];
        for (int a = 0; a < 3; ++a) {
            const __m128i q = _mm_and_si128(_mm_loadu_si128(reinterpret_cast<const __m128i*>(sums[a] + i)), mask);
            c[a] = _mm_add_ps(o[a], _mm_mul_ps(_mm_cvtepi32_ps(q), step4));
        }
        const __m128 xy_lo = _mm_unpacklo_ps(c[0], c[1]), xy_hi = _mm_unpackhi_ps(c[0], c[1]);
        const __m128 yz_lo = _mm_unpacklo_ps(c[1], c[2]), yz_hi = _mm_unpackhi_ps(c[1], c[2]);
        const __m128 zx_lo = _mm_unpacklo_ps(c[2], c[0]), zx_hi = _mm_unpackhi_ps(c[2], c[0]);
        _mm_storeu_ps(p + 3 * i, _mm_shuffle_ps(xy_lo, zx_lo, _MM_SHUFFLE(3, 0, 1, 0)));      // x0 y0 z0 x1
        _mm_storeu_ps(p + 3 * i + 4, _mm_shuffle_ps(yz_lo, xy_hi, _MM_SHUFFLE(1, 0, 3, 2)));  // y1 z1 x2 y2
        _mm_storeu_ps(p + 3 * i + 8, _mm_shuffle_ps(zx_hi, yz_hi, _MM_SHUFFLE(3, 2, 3, 0)));  // z2 x3 y3 z3
    }
#endif
    for (; i < n; ++i)
        for (int a = 0; a < 3; ++a) p[3 * i + a] = grid_position(origin[a], step, sums[a][i] & grid_mask);
}

#if CATPAQ_POINTS_AVX2
#pragma GCC push_options
#pragma GCC target("avx2")
// positions_from_sums eight points per step: the same in-lane shuffles put points 0-3 and 4-7
// in x y z order in the two 128-bit halves, and three cross-half permutes join them for three
// 32-byte stores (measured: the baseline loop was a third of the conversions' time).
void positions_from_sums_avx2(const uint32_t* const sums[3], size_t n, const float origin[3], float step, float* p) {
    const uint32_t grid_mask = (1u << kMaxGridBits) - 1;
    const __m256i mask = _mm256_set1_epi32(int32_t(grid_mask));
    const __m256 step8 = _mm256_set1_ps(step);
    __m256 o[3];
    for (int a = 0; a < 3; ++a) o[a] = _mm256_set1_ps(origin[a]);
    size_t i = 0;
    for (; i + 8 <= n; i += 8) {
        __m256 c[3];
        for (int a = 0; a < 3; ++a) {
            const __m256i q = _mm256_and_si256(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(sums[a] + i)), mask);
            c[a] = _mm256_add_ps(o[a], _mm256_mul_ps(_mm256_cvtepi32_ps(q), step8));
        }
        const __m256 xy_lo = _mm256_unpacklo_ps(c[0], c[1]), xy_hi = _mm256_unpackhi_ps(c[0], c[1]);
        const __m256 yz_lo = _mm256_unpacklo_ps(c[1], c[2]), yz_hi = _mm256_unpackhi_ps(c[1], c[2]);
        const __m256 zx_lo = _mm256_unpacklo_ps(c[2], c[0]), zx_hi = _mm256_unpackhi_ps(c[2], c[0]);
        const __m256 r0 = _mm256_shuffle_ps(xy_lo, zx_lo, _MM_SHUFFLE(3, 0, 1, 0));  // x0 y0 z0 x1 | x4 y4 z4 x5
        const __m256 r1 = _mm256_shuffle_ps(yz_lo, xy_hi, _MM_SHUFFLE(1, 0, 3, 2));  // y1 z1 x2 y2 | y5 z5 x6 y6
        const __m256 r2 = _mm256_shuffle_ps(zx_hi, yz_hi, _MM_SHUFFLE(3, 2, 3, 0));  // z2 x3 y3 z3 | z6 x7 y7 z7
        _mm256_storeu_ps(p + 3 * i, _mm256_permute2f128_ps(r0, r1, 0x20));
        _mm256_storeu_ps(p + 3 * i + 8, _mm256_permute2f128_ps(r2, r0, 0x30));
        _mm256_storeu_ps(p + 3 * i + 16, _mm256_permute2f128_ps(r1, r2, 0x31));
    }
    const uint32_t* const rest[3] = {sums[0] + i, sums[1] + i, sums[2] + i};
    positions_from_sums(rest, n - i, origin, step, p + 3 * i);
}
#pragma GCC pop_options
#endif

// Octahedral codes from the running sums of u and v (modulo 256 each).
inline void normals_from_sums(const uint32_t* u, const uint32_t* v, size_t n, uint16_t* normals) {
    for (size_t i = 0; i < n; ++i) normals[i] = uint16_t((u[i] & 0xff) | (v[i] & 0xff) << 8);
}
// Radii from the running sums of their grid indices (radius_value, the decoder's float operations).
inline void radii_from_sums(const uint32_t* r, size_t n, float base, float step, float pad, float* radii) {
    for (size_t i = 0; i < n; ++i) radii[i] = radius_value(base, step, pad, r[i] & ((1u << 30) - 1));
}

#if CATPAQ_POINTS_AVX2
#pragma GCC push_options
#pragma GCC target("avx2")
// The same loops, which GCC vectorizes eight values per step for AVX2 (measured: 2% of the
// decoder's time saved, alternated runs).
void normals_from_sums_avx2(const uint32_t* u, const uint32_t* v, size_t n, uint16_t* normals) {
    normals_from_sums(u, v, n, normals);
}
void radii_from_sums_avx2(const uint32_t* r, size_t n, float base, float step, float pad, float* radii) {
    radii_from_sums(r, n, base, step, pad, radii);
}
#pragma GCC pop_options
#endif

// RGB from the running sums of quantized Y, Co, Cg (dequantize_color), eight points per step in
// 16-bit lanes (every intermediate fits: |Co|, |Cg| <= 255, Y <= 255), the clamp to 0..255 by
// the saturating pack. GCC left the scalar loop unvectorized (byte stores three apart): it was
// a tenth of the decoder's time.
void colors_from_sums(const uint32_t* const sums[3], size_t n, int luma_shift, int chroma_shift, uint8_t* rgb) {
    size_t i = 0;
#ifdef __SSE2__
    const __m128i luma_mask = _mm_set1_epi32(0x1ff), chroma_mask = _mm_set1_epi32(0x3ff);
    const __m128i luma_count = _mm_cvtsi32_si128(luma_shift), chroma_count = _mm_cvtsi32_si128(chroma_shift);
    const __m128i top_y = _mm_set1_epi16(255), top_c = _mm_set1_epi16(510), zero = _mm_setzero_si128();
    // min(c << s, top) = min(min(c, (top >> s) + 1) << s, top), without overflowing 16 bits.
    const __m128i cap_y = _mm_set1_epi16(int16_t((255 >> luma_shift) + 1));
    const __m128i cap_c = _mm_set1_epi16(int16_t((510 >> chroma_shift) + 1));
    auto load8 = [&](const uint32_t* at, __m128i component_mask, __m128i cap) {
        const __m128i lo = _mm_and_si128(_mm_loadu_si128(reinterpret_cast<const __m128i*>(at)), component_mask);
        const __m128i hi = _mm_and_si128(_mm_loadu_si128(reinterpret_cast<const __m128i*>(at + 4)), component_mask);
        return _mm_min_epi16(_mm_packs_epi32(lo, hi), cap);  // < 2^10: no saturation
    };
    // The last point is left to the scalar loop: each point's 4-byte store writes one byte past it.
    for (; i + 9 <= n; i += 8) {
        const __m128i y = _mm_min_epi16(_mm_sll_epi16(load8(sums[0] + i, luma_mask, cap_y), luma_count), top_y);
        const __m128i co = _mm_sub_epi16(_mm_min_epi16(_mm_sll_epi16(load8(sums[1] + i, chroma_mask, cap_c), chroma_count), top_c), top_y);
        const __m128i cg = _mm_sub_epi16(_mm_min_epi16(_mm_sll_epi16(load8(sums[2] + i, chroma_mask, cap_c), chroma_count), top_c), top_y);
        const __m128i t = _mm_sub_epi16(y, _mm_srai_epi16(cg, 1));
        const __m128i g = _mm_add_epi16(cg, t);
        const __m128i b = _mm_sub_epi16(t, _mm_srai_epi16(co, 1));
        const __m128i r = _mm_add_epi16(b, co);
        const __m128i r8 = _mm_packus_epi16(r, zero), g8 = _mm_packus_epi16(g, zero), b8 = _mm_packus_epi16(b, zero);
        const __m128i rg = _mm_unpacklo_epi8(r8, g8), b0 = _mm_unpacklo_epi8(b8, zero);
        alignas(16) uint32_t packed[8];
        _mm_store_si128(reinterpret_cast<__m128i*>(packed), _mm_unpacklo_epi16(rg, b0));
        _mm_store_si128(reinterpret_cast<__m128i*>(packed + 4), _mm_unpackhi_epi16(rg, b0));
        for (int k = 0; k < 8; ++k) std::memcpy(rgb + 3 * (i + size_t(k)), &packed[k], 4);
    }
#endif
    for (; i < n; ++i)
        dequantize_color(sums[0][i] & 0x1ff, sums[1][i] & 0x3ff, sums[2][i] & 0x3ff, luma_shift, chroma_shift, &rgb[3 * i]);
}

// The work space get_stream needs for n values: the quotients (n + 64 bytes), the blocks'
// parameters (a byte each, then 16 spare) and the one bits' positions (n + 64).
size_t stream_work_bytes(size_t n) { return 2 * (n + 64) + (n + kRiceBlock - 1) / kRiceBlock + 16; }

// The running sums of a block of zeros: count copies of running. Sixteen bytes per store and
// four stores per step for a full block (measured: GCC's loop of one store per step took 2% of
// the decoder's time on points_bench's scan, whose chroma is blocks of zeros).
inline void fill_sums(uint32_t* sums, size_t count, uint32_t running) {
    size_t i = 0;
#ifdef __SSE2__
    const __m128i v = _mm_set1_epi32(int32_t(running));
    for (; i + 16 <= count; i += 16)
        for (size_t j = 0; j < 16; j += 4) _mm_storeu_si128(reinterpret_cast<__m128i*>(sums + i + j), v);
#endif
    for (; i < count; ++i) sums[i] = running;
}

// A block parameter's mark for a block of zeros (version 3 on), among the Rice parameters.
constexpr uint8_t kZeroBlock = 0xff;

// Decodes one stream of n values from [cursor, end) (the node's streams; kRicePadding readable
// bytes follow end) into sums[i], the running sum (mod 2^32) of the unzigzagged values 0..i.
// zero_blocks: version 3 on (parameter 0 marks a block of zeros, else k + 1). work:
// stream_work_bytes(n) bytes (the quotients, the blocks' parameters and the one bits'
// positions, each with slack); extra: kRiceBlock zeros, for take_escapes, left zero. Advances
// cursor past the stream.
const char* get_stream(const uint8_t*& cursor, const uint8_t* end, size_t n, bool zero_blocks, uint8_t* work,
                       uint32_t* extra, uint32_t* sums) {
    const size_t blocks = (n + kRiceBlock - 1) / kRiceBlock;
    // Block parameters: checked here, kept as bytes (k, or kZeroBlock) after the quotients.
    uint8_t* ks = work + n + 64;
    BitReader parameters{cursor, end};
    uint32_t parameter = 0;
    size_t full_low_bytes = 0, coded = 0;  // coded: values outside zero blocks
    for (size_t b = 0; b < blocks; ++b) {
        if (b == 0 || parameters.get(1) == 1) {
            if (b == 0) parameter = parameters.get(5);
            else if (parameters.get(1) == 0) parameter = parameters.get(1) ? parameter + 1 : parameter - 1;
            else parameter = parameters.get(5);
        }
        if (parameter > kRiceMaxK) return "bad Rice parameter";
        const size_t values = std::min(n, (b + 1) * kRiceBlock) - b * kRiceBlock;
        if (zero_blocks && parameter == 0) {
            ks[b] = kZeroBlock;
            continue;
        }
        const uint32_t k = zero_blocks ? parameter - 1 : parameter;
        ks[b] = uint8_t(k);
        coded += values;
        if (values == kRiceBlock) full_low_bytes += 16 * size_t(k);
    }
    if (parameters.overrun()) return "truncated stream";
    cursor += parameters.bytes();
    uint8_t* const q = work;
    uint8_t* ones = ks + blocks + 16;
    if (const char* why = get_unary(cursor, end, coded, ones, q)) return why;
    const size_t rest = n % kRiceBlock;
    const size_t partial_bytes = rest && ks[blocks - 1] != kZeroBlock ? (rest * ks[blocks - 1] + 7) / 8 : 0;
    if (full_low_bytes + partial_bytes > size_t(end - cursor)) return "truncated stream";
    StreamParts s{cursor, {cursor + full_low_bytes, cursor + full_low_bytes + partial_bytes},
                  {cursor + full_low_bytes + partial_bytes, end}};
    uint32_t running = 0;
    const uint8_t* qb = q;  // the next coded block's quotients
    for (size_t b = 0; b < blocks; ++b) {
        const size_t first = b * kRiceBlock, count = std::min(n, first + kRiceBlock) - first;
        const uint32_t kb = ks[b];
        if (kb == kZeroBlock) {
            fill_sums(sums + first, count, running);
            continue;
        }
        const bool full = count == kRiceBlock;
        const char* why = nullptr;
#ifdef __SSE2__
        if (full) {
            uint64_t escapes[2];
            if (!escape_mask(qb, escapes)) return "unary run too long";
            const bool escaped = (escapes[0] | escapes[1]) != 0;
            if (escaped && !take_escapes(s.exceptions, escapes, kb, extra)) return "bad escape";
            get_block_any_k(s.low, qb, extra, kb, running, sums + first);
            if (escaped) clear_escapes(escapes, extra);
        } else {
            why = get_block_scalar(s, qb, count, kb, full, running, sums + first);
        }
#else
        (void)extra;
        why = get_block_scalar(s, qb, count, kb, full, running, sums + first);
#endif
        if (why) return why;
        if (full) s.low += 16 * size_t(kb);
        qb += count;
    }
    if (s.exceptions.overrun()) return "truncated exceptions";
    cursor = s.exceptions.begin + s.exceptions.bytes();
    return nullptr;
}

}  // namespace

bool use_point_decoder_avx2(bool enable) {
#if CATPAQ_POINTS_AVX2
    g_use_avx2 = enable && __builtin_cpu_supports("avx2");
    return g_use_avx2;
#else
    (void)enable;
    return false;
#endif
}

std::string peek_point_node(const uint8_t* data, size_t size, size_t& count, uint8_t& flags) {
    if (size < kHeaderSize + kChecksumSize) return "node too short";
    if (std::memcmp(data, kPointNodeMagic, 4) != 0) return "not a point node (bad magic)";
    if (data[4] < kPointNodeOldestVersion || data[4] > kPointNodeVersion)
        return strprintf("unsupported point node version %u (this build reads %u to %u)", data[4], kPointNodeOldestVersion,
                         kPointNodeVersion);
    flags = data[5];
    if (flags & ~(kPointHasNormals | kPointHasColors)) return "unknown point node flags";
    ByteReader r(data + 8, 4);
    count = r.u32();
    if (count == 0 || count >= kMaxPoints) return "bad point count";
    return "";
}

std::string decode_point_node(const uint8_t* data, size_t size, DecodedPoints& out) {
    size_t n = 0;
    uint8_t flags = 0;
    std::string problem = peek_point_node(data, size, n, flags);
    if (!problem.empty()) return problem;
    ByteReader trailer(data + size - kChecksumSize, kChecksumSize);
    if (trailer.u64() != checksum64(data, size - kChecksumSize)) return "point node checksum mismatch (corrupt data)";
    ByteReader h(data + 6, kHeaderSize - 6);
    const int luma_bits = h.u8(), chroma_bits = h.u8();
    h.u32();
    float origin[3];
    for (float& o : origin) o = h.f32();
    const float step = h.f32(), radius_base = h.f32(), radius_step = h.f32(), pad = h.f32();
    if (luma_bits < 1 || luma_bits > 8 || chroma_bits < 1 || chroma_bits > 9) return "bad colour precision";
    for (float v : {origin[0], origin[1], origin[2], step, radius_base, radius_step, pad})
        if (!std::isfinite(v)) return "non-finite header value";
    if (!(step > 0) || !(radius_step > 0) || !(pad >= 0) || !(radius_base >= 0)) return "bad quantization header";

    const bool has_normals = flags & kPointHasNormals, has_colors = flags & kPointHasColors;
    const size_t streams = 3 + (has_normals ? 2 : 0) + (has_colors ? 3 : 0) + 1;
    // Every value takes at least one bit (version 2), every block at least its parameter bit
    // (version 3 on, where a block of zeros has no other bits): a count the bytes cannot hold is
    // refused before anything is allocated for it.
    const bool zero_blocks = data[4] >= 3;
    const size_t body = size - kChecksumSize - kHeaderSize;
    const size_t least_bits = zero_blocks ? (n + kRiceBlock - 1) / kRiceBlock : n;
    if (streams * least_bits > 8 * body) return "point count too large for the node size";

    // A padded copy of the streams, so that the block decoders may load 16 bytes anywhere in
    // them; after it, get_stream's work space (stream_work_bytes), the escapes' array and three arrays of
    // running sums (the attributes decoded together: a position's axes, a colour's components).
    std::vector<uint32_t>& scratch = out.scratch;
    const size_t padded_words = (body + kRicePadding + 3) / 4;
    const size_t work_words = (stream_work_bytes(n) + 3) / 4;
    scratch.resize(padded_words + work_words + kRiceBlock + 3 * n);
    uint8_t* copy = reinterpret_cast<uint8_t*>(scratch.data());
    std::memcpy(copy, data + kHeaderSize, body);
    std::memset(copy + body, 0, padded_words * 4 - body);
    uint8_t* work = reinterpret_cast<uint8_t*>(scratch.data() + padded_words);
    uint32_t* const extra = scratch.data() + padded_words + work_words;
    std::memset(extra, 0, kRiceBlock * sizeof(uint32_t));
    uint32_t* const sums0 = extra + kRiceBlock;
    uint32_t* const sums[3] = {sums0, sums0 + n, sums0 + 2 * n};
    const uint8_t* cursor = copy;
    const uint8_t* end = copy + body;
    auto failed = [](const char* why) { return std::string("point node: ") + why; };

    out.count = n;
    out.flags = flags;
    out.position_error = pad;
    out.grid_step = step;
    out.positions.resize(3 * n);
    for (int a = 0; a < 3; ++a)
        if (const char* why = get_stream(cursor, end, n, zero_blocks, work, extra, sums[a])) return failed(why);
#if CATPAQ_POINTS_AVX2
    if (g_use_avx2) positions_from_sums_avx2(sums, n, origin, step, out.positions.data());
    else
#endif
        positions_from_sums(sums, n, origin, step, out.positions.data());
    if (has_normals) {
        for (int c = 0; c < 2; ++c)
            if (const char* why = get_stream(cursor, end, n, zero_blocks, work, extra, sums[c])) return failed(why);
        out.normals.resize(n);
        uint16_t* normals = out.normals.data();
        const uint32_t *u = sums[0], *v = sums[1];
#if CATPAQ_POINTS_AVX2
        if (g_use_avx2) normals_from_sums_avx2(u, v, n, normals);
        else
#endif
            normals_from_sums(u, v, n, normals);
    } else {
        out.normals.clear();
    }
    if (has_colors) {
        for (int c = 0; c < 3; ++c)
            if (const char* why = get_stream(cursor, end, n, zero_blocks, work, extra, sums[c])) return failed(why);
        out.colors.resize(3 * n);
        colors_from_sums(sums, n, 8 - luma_bits, 9 - chroma_bits, out.colors.data());
    } else {
        out.colors.clear();
    }
    if (const char* why = get_stream(cursor, end, n, zero_blocks, work, extra, sums[0])) return failed(why);
    out.radii.resize(n);
    float* radii = out.radii.data();
    const uint32_t* r = sums[0];
#if CATPAQ_POINTS_AVX2
    if (g_use_avx2) radii_from_sums_avx2(r, n, radius_base, radius_step, pad, radii);
    else
#endif
        radii_from_sums(r, n, radius_base, radius_step, pad, radii);
    if (cursor != end) return "point node: bytes left after the last stream";
    return "";
}

}  // namespace catpaq
