#pragma once
// Static rANS entropy coder plus a raw bit stream (private to common_codec).
//
// Symbols are coded with four 32-bit rANS states ("lanes") sharing one byte stream. Every
// symbol names its lane (the codec assigns lanes statically, e.g. one per coordinate, so a
// decoder loop has up to four independent dependency chains without any state rotation). The
// shared byte stream is consumed in decode order. States live in [kStateLower, 2^31);
// renormalisation is byte-wise, at most two bytes per symbol (the second behind a rarely taken
// branch, see renormalise). Raw bits (the low bits of large residuals, explicit indices, table
// fields) go to a separate little-endian bit stream read through a 64-bit buffer. The encoder collects everything first and encodes the
// symbols backwards once the tables are known; it starts every state at kStateLower, so the
// decoder checks that all states return to exactly kStateLower after the last symbol, with
// every byte consumed and the bit stream's padding zero: a strong end-of-stream check.
//
// Layout: u32 state0..state3 | varint bit_bytes | rANS bytes | bit stream (bit_bytes)
//
// A symbol is coded with a frequency table whose frequencies sum to 2^scale_bits
// (kMinScaleBits..kMaxScaleBits). Tables are transmitted in the streams themselves
// (put_table/get_table): alphabet size (5 raw bits) and scale (3 raw bits), then per symbol a
// log-domain weight code (0 = absent, else 1..40 for (4 + (k-1)%4) << ((k-1)/4): two mantissa
// bits, about 19% steps, which costs < 0.003 bit per coded symbol) coded as the delta to the
// previous present code with a fixed built-in meta table on lane 0 (escape: 6 raw bits).
// Frequencies are derived from the weights by one deterministic integer normalisation
// (build_freqs).
#include <array>
#include <bit>
#include <cassert>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <vector>

#define CATPAQ_RANS_INLINE inline __attribute__((always_inline))

namespace catpaq::rans {

constexpr uint32_t kStateLower = 1u << 23;
constexpr int kMaxAlphabet = 32;
constexpr int kMinScaleBits = 5;
constexpr int kMaxScaleBits = 12;
constexpr int kMaxRawBits = 32;
constexpr int kMaxWeightCode = 40;

// Transmitted description of a table: alphabet size, scale, per-symbol weight code (0 = absent).
struct TableDesc {
    int nsym = 1;
    int scale_bits = kMinScaleBits;
    std::array<uint8_t, kMaxAlphabet> code{};
};

// Normalised frequencies derived from a TableDesc (deterministically, same on both sides).
struct FreqTable {
    int scale_bits = kMinScaleBits;
    int nsym = 0;
    std::array<uint32_t, kMaxAlphabet> freq{}, start{};
};

// Chooses a description for the given symbol counts (nsym <= kMaxAlphabet, counts may be all zero).
// When `freqs` is given it receives build_freqs() of the description and, when `data_bits` is
// given too, that receives data_cost_bits(counts, *freqs) (both known here already).
TableDesc describe_counts(const uint32_t* counts, int nsym, FreqTable* freqs = nullptr, double* data_bits = nullptr);
// Derives frequencies; returns false if the description is invalid (corrupt data).
bool build_freqs(const TableDesc& desc, FreqTable& out);
// Estimated cost in bits of coding `counts` with `freqs`.
double data_cost_bits(const uint32_t* counts, const FreqTable& freqs);
// Estimated cost in bits of a table description.
double table_cost_bits(const TableDesc& desc);

// Decoding table: slot -> freq | (slot - start) << 16, and slot -> symbol apart. (Two loads per
// symbol, from the same slot, instead of one packed word that took six instructions to unpack.)
struct DecodeTable {
    int scale_bits = 0;
    uint32_t mask = 0;
    std::vector<uint32_t> lut;
    std::vector<uint8_t> syms;
    void build(const FreqTable& f);
};

// Encoder form of one symbol: the state update x -> (x / freq) * 2^scale + x % freq + start
// without a division, by a multiply with a rounded reciprocal (Fabian Giesen's ryg_rans,
// rans_byte.h; exact for every state the encoder meets, x < 2^31), instead of a 32-bit division
// per symbol. x_max: renormalise (shift out a byte) while x >= x_max.
struct EncSymbol {
    uint32_t x_max = 0;
    uint32_t rcp_freq = 0;
    uint32_t bias = 0;
    uint16_t cmpl_freq = 0;  // 2^scale - freq
    uint8_t rcp_shift = 0;
    uint8_t lane = 0;  // filled in by Encoder::put

    static EncSymbol make(uint32_t start, uint32_t freq, int scale_bits);
    // The coded state for x (requires x < x_max): the same value as the division form.
    CATPAQ_RANS_INLINE uint32_t update(uint32_t x) const {
        const uint32_t q = uint32_t((uint64_t(x) * rcp_freq) >> 32) >> rcp_shift;
        return x + bias + q * cmpl_freq;
    }
};

// EncSymbols of a whole FreqTable (symbols absent from it are left zero and must not be put).
struct EncTable {
    std::array<EncSymbol, kMaxAlphabet> sym{};
    void build(const FreqTable& f);
};

class Encoder {
public:
    // Forgets everything put so far but keeps the buffers (an encoder is reused per fragment).
    void reset();
    // Appends, in decode order, a symbol on `lane` (0..3) / raw bits (nbits <= 32).
    void put(const EncTable& t, uint32_t sym, int lane) {
        EncSymbol s = t.sym[sym];
        s.lane = uint8_t(lane);
        ops_.push_back(s);
    }
    CATPAQ_RANS_INLINE void put_bits(uint32_t value, int nbits) {
        // Whole 32-bit words are flushed, so 32 more bits always fit in the 64-bit accumulator.
        assert(nbits >= 0 && nbits <= kMaxRawBits);
        const uint64_t mask = (uint64_t(1) << nbits) - 1;
        bit_acc_ |= (uint64_t(value) & mask) << bit_fill_;
        bit_fill_ += nbits;
        if (bit_fill_ >= 32) flush_word();
    }
    void put_table(const TableDesc& desc);
    // Starts a new section (for size reports); sections are numbered from 0 in call order.
    void begin_section() { sections_.push_back({ops_.size(), bit_count()}); }

    // Encodes everything and appends the layout above to `out`. If given, section_bytes[i]
    // receives the bytes attributable to section i (rANS bytes emitted for its symbols plus its
    // raw bits / 8; the fixed fields go to section 0), summing to the appended size.
    void finish(std::vector<uint8_t>& out, std::vector<size_t>* section_bytes);

private:
    struct Section {
        size_t first_op;
        uint64_t first_bit;
    };
    uint64_t bit_count() const { return 8 * uint64_t(bits_.size()) + uint64_t(bit_fill_); }
    void flush_word();
    // rANS-codes ops_[first, end) backwards, writing bytes downwards from `at`; returns the
    // new write position.
    uint8_t* encode_ops(size_t first, size_t end, uint32_t state[4], uint8_t* at) const;

    std::vector<EncSymbol> ops_;
    std::vector<Section> sections_;
    std::vector<uint8_t> bits_;
    std::vector<uint8_t> rans_bytes_;  // scratch of finish()
    uint64_t bit_acc_ = 0;
    int bit_fill_ = 0;
};

// low_bits(n) = 2^n - 1 for n <= 32, by a table: one load instead of building the mask with a
// variable shift (which on x86 also ties up the count register) in every raw bits read.
struct LowBitsTable {
    uint32_t mask[kMaxRawBits + 1];
    constexpr LowBitsTable() : mask{} {
        for (int n = 0; n <= kMaxRawBits; ++n) mask[n] = n == 32 ? ~0u : (1u << n) - 1;
    }
};
inline constexpr LowBitsTable kLowBits{};
CATPAQ_RANS_INLINE uint32_t low_bits(uint32_t n) { return kLowBits.mask[n]; }

// Read-only view of a DecodeTable for the hot loops (plain values the compiler keeps in registers).
struct TableView {
    const uint32_t* lut;
    const uint8_t* syms;
    uint32_t mask;
    uint32_t shift;
    explicit TableView(const DecodeTable& t)
        : lut(t.lut.data()), syms(t.syms.data()), mask(t.mask), shift(uint32_t(t.scale_bits)) {}
};

// The decoder is a plain value: hot loops copy it into a local (so that every field lives in a
// register), decode, and copy it back. Nothing here takes the address of a field.
//
// Hot loops use the unchecked forms (sym, take_bits) after establishing the preconditions with
// rans_bytes_left() (each symbol consumes at most 2 bytes) and need_bits(); the checked forms
// (get, get_bits) work anywhere.
struct Decoder {
    static constexpr uint32_t kMaxBytesPerSymbol = 2;

    // Parses the layout; false if it is inconsistent (lengths, states out of range).
    bool init(const uint8_t* data, size_t size);

    template <int L>
    CATPAQ_RANS_INLINE uint32_t& lane() {
        static_assert(L >= 0 && L < 4);
        if constexpr (L == 0) return x0;
        if constexpr (L == 1) return x1;
        if constexpr (L == 2) return x2;
        if constexpr (L == 3) return x3;
    }
    size_t rans_bytes_left() const { return size_t(end - p); }

    // Symbol on lane L; requires rans_bytes_left() >= 2.
    template <int L>
    CATPAQ_RANS_INLINE uint32_t sym(const TableView& t) {
        uint32_t x = lane<L>();
        const uint32_t slot = x & t.mask;
        const uint32_t e = t.lut[slot];
        x = (e & 0xffffu) * (x >> t.shift) + (e >> 16);
        renormalise(x);
        lane<L>() = x;
        return t.syms[slot];
    }
    // Brings a decoded state back to [kStateLower, 2^31): k = 0, 1 or 2 bytes (every step
    // leaves x >= kStateLower >> 12; requires rans_bytes_left() >= 2). The first byte by a
    // compare, a conditional move and an add of the carry; the second by a branch, taken only
    // after symbols of frequency below 2^(scale - 8) (rare by definition). Measured: fewer
    // instructions than the branch-free form reading two bytes and shifting by 8 k, which took
    // about a third of every symbol's instructions.
    CATPAQ_RANS_INLINE void renormalise(uint32_t& x) {
        const uint32_t with_byte = (x << 8) | p[0];
#if defined(__x86_64__) && defined(__GNUC__)
        asm("cmpl %[lower], %[x]\n\t"
            "cmovb %[with_byte], %[x]\n\t"
            "adc $0, %[p]"
            : [x] "+r"(x), [p] "+r"(p)
            : [with_byte] "r"(with_byte), [lower] "i"(kStateLower)
            : "cc");
#else
        const bool need = x < kStateLower;
        x = need ? with_byte : x;
        p += need;
#endif
        if (x < kStateLower) [[unlikely]]
            x = (x << 8) | *p++;
    }

    // Symbol on lane L, any position.
    template <int L>
    CATPAQ_RANS_INLINE uint32_t get(const TableView& t) {
        if (rans_bytes_left() >= kMaxBytesPerSymbol) [[likely]]
            return sym<L>(t);
        // Near the end, byte by byte with checks, inline: the last symbols of a stream often
        // need no byte at all (probable symbols cost a fraction of a bit), and a call per
        // symbol there took about 1% of the decoder's time.
        uint32_t x = lane<L>();
        const uint32_t slot = x & t.mask;
        const uint32_t e = t.lut[slot];
        x = (e & 0xffffu) * (x >> t.shift) + (e >> 16);
        while (x < kStateLower) {  // at most twice: x >= kStateLower >> 12 before
            if (p == end) {
                failed = true;
                x |= kStateLower;  // keep the state in range; the stream is already invalid
                break;
            }
            x = (x << 8) | *p++;
        }
        lane<L>() = x;
        return t.syms[slot];
    }
    uint32_t get(const TableView& t) { return get<0>(t); }

    // Makes at least n <= 56 bits available to take_bits. Past the end of the bit stream zero
    // bits are supplied; consuming any of them makes finished_cleanly() false.
    CATPAQ_RANS_INLINE void need_bits(uint32_t n) {
        if (bit_count < n) [[unlikely]]
            refill(n);
    }
    // Raw bits; requires need_bits(>= nbits) since the last refill accounting.
    CATPAQ_RANS_INLINE uint32_t take_bits(uint32_t nbits) {
        uint32_t v = uint32_t(bit_buf) & low_bits(nbits);
        bit_buf >>= nbits;
        bit_count -= nbits;
        return v;
    }
    // Raw bits, any position (0 <= nbits <= 32).
    CATPAQ_RANS_INLINE uint32_t get_bits(uint32_t nbits) {
        if (nbits > 32) nbits = 32;
        if (bit_count < nbits) refill(nbits);
        return take_bits(nbits);
    }

    // Reads a table description and builds both forms; false if invalid.
    bool get_table(FreqTable& freqs, DecodeTable& table);

    // False once any stream was read past its end.
    bool ok() const { return !failed; }
    // True if no read went past an end, every byte was consumed, the bit stream's padding is
    // zero and all states are back at their initial value.
    bool finished_cleanly() const;

    uint32_t x0 = 0, x1 = 0, x2 = 0, x3 = 0;
    const uint8_t *p = nullptr, *end = nullptr;
    const uint8_t *bit_p = nullptr, *bit_end = nullptr;
    uint64_t bit_buf = 0;
    uint32_t bit_count = 0;  // valid low bits in bit_buf
    uint64_t bit_phantom = 0;  // zero bits supplied past the end of the bit stream
    bool failed = true;

private:
    // refill's slow path works on a copy passed and returned by value: a hot loop's decoder (a
    // local copy, see above) then never has its address taken, and the compiler keeps its fields
    // in registers. As a member function called on it, it made the decoder live on the stack,
    // with a store and a reload on every symbol's dependency chain (so does get's slow path,
    // written inline for the same reason).
    static Decoder refilled_slowly(Decoder d, uint32_t need);
    uint32_t get_meta(const uint8_t* syms, const FreqTable& f);
    void refill_slow(uint32_t need);
    CATPAQ_RANS_INLINE void refill(uint32_t need) {
        if (bit_end - bit_p >= 8) [[likely]] {
            uint64_t w;
            std::memcpy(&w, bit_p, 8);
            if constexpr (std::endian::native == std::endian::big) w = __builtin_bswap64(w);
            bit_buf |= w << bit_count;
            bit_p += (63 - bit_count) >> 3;
            bit_count |= 56;
        } else {
            *this = refilled_slowly(*this, need);
        }
    }
};

}  // namespace catpaq::rans
