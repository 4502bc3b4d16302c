#pragma once
// The node codec of the point format: a few thousand splats (position, normal, colour, radius)
// in, a compact checksummed byte string out (after seed 002 section 3.3). Byte layout:
// docs/formats/points.md ("Node payload").
//
// Positions are quantized on a per-node grid whose step keeps every decoded position within a
// quarter (by default) of the node's smallest splat radius (Euclidean distance, float rounding included);
// radii are quantized upwards on a grid of the same step and enlarged by the largest position
// error, so a decoded splat always covers the splat it was made from. Points are ordered along
// a Morton curve of their grid cells, every attribute is delta coded along that order
// (positions per axis, octahedral normals modulo 256, colours in YCoCg, radii), and the
// zigzagged residuals are entropy coded with block-adaptive Rice codes whose unary quotients and
// binary low bits are stored apart (the low bits in SIMD bit-packing layout), so that they
// decode with table look-ups and SIMD shifts rather than one bit-string walk per value; from
// version 3 on, a block of zero residuals is its parameter alone.
//
// Thread safety: all functions are reentrant; decode_point_node only writes `out`.
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace catpaq {

// The version the encoder writes by default; the decoder reads kPointNodeOldestVersion to it.
// Version 3 adds blocks of zeros (a parameter with no other bits) to version 2's streams.
constexpr uint8_t kPointNodeVersion = 3;
constexpr uint8_t kPointNodeOldestVersion = 2;
constexpr char kPointNodeMagic[4] = {'C', 'P', 'P', 'N'};
// Node payload flags: which optional attributes the points carry.
constexpr uint8_t kPointHasNormals = 1u << 0;
constexpr uint8_t kPointHasColors = 1u << 1;

// Colour precision in the YCoCg space: luma (Y, 8 bits at full precision) and chroma (Co, Cg, 9
// bits each at full precision). 8/9 is lossless for 8-bit RGB; seed 002 uses 5/6.
struct ColorBits {
    uint8_t luma = 8;    // 1..8
    uint8_t chroma = 9;  // 1..9
};

// What the encoder may lose: colour precision, and the position error as a fraction of the
// node's smallest splat radius (seed 002: a quarter; the radius grid uses the same step).
struct PointEncodeSettings {
    ColorBits color_bits;
    double error_fraction = 0.25;  // (0, 1]
    // The payload version written (kPointNodeOldestVersion .. kPointNodeVersion): older ones for
    // tests and benches that compare versions. Every version decodes to the same points.
    uint8_t version = kPointNodeVersion;
};

// The encoder's input: `count` points as parallel arrays the caller owns.
struct PointSamplesView {
    size_t count = 0;
    const double* positions = nullptr;  // 3 per point, relative to the dataset origin
    const float* normals = nullptr;     // 3 per point, unit length, or null (no normals)
    const uint8_t* colors = nullptr;    // RGB per point, or null (no colours)
    const float* radii = nullptr;       // 1 per point, each > 0 and finite
};

// A decoded node, as the client draws it. Buffers are reused across decodes (no allocation once
// they have grown to the largest node).
struct DecodedPoints {
    size_t count = 0;
    uint8_t flags = 0;                 // kPointHasNormals | kPointHasColors
    std::vector<float> positions;      // 3 per point, relative to the dataset origin
    std::vector<uint16_t> normals;     // octahedral 8+8 (common_codec/octahedral.h), if flagged
    std::vector<uint8_t> colors;       // RGB per point, if flagged
    std::vector<float> radii;          // splat radii, already enlarged by position_error
    float position_error = 0;          // bound of |decoded - encoded position| over the node
    float grid_step = 0;               // the position grid's step
    std::vector<uint32_t> scratch;     // decoder work space
};

struct PointEncodeStats {
    double position_error = 0;  // largest |decoded - input| over the points (measured)
    double min_radius = 0;      // the smallest input radius, which sets the grid step
    size_t bytes_position = 0, bytes_normal = 0, bytes_color = 0, bytes_radius = 0, bytes_header = 0;
};

// Encodes `points` (count >= 1, < 2^24). `order`, when given, receives the decoded order: decoded
// point i is input point order[i]. `decoded`, when given, receives decode_point_node(result)
// (the encoder decodes its own output to measure the position error: callers building the next
// level from decoded data get it for free). Asserts on caller bugs (non-finite or non-positive
// radii, count 0).
std::vector<uint8_t> encode_point_node(const PointSamplesView& points, const PointEncodeSettings& settings,
                                       std::vector<uint32_t>* order = nullptr, DecodedPoints* decoded = nullptr,
                                       PointEncodeStats* stats = nullptr);

// Decodes a node payload. Safe on any bytes: returns an empty string on success, else what is
// wrong (bad magic, unknown version, truncated, checksum mismatch, inconsistent streams), and
// never reads outside [data, data + size).
std::string decode_point_node(const uint8_t* data, size_t size, DecodedPoints& out);

// For tests and benchmarks: whether decode_point_node may use its AVX2 kernels (by default it
// does where the CPU has AVX2, else the SSE2 ones of baseline x86-64; outputs are identical).
// Returns whether they are in use after the call. Not thread safe: call before decoding.
bool use_point_decoder_avx2(bool enable);

// Reads only the fixed header: the point count and flags. Empty string on success.
std::string peek_point_node(const uint8_t* data, size_t size, size_t& count, uint8_t& flags);

}  // namespace catpaq
