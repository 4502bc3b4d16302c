// The kd-tree partition in core (partition.h).
#include "partition.h"

#include <cmath>

#include <tbb/parallel_for.h>
#include <tbb/parallel_invoke.h>
#include <tbb/parallel_reduce.h>

#include "base/error.h"
#include "base/progress.h"

namespace catpaq::points_detail {

int longest_axis(const float lo[3], const float hi[3]) {
    int axis = 0;
    for (int a = 1; a < 3; ++a)
        if (hi[a] - lo[a] > hi[axis] - lo[axis]) axis = a;
    return axis;
}

float balanced_margin(const float lo[3], const float hi[3], double max_aspect) {
    const float longest = std::max({hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]});
    return longest / float(std::max(max_aspect, 2.0));
}

int balanced_axis(const float lo[3], const float hi[3], const uint64_t imbalance[3]) {
    int best = -1;
    for (int axis = 0; axis < 3; ++axis) {
        if (imbalance[axis] == UINT64_MAX) continue;
        if (best < 0 || imbalance[axis] < imbalance[best] ||
            (imbalance[axis] == imbalance[best] && hi[axis] - lo[axis] > hi[best] - lo[best]))
            best = axis;
    }
    return best;
}

namespace {

class Partitioner {
public:
    Partitioner(Items& items, const PartitionSettings& settings, Progress* progress)
        : items_(items), settings_(settings), progress_(progress) {}

    std::vector<HNode> partition(uint32_t begin, uint32_t end, uint64_t key, int depth);

private:
    uint32_t choose_split(uint32_t begin, uint32_t end, int depth) const;
    uint32_t split_midpoint(uint32_t begin, uint32_t end, const float lo[3], const float hi[3]) const;
    uint32_t split_balanced(uint32_t begin, uint32_t end, const float lo[3], const float hi[3]) const;
    uint32_t split_by_rank(uint32_t begin, uint32_t end, int axis) const;
    uint32_t split_by_plane(uint32_t begin, uint32_t end, int axis, float plane) const;

    Items& items_;
    const PartitionSettings& settings_;
    Progress* progress_;
};

// The n/2 smallest in the order (coordinate, input index) to the left.
uint32_t Partitioner::split_by_rank(uint32_t begin, uint32_t end, int axis) const {
    const uint32_t middle = begin + (end - begin) / 2;
    std::nth_element(items_.begin() + begin, items_.begin() + middle, items_.begin() + end,
                     [axis](const PartitionItem& a, const PartitionItem& b) {
                         return rank_order_key(a, axis) < rank_order_key(b, axis);
                     });
    return middle;
}

// The points below the plane to the left; by rank if that leaves a side empty.
uint32_t Partitioner::split_by_plane(uint32_t begin, uint32_t end, int axis, float plane) const {
    auto middle = std::partition(items_.begin() + begin, items_.begin() + end,
                                 [axis, plane](const PartitionItem& i) { return i.p[axis] < plane; });
    const uint32_t at = uint32_t(middle - items_.begin());
    if (at == begin || at == end) return split_by_rank(begin, end, axis);
    return at;
}

// Seed 002: the middle of the longest side of the tight box. A tight box has points on both of
// its faces, so both sides are non-empty unless the box is too thin for floats to hold a plane
// between them.
uint32_t Partitioner::split_midpoint(uint32_t begin, uint32_t end, const float lo[3], const float hi[3]) const {
    const int axis = longest_axis(lo, hi);
    return split_by_plane(begin, end, axis, 0.5f * (lo[axis] + hi[axis]));
}

// The value of rank n / 2 of the items' coordinates on `axis` (what std::nth_element puts at
// n / 2 of a copy of them). Large ranges select by a histogram of the top 16 bits of the
// coordinates' order-preserving keys and a selection within the bucket holding that rank: on
// 10M points, the copies and nth_elements of the balanced split were a tenth of the CPU time.
float median_coordinate(const Items& items, uint32_t begin, uint32_t end, int axis) {
    const size_t n = end - begin, rank = n / 2;
    std::vector<float> values;
    if (n < kParallelPoints) {
        std::vector<float> next;
        return select_rank(n, rank, [&](size_t i) { return items[begin + i].p[axis]; }, values, next);
    }
    auto key = float_order_key;
    std::vector<uint32_t> counts(size_t(1) << 16, 0);
    for (uint32_t i = begin; i < end; ++i) ++counts[key(items[i].p[axis]) >> 16];
    uint32_t bucket = 0;
    size_t before = 0;
    while (before + counts[bucket] <= rank) before += counts[bucket++];
    values.reserve(counts[bucket]);
    for (uint32_t i = begin; i < end; ++i)
        if (key(items[i].p[axis]) >> 16 == bucket) values.push_back(items[i].p[axis]);
    std::nth_element(values.begin(), values.begin() + ptrdiff_t(rank - before), values.end());
    return values[rank - before];
}

// Seed 000: among the planes whose children are not thinner (across the plane) than the
// longest side / max_aspect, the most balanced one; on each axis that is the median clamped to
// the acceptable range, and the axis whose plane splits the counts most evenly wins. A median
// that needs no clamping splits by rank (imbalance 0).
uint32_t Partitioner::split_balanced(uint32_t begin, uint32_t end, const float lo[3], const float hi[3]) const {
    const float margin = balanced_margin(lo, hi, settings_.max_aspect);
    const uint32_t n = end - begin;
    // Each axis's median plane and how unevenly it splits; the three are independent, and on
    // large nodes (the first levels, which run before the tree fans out over the cores) they are
    // found in parallel.
    float planes[3] = {0, 0, 0};
    uint64_t imbalances[3] = {UINT64_MAX, UINT64_MAX, UINT64_MAX};
    auto evaluate = [&](int axis) {
        if (hi[axis] - lo[axis] < 2 * margin) return;
        const float median = median_coordinate(items_, begin, end, axis);
        const float plane = std::clamp(median, lo[axis] + margin, hi[axis] - margin);
        uint64_t below = 0;
        for (uint32_t i = begin; i < end; ++i) below += items_[i].p[axis] < plane;
        planes[axis] = plane;
        imbalances[axis] = plane == median ? 0 : split_imbalance(below, n);
    };
    if (n > kParallelPoints) {
        tbb::parallel_for(0, 3, evaluate);
    } else {
        for (int axis = 0; axis < 3; ++axis) evaluate(axis);
    }
    const int axis = balanced_axis(lo, hi, imbalances);
    if (axis < 0) return split_midpoint(begin, end, lo, hi);
    if (imbalances[axis] == 0) return split_by_rank(begin, end, axis);
    return split_by_plane(begin, end, axis, planes[axis]);
}

// The tight box of items[begin, end) (in parallel for large ranges).
void item_bounds(const Items& items, uint32_t begin, uint32_t end, float lo[3], float hi[3]) {
    struct Box {
        float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
        void add(const Box& o) {
            for (int a = 0; a < 3; ++a) {
                lo[a] = std::min(lo[a], o.lo[a]);
                hi[a] = std::max(hi[a], o.hi[a]);
            }
        }
    };
    auto range_box = [&items](size_t first, size_t last) {
        Box box;
        for (size_t i = first; i < last; ++i)
            for (int a = 0; a < 3; ++a) {
                box.lo[a] = std::min(box.lo[a], items[i].p[a]);
                box.hi[a] = std::max(box.hi[a], items[i].p[a]);
            }
        return box;
    };
    Box box;
    if (end - begin > kParallelPoints) {
        box = tbb::parallel_reduce(
            tbb::blocked_range<size_t>(begin, end, 1 << 15), Box(),
            [&](const tbb::blocked_range<size_t>& r, Box b) {
                b.add(range_box(r.begin(), r.end()));
                return b;
            },
            [](Box a, const Box& b) {
                a.add(b);
                return a;
            });
    } else {
        box = range_box(begin, end);
    }
    std::copy(box.lo, box.lo + 3, lo);
    std::copy(box.hi, box.hi + 3, hi);
}

uint32_t Partitioner::choose_split(uint32_t begin, uint32_t end, int depth) const {
    // Deep trees come from points that coincide or nearly do: split them by rank.
    if (depth >= kMidpointMaxDepth) return split_by_rank(begin, end, 0);
    float lo[3], hi[3];
    item_bounds(items_, begin, end, lo, hi);
    if (settings_.split == PointSplitRule::Balanced) return split_balanced(begin, end, lo, hi);
    return split_midpoint(begin, end, lo, hi);
}

std::vector<HNode> Partitioner::partition(uint32_t begin, uint32_t end, uint64_t key, int depth) {
    HNode node;
    node.begin = begin;
    node.end = end;
    node.key = key;
    node.depth = depth;
    if (end - begin <= settings_.node_points) {
        std::sort(items_.begin() + begin, items_.begin() + end,
                  [](const PartitionItem& a, const PartitionItem& b) { return a.index < b.index; });
        if (progress_) progress_->add(end - begin);
        return {node};
    }
    if (depth >= kPointMaxDepth) fail("the point hierarchy would be deeper than %d levels", kPointMaxDepth);
    const uint32_t middle = choose_split(begin, end, depth);
    std::vector<HNode> left, right;
    if (end - begin > kParallelPoints) {
        tbb::parallel_invoke([&] { left = partition(begin, middle, 2 * key, depth + 1); },
                             [&] { right = partition(middle, end, 2 * key + 1, depth + 1); });
    } else {
        left = partition(begin, middle, 2 * key, depth + 1);
        right = partition(middle, end, 2 * key + 1, depth + 1);
    }
    std::vector<HNode> out;
    out.reserve(1 + left.size() + right.size());
    node.left = 1;
    node.right = int32_t(1 + left.size());
    out.push_back(node);
    for (HNode& child : left) {
        if (child.left >= 0) child.left += 1, child.right += 1;
        out.push_back(child);
    }
    for (HNode& child : right) {
        if (child.left >= 0) child.left += node.right, child.right += node.right;
        out.push_back(child);
    }
    return out;
}

}  // namespace

std::vector<HNode> partition_items(Items& items, uint32_t begin, uint32_t end, uint64_t key, int depth,
                                   const PartitionSettings& settings, Progress* progress) {
    return Partitioner(items, settings, progress).partition(begin, end, key, depth);
}

}  // namespace catpaq::points_detail
