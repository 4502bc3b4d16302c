// LAS 1.2 and LAZ writing for the benchmark (laz_writer.h). The compressed form follows LASzip's
// definition of "pointwise chunked" LAZ with version 2 items: an adaptive arithmetic coder
// (Amir Said's FastAC as LASzip adapted it: 32-bit base and length, a byte out whenever the
// length falls below 2^24, symbol models whose cumulative counts are rebuilt on a growing cycle,
// bit models likewise), an integer compressor that sends a corrector's bit length k under a
// context and then its k bits, and the POINT10 and RGB12 item compressors that decide what is
// predicted from what. Decoders replay the same model updates, so every count, cycle and rounding
// below is part of the format: changing one makes files no LAZ reader can read.
#include "laz_writer.h"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <memory>

#include <filesystem>
#include <pwd.h>
#include <unistd.h>

#include "base/atomic_file.h"
#include "base/child_process.h"
#include "base/error.h"

namespace catpaq::laz {
namespace {

// ---------------------------------------------------------------------------------------------
// Little-endian output

void put_u8(std::string& out, uint8_t v) { out.push_back(char(v)); }
void put_u16(std::string& out, uint16_t v) {
    for (int i = 0; i < 2; ++i) out.push_back(char(v >> (8 * i)));
}
void put_u32(std::string& out, uint32_t v) {
    for (int i = 0; i < 4; ++i) out.push_back(char(v >> (8 * i)));
}
void put_u64(std::string& out, uint64_t v) {
    for (int i = 0; i < 8; ++i) out.push_back(char(v >> (8 * i)));
}
void put_f64(std::string& out, double v) {
    uint64_t bits;
    std::memcpy(&bits, &v, 8);
    put_u64(out, bits);
}
// A fixed-width text field, zero-padded (LAS's char[n]).
void put_text(std::string& out, const std::string& text, size_t width) {
    assert(text.size() <= width);
    out += text;
    out.append(width - text.size(), '\0');
}
void patch_u64(std::string& out, size_t at, uint64_t v) {
    for (int i = 0; i < 8; ++i) out[at + i] = char(v >> (8 * i));
}

// The return/flags byte of formats 0-5: return number in bits 0-2, number of returns in bits
// 3-5, scan direction in bit 6, edge of flight line in bit 7.
uint8_t flags_byte(const LasPoint& p) {
    return uint8_t(p.return_number | (p.number_of_returns << 3) | (p.scan_direction ? 0x40 : 0) |
                   (p.edge_of_flight_line ? 0x80 : 0));
}

// ---------------------------------------------------------------------------------------------
// The adaptive models (LASzip's ArithmeticBitModel and ArithmeticModel, encoder side)

constexpr uint32_t kMinLength = 0x01000000u;  // below this the coder sends its top byte
constexpr uint32_t kMaxLength = 0xFFFFFFFFu;  // the interval's length after a (re)start
constexpr uint32_t kBitLengthShift = 13;      // bit models: probabilities of 13 bits
constexpr uint32_t kBitMaxCount = 1u << kBitLengthShift;
constexpr uint32_t kSymbolLengthShift = 15;  // symbol models: cumulative counts of 15 bits
constexpr uint32_t kSymbolMaxCount = 1u << kSymbolLengthShift;

// A binary model: the probability of a zero, re-estimated every `update_cycle` bits (4 at first,
// growing by 5/4 to 64), the counts halved when they pass kBitMaxCount.
class BitModel {
public:
    BitModel() { reset(); }
    void reset() {
        zero_count_ = 1;
        count_ = 2;
        zero_probability_ = 1u << (kBitLengthShift - 1);
        update_cycle_ = until_update_ = 4;
    }
    uint32_t zero_probability() const { return zero_probability_; }
    void count(uint32_t bit) {
        if (bit == 0) ++zero_count_;
        if (--until_update_ == 0) update();
    }

private:
    void update() {
        if ((count_ += update_cycle_) > kBitMaxCount) {
            count_ = (count_ + 1) >> 1;
            zero_count_ = (zero_count_ + 1) >> 1;
            if (zero_count_ == count_) ++count_;  // a one stays possible
        }
        const uint32_t scale = 0x80000000u / count_;
        zero_probability_ = (zero_count_ * scale) >> (31 - kBitLengthShift);
        update_cycle_ = std::min<uint32_t>((5 * update_cycle_) >> 2, 64);
        until_update_ = update_cycle_;
    }
    uint32_t zero_count_, count_, zero_probability_, update_cycle_, until_update_;
};

// A model of `symbols` symbols (2..2048): each symbol's cumulative count scaled to 15 bits,
// rebuilt every `update_cycle` symbols ((symbols + 6) / 2 at first, growing by 5/4 to
// 8 (symbols + 6)), the counts halved when their total passes kSymbolMaxCount.
class SymbolModel {
public:
    explicit SymbolModel(uint32_t symbols) : cumulative_(symbols), counts_(symbols) {
        assert(symbols >= 2 && symbols <= 2048);
        reset();
    }
    void reset() {
        std::fill(counts_.begin(), counts_.end(), 1u);
        total_ = 0;
        update_cycle_ = symbols();
        update();  // the total becomes the symbol count: every symbol counted once
        update_cycle_ = until_update_ = (symbols() + 6) >> 1;
    }
    uint32_t symbols() const { return uint32_t(counts_.size()); }
    uint32_t last_symbol() const { return symbols() - 1; }
    uint32_t cumulative(uint32_t symbol) const { return cumulative_[symbol]; }
    void count(uint32_t symbol) {
        ++counts_[symbol];
        if (--until_update_ == 0) update();
    }

private:
    void update() {
        if ((total_ += update_cycle_) > kSymbolMaxCount) {
            total_ = 0;
            for (uint32_t& c : counts_) total_ += (c = (c + 1) >> 1);
        }
        const uint32_t scale = 0x80000000u / total_;
        uint32_t sum = 0;
        for (uint32_t k = 0; k < symbols(); ++k) {
            cumulative_[k] = (scale * sum) >> (31 - kSymbolLengthShift);
            sum += counts_[k];
        }
        update_cycle_ = std::min((5 * update_cycle_) >> 2, (symbols() + 6) << 3);
        until_update_ = update_cycle_;
    }
    std::vector<uint32_t> cumulative_, counts_;
    uint32_t total_ = 0, update_cycle_ = 0, until_update_ = 0;
};

// ---------------------------------------------------------------------------------------------
// The arithmetic encoder (LASzip's ArithmeticEncoder), appending to a string. The interval is
// [base, base + length) in 32 bits; when base overflows, the carry goes into the bytes already
// sent, which is why they stay in memory until the chunk is done.

class ArithmeticEncoder {
public:
    explicit ArithmeticEncoder(std::string& out) : out_(out), start_(out.size()) {}

    void encode_bit(BitModel& model, uint32_t bit) {
        assert(bit <= 1);
        const uint32_t split = model.zero_probability() * (length_ >> kBitLengthShift);
        if (bit == 0) {
            length_ = split;
        } else {
            add_to_base(split);
            length_ -= split;
        }
        if (length_ < kMinLength) renormalize();
        model.count(bit);
    }

    void encode_symbol(SymbolModel& model, uint32_t symbol) {
        assert(symbol <= model.last_symbol());
        if (symbol == model.last_symbol()) {  // the top of the interval: no second product
            const uint32_t low = model.cumulative(symbol) * (length_ >> kSymbolLengthShift);
            add_to_base(low);
            length_ -= low;
        } else {
            length_ >>= kSymbolLengthShift;
            const uint32_t low = model.cumulative(symbol) * length_;
            add_to_base(low);
            length_ = model.cumulative(symbol + 1) * length_ - low;
        }
        if (length_ < kMinLength) renormalize();
        model.count(symbol);
    }

    // `bits` (1..32) raw bits of `value`; more than 19 go as 16 then the rest, so that the
    // length keeps enough bits for the product.
    void write_bits(uint32_t bits, uint32_t value) {
        assert(bits >= 1 && bits <= 32 && (bits == 32 || value < (1u << bits)));
        if (bits > 19) {
            write_raw(16, value & 0xFFFFu);
            value >>= 16;
            bits -= 16;
        }
        write_raw(bits, value);
    }

    // Ends the stream: moves base into the interval so the bytes sent identify it, sends the
    // last bytes, then two or three zero bytes because the decoder reads 4 bytes ahead (its
    // start reads 4 and it reads one per byte the encoder sent, so it must find them here rather
    // than in the next chunk).
    void finish() {
        const uint32_t before = base_;
        bool third_zero = true;
        if (length_ > 2 * kMinLength) {
            base_ += kMinLength;
            length_ = kMinLength >> 1;  // one more byte identifies the interval
        } else {
            base_ += kMinLength >> 1;
            length_ = kMinLength >> 9;  // two more bytes
            third_zero = false;
        }
        if (base_ < before) propagate_carry();
        renormalize();
        out_.append(third_zero ? 3 : 2, '\0');
    }

private:
    void write_raw(uint32_t bits, uint32_t value) {
        length_ >>= bits;
        add_to_base(value * length_);
        if (length_ < kMinLength) renormalize();
    }
    void add_to_base(uint32_t amount) {
        const uint32_t before = base_;
        base_ += amount;
        if (base_ < before) propagate_carry();
    }
    // Adds one to the number the sent bytes spell: trailing 0xFF bytes become 0.
    void propagate_carry() {
        size_t i = out_.size();
        while (i > start_ && uint8_t(out_[i - 1]) == 0xFF) out_[--i] = 0;
        assert(i > start_);  // the coded number stays below 1: a carry never leaves the stream
        out_[i - 1] = char(uint8_t(out_[i - 1]) + 1);
    }
    // Sends base's top byte and scales the interval by 256 until its length is large again.
    void renormalize() {
        do {
            out_.push_back(char(base_ >> 24));
            base_ <<= 8;
        } while ((length_ <<= 8) < kMinLength);
    }

    std::string& out_;
    const size_t start_;  // this stream's first byte in out_
    uint32_t base_ = 0, length_ = kMaxLength;
};

// ---------------------------------------------------------------------------------------------
// LASzip's IntegerCompressor: codes real - predicted (the corrector c). With k the smallest
// integer such that c lies in [-(2^k - 1), 2^k], k goes under a symbol model chosen by the
// caller's context; then c's place in that interval, k bits: for k <= bits_high under a model of
// its own per k, else the top bits_high bits so and the rest raw. k = 0 (c is 0 or 1) is one
// modelled bit. Always the "range 0" form: correctors wrap modulo 2^bits.

class IntegerCompressor {
public:
    IntegerCompressor(uint32_t bits, uint32_t contexts, uint32_t bits_high = 8)
        : bits_(bits), bits_high_(bits_high), k_models_(contexts, SymbolModel(bits + 1)) {
        assert(bits >= 1 && bits <= 32 && contexts >= 1);
        for (uint32_t k = 1; k <= bits; ++k) in_interval_.emplace_back(1u << std::min(k, bits_high));
    }

    void reset() {
        for (SymbolModel& m : k_models_) m.reset();
        zero_or_one_.reset();
        for (SymbolModel& m : in_interval_) m.reset();
        k_ = 0;
    }

    void compress(ArithmeticEncoder& encoder, int32_t predicted, int32_t real, uint32_t context) {
        assert(context < k_models_.size());
        write_corrector(encoder, fold(int64_t(real) - int64_t(predicted)), k_models_[context]);
    }

    // The k of the last corrector: the item compressors choose later contexts by it.
    uint32_t last_k() const { return k_; }

private:
    // The corrector in [-2^(bits-1), 2^(bits-1) - 1], modulo 2^bits.
    int32_t fold(int64_t corrector) const {
        if (bits_ == 32) return int32_t(uint32_t(uint64_t(corrector)));
        const int64_t range = int64_t(1) << bits_, low = -(range / 2), high = low + range - 1;
        if (corrector < low) corrector += range;
        else if (corrector > high) corrector -= range;
        return int32_t(corrector);
    }

    void write_corrector(ArithmeticEncoder& encoder, int32_t c, SymbolModel& k_model) {
        // c in [-(2^k - 1), 2^k]: k is the bit length of |c| for c <= 0 and of c - 1 above.
        const uint32_t magnitude = c <= 0 ? 0u - uint32_t(c) : uint32_t(c) - 1;
        k_ = 0;
        for (uint32_t m = magnitude; m; m >>= 1) ++k_;
        encoder.encode_symbol(k_model, k_);
        if (k_ == 0) {
            encoder.encode_bit(zero_or_one_, uint32_t(c));
            return;
        }
        if (k_ == 32) return;  // c is -2^31, the only corrector of k 32: nothing more to say
        // Negative c maps to [0, 2^(k-1) - 1], positive c to [2^(k-1), 2^k - 1].
        const uint32_t place = c < 0 ? uint32_t(int64_t(c) + (int64_t(1) << k_) - 1) : uint32_t(c) - 1;
        SymbolModel& model = in_interval_[k_ - 1];
        if (k_ <= bits_high_) {
            encoder.encode_symbol(model, place);
        } else {
            const uint32_t low_bits = k_ - bits_high_;
            encoder.encode_symbol(model, place >> low_bits);
            encoder.write_bits(low_bits, place & ((1u << low_bits) - 1));
        }
    }

    uint32_t bits_, bits_high_;
    std::vector<SymbolModel> k_models_;     // one per context, symbols 0..bits
    BitModel zero_or_one_;                  // k = 0
    std::vector<SymbolModel> in_interval_;  // k = 1..bits: c's place in its interval
    uint32_t k_ = 0;
};

// ---------------------------------------------------------------------------------------------
// The POINT10 item, version 2

// LASzip's streaming median of the last five values: five sorted values; each new value
// replaces the largest or the smallest, alternating by where the values arrive, so the middle
// one follows the recent differences without sorting a window.
class StreamingMedian5 {
public:
    void reset() {
        std::fill(std::begin(values_), std::end(values_), 0);
        drop_largest_ = true;
    }
    int32_t median() const { return values_[2]; }
    void add(int32_t v) {
        const int32_t median = values_[2];
        if (drop_largest_) {
            int i = 4;  // the largest's slot is free: shift larger values up into it
            for (; i > 0 && v < values_[i - 1]; --i) values_[i] = values_[i - 1];
            values_[i] = v;
            if (v >= median) drop_largest_ = false;
        } else {
            int i = 0;  // the smallest's slot is free: shift smaller values down into it
            for (; i < 4 && values_[i + 1] < v; ++i) values_[i] = values_[i + 1];
            values_[i] = v;
            if (v <= median) drop_largest_ = true;
        }
    }

private:
    int32_t values_[5] = {0, 0, 0, 0, 0};
    bool drop_largest_ = true;
};

// The context of a point's return number r among n returns ([n][r], 0..15): LASzip's table,
// which gives the 15 valid pairs (1 <= r <= n <= 5) their own contexts and shares the rest.
constexpr uint8_t kReturnContext[8][8] = {
    {15, 14, 13, 12, 11, 10, 9, 8},   {14, 0, 1, 3, 6, 10, 10, 9},      {13, 1, 2, 4, 7, 11, 11, 10},
    {12, 3, 4, 5, 8, 12, 12, 11},     {11, 6, 7, 8, 9, 13, 13, 12},     {10, 10, 11, 12, 13, 14, 14, 13},
    {9, 10, 11, 12, 13, 14, 15, 14},  {8, 9, 10, 11, 12, 13, 14, 15}};

class Point10Compressor {
public:
    Point10Compressor() : changed_(64), scan_angle_{SymbolModel(256), SymbolModel(256)} {}

    // A chunk's first point, written raw by the caller, starts the predictions; every model
    // starts over (models made on demand in an earlier chunk are reset, as new ones would be).
    void start_chunk(const LasPoint& first) {
        changed_.reset();
        intensity_.reset();
        for (SymbolModel& m : scan_angle_) m.reset();
        source_id_.reset();
        for (auto* table : {&flags_by_last_, &classification_by_last_, &user_data_by_last_})
            for (std::unique_ptr<SymbolModel>& m : *table)
                if (m) m->reset();
        dx_.reset();
        dy_.reset();
        z_.reset();
        for (int i = 0; i < 16; ++i) {
            x_diffs_[i].reset();
            y_diffs_[i].reset();
            last_intensity_[i] = 0;  // not the first point's: LASzip starts these at 0
        }
        std::fill(std::begin(last_z_), std::end(last_z_), 0);  // likewise
        last_ = first;
    }

    void compress(ArithmeticEncoder& encoder, const LasPoint& p) {
        const uint32_t r = p.return_number, n = p.number_of_returns;
        const uint32_t context = kReturnContext[n][r];
        const uint32_t level = n > r ? n - r : r - n;  // LASzip's number_return_level table
        const uint8_t flags = flags_byte(p), last_flags = flags_byte(last_);

        // Which of the other fields differ from the last point's (intensity: from the last of
        // the same return context).
        const uint32_t changed = (uint32_t(flags != last_flags) << 5) |
                                 (uint32_t(p.intensity != last_intensity_[context]) << 4) |
                                 (uint32_t(p.classification != last_.classification) << 3) |
                                 (uint32_t(p.scan_angle_rank != last_.scan_angle_rank) << 2) |
                                 (uint32_t(p.user_data != last_.user_data) << 1) |
                                 uint32_t(p.point_source_id != last_.point_source_id);
        encoder.encode_symbol(changed_, changed);
        if (changed & 32) encoder.encode_symbol(model_for(flags_by_last_, last_flags), flags);
        if (changed & 16) {
            intensity_.compress(encoder, last_intensity_[context], p.intensity, std::min(context, 3u));
            last_intensity_[context] = p.intensity;
        }
        if (changed & 8) encoder.encode_symbol(model_for(classification_by_last_, last_.classification), p.classification);
        if (changed & 4)  // the byte difference, under the current point's scan direction
            encoder.encode_symbol(scan_angle_[p.scan_direction ? 1 : 0],
                                  uint8_t(uint8_t(p.scan_angle_rank) - uint8_t(last_.scan_angle_rank)));
        if (changed & 2) encoder.encode_symbol(model_for(user_data_by_last_, last_.user_data), p.user_data);
        if (changed & 1) source_id_.compress(encoder, last_.point_source_id, p.point_source_id, 0);

        // x: the difference from the last x, predicted by the median of the recent ones; y
        // likewise under a context from x's k; z from the last z of the same return level
        // under a context from x's and y's k. Differences wrap modulo 2^32 as LASzip's do.
        const uint32_t single = n == 1 ? 1 : 0;
        const int32_t dx = int32_t(uint32_t(p.x) - uint32_t(last_.x));
        dx_.compress(encoder, x_diffs_[context].median(), dx, single);
        x_diffs_[context].add(dx);
        uint32_t k = dx_.last_k();
        const int32_t dy = int32_t(uint32_t(p.y) - uint32_t(last_.y));
        dy_.compress(encoder, y_diffs_[context].median(), dy, single + (k < 20 ? k & ~1u : 20));
        y_diffs_[context].add(dy);
        k = (dx_.last_k() + dy_.last_k()) / 2;
        z_.compress(encoder, last_z_[level], p.z, single + (k < 18 ? k & ~1u : 18));
        last_z_[level] = p.z;
        last_ = p;
    }

private:
    // The model of a byte given the last point's value of it, made when first needed.
    static SymbolModel& model_for(std::array<std::unique_ptr<SymbolModel>, 256>& table, uint8_t last) {
        if (!table[last]) table[last] = std::make_unique<SymbolModel>(256);
        return *table[last];
    }

    SymbolModel changed_;
    IntegerCompressor intensity_{16, 4};
    SymbolModel scan_angle_[2];
    IntegerCompressor source_id_{16, 1};
    std::array<std::unique_ptr<SymbolModel>, 256> flags_by_last_, classification_by_last_, user_data_by_last_;
    IntegerCompressor dx_{32, 2}, dy_{32, 22}, z_{32, 20};
    StreamingMedian5 x_diffs_[16], y_diffs_[16];
    uint16_t last_intensity_[16] = {};
    int32_t last_z_[8] = {};
    LasPoint last_;
};

// ---------------------------------------------------------------------------------------------
// The RGB12 item, version 2: which of the six bytes changed (and whether the colour is grey),
// then red's bytes as differences, green's and blue's as corrections of red's difference
// applied to their own last value.

class Rgb12Compressor {
public:
    Rgb12Compressor() : byte_used_(128), diffs_(6, SymbolModel(256)) {}

    void start_chunk(const LasPoint& first) {
        byte_used_.reset();
        for (SymbolModel& m : diffs_) m.reset();
        std::copy(std::begin(first.rgb), std::end(first.rgb), last_);
    }

    void compress(ArithmeticEncoder& encoder, const LasPoint& p) {
        const uint16_t* c = p.rgb;
        auto lo = [](uint16_t v) { return int(v & 0xFF); };
        auto hi = [](uint16_t v) { return int(v >> 8); };
        auto clamp = [](int v) { return std::clamp(v, 0, 255); };
        auto fold = [](int v) { return uint32_t(uint8_t(v)); };  // a difference modulo 256
        uint32_t used = 0;
        for (int i = 0; i < 3; ++i) {
            used |= uint32_t(lo(c[i]) != lo(last_[i])) << (2 * i);
            used |= uint32_t(hi(c[i]) != hi(last_[i])) << (2 * i + 1);
        }
        const bool coloured = lo(c[0]) != lo(c[1]) || lo(c[0]) != lo(c[2]) || hi(c[0]) != hi(c[1]) || hi(c[0]) != hi(c[2]);
        used |= uint32_t(coloured) << 6;  // else green and blue are red's, nothing more is sent
        encoder.encode_symbol(byte_used_, used);
        int diff_lo = 0, diff_hi = 0;
        if (used & 1) encoder.encode_symbol(diffs_[0], fold(diff_lo = lo(c[0]) - lo(last_[0])));
        if (used & 2) encoder.encode_symbol(diffs_[1], fold(diff_hi = hi(c[0]) - hi(last_[0])));
        if (coloured) {
            if (used & 4) encoder.encode_symbol(diffs_[2], fold(lo(c[1]) - clamp(diff_lo + lo(last_[1]))));
            if (used & 16) {  // blue from the mean of red's and green's differences
                diff_lo = (diff_lo + lo(c[1]) - lo(last_[1])) / 2;
                encoder.encode_symbol(diffs_[4], fold(lo(c[2]) - clamp(diff_lo + lo(last_[2]))));
            }
            if (used & 8) encoder.encode_symbol(diffs_[3], fold(hi(c[1]) - clamp(diff_hi + hi(last_[1]))));
            if (used & 32) {
                diff_hi = (diff_hi + hi(c[1]) - hi(last_[1])) / 2;
                encoder.encode_symbol(diffs_[5], fold(hi(c[2]) - clamp(diff_hi + hi(last_[2]))));
            }
        }
        std::copy(c, c + 3, last_);
    }

private:
    SymbolModel byte_used_;
    std::vector<SymbolModel> diffs_;  // red low, red high, green low, green high, blue low, blue high
    uint16_t last_[3] = {0, 0, 0};
};

// ---------------------------------------------------------------------------------------------
// The file

constexpr uint16_t kHeaderSize = 227;  // LAS 1.2 public header block
constexpr uint16_t kVlrHeaderSize = 54;
constexpr uint16_t kLaszipRecordId = 22204;
constexpr uint16_t kCompressorPointwiseChunked = 2;
constexpr uint16_t kItemPoint10 = 6, kItemRgb12 = 8;

void check_layout(const LasLayout& layout) {
    for (int a = 0; a < 3; ++a) {
        if (!(std::isfinite(layout.scale[a]) && layout.scale[a] > 0))
            fail("LAS writer: scale %g is not a finite positive number", layout.scale[a]);
        if (!std::isfinite(layout.offset[a])) fail("LAS writer: offset %g is not finite", layout.offset[a]);
    }
}

void check_points(const std::vector<LasPoint>& points) {
    if (points.size() > UINT32_MAX) fail("LAS writer: %zu points, LAS 1.2 holds at most 2^32 - 1", points.size());
    for (size_t i = 0; i < points.size(); ++i)
        if (points[i].return_number > 7 || points[i].number_of_returns > 7)
            fail("LAS writer: point %zu has return %u of %u; both must fit 3 bits (0..7)", i, points[i].return_number,
                 points[i].number_of_returns);
}

// The public header block of LAS 1.2 with the points' counts and bounds.
std::string las_header(const std::vector<LasPoint>& points, const LasLayout& layout, bool compressed,
                       uint32_t vlr_count, uint32_t vlr_bytes) {
    std::string out;
    out += "LASF";
    put_u16(out, 0);                  // file source ID
    put_u16(out, 0);                  // global encoding
    out.append(16, '\0');             // project GUID
    put_u8(out, 1);                   // version 1.2
    put_u8(out, 2);
    put_text(out, "OTHER", 32);       // system identifier
    put_text(out, "catpaq points_bench", 32);
    put_u16(out, 0);                  // creation day and year: not recorded, so files are reproducible
    put_u16(out, 0);
    put_u16(out, kHeaderSize);
    put_u32(out, kHeaderSize + vlr_bytes);  // offset to the point data
    put_u32(out, vlr_count);
    const uint8_t format = layout.colors ? 2 : 0;
    put_u8(out, uint8_t(compressed ? format | 0x80 : format));  // bit 7: LASzip's mark of LAZ
    put_u16(out, uint16_t(las_record_length(layout.colors)));
    put_u32(out, uint32_t(points.size()));
    uint32_t by_return[5] = {};
    for (const LasPoint& p : points)
        if (p.return_number >= 1 && p.return_number <= 5) ++by_return[p.return_number - 1];
    for (uint32_t count : by_return) put_u32(out, count);
    for (double s : layout.scale) put_f64(out, s);
    for (double o : layout.offset) put_f64(out, o);
    int32_t low[3] = {0, 0, 0}, high[3] = {0, 0, 0};
    for (size_t i = 0; i < points.size(); ++i) {
        const int32_t v[3] = {points[i].x, points[i].y, points[i].z};
        for (int a = 0; a < 3; ++a) {
            low[a] = i ? std::min(low[a], v[a]) : v[a];
            high[a] = i ? std::max(high[a], v[a]) : v[a];
        }
    }
    for (int a = 0; a < 3; ++a) {  // max x, min x, max y, min y, max z, min z
        put_f64(out, high[a] * layout.scale[a] + layout.offset[a]);
        put_f64(out, low[a] * layout.scale[a] + layout.offset[a]);
    }
    assert(out.size() == kHeaderSize);
    return out;
}

// The "laszip encoded" VLR: compressor, coder, version, options, chunk size, the special EVLR
// fields (none: -1) and the items (type, size, version) each record is made of.
std::string laszip_vlr(const LasLayout& layout, uint32_t chunk_points) {
    std::string payload;
    put_u16(payload, kCompressorPointwiseChunked);
    put_u16(payload, 0);  // coder: arithmetic
    put_u8(payload, 2);   // the LASzip version whose format this is: 2.2.0
    put_u8(payload, 2);
    put_u16(payload, 0);
    put_u32(payload, 0);  // options
    put_u32(payload, chunk_points);
    put_u64(payload, uint64_t(-1));  // number of special EVLRs
    put_u64(payload, uint64_t(-1));  // offset to special EVLRs
    put_u16(payload, layout.colors ? 2 : 1);
    put_u16(payload, kItemPoint10);
    put_u16(payload, 20);
    put_u16(payload, 2);
    if (layout.colors) {
        put_u16(payload, kItemRgb12);
        put_u16(payload, 6);
        put_u16(payload, 2);
    }
    std::string out;
    put_u16(out, 0);  // reserved
    put_text(out, "laszip encoded", 16);
    put_u16(out, kLaszipRecordId);
    put_u16(out, uint16_t(payload.size()));
    put_text(out, "LAZ of catpaq's bench writer", 32);
    assert(out.size() == kVlrHeaderSize);
    return out + payload;
}

// The chunk table: version 0, the chunk count, then each chunk's byte count coded as an integer
// predicted by the previous one (context 1; context 0 would carry point counts, which a fixed
// chunk size leaves out).
void append_chunk_table(std::string& out, const std::vector<uint32_t>& chunk_bytes) {
    put_u32(out, 0);
    put_u32(out, uint32_t(chunk_bytes.size()));
    if (chunk_bytes.empty()) return;
    ArithmeticEncoder encoder(out);
    IntegerCompressor sizes(32, 2);
    sizes.reset();
    for (size_t i = 0; i < chunk_bytes.size(); ++i)
        sizes.compress(encoder, int32_t(i ? chunk_bytes[i - 1] : 0), int32_t(chunk_bytes[i]), 1);
    encoder.finish();
}

}  // namespace

size_t las_record_length(bool colors) { return colors ? 26 : 20; }

void append_las_record(const LasPoint& p, bool colors, std::string& out) {
    put_u32(out, uint32_t(p.x));
    put_u32(out, uint32_t(p.y));
    put_u32(out, uint32_t(p.z));
    put_u16(out, p.intensity);
    put_u8(out, flags_byte(p));
    put_u8(out, p.classification);
    put_u8(out, uint8_t(p.scan_angle_rank));
    put_u8(out, p.user_data);
    put_u16(out, p.point_source_id);
    if (colors)
        for (uint16_t c : p.rgb) put_u16(out, c);
}

std::vector<LasPoint> quantize_points(const std::vector<std::array<double, 3>>& positions,
                                      const std::vector<std::array<uint8_t, 3>>& colors, const LasLayout& layout) {
    check_layout(layout);
    if (!colors.empty() && colors.size() != positions.size())
        fail("LAS writer: %zu colours for %zu points", colors.size(), positions.size());
    std::vector<LasPoint> points(positions.size());
    for (size_t i = 0; i < positions.size(); ++i) {
        int32_t* fields[3] = {&points[i].x, &points[i].y, &points[i].z};
        for (int a = 0; a < 3; ++a) {
            const double steps = std::round((positions[i][a] - layout.offset[a]) / layout.scale[a]);
            if (!(steps >= double(INT32_MIN) && steps <= double(INT32_MAX)))
                fail("LAS writer: point %zu's coordinate %g is not within 2^31 steps of %g at scale %g", i,
                     positions[i][a], layout.offset[a], layout.scale[a]);
            *fields[a] = int32_t(steps);
        }
        if (!colors.empty())
            for (int c = 0; c < 3; ++c) points[i].rgb[c] = uint16_t(colors[i][c] * 257);
    }
    return points;
}

std::string encode_laz(const std::vector<LasPoint>& points, const LasLayout& layout, uint32_t chunk_points,
                       uint32_t* chunks) {
    check_layout(layout);
    check_points(points);
    if (chunk_points == 0) fail("LAZ writer: a chunk must hold at least one point");
    const std::string vlr = laszip_vlr(layout, chunk_points);
    std::string out = las_header(points, layout, true, 1, uint32_t(vlr.size())) + vlr;
    const size_t table_offset_at = out.size();
    put_u64(out, 0);  // the chunk table's offset, known at the end
    Point10Compressor point10;
    Rgb12Compressor rgb12;
    std::vector<uint32_t> chunk_bytes;
    for (size_t begin = 0; begin < points.size(); begin += chunk_points) {
        const size_t chunk_start = out.size(), end = std::min(points.size(), begin + chunk_points);
        append_las_record(points[begin], layout.colors, out);  // the items' raw bytes, in order
        point10.start_chunk(points[begin]);
        if (layout.colors) rgb12.start_chunk(points[begin]);
        ArithmeticEncoder encoder(out);
        for (size_t i = begin + 1; i < end; ++i) {
            point10.compress(encoder, points[i]);
            if (layout.colors) rgb12.compress(encoder, points[i]);
        }
        encoder.finish();
        if (out.size() - chunk_start > UINT32_MAX) fail("LAZ writer: a chunk of more than 4 GiB");
        chunk_bytes.push_back(uint32_t(out.size() - chunk_start));
    }
    patch_u64(out, table_offset_at, out.size());
    append_chunk_table(out, chunk_bytes);
    if (chunks) *chunks = uint32_t(chunk_bytes.size());
    return out;
}

LasFileSummary write_las_file(const std::string& path, const std::vector<LasPoint>& points, const LasLayout& layout,
                              bool compressed, uint32_t chunk_points) {
    LasFileSummary summary;
    std::string bytes;
    size_t point_data_at = kHeaderSize;
    if (compressed) {
        bytes = encode_laz(points, layout, chunk_points, &summary.chunks);
        point_data_at += laszip_vlr(layout, chunk_points).size();
    } else {
        check_layout(layout);
        check_points(points);
        bytes = las_header(points, layout, false, 0, 0);
        bytes.reserve(bytes.size() + points.size() * las_record_length(layout.colors));
        for (const LasPoint& p : points) append_las_record(p, layout.colors, bytes);
    }
    write_file_atomic(path, bytes.data(), bytes.size());
    summary.file_bytes = bytes.size();
    summary.point_bytes = bytes.size() - point_data_at;
    return summary;
}

namespace {

// The value of `"key":` in laz_decode.mjs's one line of JSON (numbers and plain strings only).
std::string json_field(const std::string& json, const std::string& key) {
    const std::string quoted = "\"" + key + "\":";
    const size_t at = json.find(quoted);
    if (at == std::string::npos) fail("laz_decode.mjs printed no \"%s\": %s", key.c_str(), json.c_str());
    size_t begin = at + quoted.size(), end = json.find_first_of(",}", begin);
    std::string value = json.substr(begin, end - begin);
    if (value.size() >= 2 && value.front() == '"') value = value.substr(1, value.size() - 2);
    return value;
}

}  // namespace

LazPerfDecoder find_lazperf_decoder(const std::string& source_dir) {
    namespace fs = std::filesystem;
    LazPerfDecoder decoder;
    const char* path = std::getenv("PATH");
    std::string dirs = path ? path : "/usr/bin:/bin";
    for (size_t begin = 0; begin <= dirs.size() && decoder.node.empty();) {
        size_t end = dirs.find(':', begin);
        if (end == std::string::npos) end = dirs.size();
        const fs::path candidate = fs::path(dirs.substr(begin, end - begin)) / "node";
        if (end > begin && ::access(candidate.c_str(), X_OK) == 0) decoder.node = candidate.string();
        begin = end + 1;
    }
    if (decoder.node.empty())
        fail("node is not installed (not in PATH): the LAZ check needs it; scripts/setup.sh --tests installs nodejs and npm");
    decoder.script = (fs::path(source_dir) / "scripts" / "report" / "laz_decode.mjs").string();
    if (!fs::exists(decoder.script)) fail("the LAZ decoder script '%s' is missing", decoder.script.c_str());
    if (const char* dir = std::getenv("CATPAQ_NPM_DIR"); dir && *dir) {
        decoder.modules = dir;
    } else {
        const char* home = std::getenv("HOME");
        if (!home || !*home) {
            const passwd* user = getpwuid(getuid());
            home = user ? user->pw_dir : "/";
        }
        decoder.modules = (fs::path(home) / ".cache" / "catpaq-npm").string();
    }
    const fs::path package = fs::path(decoder.modules) / "node_modules" / "laz-perf" / "package.json";
    if (!fs::exists(package))
        fail("laz-perf is not installed ('%s' is missing): scripts/setup.sh --tests installs it (npm laz-perf@0.0.7 into "
             "$CATPAQ_NPM_DIR, default ~/.cache/catpaq-npm)",
             package.c_str());
    return decoder;
}

DecodedLas decode_with_lazperf(const LazPerfDecoder& decoder, const std::string& path, const std::string& scratch) {
    const ChildRun run = run_measured({decoder.node, decoder.script, path, "--raw", scratch, "--modules", decoder.modules},
                                      scratch + ".log");
    if (run.status != 0) {
        std::filesystem::remove(scratch);
        fail("laz-perf could not decode '%s' (exit status %d): %s", path.c_str(), run.status, run.output.c_str());
    }
    const size_t line = run.output.rfind("{\"points\"");
    if (line == std::string::npos) fail("laz_decode.mjs printed no result: %s", run.output.c_str());
    const std::string json = run.output.substr(line);
    DecodedLas decoded;
    decoded.points = std::stoull(json_field(json, "points"));
    decoded.format = std::stoi(json_field(json, "format"));
    decoded.record_length = std::stoi(json_field(json, "record_length"));
    decoded.records = read_file(scratch);
    std::filesystem::remove(scratch);
    return decoded;
}

}  // namespace catpaq::laz
