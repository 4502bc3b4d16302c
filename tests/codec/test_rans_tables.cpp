// rANS table description (common_codec/src/rans.h): describe_counts picks, per present symbol,
// the weight code nearest in the log domain, and data_cost_bits prices counts with log2 of the
// frequencies. Both were sped up (binary search, a log2 table); these tests pin them to the
// straightforward definitions, because the encoder's choices, and so its bytes, depend on them.
#include <gtest/gtest.h>

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
