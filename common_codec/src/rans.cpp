#include "rans.h"

#include <algorithm>
#include <cassert>
#include <bit>
#include <cmath>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

namespace catpaq::rans {

namespace {

uint32_t weight_value(int code) { return code <= 0 ? 0u : uint32_t(4 + (code - 1) % 4) << ((code - 1) / 4); }

// Meta table for the table descriptions: symbol 0 = absent, 1..29 = delta (sym - 15) of the
// weight code against the previous present one (starting at kMaxWeightCode), 30 = escape
// followed by the code in 6 raw bits. Frequencies (sum 4096; the escape takes the remainder)
// fitted to the tables of the bunny fragments (smoothed): absent symbols are common in the
// sparse tails, present weights mostly fall by 1-6 codes per symbol.
constexpr int kMetaSymbols = 31;
constexpr int kMetaEscape = 30;
constexpr int kMetaBias = 15;
constexpr std::array<uint16_t, kMetaSymbols> kMetaFreq = {
    // absent, then delta -14 .. -1
    1025, 19, 26, 40, 43, 58, 71, 101, 115, 164, 159, 255, 164, 206, 243,
    // delta 0
    648,
    // delta +1 .. +14
    186, 119, 61, 85, 51, 59, 38, 21, 23, 14, 11, 6, 4, 4,
    // escape
    0 /* the remainder of 4096 */};

constexpr uint32_t meta_listed_sum() {
    uint32_t sum = 0;
    for (int i = 0; i < kMetaEscape; ++i) sum += kMetaFreq[size_t(i)];
    return sum;
}
static_assert(meta_listed_sum() < 4096, "the escape symbol needs a frequency");

struct Meta {
    FreqTable freqs;
    DecodeTable table;
    EncTable enc;
    Meta() {
        uint32_t sum = 0;
        for (int i = 0; i < kMetaSymbols - 1; ++i) sum += kMetaFreq[size_t(i)];
        freqs.scale_bits = 12;
        freqs.nsym = kMetaSymbols;
        uint32_t start = 0;
        for (int i = 0; i < kMetaSymbols; ++i) {
            uint32_t f = i == kMetaEscape ? (1u << 12) - sum : kMetaFreq[size_t(i)];
            freqs.freq[size_t(i)] = f;
            freqs.start[size_t(i)] = start;
            start += f;
        }
        table.build(freqs);
        enc.build(freqs);
    }
};

const Meta& meta() {
    static const Meta m;
    return m;
}

}  // namespace

// Weights of a description scaled to 2^kMaxScaleBits: scaled[i] = floor(w_i * 4096 / W) with W
// the sum of the weights. The frequency at any scale s is then scaled[i] >> (12 - s), which equals
// floor(w_i * 2^s / W) (floor(floor(x) / 2^k) = floor(x / 2^k)): describe_counts prices all eight
// scales with one division per symbol instead of eight. Returns false for an invalid description.
static bool scaled_weights(const TableDesc& desc, std::array<uint32_t, kMaxAlphabet>& scaled) {
    const int n = desc.nsym;
    uint32_t total_weight = 0;
    for (int i = 0; i < n; ++i) {
        if (desc.code[size_t(i)] > kMaxWeightCode) return false;
        total_weight += weight_value(desc.code[size_t(i)]);
    }
    // weight_value(kMaxWeightCode) = 7 << 9, so w * 2^12 < 2^32.
    static_assert(uint64_t(7u << 9) << kMaxScaleBits < (uint64_t(1) << 32));
    for (int i = 0; i < n; ++i)
        scaled[size_t(i)] = (weight_value(desc.code[size_t(i)]) << kMaxScaleBits) / total_weight;
    return true;
}

// Frequencies at `scale_bits` from scaled_weights (n >= 2, the last symbol present): each present
// symbol gets max(1, floor(w * 2^scale / W)), then the first largest absorbs the difference.
// Writes out.freq[0, n) (and nsym, scale_bits) only: enough for data_cost_bits when the rest of
// out.freq is zero.
static bool frequencies(const std::array<uint32_t, kMaxAlphabet>& scaled, const TableDesc& desc, int scale_bits,
                        FreqTable& out) {
    const int n = desc.nsym;
    const uint32_t total_freq = 1u << scale_bits;
    const int down = kMaxScaleBits - scale_bits;
    out.scale_bits = scale_bits;
    out.nsym = n;
    uint32_t sum = 0;
    for (int i = 0; i < n; ++i) {
        out.freq[size_t(i)] = desc.code[size_t(i)] == 0 ? 0u : std::max(1u, scaled[size_t(i)] >> down);
        sum += out.freq[size_t(i)];
    }
    auto first_max = [&]() {
        int best = 0;
        for (int i = 1; i < n; ++i)
            if (out.freq[size_t(i)] > out.freq[size_t(best)]) best = i;
        return best;
    };
    if (sum < total_freq) {
        out.freq[size_t(first_max())] += total_freq - sum;
    } else {
        // The excess comes only from symbols raised to 1, so it is at most n - 1 < total_freq;
        // the largest frequency is then above 1 while the sum exceeds total_freq.
        while (sum > total_freq) {
            int best = first_max();
            if (out.freq[size_t(best)] <= 1) return false;  // cannot happen (total_freq >= 32 >= n)
            --out.freq[size_t(best)];
            --sum;
        }
    }
    return true;
}

// frequencies() plus the rest of a complete FreqTable.
static bool normalise(const std::array<uint32_t, kMaxAlphabet>& scaled, const TableDesc& desc, int scale_bits,
                      FreqTable& out) {
    const int n = desc.nsym;
    out.freq.fill(0);
    out.start.fill(0);
    if (!frequencies(scaled, desc, scale_bits, out)) return false;
    uint32_t start = 0;
    for (int i = 0; i < n; ++i) {
        out.start[size_t(i)] = start;
        start += out.freq[size_t(i)];
    }
    return true;
}

bool build_freqs(const TableDesc& desc, FreqTable& out) {
    if (desc.nsym < 1 || desc.nsym > kMaxAlphabet) return false;
    if (desc.scale_bits < kMinScaleBits || desc.scale_bits > kMaxScaleBits) return false;
    if (desc.nsym == 1) {
        out.scale_bits = desc.scale_bits;
        out.nsym = 1;
        out.freq.fill(0);
        out.start.fill(0);
        out.freq[0] = 1u << desc.scale_bits;
        return true;
    }
    if (desc.code[size_t(desc.nsym - 1)] == 0) return false;  // the last symbol is present by construction
    std::array<uint32_t, kMaxAlphabet> scaled;
    return scaled_weights(desc, scaled) && normalise(scaled, desc, desc.scale_bits, out);
}

// log2 of every possible frequency (at most 2^kMaxScaleBits), the same values std::log2 gives:
// the encoder costs every trial table at every scale (re-encoding the 1M-triangle scan's
// fragments: 2.3% fewer instructions with the table, by cachegrind).
static const std::array<double, (1u << kMaxScaleBits) + 1>& log2_of_frequency() {
    static const auto table = [] {
        std::array<double, (1u << kMaxScaleBits) + 1> t{};
        for (uint32_t f = 1; f < t.size(); ++f) t[f] = std::log2(double(f));
        return t;
    }();
    return table;
}

double data_cost_bits(const uint32_t* counts, const FreqTable& freqs) {
    const auto& log2f = log2_of_frequency();
    double bits = 0;
    for (int i = 0; i < kMaxAlphabet; ++i) {
        if (counts[i] == 0) continue;
        if (i >= freqs.nsym || freqs.freq[size_t(i)] == 0) return 1e30;
        const uint32_t f = freqs.freq[size_t(i)];
        bits += double(counts[i]) * (double(freqs.scale_bits) - (f < log2f.size() ? log2f[f] : std::log2(double(f))));
    }
    return bits;
}

// Cost in bits of the present symbols of describe_counts at one scale: frequencies() and
// data_cost_bits() restricted to the present symbols (absent ones have frequency 0, so they
// neither take part in the sum and the largest nor cost anything), with the same operations in
// the same order, so the same doubles. The encoder prices every trial table at all eight
// scales: looping over the 32 symbols with their zero tests was most of describe_counts
// (with the cost returned to the caller below: encode_bench encode about 2% faster).
struct PresentSymbols {
    int n = 0;                                   // number present (>= 2)
    std::array<uint8_t, kMaxAlphabet> symbol{};  // in increasing order
    std::array<double, kMaxAlphabet> count{};
};
static double cost_at_scale(const PresentSymbols& p, const std::array<uint32_t, kMaxAlphabet>& scaled,
                            int scale_bits) {
    const auto& log2f = log2_of_frequency();
    const uint32_t total_freq = 1u << scale_bits;
    const int down = kMaxScaleBits - scale_bits;
    uint32_t freq[kMaxAlphabet];
    uint32_t sum = 0;
    for (int j = 0; j < p.n; ++j) {
        freq[j] = std::max(1u, scaled[p.symbol[size_t(j)]] >> down);
        sum += freq[j];
    }
    auto first_max = [&]() {
        int best = 0;
        for (int j = 1; j < p.n; ++j)
            if (freq[j] > freq[best]) best = j;
        return best;
    };
    if (sum < total_freq) {
        freq[first_max()] += total_freq - sum;
    } else {
        while (sum > total_freq) {
            const int best = first_max();
            if (freq[best] <= 1) return 1e30;
            --freq[best];
            --sum;
        }
    }
    double bits = 0;
    for (int j = 0; j < p.n; ++j) bits += p.count[size_t(j)] * (double(scale_bits) - log2f[freq[j]]);
    return bits;
}

TableDesc describe_counts(const uint32_t* counts, int nsym, FreqTable* freqs, double* data_bits) {
    assert(nsym >= 1 && nsym <= kMaxAlphabet);
    TableDesc desc;
    int last = -1;
    PresentSymbols present;
    uint32_t max_count = 0;
    for (int i = 0; i < nsym; ++i) {
        if (counts[i] == 0) continue;
        last = i;
        present.symbol[size_t(present.n)] = uint8_t(i);
        present.count[size_t(present.n)] = double(counts[i]);
        ++present.n;
        max_count = std::max(max_count, counts[i]);
    }
    // The complete table and cost of a finished description, the slow way.
    auto finish_slowly = [&]() {
        if (freqs) {
            [[maybe_unused]] const bool ok = build_freqs(desc, *freqs);
            assert(ok);
            if (data_bits) *data_bits = data_cost_bits(counts, *freqs);
        }
        return desc;
    };
    if (present.n <= 1) {
        // One symbol (or none): give it the whole range, so it costs nothing.
        desc.nsym = last + 1 > 0 ? last + 1 : 1;
        desc.scale_bits = kMinScaleBits;
        if (desc.nsym > 1) desc.code[size_t(last)] = kMaxWeightCode;
        return finish_slowly();
    }
    desc.nsym = last + 1;
    static const std::array<double, kMaxWeightCode + 1> log_weight = [] {
        std::array<double, kMaxWeightCode + 1> t{};
        for (int k = 1; k <= kMaxWeightCode; ++k) t[size_t(k)] = std::log2(double(weight_value(k)));
        return t;
    }();
    const double top = log_weight[kMaxWeightCode];
    for (int j = 0; j < present.n; ++j) {
        const int i = present.symbol[size_t(j)];
        // The code nearest in the log domain to the count scaled so that the largest gets the top.
        const double target = top + std::log2(double(counts[i]) / double(max_count));
        // log_weight rises strictly with the code, so the distance to the target falls up to the
        // first code at or above it and rises after: the nearest is that code or the one before,
        // the smaller on a tie (as a linear scan keeping the first strict minimum would choose).
        const auto above = std::lower_bound(log_weight.begin() + 1, log_weight.end(), target);
        int best = int(above - log_weight.begin());
        if (best > kMaxWeightCode ||
            (best > 1 && std::fabs(log_weight[size_t(best - 1)] - target) <= std::fabs(log_weight[size_t(best)] - target)))
            --best;
        desc.code[size_t(i)] = uint8_t(best);
    }
    // Smallest scale whose cost is within a hair of the best (smaller tables decode faster).
    // The frequencies are those build_freqs derives, for all scales from one scaled_weights.
    std::array<uint32_t, kMaxAlphabet> scaled;
    if (!scaled_weights(desc, scaled)) {  // cannot happen (every code is valid)
        desc.scale_bits = kMaxScaleBits;
        return finish_slowly();
    }
    double costs[kMaxScaleBits + 1];
    double best_cost = 1e30;
    for (int s = kMinScaleBits; s <= kMaxScaleBits; ++s) {
        costs[s] = cost_at_scale(present, scaled, s);
        best_cost = std::min(best_cost, costs[s]);
    }
    desc.scale_bits = kMaxScaleBits;
    for (int s = kMinScaleBits; s <= kMaxScaleBits; ++s) {
        if (costs[s] <= best_cost * 1.001 + 0.5) {
            desc.scale_bits = s;
            break;
        }
    }
    // The chosen scale's table is the one build_freqs derives, and its cost is already known
    // (saves the caller build_freqs and data_cost_bits).
    if (freqs) {
        [[maybe_unused]] const bool ok = normalise(scaled, desc, desc.scale_bits, *freqs);
        assert(ok);
        if (data_bits) *data_bits = costs[desc.scale_bits];
    }
    return desc;
}

void DecodeTable::build(const FreqTable& f) {
    scale_bits = f.scale_bits;
    const uint32_t total = 1u << f.scale_bits;
    mask = total - 1;
    lut.resize(total);
    syms.resize(total);
    for (int s = 0; s < f.nsym; ++s) {
        uint32_t freq = f.freq[size_t(s)], start = f.start[size_t(s)];
        uint32_t* out = lut.data() + start;
        uint32_t j = 0;
#if defined(__SSE2__)
        // Four slots per store (tables are rebuilt for every fragment: this loop was about 2.5% of
        // the decoder's time, written out by four or vectorised by GCC with shuffles).
        __m128i slots = _mm_setr_epi32(int32_t(freq), int32_t(freq | 1u << 16), int32_t(freq | 2u << 16),
                                       int32_t(freq | 3u << 16));
        const __m128i step = _mm_set1_epi32(4 << 16);
        for (; j + 4 <= freq; j += 4) {
            _mm_storeu_si128(reinterpret_cast<__m128i*>(out + j), slots);
            slots = _mm_add_epi32(slots, step);
        }
#endif
        for (; j < freq; ++j) out[j] = freq | (j << 16);
        std::memset(syms.data() + start, s, freq);
    }
}

double table_cost_bits(const TableDesc& desc) {
    if (desc.nsym == 1) return 8;
    const FreqTable& m = meta().freqs;
    double bits = 8;
    int prev = kMaxWeightCode;
    for (int i = 0; i < desc.nsym; ++i) {
        int k = desc.code[size_t(i)];
        uint32_t sym;
        if (k == 0) {
            sym = 0;
        } else {
            int d = k - prev;
            sym = d >= 1 - kMetaBias && d <= kMetaEscape - 1 - kMetaBias ? uint32_t(d + kMetaBias) : kMetaEscape;
            if (sym == kMetaEscape) bits += 6;
            prev = k;
        }
        bits += 12.0 - log2_of_frequency()[m.freq[sym]];
    }
    return bits;
}

EncSymbol EncSymbol::make(uint32_t start, uint32_t freq, int scale_bits) {
    // ryg_rans RansEncSymbolInit: for freq >= 2, rcp = ceil(2^(shift + 31) / freq) with
    // shift = ceil(log2(freq)) makes q = floor(x / freq) for all x < 2^31; freq = 1 is handled by
    // rcp = 2^32 - 1 (q = x - 1) and a bias that adds the missing 2^scale - 1.
    EncSymbol s;
    const uint32_t total = 1u << scale_bits;
    s.x_max = ((kStateLower >> scale_bits) << 8) * freq;
    s.cmpl_freq = uint16_t(total - freq);
    if (freq < 2) {
        s.rcp_freq = ~0u;
        s.rcp_shift = 0;
        s.bias = start + total - 1;
    } else {
        uint32_t shift = 0;
        while (freq > (1u << shift)) ++shift;
        s.rcp_freq = uint32_t(((uint64_t(1) << (shift + 31)) + freq - 1) / freq);
        s.rcp_shift = uint8_t(shift - 1);
        s.bias = start;
    }
    return s;
}

void EncTable::build(const FreqTable& f) {
    sym.fill(EncSymbol{});
    for (int i = 0; i < f.nsym; ++i)
        if (f.freq[size_t(i)] != 0) sym[size_t(i)] = EncSymbol::make(f.start[size_t(i)], f.freq[size_t(i)], f.scale_bits);
}

void Encoder::reset() {
    ops_.clear();
    sections_.clear();
    bits_.clear();
    bit_acc_ = 0;
    bit_fill_ = 0;
}

void Encoder::flush_word() {
    const uint32_t w = uint32_t(bit_acc_);
    const uint8_t b[4] = {uint8_t(w), uint8_t(w >> 8), uint8_t(w >> 16), uint8_t(w >> 24)};
    bits_.insert(bits_.end(), b, b + 4);
    bit_acc_ >>= 32;
    bit_fill_ -= 32;
}

void Encoder::put_table(const TableDesc& desc) {
    put_bits(uint32_t(desc.nsym - 1), 5);
    put_bits(uint32_t(desc.scale_bits - kMinScaleBits), 3);
    if (desc.nsym == 1) return;
    const EncTable& m = meta().enc;
    int prev = kMaxWeightCode;
    for (int i = 0; i < desc.nsym; ++i) {
        int k = desc.code[size_t(i)];
        if (k == 0) {
            put(m, 0, 0);
            continue;
        }
        int d = k - prev;
        if (d >= 1 - kMetaBias && d <= kMetaEscape - 1 - kMetaBias) {
            put(m, uint32_t(d + kMetaBias), 0);
        } else {
            put(m, kMetaEscape, 0);
            put_bits(uint32_t(k), 6);
        }
        prev = k;
    }
}

namespace {
void put_varint(std::vector<uint8_t>& out, uint64_t v) {
    while (v >= 0x80) {
        out.push_back(uint8_t(v | 0x80));
        v >>= 7;
    }
    out.push_back(uint8_t(v));
}
}  // namespace

// One encoder step of a state: renormalise, then code the symbol.
CATPAQ_RANS_INLINE static uint32_t encode_step(const EncSymbol& op, uint32_t x, uint8_t*& at) {
    // Renormalise: shift out k = 0, 1 or 2 bytes (x >> 8 >= x_max iff x >= x_max << 8).
    // Both candidate bytes are stored below `at` unconditionally (the buffer has room) and
    // the k wanted ones kept, without a branch on the unpredictable k.
    const uint32_t k = uint32_t(x >= op.x_max) + uint32_t(uint64_t(x) >= uint64_t(op.x_max) << 8);
    at[-1] = uint8_t(x);
    at[-2] = uint8_t(x >> 8);
    at -= k;
    x = uint32_t(uint64_t(x) >> (8 * k));
    return op.update(x);
}

uint8_t* Encoder::encode_ops(size_t first, size_t end, uint32_t state[4], uint8_t* at) const {
    // The four states in registers, the lane picked by a branch: lanes follow short periodic
    // patterns (0 1 2 per vertex for positions and colours, 0 1 for normals, 0 1 2 3 for
    // connectivity), which the branch predictor learns, while state[op.lane] in memory put a
    // store-to-load forwarding on every symbol's dependency chain (encode_bench encode about
    // 4% faster; encode_ops was 11% of its profile, 8% after).
    uint32_t x0 = state[0], x1 = state[1], x2 = state[2], x3 = state[3];
    const EncSymbol* const ops = ops_.data();
    for (size_t i = end; i-- > first;) {
        const EncSymbol& op = ops[i];
        switch (op.lane) {
            case 0: x0 = encode_step(op, x0, at); break;
            case 1: x1 = encode_step(op, x1, at); break;
            case 2: x2 = encode_step(op, x2, at); break;
            default: x3 = encode_step(op, x3, at); break;
        }
    }
    state[0] = x0, state[1] = x1, state[2] = x2, state[3] = x3;
    return at;
}

void Encoder::finish(std::vector<uint8_t>& out, std::vector<size_t>* section_bytes) {
    // Remaining raw bits, the last byte padded with zeros.
    const uint64_t bits_put = bit_count();
    for (; bit_fill_ > 0; bit_fill_ -= 8) {
        bits_.push_back(uint8_t(bit_acc_));
        bit_acc_ >>= 8;
    }
    bit_fill_ = 0;
    bit_acc_ = 0;
    // The rANS bytes are produced last to first: written downwards from the end of a buffer of
    // the largest possible size (2 bytes per symbol) plus the 2 bytes of slack encode_ops needs.
    rans_bytes_.resize(2 * ops_.size() + 2);
    uint8_t* const top = rans_bytes_.data() + rans_bytes_.size();
    uint8_t* at = top;
    uint32_t state[4] = {kStateLower, kStateLower, kStateLower, kStateLower};
    std::vector<size_t> rans_bytes(sections_.size(), 0);
    size_t end = ops_.size();
    for (size_t k = sections_.size(); k-- > 0;) {
        uint8_t* before = at;
        at = encode_ops(sections_[k].first_op, end, state, at);
        rans_bytes[k] = size_t(before - at);
        end = sections_[k].first_op;
    }
    at = encode_ops(0, end, state, at);  // symbols before the first section (none are counted)
    const size_t at_out = out.size();
    for (uint32_t x : state)
        for (int k = 0; k < 4; ++k) out.push_back(uint8_t(x >> (8 * k)));
    put_varint(out, bits_.size());
    out.insert(out.end(), at, top);
    out.insert(out.end(), bits_.begin(), bits_.end());
    if (section_bytes) {
        // Raw bits per section, rounded so that the total is exact; fixed fields to section 0.
        section_bytes->assign(sections_.size(), 0);
        uint64_t assigned_bits = 0;
        size_t assigned = 0;
        for (size_t k = 0; k < sections_.size(); ++k) {
            uint64_t end_bit = k + 1 < sections_.size() ? sections_[k + 1].first_bit : bits_put;
            uint64_t bits_here = end_bit - sections_[k].first_bit;
            size_t bytes = size_t((assigned_bits + bits_here + 7) / 8) - size_t((assigned_bits + 7) / 8);
            assigned_bits += bits_here;
            (*section_bytes)[k] = rans_bytes[k] + bytes;
            assigned += (*section_bytes)[k];
        }
        if (!section_bytes->empty()) (*section_bytes)[0] += (out.size() - at_out) - assigned;
    }
}

bool Decoder::init(const uint8_t* data, size_t size) {
    failed = true;
    if (size < 16) return false;
    uint32_t x[4];
    for (int s = 0; s < 4; ++s) {
        const uint8_t* q = data + 4 * s;
        x[s] = uint32_t(q[0]) | uint32_t(q[1]) << 8 | uint32_t(q[2]) << 16 | uint32_t(q[3]) << 24;
        if (x[s] < kStateLower || x[s] >= (kStateLower << 8)) return false;
    }
    x0 = x[0], x1 = x[1], x2 = x[2], x3 = x[3];
    const uint8_t* q = data + 16;
    const uint8_t* stop = data + size;
    uint64_t bit_bytes = 0;
    for (int shift = 0;; shift += 7) {
        if (q == stop || shift > 35) return false;
        uint8_t b = *q++;
        bit_bytes |= uint64_t(b & 0x7f) << shift;
        if (!(b & 0x80)) break;
    }
    if (bit_bytes > size_t(stop - q)) return false;
    p = q;
    end = stop - bit_bytes;
    bit_p = end;
    bit_end = stop;
    bit_buf = 0;
    bit_count = 0;
    bit_phantom = 0;
    failed = false;
    return true;
}

Decoder Decoder::refilled_slowly(Decoder d, uint32_t need) {
    d.refill_slow(need);
    return d;
}

void Decoder::refill_slow(uint32_t need) {
    while (bit_count <= 56 && bit_p < bit_end) {
        bit_buf |= uint64_t(*bit_p++) << bit_count;
        bit_count += 8;
    }
    if (bit_count < need) {
        // Past the end: supply zero bits (bit_buf holds zeros above bit_count), remembered so
        // that consuming them is detected at the end.
        bit_phantom += need - bit_count;
        bit_count = need;
    }
}

bool Decoder::finished_cleanly() const {
    if (failed) return false;
    if (x0 != kStateLower || x1 != kStateLower || x2 != kStateLower || x3 != kStateLower) return false;
    if (p != end) return false;
    // Supplied zero bits sit on top of the buffer: none may have been consumed. The real bits
    // left (fewer than 8: padding) must be zero, and no byte may be left unread.
    if (bit_p != bit_end || bit_count < bit_phantom) return false;
    uint64_t real = bit_count - bit_phantom;
    if (real >= 8) return false;
    return (bit_buf & ((uint64_t(1) << real) - 1)) == 0;
}

// A symbol of the meta table (on lane 0, any position), the same state update as get(), but
// from the table's 4 KB symbol map and its 31 frequencies instead of its 16 KB packed words: the
// descriptions are decoded one symbol after another at the start of every fragment, when the
// packed table had mostly left the L1 cache (its loads were 70% of get_table's time, get_table
// about 2.5% of the decoder's).
uint32_t Decoder::get_meta(const uint8_t* syms, const FreqTable& f) {
    uint32_t x = x0;
    const uint32_t slot = x & ((1u << 12) - 1);
    const uint32_t s = syms[slot];
    x = f.freq[s] * (x >> 12) + slot - f.start[s];
    if (rans_bytes_left() >= kMaxBytesPerSymbol) {
        renormalise(x);
    } else {
        for (int i = 0; i < 2 && x < kStateLower; ++i) {
            if (p == end) {
                failed = true;
                x |= kStateLower;  // keep the state in range; the stream is already invalid
                break;
            }
            x = (x << 8) | *p++;
        }
    }
    x0 = x;
    return s;
}

bool Decoder::get_table(FreqTable& freqs, DecodeTable& table) {
    TableDesc desc;
    desc.nsym = int(get_bits(5)) + 1;
    desc.scale_bits = int(get_bits(3)) + kMinScaleBits;
    if (desc.scale_bits > kMaxScaleBits) return false;
    if (desc.nsym > 1) {
        const Meta& m = meta();
        int prev = kMaxWeightCode;
        for (int i = 0; i < desc.nsym; ++i) {
            uint32_t s = get_meta(m.table.syms.data(), m.freqs);
            int k;
            if (s == 0) {
                k = 0;
            } else if (s == uint32_t(kMetaEscape)) {
                k = int(get_bits(6));
                if (k < 1 || k > kMaxWeightCode) return false;
            } else {
                k = prev + int(s) - kMetaBias;
                if (k < 1 || k > kMaxWeightCode) return false;
            }
            desc.code[size_t(i)] = uint8_t(k);
            if (k) prev = k;
        }
    }
    if (!build_freqs(desc, freqs)) return false;
    table.build(freqs);
    return !failed;
}

}  // namespace catpaq::rans
