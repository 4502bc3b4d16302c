// The node codec (points/codec.h): quantization, Morton order, delta + zigzag residuals, and
// block-adaptive Rice codes on four lanes (rice.h). Byte layout: docs/formats/points.md.
#include "points/codec.h"

#include <algorithm>
#include <array>
#include <cassert>
#include <cmath>
#include <cstring>

#include "base/bytes.h"
#include "base/checksum.h"
#include "base/error.h"
#include "common_codec/octahedral.h"
#include "rice.h"

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

// Chooses the block's Rice parameter: the cheapest k among those near log2 of the mean.
uint32_t choose_k(const uint32_t* values, size_t n, uint32_t escape_bits) {
    uint64_t sum = 0;
    for (size_t i = 0; i < n; ++i) sum += values[i];
    uint32_t guess = n ? bit_width32(uint32_t(std::min<uint64_t>(sum / n, UINT32_MAX))) : 0;
    uint32_t lo = guess > 2 ? guess - 2 : 0, hi = std::min(std::min(guess + 1, escape_bits), kRiceMaxK);
    uint32_t best_k = lo;
    uint64_t best = UINT64_MAX;
    for (uint32_t k = lo; k <= std::max(lo, hi); ++k) {
        uint64_t cost = 0;
        for (size_t i = 0; i < n; ++i) cost += rice_cost(values[i], k, escape_bits);
        if (cost < best) best = cost, best_k = k;
    }
    return best_k;
}

// Writes one stream: escape width, the blocks' k (5 bits each), four lane sizes, the lanes.
void put_stream(ByteWriter& out, const std::vector<uint32_t>& values, BitWriter lanes[kRiceLanes]) {
    const size_t n = values.size();
    uint32_t largest = 0;
    for (uint32_t v : values) largest = std::max(largest, v);
    const uint32_t escape_bits = bit_width32(largest);
    out.u8(uint8_t(escape_bits));
    const size_t blocks = (n + kRiceBlock - 1) / kRiceBlock;
    BitWriter ks;
    for (int l = 0; l < kRiceLanes; ++l) lanes[l].clear();
    for (size_t b = 0; b < blocks; ++b) {
        size_t first = b * kRiceBlock, end = std::min(n, first + kRiceBlock);
        uint32_t k = choose_k(values.data() + first, end - first, escape_bits);
        ks.put(k, 5);
        for (size_t i = first; i < end; ++i) rice_put(lanes[i % kRiceLanes], values[i], k, escape_bits);
    }
    std::vector<uint8_t>& k_bytes = ks.finish();
    out.raw(k_bytes.data(), k_bytes.size());
    for (int l = 0; l < kRiceLanes; ++l) out.varint(lanes[l].finish().size());
    for (int l = 0; l < kRiceLanes; ++l) {
        std::vector<uint8_t>& bytes = lanes[l].finish();
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

// Grid coordinates of every point (3 per point).
std::vector<uint32_t> quantize_positions(const PointSamplesView& points, const Grid& grid) {
    std::vector<uint32_t> q(3 * points.count);
    for (size_t i = 0; i < points.count; ++i)
        for (int a = 0; a < 3; ++a) {
            double t = std::nearbyint((points.positions[3 * i + a] - double(grid.origin[a])) / double(grid.step));
            q[3 * i + a] = uint32_t(std::clamp(t, 0.0, double((1u << kMaxGridBits) - 1)));
        }
    return q;
}

// The points' order along the Morton curve of their cells (the coarsest 21 bits per axis).
void morton_order(const std::vector<uint32_t>& q, std::vector<uint32_t>& order) {
    const size_t n = q.size() / 3;
    uint32_t largest = 0;
    for (uint32_t v : q) largest = std::max(largest, v);
    const uint32_t shift = bit_width32(largest) > kMortonBits ? bit_width32(largest) - kMortonBits : 0;
    std::vector<std::pair<uint64_t, uint32_t>> keys(n);
    for (size_t i = 0; i < n; ++i) {
        uint64_t key = spread_bits21(q[3 * i] >> shift) | spread_bits21(q[3 * i + 1] >> shift) << 1 |
                       spread_bits21(q[3 * i + 2] >> shift) << 2;
        keys[i] = {key, uint32_t(i)};
    }
    std::sort(keys.begin(), keys.end());
    order.resize(n);
    for (size_t i = 0; i < n; ++i) order[i] = keys[i].second;
}

// Appends the zigzagged deltas of values[order[i] * stride + offset] as one stream.
struct StreamWriter {
    ByteWriter& out;
    const std::vector<uint32_t>& order;
    std::vector<uint32_t> residuals;
    BitWriter lanes[kRiceLanes];

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
        put_stream(out, residuals, lanes);
        return out.size() - before;
    }
};

// The quantized Y, Co, Cg of an RGB colour: chroma to the nearest step, then the luma (of the
// nearest and its neighbours) that best restores RGB given that chroma.
std::array<uint32_t, 3> quantize_color(const uint8_t* rgb, int luma_shift, int chroma_shift) {
    Ycocg c = to_ycocg(rgb[0], rgb[1], rgb[2]);
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

// Decodes the node in `out` (its checksum and pad not yet set), measures every point's
// position error against the input, then sets the pad so that every decoded splat covers its
// input splat grown by that error, and seals the node with its checksum. `decoded` receives
// the final decode.
void seal_node(ByteWriter& out, size_t pad_at, size_t body_end, const PointSamplesView& points,
               const std::vector<uint32_t>& order, DecodedPoints& decoded, PointEncodeStats& stats) {
    const size_t n = points.count;
    auto decode_with_pad = [&](float pad) {
        uint32_t pad_bits;
        std::memcpy(&pad_bits, &pad, 4);
        out.patch_u32(pad_at, pad_bits);
        out.patch_u64(body_end, checksum64(out.bytes().data(), body_end));
        std::string problem = decode_point_node(out.bytes().data(), out.size(), decoded);
        assert(problem.empty() && "the encoder's own output must decode");
        (void)problem;
    };
    decode_with_pad(0.0f);
    std::vector<double> error(n);
    double worst = 0;
    for (size_t i = 0; i < n; ++i) {
        const double* p = points.positions + 3 * order[i];
        double d2 = 0;
        for (int a = 0; a < 3; ++a) d2 += (double(decoded.positions[3 * i + a]) - p[a]) * (double(decoded.positions[3 * i + a]) - p[a]);
        error[i] = std::sqrt(d2);
        worst = std::max(worst, error[i]);
    }
    stats.position_error = worst;
    float pad = round_up(worst);
    for (int attempt = 0;; ++attempt) {
        decode_with_pad(pad);
        double deficit = 0;
        for (size_t i = 0; i < n; ++i)
            deficit = std::max(deficit, double(points.radii[order[i]]) + error[i] - double(decoded.radii[i]));
        if (deficit <= 0) break;
        assert(attempt < 8);
        pad = round_up(double(pad) + deficit * (1.0 + 1e-6));
    }
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
    double min_radius = INFINITY;
    for (size_t i = 0; i < n; ++i) {
        assert(std::isfinite(points.radii[i]) && points.radii[i] > 0);
        min_radius = std::min(min_radius, double(points.radii[i]));
    }
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
    out.raw(kPointNodeMagic, 4);
    out.u8(kPointNodeVersion);
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
    StreamWriter streams{out, order, {}, {}};
    for (int a = 0; a < 3; ++a)
        stats.bytes_position += streams.put_deltas([&](uint32_t i) { return int32_t(q[3 * i + a]); });
    if (has_normals) {
        std::vector<uint16_t> codes(n);
        for (size_t i = 0; i < n; ++i)
            codes[i] = oct_encode_precise(points.normals[3 * i], points.normals[3 * i + 1], points.normals[3 * i + 2]);
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

// Decodes one stream of `n` values from [cursor, end) (end: the unpadded end of the node's
// streams; kRicePadding readable bytes follow it), handing value i to sink(i, value) in order.
// The sinks reconstruct attributes as the values arrive (prefix sums, dequantization), so no
// value makes a round trip through memory. Advances cursor past the stream.
template <class Sink>
__attribute__((always_inline)) inline const char* get_stream(const uint8_t*& cursor, const uint8_t* end, size_t n,
                                                             Sink&& sink) {
    ByteReader r(cursor, size_t(end - cursor));
    const uint32_t escape_bits = r.u8();
    if (escape_bits > 32) return "bad escape width";
    const size_t blocks = (n + kRiceBlock - 1) / kRiceBlock;
    const size_t k_size = (blocks * 5 + 7) / 8;
    const uint8_t* k_bytes = r.take(k_size);
    uint64_t lane_size[kRiceLanes];
    uint64_t total = 0;
    for (int l = 0; l < kRiceLanes; ++l) {
        lane_size[l] = r.varint();
        total += lane_size[l];
    }
    if (!r.ok() || total > r.remaining()) return "truncated stream";
    RiceLane lanes[kRiceLanes];
    const uint8_t* lane_begin[kRiceLanes];
    const uint8_t* lane_end[kRiceLanes];
    const uint8_t* at = r.cursor();
    for (int l = 0; l < kRiceLanes; ++l) {
        lane_begin[l] = at;
        lanes[l].p = at;
        at += lane_size[l];
        lane_end[l] = at;
    }
    for (size_t b = 0; b < blocks; ++b) {
        // k: 5 bits at bit 5b of k_bytes (read bytewise: the k array is not padded).
        const size_t bit = 5 * b;
        const uint32_t two = k_bytes[bit >> 3] | ((bit >> 3) + 1 < k_size ? uint32_t(k_bytes[(bit >> 3) + 1]) << 8 : 0u);
        const uint32_t k = (two >> (bit & 7)) & 31;
        const uint64_t k_mask = (uint64_t(1) << k) - 1;
        for (int l = 0; l < kRiceLanes; ++l)
            if (lanes[l].p > lane_end[l] + 8) return "stream overrun";
        const size_t first = b * kRiceBlock;
        const uint32_t longest = kRiceEscape + std::max(escape_bits, k);  // bits of the block's longest code
        if (first + kRiceBlock <= n) {
            RiceLane l[kRiceLanes];
            for (int j = 0; j < kRiceLanes; ++j) l[j] = lanes[j];
            if (longest <= kRicePairBits) {
                for (size_t i = first; i < first + kRiceBlock; i += 2 * kRiceLanes) {
                    uint32_t v[2 * kRiceLanes];
#pragma GCC unroll 8
                    for (int j = 0; j < kRiceLanes; ++j) l[j].refill();
#pragma GCC unroll 8
                    for (int j = 0; j < kRiceLanes; ++j) v[j] = l[j].get(k, k_mask, escape_bits);
#pragma GCC unroll 8
                    for (int j = 0; j < kRiceLanes; ++j) v[kRiceLanes + j] = l[j].get(k, k_mask, escape_bits);
#pragma GCC unroll 16
                    for (int j = 0; j < 2 * kRiceLanes; ++j) sink(i + size_t(j), v[j]);
                }
            } else {
                for (size_t i = first; i < first + kRiceBlock; i += kRiceLanes) {
                    uint32_t v[kRiceLanes];
#pragma GCC unroll 8
                    for (int j = 0; j < kRiceLanes; ++j) l[j].refill();
#pragma GCC unroll 8
                    for (int j = 0; j < kRiceLanes; ++j) v[j] = l[j].get(k, k_mask, escape_bits);
#pragma GCC unroll 8
                    for (int j = 0; j < kRiceLanes; ++j) sink(i + size_t(j), v[j]);
                }
            }
            for (int j = 0; j < kRiceLanes; ++j) lanes[j] = l[j];
        } else {
            for (size_t i = first; i < n; ++i) {
                RiceLane& lane = lanes[i % kRiceLanes];
                lane.refill();
                sink(i, lane.get(k, k_mask, escape_bits));
            }
        }
    }
    // Every lane must end exactly where its size says (the encoder pads to a byte with zeros).
    for (int l = 0; l < kRiceLanes; ++l) {
        uint64_t used = lanes[l].consumed_bits(lane_begin[l]);
        if ((used + 7) / 8 != lane_size[l]) return "stream length mismatch";
    }
    cursor = lane_end[kRiceLanes - 1];
    return nullptr;
}

}  // namespace

std::string peek_point_node(const uint8_t* data, size_t size, size_t& count, uint8_t& flags) {
    if (size < kHeaderSize + kChecksumSize) return "node too short";
    if (std::memcmp(data, kPointNodeMagic, 4) != 0) return "not a point node (bad magic)";
    if (data[4] != kPointNodeVersion)
        return strprintf("unsupported point node version %u (this build reads %u)", data[4], kPointNodeVersion);
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
    // Every value takes at least one bit: a count the bytes cannot hold is refused before
    // anything is allocated for it.
    const size_t body = size - kChecksumSize - kHeaderSize;
    if (streams * n > 8 * body) return "point count too large for the node size";

    // A padded copy of the streams, so that lane refills may read 8 bytes anywhere; after it,
    // room for the colours' quantized components.
    std::vector<uint32_t>& scratch = out.scratch;
    const size_t padded_words = (body + kRicePadding + 8 + 3) / 4;
    scratch.resize(padded_words + (has_colors ? 3 * n : 0));
    uint8_t* copy = reinterpret_cast<uint8_t*>(scratch.data());
    std::memcpy(copy, data + kHeaderSize, body);
    std::memset(copy + body, 0, padded_words * 4 - body);
    const uint8_t* cursor = copy;
    const uint8_t* end = copy + body;
    auto failed = [](const char* why) { return std::string("point node: ") + why; };

    out.count = n;
    out.flags = flags;
    out.position_error = pad;
    out.grid_step = step;
    out.positions.resize(3 * n);
    for (int a = 0; a < 3; ++a) {
        float* p = out.positions.data() + a;
        const float o = origin[a];
        uint32_t q = 0;
        const char* why = get_stream(cursor, end, n, [&](size_t i, uint32_t v) __attribute__((always_inline)) {
            q += uint32_t(unzigzag(v));
            p[3 * i] = grid_position(o, step, q & ((1u << kMaxGridBits) - 1));
        });
        if (why) return failed(why);
    }
    if (has_normals) {
        out.normals.resize(n);
        uint16_t* normals = out.normals.data();
        uint32_t u = 0, w = 0;
        const char* why = get_stream(cursor, end, n, [&](size_t i, uint32_t v) __attribute__((always_inline)) {
            u += uint32_t(unzigzag(v));
            normals[i] = uint16_t(u & 0xff);
        });
        if (!why) why = get_stream(cursor, end, n, [&](size_t i, uint32_t v) __attribute__((always_inline)) {
            w += uint32_t(unzigzag(v));
            normals[i] = uint16_t(normals[i] | (w & 0xff) << 8);
        });
        if (why) return failed(why);
    } else {
        out.normals.clear();
    }
    if (has_colors) {
        // The three quantized components first, then RGB in one pass the compiler vectorizes.
        out.colors.resize(3 * n);
        uint32_t* yq = scratch.data() + padded_words;
        uint32_t* coq = yq + n;
        uint32_t* cgq = coq + n;
        uint32_t y = 0, co = 0, cg = 0;
        const char* why = get_stream(cursor, end, n, [&](size_t i, uint32_t v) __attribute__((always_inline)) {
            y += uint32_t(unzigzag(v));
            yq[i] = y & 0x1ff;
        });
        if (!why) why = get_stream(cursor, end, n, [&](size_t i, uint32_t v) __attribute__((always_inline)) {
            co += uint32_t(unzigzag(v));
            coq[i] = co & 0x3ff;
        });
        if (!why) why = get_stream(cursor, end, n, [&](size_t i, uint32_t v) __attribute__((always_inline)) {
            cg += uint32_t(unzigzag(v));
            cgq[i] = cg & 0x3ff;
        });
        if (why) return failed(why);
        const int luma_shift = 8 - luma_bits, chroma_shift = 9 - chroma_bits;
        uint8_t* colors = out.colors.data();
        for (size_t i = 0; i < n; ++i)
            dequantize_color(yq[i], coq[i], cgq[i], luma_shift, chroma_shift, &colors[3 * i]);
    } else {
        out.colors.clear();
    }
    out.radii.resize(n);
    float* radii = out.radii.data();
    uint32_t r = 0;
    const char* why = get_stream(cursor, end, n, [&](size_t i, uint32_t v) __attribute__((always_inline)) {
        r += uint32_t(unzigzag(v));
        radii[i] = radius_value(radius_base, radius_step, pad, r & ((1u << 30) - 1));
    });
    if (why) return failed(why);
    if (cursor != end) return "point node: bytes left after the last stream";
    return "";
}

}  // namespace catpaq
