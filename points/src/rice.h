#pragma once
// Private to the points module: block-adaptive Rice codes with the unary and binary halves in
// separate arrays, the entropy coder of the node codec (docs/formats/points.md, "Streams").
//
// A stream codes `count` unsigned values in blocks of kRiceBlock, each block with its own Rice
// parameter k. Value v has quotient q = v >> k and the k low bits of v. The quotients of the
// whole stream are one unary bit string (q zero bits, then a one); the low bits are packed at
// a fixed width per block, so they decode without any serial dependency: for a full block, in
// the "vertical" layout of SIMD bit packing (four interleaved 32-bit word lanes, value i in lane
// i % 4), where one SSE2 shift extracts four values at once. Quotients of kRiceEscape or more
// are coded as kRiceEscape, and the excess q - kRiceEscape goes to an exception array after the
// low bits, in an Exp-Golomb code of order kEscapeOrder (measured on scans: 23% fewer bits for
// the escapes than their high bits at the stream's largest width, 0.017 bytes per point).
//
// Why not one interleaved Rice bit stream (format version 1): its decoder is a serial chain of
// count-zeros-then-shift steps per value, which kept the node decoder at 30-45 M points/s
// (9 values per point); with the halves apart, the unary string decodes a byte (about four
// values) per table look-up and the rest is branch-free SIMD. The bit cost is the same, but for
// one more bit per escape.
#include <bit>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <vector>

#ifdef __SSE2__
#include <emmintrin.h>
#endif

namespace catpaq::points_detail {

constexpr size_t kRiceBlock = 128;
constexpr uint32_t kRiceEscape = 8;
constexpr uint32_t kRiceMaxK = 31;  // also the width of an absolute k in the parameter string
constexpr uint32_t kEscapeOrder = 2;
constexpr uint32_t kEscapeMaxPrefix = 30;  // the Exp-Golomb prefix of any 32-bit excess
// The decoder reads up to this many bytes past the end of a stream's parts (32-byte loads of
// the low bits, 8-byte loads of the partial block and exceptions): it pads its copy of the node.
constexpr size_t kRicePadding = 64;

__attribute__((always_inline)) inline uint32_t zigzag(int32_t v) { return (uint32_t(v) << 1) ^ uint32_t(v >> 31); }
__attribute__((always_inline)) inline int32_t unzigzag(uint32_t v) { return int32_t(v >> 1) ^ -int32_t(v & 1); }

// Bits needed to write v (0 for 0).
inline uint32_t bit_width32(uint32_t v) { return uint32_t(std::bit_width(v)); }

// Bits of the Exp-Golomb code (order kEscapeOrder) of an escape's excess e: n zeros, a one,
// the n bits of x = (e >> kEscapeOrder) + 1 below its top bit, then e's kEscapeOrder low bits.
inline uint32_t escape_prefix(uint32_t e) { return uint32_t(std::bit_width((uint64_t(e) >> kEscapeOrder) + 1)) - 1; }
inline uint64_t escape_cost(uint32_t e) { return 2 * escape_prefix(e) + 1 + kEscapeOrder; }

// Cost in bits of coding v with parameter k.
inline uint64_t rice_cost(uint32_t v, uint32_t k) {
    uint32_t q = v >> k;
    return q >= kRiceEscape ? kRiceEscape + 1 + k + escape_cost(q - kRiceEscape) : q + 1 + k;
}

// rice_cost summed over values[0..n) (n below 2^24), the encoder's cost of a block under each
// parameter it tries. Four values at a time, every escape's cost without branches: the encoder
// tries k from log2 of the block's mean less 2, where most blocks have escapes, and the scalar
// loop's branch on q >= kRiceEscape mispredicted (it was a quarter of put_stream's samples on
// the 1M scan, after a branch-free pass for the unary parts). Measured: put_stream 3.7-3.9% ->
// 3.1-3.4% of the 1M scan's conversion samples (3 profiles each); point_encode_bench on its
// nodes 358 -> 343 ms. Equal to the scalar sum for every input (tests/points/test_codec.cpp).
inline uint64_t rice_bits(const uint32_t* values, size_t n, uint32_t k) {
    uint64_t cost = uint64_t(n) * (1 + k);
    size_t i = 0;
#ifdef __SSE2__
    static_assert(kRiceEscape == 8 && kEscapeOrder == 2, "the SSE2 path shifts by these constants");
    const __m128i count = _mm_cvtsi32_si128(int(k)), zero = _mm_setzero_si128();
    const __m128i escape = _mm_set1_epi32(int(kRiceEscape)), one = _mm_set1_epi32(1);
    const __m128i above24 = _mm_set1_epi32((1 << 24) - 1), low8 = _mm_set1_epi32(0xff);
    // 2 * (exponent - 127) + 1 + kEscapeOrder = 2 * exponent - 251.
    const __m128i fixed = _mm_set1_epi32(1 + int(kEscapeOrder) - 2 * 127);
    __m128i sum = zero;  // per lane n / 4 terms of at most 8 + 2 * 30 + 3 bits
    for (; i + 4 <= n; i += 4) {
        const __m128i q = _mm_srl_epi32(_mm_loadu_si128(reinterpret_cast<const __m128i*>(values + i)), count);
        // q < 8 as unsigned: no bit above the third (SSE2 compares only signed).
        const __m128i kept = _mm_cmpeq_epi32(_mm_srli_epi32(q, 3), zero);
        const __m128i unary = _mm_or_si128(_mm_and_si128(kept, q), _mm_andnot_si128(kept, escape));
        // x = (e >> kEscapeOrder) + 1 for the excess e = q - 8 (below 2^31 even where q does not
        // escape and e wraps); escape_prefix is bit_width(x) - 1, the exponent of float(x) if
        // the conversion does not round x up to the next power of two: x below 2^24 converts
        // exactly, and from 2^24 to 2^31 does so without its low 8 bits (24 significant bits).
        __m128i x = _mm_add_epi32(_mm_srli_epi32(_mm_sub_epi32(q, escape), int(kEscapeOrder)), one);
        x = _mm_andnot_si128(_mm_and_si128(_mm_cmpgt_epi32(x, above24), low8), x);
        const __m128i exponent = _mm_srli_epi32(_mm_castps_si128(_mm_cvtepi32_ps(x)), 23);
        const __m128i escaped_bits = _mm_add_epi32(_mm_add_epi32(exponent, exponent), fixed);  // escape_cost(e)
        sum = _mm_add_epi32(sum, _mm_add_epi32(unary, _mm_andnot_si128(kept, escaped_bits)));
    }
    alignas(16) uint32_t lanes[4];
    _mm_store_si128(reinterpret_cast<__m128i*>(lanes), sum);
    cost += uint64_t(lanes[0]) + lanes[1] + lanes[2] + lanes[3];
#endif
    for (; i < n; ++i) cost += rice_cost(values[i], k) - (1 + k);
    return cost;
}

// Appends bits least significant first. Whole bytes leave the accumulator by one 8-byte store
// at the end of what is written (the buffer is kept 8 bytes longer), where a push_back per byte
// and its capacity check took a tenth of put_stream's samples (the unary quotients go 32 bits
// per put; point_encode_bench 243 -> 237 ms).
class BitWriter {
public:
    void put(uint64_t value, uint32_t nbits) {  // nbits <= 32
        acc_ |= (value & ((uint64_t(1) << nbits) - 1)) << fill_;
        fill_ += nbits;  // at most 7 + 32
        if (used_ + 8 > bytes_.size()) bytes_.resize(2 * bytes_.size() + 64);
        uint64_t word = acc_;
        if constexpr (std::endian::native == std::endian::big) word = __builtin_bswap64(word);
        std::memcpy(bytes_.data() + used_, &word, 8);  // the whole bytes, and scratch after them
        used_ += fill_ >> 3;
        acc_ >>= fill_ & ~7u;
        fill_ &= 7;
    }
    // Pads to a whole byte with zeros and returns the bytes.
    std::vector<uint8_t>& finish() {
        if (fill_ > 0) put(0, 8 - fill_);
        bytes_.resize(used_);
        acc_ = 0;
        return bytes_;
    }
    void clear() {
        bytes_.clear();
        used_ = 0;
        acc_ = 0;
        fill_ = 0;
    }
    uint64_t bit_count() const { return 8 * uint64_t(used_) + fill_; }

private:
    std::vector<uint8_t> bytes_;  // used_ bytes written, then at least 8 more (none after finish())
    size_t used_ = 0;
    uint64_t acc_ = 0;
    uint32_t fill_ = 0;
};

// Reads bits least significant first from a buffer that may be read 8 bytes past `end`; the
// caller checks overrun() once at the end rather than per read.
struct BitReader {
    const uint8_t* begin;
    const uint8_t* end;
    uint64_t bit = 0;

    uint32_t get(uint32_t nbits) {  // nbits <= 32; past the end, reads padding
        if ((bit >> 3) >= uint64_t(end - begin) + 8) return 0;  // keep far-off reads inside the padding
        uint64_t word;
        std::memcpy(&word, begin + (bit >> 3), 8);
        if constexpr (std::endian::native == std::endian::big) word = __builtin_bswap64(word);
        uint32_t v = uint32_t((word >> (bit & 7)) & ((uint64_t(1) << nbits) - 1));
        bit += nbits;
        return v;
    }
    // Zero bits up to the next one bit, which is consumed too; above `most`, corrupt: returns
    // most + 1 (and consumes nothing).
    uint32_t zeros_then_one(uint32_t most) {  // most <= 48
        if ((bit >> 3) >= uint64_t(end - begin) + 8) return most + 1;
        uint64_t word;
        std::memcpy(&word, begin + (bit >> 3), 8);
        if constexpr (std::endian::native == std::endian::big) word = __builtin_bswap64(word);
        const uint32_t zeros = uint32_t(__builtin_ctzll((word >> (bit & 7)) | (uint64_t(1) << 56)));
        if (zeros > most) return most + 1;
        bit += zeros + 1;
        return zeros;
    }
    // An escape's quotient: kRiceEscape plus the Exp-Golomb excess (escape_cost); false if its
    // prefix is longer than any 32-bit value's.
    bool escape_quotient(uint64_t& q) {
        const uint32_t n = zeros_then_one(kEscapeMaxPrefix);
        if (n > kEscapeMaxPrefix) return false;
        const uint64_t x = (uint64_t(1) << n) | get(n);
        q = kRiceEscape + (((x - 1) << kEscapeOrder) | get(kEscapeOrder));
        return true;
    }
    bool overrun() const { return bit > 8 * uint64_t(end - begin); }
    size_t bytes() const { return size_t((bit + 7) >> 3); }
};

}  // namespace catpaq::points_detail
