// rANS table description (common_codec/src/rans.h): describe_counts picks, per present symbol,
// the weight code nearest in the log domain, and data_cost_bits prices counts with log2 of the
// frequencies. Both were sped up (binary search, a log2 table); these tests pin them to the
// straightforward definitions, because the encoder's choices, and so its bytes, depend on them.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <random>

#include "../../common_codec/src/rans.h"

using namespace catpaq;

namespace {

uint32_t weight_value(int code) { return code <= 0 ? 0u : uint32_t(4 + (code - 1) % 4) << ((code - 1) / 4); }

// The nearest code by a linear scan keeping the first strict minimum.
int nearest_code(uint32_t count, uint32_t max_count) {
    const double top = std::log2(double(weight_value(rans::kMaxWeightCode)));
    const double target = top + std::log2(double(count) / double(max_count));
    int best = 1;
    for (int k = 2; k <= rans::kMaxWeightCode; ++k)
        if (std::fabs(std::log2(double(weight_value(k))) - target) <
            std::fabs(std::log2(double(weight_value(best))) - target))
            best = k;
    return best;
}

}  // namespace

TEST(RansTables, DescribeCountsPicksTheNearestWeightCode) {
    std::mt19937 rng(7);
    for (int round = 0; round < 20000; ++round) {
        uint32_t counts[rans::kMaxAlphabet] = {};
        const int nsym = 2 + int(rng() % (rans::kMaxAlphabet - 1));
        const uint32_t scale = 1u << (rng() % 20);
        for (int i = 0; i < nsym; ++i)
            if (rng() % 3 != 0) counts[i] = uint32_t(rng() % scale);
        counts[rng() % nsym] += 1 + uint32_t(rng() % 1000);  // at least two present, usually
        counts[rng() % nsym] += 1;
        uint32_t max_count = 0;
        int present = 0;
        for (int i = 0; i < nsym; ++i) {
            max_count = std::max(max_count, counts[i]);
            present += counts[i] != 0;
        }
        if (present < 2) continue;
        const rans::TableDesc d = rans::describe_counts(counts, nsym);
        for (int i = 0; i < nsym; ++i) {
            const int expected = counts[i] ? nearest_code(counts[i], max_count) : 0;
            ASSERT_EQ(int(d.code[size_t(i)]), expected) << "round " << round << " symbol " << i;
        }
    }
}

TEST(RansTables, DataCostMatchesLog2OfTheFrequencies) {
    std::mt19937 rng(11);
    for (int round = 0; round < 2000; ++round) {
        uint32_t counts[rans::kMaxAlphabet] = {};
        for (int i = 0; i < rans::kMaxAlphabet; ++i) counts[i] = rng() % 2 ? uint32_t(rng() % 5000) : 0;
        counts[0] += 1;
        const rans::TableDesc d = rans::describe_counts(counts, rans::kMaxAlphabet);
        rans::FreqTable f;
        ASSERT_TRUE(rans::build_freqs(d, f));
        double expected = 0;
        for (int i = 0; i < rans::kMaxAlphabet; ++i)
            if (counts[i]) expected += double(counts[i]) * (double(f.scale_bits) - std::log2(double(f.freq[size_t(i)])));
        EXPECT_EQ(rans::data_cost_bits(counts, f), expected);
    }
}

// describe_counts prices each scale over the present symbols only and hands back the chosen
// scale's table and cost: they must be exactly build_freqs() of the description and
// data_cost_bits() of the counts with it, and the chosen scale the smallest within a hair of
// the cheapest, as pricing every scale the straightforward way gives.
TEST(RansTables, DescribeCountsReturnsTheTableAndCostOfItsDescription) {
    std::mt19937 rng(13);
    for (int round = 0; round < 5000; ++round) {
        uint32_t counts[rans::kMaxAlphabet] = {};
        const int nsym = 1 + int(rng() % rans::kMaxAlphabet);
        const uint32_t scale = 1u << (rng() % 18);
        for (int i = 0; i < nsym; ++i)
            if (rng() % 3 != 0) counts[i] = uint32_t(rng() % scale);
        if (rng() % 2) counts[rng() % nsym] += 1;
        rans::FreqTable returned;
        double returned_bits = -1;
        const rans::TableDesc d = rans::describe_counts(counts, nsym, &returned, &returned_bits);
        rans::FreqTable expected;
        ASSERT_TRUE(rans::build_freqs(d, expected)) << "round " << round;
        ASSERT_EQ(returned.scale_bits, expected.scale_bits) << "round " << round;
        for (int i = 0; i < d.nsym; ++i) {
            ASSERT_EQ(returned.freq[size_t(i)], expected.freq[size_t(i)]) << "round " << round << " symbol " << i;
            ASSERT_EQ(returned.start[size_t(i)], expected.start[size_t(i)]) << "round " << round << " symbol " << i;
        }
        ASSERT_EQ(returned_bits, rans::data_cost_bits(counts, expected)) << "round " << round;
        // The same description without the outputs.
        const rans::TableDesc plain = rans::describe_counts(counts, nsym);
        ASSERT_EQ(plain.scale_bits, d.scale_bits);
        for (int i = 0; i < rans::kMaxAlphabet; ++i) ASSERT_EQ(plain.code[size_t(i)], d.code[size_t(i)]);
        // The scale: the smallest whose cost is within a hair (0.1% + half a bit) of the
        // cheapest, every scale priced the plain way. (One present symbol or none costs nothing
        // at the smallest scale.)
        double cost[rans::kMaxScaleBits + 1], best = 1e30;
        for (int s = rans::kMinScaleBits; s <= rans::kMaxScaleBits; ++s) {
            rans::TableDesc at = d;
            at.scale_bits = s;
            rans::FreqTable f;
            cost[s] = rans::build_freqs(at, f) ? rans::data_cost_bits(counts, f) : 1e30;
            best = std::min(best, cost[s]);
        }
        EXPECT_LE(cost[d.scale_bits], best * 1.001 + 0.5) << "round " << round;
        for (int s = rans::kMinScaleBits; s < d.scale_bits; ++s)
            EXPECT_GT(cost[s], best * 1.001 + 0.5) << "round " << round << " scale " << s;
    }
}

// build_freqs derives every scale's frequencies from one division per symbol (floor(w 2^12 / W)
// shifted down); this pins it to the direct floor(w 2^s / W) with the same adjustments.
TEST(RansTables, BuildFreqsMatchesTheDirectDivision) {
    std::mt19937 rng(5);
    for (int round = 0; round < 200000; ++round) {
        rans::TableDesc d;
        d.nsym = 2 + int(rng() % (rans::kMaxAlphabet - 1));
        d.scale_bits = rans::kMinScaleBits + int(rng() % (rans::kMaxScaleBits - rans::kMinScaleBits + 1));
        for (int i = 0; i < d.nsym; ++i) d.code[size_t(i)] = rng() % 3 == 0 ? 0 : uint8_t(1 + rng() % rans::kMaxWeightCode);
        d.code[size_t(d.nsym - 1)] = uint8_t(1 + rng() % rans::kMaxWeightCode);
        rans::FreqTable f;
        ASSERT_TRUE(rans::build_freqs(d, f));
        const uint32_t total = 1u << d.scale_bits;
        uint32_t w_total = 0, freq[rans::kMaxAlphabet] = {}, sum = 0;
        for (int i = 0; i < d.nsym; ++i) w_total += weight_value(d.code[size_t(i)]);
        for (int i = 0; i < d.nsym; ++i) {
            const uint32_t w = weight_value(d.code[size_t(i)]);
            if (w == 0) continue;
            freq[i] = std::max(1u, uint32_t(uint64_t(w) * total / w_total));
            sum += freq[i];
        }
        auto first_max = [&] { return int(std::max_element(freq, freq + d.nsym) - freq); };
        if (sum < total) freq[first_max()] += total - sum;
        for (; sum > total; --sum) --freq[first_max()];
        uint32_t start = 0;
        for (int i = 0; i < d.nsym; ++i) {
            ASSERT_EQ(f.freq[size_t(i)], freq[i]) << "round " << round << " symbol " << i;
            ASSERT_EQ(f.start[size_t(i)], start);
            start += freq[i];
        }
    }
}

// The encoder's division-free state update equals (x / freq) * 2^scale + x % freq + start for
// every frequency at every scale and states across the whole range the encoder meets
// ([kStateLower, x_max), after renormalisation).
TEST(RansTables, EncoderReciprocalUpdateEqualsTheDivision) {
    std::mt19937 rng(3);
    for (int scale = rans::kMinScaleBits; scale <= rans::kMaxScaleBits; ++scale) {
        const uint32_t total = 1u << scale;
        for (uint32_t freq = 1; freq <= total; ++freq) {
            const uint32_t start = total - freq;
            const rans::EncSymbol s = rans::EncSymbol::make(start, freq, scale);
            ASSERT_EQ(uint64_t(s.x_max), ((uint64_t(rans::kStateLower) >> scale) << 8) * freq);
            auto check = [&](uint32_t x) {
                const uint32_t expected = ((x / freq) << scale) + x % freq + start;
                ASSERT_EQ(s.update(x), expected) << "x " << x << " freq " << freq << " scale " << scale;
            };
            // Renormalised states lie in [x_max >> 8, x_max) (and never below kStateLower >> 12).
            const uint32_t lo = std::max<uint32_t>(1, s.x_max >> 8), hi = s.x_max - 1;
            check(lo);
            check(hi);
            for (uint32_t k = 1; k < 64; ++k) check(lo + uint32_t(uint64_t(hi - lo) * k / 64));
            for (int k = 0; k < 64; ++k) check(lo + rng() % (hi - lo + 1));
            // Multiples of freq and their neighbours (where x / freq steps).
            for (int k = 0; k < 16; ++k) {
                const uint32_t m = (lo / freq + 1 + rng() % ((hi - lo) / freq + 1)) * freq;
                for (uint32_t x : {m - 1, m, m + 1})
                    if (x >= lo && x <= hi) check(x);
            }
        }
    }
}
