#pragma once
// Private to the points module: block-adaptive Rice codes over four interleaved bit lanes, the
// entropy coder of the node codec (docs/formats/points.md, "Streams").
//
// A stream codes `count` unsigned values. Value i goes to lane i % 4; every lane is its own
// little-endian bit stream, so a decoder loop advances four independent dependency chains at
// once (a single Rice stream is a serial chain of shift-after-count-zeros steps: four lanes
// nearly quadruple the values decoded per cycle). Values are grouped in blocks of kRiceBlock
// (kRiceBlock / 4 per lane); each block has its own Rice parameter k, so the code follows the
// local magnitude of the residuals at a cost of 5 bits per block.
//
// A value v is coded as q = v >> k zero bits, a one bit, then the k low bits of v (least
// significant first). Quotients of kRiceEscape or more are escaped: kRiceEscape zero bits, then
// v in `escape_bits` raw bits (the bit width of the stream's largest value), so one outlier
// costs at most kRiceEscape + escape_bits bits instead of a long run of zeros. Every code is at
// most kRiceEscape + 32 = 40 bits, so one refill (which leaves at least 56 bits) per value
// suffices; where a block's codes are at most kRicePairBits long, one refill serves two values.
#include <bit>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <vector>

namespace catpaq::points_detail {

constexpr int kRiceLanes = 4;
constexpr size_t kRiceBlock = 128;
constexpr uint32_t kRiceEscape = 8;
constexpr uint32_t kRiceMaxK = 31;  // stored in 5 bits
constexpr uint32_t kRicePairBits = 28;  // two codes this long fit in the 56 bits a refill leaves
// Bytes a decoder may read past the end of a lane (refills load 8 bytes at a time) and the most
// bytes one block can take from a lane: the decoder pads its input by this much.
constexpr size_t kRiceBlockMaxBytes = (kRiceBlock / kRiceLanes) * 6 + 8;
constexpr size_t kRicePadding = kRiceBlockMaxBytes + 8;

__attribute__((always_inline)) inline uint32_t zigzag(int32_t v) { return (uint32_t(v) << 1) ^ uint32_t(v >> 31); }
__attribute__((always_inline)) inline int32_t unzigzag(uint32_t v) { return int32_t(v >> 1) ^ -int32_t(v & 1); }

// Bits needed to write v (0 for 0).
inline uint32_t bit_width32(uint32_t v) { return uint32_t(std::bit_width(v)); }

// Cost in bits of coding v with parameter k under escape width w.
inline uint64_t rice_cost(uint32_t v, uint32_t k, uint32_t w) {
    uint32_t q = v >> k;
    return q >= kRiceEscape ? kRiceEscape + w : q + 1 + k;
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
    void put_zeros(uint32_t n) {
        while (n > 32) {
            put(0, 32);
            n -= 32;
        }
        put(0, n);
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

inline void rice_put(BitWriter& w, uint32_t v, uint32_t k, uint32_t escape_bits) {
    uint32_t q = v >> k;
    if (q >= kRiceEscape) {
        w.put(0, kRiceEscape);
        w.put(v, escape_bits);
    } else {
        w.put(uint64_t(1) << q, q + 1);
        w.put(v, k);
    }
}

// One lane's reader. The caller guarantees that 8 bytes can be read at any position up to the
// lane's end plus kRiceBlockMaxBytes (the decoder pads its copy of the node), and checks per
// block that the lane has not run past that.
struct RiceLane {
    const uint8_t* p;
    uint64_t buf = 0;
    uint32_t count = 0;  // valid bits in buf

    __attribute__((always_inline)) inline void refill() {
        uint64_t word;
        std::memcpy(&word, p, 8);
        if constexpr (std::endian::native == std::endian::big) word = __builtin_bswap64(word);
        buf |= word << count;
        p += (63 - count) >> 3;
        count |= 56;
    }
    // Decodes one value (at least as many valid bits as its code must be in buf).
    __attribute__((always_inline)) inline uint32_t get(uint32_t k, uint64_t k_mask, uint32_t escape_bits) {
        uint32_t q = uint32_t(__builtin_ctzll(buf | (uint64_t(1) << kRiceEscape)));
        if (q < kRiceEscape) [[likely]] {
            buf >>= q + 1;
            uint32_t low = uint32_t(buf & k_mask);
            buf >>= k;
            count -= q + 1 + k;
            return (q << k) | low;
        }
        buf >>= kRiceEscape;
        uint32_t v = uint32_t(buf & ((uint64_t(1) << escape_bits) - 1));
        buf >>= escape_bits;
        count -= kRiceEscape + escape_bits;
        return v;
    }
    // Bits consumed from the lane's first byte.
    uint64_t consumed_bits(const uint8_t* begin) const { return 8 * uint64_t(p - begin) - count; }
};

}  // namespace catpaq::points_detail
