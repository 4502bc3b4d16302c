#pragma once
// Private to the points module: the kd-tree partition of a point cloud (points/builder.h, step
// 2), in core over an array of items, and the pieces of its split rule that the out-of-core
// partition (out_of_core.h) shares, so that both make the same tree.
//
// A node's split is a function of the *set* of its points, never of their order in memory:
// planes come from the tight box and from coordinate ranks; a split by rank sends left the n/2
// smallest points in the order (coordinate, input index); a leaf lists its points by input
// index. A subtree partitioned from any arrangement of its points is therefore the same, which
// is what lets the out-of-core converter partition the top of the tree by passes over a file
// and each part below in core, and still write the same dataset.
#include <algorithm>
#include <bit>
#include <cstdint>
#include <cstring>
#include <vector>

#include "base/default_init.h"
#include "points/format.h"

namespace catpaq {
class Progress;
}

namespace catpaq::points_detail {

constexpr size_t kParallelPoints = 1 << 16;  // ranges this large are partitioned in parallel
constexpr int kMidpointMaxDepth = 48;        // deeper, the planes give way to ranks

// One node of the hierarchy: a range of the (permuted) points, and children in the same array.
struct HNode {
    uint32_t begin = 0, end = 0;
    int32_t left = -1, right = -1;
    uint64_t key = 1;
    int depth = 0;
    float lo[3] = {0, 0, 0}, hi[3] = {0, 0, 0};  // tight box of the points (set for the halo search)
};

// A point as the partition moves it: its position (float, relative to the origin: enough to
// place split planes) next to its input index, so that every pass over a node reads memory in
// order (through an index array into the doubles, the first levels of a 10M cloud took 28 s of
// cache misses).
struct PartitionItem {
    float p[3];
    uint32_t index;
};
using Items = UninitializedVector<PartitionItem>;  // filled by its maker, in parallel

// Floats order as these keys do (negatives reversed below the positives; -0 just below +0).
inline uint32_t float_order_key(float v) {
    uint32_t bits;
    std::memcpy(&bits, &v, 4);
    return (bits & 0x80000000u) ? ~bits : (bits | 0x80000000u);
}
inline float float_from_order_key(uint32_t key) {
    const uint32_t bits = (key & 0x80000000u) ? (key & 0x7fffffffu) : ~key;
    float v;
    std::memcpy(&v, &bits, 4);
    return v;
}

// The order of a split by rank on `axis`: coordinate, then input index (a total order, so the
// n/2 smallest are one set however the points are arranged).
inline uint64_t rank_order_key(const PartitionItem& item, int axis) {
    return uint64_t(float_order_key(item.p[axis])) << 32 | item.index;
}

// The value of rank `rank` among n floats get(0) .. get(n - 1): the value std::nth_element
// puts at `rank` (ties aside: equal values, and -0 and +0, which compare equal), by a radix
// select: a histogram of the order keys' top bits above the smallest key picks the bucket
// holding the rank, whose values are selected the same way until few are left for
// nth_element. Written out because nth_element on a node's coordinates and radii mispredicts
// most of its branches (3% of the conversion's time); these passes have nearly none.
template <class Get>
float select_rank(size_t n, size_t rank, Get get, std::vector<float>& values, std::vector<float>& next) {
    constexpr size_t kSmall = 512;  // below, nth_element
    constexpr uint32_t kBits = 11;  // a histogram of 2048 buckets
    values.resize(n);
    for (size_t i = 0; i < n; ++i) values[i] = get(i);
    uint32_t counts[size_t(1) << kBits];
    while (values.size() > kSmall) {
        uint32_t low = UINT32_MAX, high = 0;
        for (float v : values) {
            low = std::min(low, float_order_key(v));
            high = std::max(high, float_order_key(v));
        }
        if (low == high) return values[0];
        const uint32_t width = uint32_t(std::bit_width(high - low)), shift = width > kBits ? width - kBits : 0;
        std::fill(counts, counts + (size_t(1) << kBits), 0u);
        for (float v : values) ++counts[(float_order_key(v) - low) >> shift];
        uint32_t bucket = 0;
        size_t before = 0;
        while (before + counts[bucket] <= rank) before += counts[bucket++];
        next.clear();
        for (float v : values)
            if ((float_order_key(v) - low) >> shift == bucket) next.push_back(v);
        values.swap(next);
        rank -= before;
    }
    std::nth_element(values.begin(), values.begin() + ptrdiff_t(rank), values.end());
    return values[rank];
}

struct PartitionSettings {
    size_t node_points = 4096;
    PointSplitRule split = PointSplitRule::Balanced;
    double max_aspect = 4.0;
};

// The first longest side of the box [lo, hi].
int longest_axis(const float lo[3], const float hi[3]);

// Seed 000's balanced rule: a plane must leave both children at least this thick.
float balanced_margin(const float lo[3], const float hi[3], double max_aspect);

// The balanced rule's axis among those evaluated (imbalance below UINT64_MAX): the smallest
// imbalance, ties to the longer side; -1 if none was evaluated.
int balanced_axis(const float lo[3], const float hi[3], const uint64_t imbalance[3]);

// How far a plane's count below it is from half of n.
inline uint64_t split_imbalance(uint64_t below, uint64_t n) { return below > n / 2 ? below - n / 2 : n / 2 - below; }

// Partitions items[begin, end) into the subtree of node `key` at `depth`: returns the subtree's
// nodes, its root first (children indices relative to the returned array), and leaves the
// items of every leaf in its range, sorted by input index. Counts points into `progress`.
std::vector<HNode> partition_items(Items& items, uint32_t begin, uint32_t end, uint64_t key, int depth,
                                   const PartitionSettings& settings, Progress* progress);

}  // namespace catpaq::points_detail
