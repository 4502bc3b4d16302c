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
// are coded as kRiceEscape, and the value's high bits (v >> k, W - k bits where W is the bit
// width of the stream's largest value) go to an exception array after the low bits.
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

namespace catpaq::points_detail {

constexpr size_t kRiceBlock = 128;
constexpr uint32_t kRiceEscape = 8;
constexpr uint32_t kRiceMaxK = 31;  // also the width of an absolute k in the parameter string
// The decoder reads up to this many bytes past the end of a stream's parts (16-byte loads of
// the low bits, 8-byte loads of the partial block and exceptions): it pads its copy of the node.
constexpr size_t kRicePadding = 64;

__attribute__((always_inline)) inline uint32_t zigzag(int32_t v) { return (uint32_t(v) << 1) ^ uint32_t(v >> 31); }
__attribute__((always_inline)) inline int32_t unzigzag(uint32_t v) { return int32_t(v >> 1) ^ -int32_t(v & 1); }

// Bits needed to write v (0 for 0).
inline uint32_t bit_width32(uint32_t v) { return uint32_t(std::bit_width(v)); }

// Cost in bits of coding v with parameter k under escape width w.
inline uint64_t rice_cost(uint32_t v, uint32_t k, uint32_t w) {
    uint32_t q = v >> k;
    return q >= kRiceEscape ? kRiceEscape + 1 + (w - k) + k : q + 1 + k;
}

// Appends bits least significant first.
class BitWriter {
public:
    void put(uint64_t value, uint32_t nbits) {  // nbits <= 32
        acc_ |= (value & ((uint64_t(1) << nbits) - 1)) << fill_;
        fill_ += nbits;
        while (fill_ >= 8) {
            bytes_.push_back(uint8_t(acc_));
            acc_ >>= 8;
            fill_ -= 8;
        }
    }
    // Pads to a whole byte with zeros and returns the bytes.
    std::vector<uint8_t>& finish() {
        if (fill_ > 0) bytes_.push_back(uint8_t(acc_));
        acc_ = 0;
        fill_ = 0;
        return bytes_;
    }
    void clear() {
        bytes_.clear();
        acc_ = 0;
        fill_ = 0;
    }
    uint64_t bit_count() const { return 8 * uint64_t(bytes_.size()) + fill_; }

private:
    std::vector<uint8_t> bytes_;
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
    bool overrun() const { return bit > 8 * uint64_t(end - begin); }
    size_t bytes() const { return size_t((bit + 7) >> 3); }
};

}  // namespace catpaq::points_detail
