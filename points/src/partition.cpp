// The kd-tree partition in core (partition.h).
#include "partition.h"

#include <cmath>
#include <memory>

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

float median_coordinate(const Items& items, uint32_t begin, uint32_t end, int axis);
void item_bounds(const Items& items, uint32_t begin, uint32_t end, float lo[3], float hi[3]);

class Partitioner {
public:
    Partitioner(Items& items, PartitionItem* scratch, uint32_t base, const PartitionSettings& settings, Progress* progress)
        : items_(items), scratch_(scratch), base_(base), settings_(settings), progress_(progress) {}

    std::vector<HNode> partition(uint32_t begin, uint32_t end, uint64_t key, int depth);

private:
    uint32_t choose_split(uint32_t begin, uint32_t end, int depth) const;
    uint32_t split_midpoint(uint32_t begin, uint32_t end, const float lo[3], const float hi[3]) const;
    uint32_t split_balanced(uint32_t begin, uint32_t end, const float lo[3], const float hi[3]) const;
    uint32_t split_by_rank(uint32_t begin, uint32_t end, int axis, float median) const;
    uint32_t split_by_rank(uint32_t begin, uint32_t end, int axis) const;
    uint32_t split_by_plane(uint32_t begin, uint32_t end, int axis, float plane) const;
    template <class Side>
    uint32_t stable_split(uint32_t begin, uint32_t end, size_t ties_left, Side side) const;

    Items& items_;
    PartitionItem* scratch_;  // as large as the range partitioned, from base_
    uint32_t base_;
    const PartitionSettings& settings_;
    Progress* progress_;
};

// Moves items[begin, end) so that those side() puts left (0) come first and those it puts right
// (2) last, each side in the order it had, ties (1) going left in that order until the left side
// holds left_size (no more than the ties make up): a stable partition, so that ranges sorted by input index stay sorted and a
// leaf needs no sort. Large ranges in parallel: each block counts its sides, then copies its
// items to their places in the scratch array, which is copied back. (This replaced an
// nth_element for the splits by rank and a sort of every leaf by input index: 4.4% of the 1M
// scan's conversion, most of it at the top of the tree, before the tree fans out.)
template <class Side>
uint32_t Partitioner::stable_split(uint32_t begin, uint32_t end, size_t left_size, Side side) const {
    PartitionItem* items = items_.data();
    PartitionItem* scratch = scratch_ - base_;  // indexed as items
    if (end - begin <= kParallelPoints) {
        size_t ties_left = 0;
        if (left_size > 0) {
            size_t below = 0;
            for (uint32_t i = begin; i < end; ++i) below += size_t(side(items[i]) == 0);
            ties_left = left_size > below ? left_size - below : 0;
        }
        uint32_t left = begin, right = begin;  // right: in the scratch
        for (uint32_t i = begin; i < end; ++i) {
            const PartitionItem item = items[i];
            const int s = side(item);
            const bool goes_left = s == 0 || (s == 1 && ties_left > 0);
            ties_left -= size_t(s == 1 && goes_left);
            items[left] = item;  // left <= i: item is read already
            scratch[right] = item;
            left += uint32_t(goes_left);
            right += uint32_t(!goes_left);
        }
        std::copy(scratch + begin, scratch + right, items + left);
        return left;
    }
    constexpr uint32_t kBlock = 1 << 14;
    const uint32_t blocks = (end - begin + kBlock - 1) / kBlock;
    std::vector<uint32_t> lefts(blocks), ties(blocks);
    tbb::parallel_for(uint32_t(0), blocks, [&](uint32_t b) {
        const uint32_t first = begin + b * kBlock, last = std::min(end, first + kBlock);
        uint32_t l = 0, t = 0;
        for (uint32_t i = first; i < last; ++i) {
            const int s = side(items[i]);
            l += uint32_t(s == 0);
            t += uint32_t(s == 1);
        }
        lefts[b] = l;
        ties[b] = t;
    });
    // Each block's first place on either side, and how many of its ties go left.
    size_t below = 0;
    for (uint32_t l : lefts) below += l;
    size_t ties_left = left_size > below ? left_size - below : 0;
    std::vector<uint32_t> left_at(blocks), right_at(blocks), ties_taken(blocks);
    uint32_t left_total = 0;
    for (uint32_t b = 0; b < blocks; ++b) {
        ties_taken[b] = uint32_t(std::min<size_t>(ties[b], ties_left));
        ties_left -= ties_taken[b];
        left_at[b] = left_total;
        left_total += lefts[b] + ties_taken[b];
    }
    for (uint32_t b = 0, right_total = left_total; b < blocks; ++b) {
        right_at[b] = right_total;
        right_total += std::min(end, begin + (b + 1) * kBlock) - (begin + b * kBlock) - lefts[b] - ties_taken[b];
    }
    tbb::parallel_for(uint32_t(0), blocks, [&](uint32_t b) {
        const uint32_t first = begin + b * kBlock, last = std::min(end, first + kBlock);
        uint32_t l = begin + left_at[b], r = begin + right_at[b], taken = ties_taken[b];
        for (uint32_t i = first; i < last; ++i) {
            const PartitionItem item = items[i];
            const int s = side(item);
            const bool goes_left = s == 0 || (s == 1 && taken > 0);
            taken -= uint32_t(s == 1 && goes_left);
            if (goes_left) scratch[l++] = item;
            else scratch[r++] = item;
        }
    });
    tbb::parallel_for(tbb::blocked_range<uint32_t>(begin, end, kBlock), [&](const tbb::blocked_range<uint32_t>& r) {
        std::copy(scratch + r.begin(), scratch + r.end(), items + r.begin());
    });
    return begin + left_total;
}

// The n/2 smallest in the order (coordinate, input index) to the left, given the coordinate of
// rank n/2 (as median_coordinate finds it): those whose coordinate's order key is below that
// rank's, then as many of those on it as make n/2, by input index. (median_coordinate's value
// is the rank's in float order, where -0 and +0 are equal; the order keys tell them apart, so
// a zero median is resolved by counting.)
uint32_t Partitioner::split_by_rank(uint32_t begin, uint32_t end, int axis, float median) const {
    const uint32_t half = (end - begin) / 2;
    uint32_t key = float_order_key(median);
    if (median == 0.0f) {
        size_t below = 0;
        for (uint32_t i = begin; i < end; ++i) below += float_order_key(items_[i].p[axis]) < float_order_key(0.0f);
        key = below > half ? float_order_key(-0.0f) : float_order_key(0.0f);
    }
    return stable_split(begin, end, half, [axis, key](const PartitionItem& item) {
        const uint32_t k = float_order_key(item.p[axis]);
        return k < key ? 0 : k == key ? 1 : 2;
    });
}

uint32_t Partitioner::split_by_rank(uint32_t begin, uint32_t end, int axis) const {
    return split_by_rank(begin, end, axis, median_coordinate(items_, begin, end, axis));
}

// The points below the plane to the left; by rank if that leaves a side empty.
uint32_t Partitioner::split_by_plane(uint32_t begin, uint32_t end, int axis, float plane) const {
    const uint32_t at = stable_split(begin, end, 0, [axis, plane](const PartitionItem& i) { return i.p[axis] < plane ? 0 : 2; });
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

// The values of rank n / 2 of the items' coordinates on the axes wanted (what std::nth_element
// puts at n / 2 of a copy of them; -0 and +0 aside, which compare equal), given the items' tight
// box: one pass counts the items in kSlices equal slices of the box per axis (a slice index is
// monotone in the coordinate, so the rank's value is in the slice where the counts pass it),
// a second gathers that slice's values, and select_rank finds the rank among them. Two passes
// for the three axes, in parallel over blocks for large ranges, where a histogram of order keys
// and a selection per axis took about 20 ms per level of the 1M scan's tree (a tenth of the
// conversion's wall time, mostly before the tree fans out over the cores).
void median_coordinates(const Items& items, uint32_t begin, uint32_t end, const float lo[3], const float hi[3],
                        const bool wanted[3], float median[3]) {
    constexpr uint32_t kSlices = 2048, kBlock = 1 << 15;
    const size_t n = end - begin, rank = n / 2;
    float scale[3];
    for (int a = 0; a < 3; ++a) scale[a] = hi[a] > lo[a] ? float(kSlices) / (hi[a] - lo[a]) : 0.0f;
    auto slice = [&](float v, int a) { return std::min(uint32_t((v - lo[a]) * scale[a]), kSlices - 1); };
    const uint32_t blocks = n > kParallelPoints ? uint32_t((n + kBlock - 1) / kBlock) : 1;
    auto block_range = [&](uint32_t b) {
        return std::pair<uint32_t, uint32_t>(begin + b * kBlock, blocks == 1 ? end : std::min<uint32_t>(end, begin + (b + 1) * kBlock));
    };
    // counts[(block * 3 + axis) * kSlices + slice]
    std::vector<uint32_t> counts(size_t(blocks) * 3 * kSlices, 0);
    auto count_block = [&](uint32_t b) {
        const auto [first, last] = block_range(b);
        uint32_t* c = &counts[size_t(b) * 3 * kSlices];
        for (int a = 0; a < 3; ++a) {
            if (!wanted[a]) continue;
            uint32_t* ca = c + size_t(a) * kSlices;
            for (uint32_t i = first; i < last; ++i) ++ca[slice(items[i].p[a], a)];
        }
    };
    if (blocks > 1) tbb::parallel_for(uint32_t(0), blocks, count_block);
    else count_block(0);
    // The slice holding the rank, per axis, and where each block's values in it go.
    uint32_t chosen[3] = {0, 0, 0};
    size_t before[3] = {0, 0, 0}, in_slice[3] = {0, 0, 0};
    std::vector<uint32_t> offsets(size_t(blocks) * 3, 0);
    for (int a = 0; a < 3; ++a) {
        if (!wanted[a]) continue;
        auto total = [&](uint32_t s) {
            size_t t = 0;
            for (uint32_t b = 0; b < blocks; ++b) t += counts[(size_t(b) * 3 + size_t(a)) * kSlices + s];
            return t;
        };
        uint32_t s = 0;
        size_t below = 0;
        for (size_t t = total(s); below + t <= rank; t = total(++s)) below += t;
        chosen[a] = s;
        before[a] = below;
        for (uint32_t b = 0; b < blocks; ++b) {
            offsets[size_t(b) * 3 + size_t(a)] = uint32_t(in_slice[a]);
            in_slice[a] += counts[(size_t(b) * 3 + size_t(a)) * kSlices + s];
        }
    }
    std::vector<float> values[3];
    for (int a = 0; a < 3; ++a) values[a].resize(in_slice[a]);
    auto gather_block = [&](uint32_t b) {
        const auto [first, last] = block_range(b);
        for (int a = 0; a < 3; ++a) {
            if (!wanted[a]) continue;
            float* out = values[a].data() + offsets[size_t(b) * 3 + size_t(a)];
            for (uint32_t i = first; i < last; ++i)
                if (slice(items[i].p[a], a) == chosen[a]) *out++ = items[i].p[a];
        }
    };
    if (blocks > 1) tbb::parallel_for(uint32_t(0), blocks, gather_block);
    else gather_block(0);
    std::vector<float> scratch, next;
    for (int a = 0; a < 3; ++a)
        if (wanted[a])
            median[a] = select_rank(values[a].size(), rank - before[a], [&](size_t i) { return values[a][i]; }, scratch, next);
}

float median_coordinate(const Items& items, uint32_t begin, uint32_t end, int axis) {
    float lo[3], hi[3], median[3];
    item_bounds(items, begin, end, lo, hi);
    const bool wanted[3] = {axis == 0, axis == 1, axis == 2};
    median_coordinates(items, begin, end, lo, hi, wanted, median);
    return median[axis];
}

// Seed 000: among the planes whose children are not thinner (across the plane) than the
// longest side / max_aspect, the most balanced one; on each axis that is the median clamped to
// the acceptable range, and the axis whose plane splits the counts most evenly wins. A median
// that needs no clamping splits by rank (imbalance 0).
uint32_t Partitioner::split_balanced(uint32_t begin, uint32_t end, const float lo[3], const float hi[3]) const {
    const float margin = balanced_margin(lo, hi, settings_.max_aspect);
    const uint32_t n = end - begin;
    // Each axis's median plane and how unevenly it splits (a plane on the median splits by rank:
    // evenly).
    float planes[3] = {0, 0, 0}, medians[3] = {0, 0, 0};
    uint64_t imbalances[3] = {UINT64_MAX, UINT64_MAX, UINT64_MAX};
    bool wanted[3], clamped[3] = {false, false, false};
    for (int a = 0; a < 3; ++a) wanted[a] = !(hi[a] - lo[a] < 2 * margin);
    median_coordinates(items_, begin, end, lo, hi, wanted, medians);
    for (int a = 0; a < 3; ++a) {
        if (!wanted[a]) continue;
        planes[a] = std::clamp(medians[a], lo[a] + margin, hi[a] - margin);
        clamped[a] = planes[a] != medians[a];
        imbalances[a] = 0;
    }
    if (clamped[0] || clamped[1] || clamped[2]) {
        uint64_t below[3] = {0, 0, 0};
        for (uint32_t i = begin; i < end; ++i)
            for (int a = 0; a < 3; ++a) below[a] += items_[i].p[a] < planes[a];
        for (int a = 0; a < 3; ++a)
            if (clamped[a]) imbalances[a] = split_imbalance(below[a], n);
    }
    const int axis = balanced_axis(lo, hi, imbalances);
    if (axis < 0) return split_midpoint(begin, end, lo, hi);
    if (imbalances[axis] == 0) return split_by_rank(begin, end, axis, planes[axis]);
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
    if (end - begin <= settings_.node_points) {  // sorted by input index already (stable_split)
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
    // The splits keep each side in the order it had: items in input index order give leaves in
    // that order.
    auto by_index = [](const PartitionItem& a, const PartitionItem& b) { return a.index < b.index; };
    if (!std::is_sorted(items.begin() + begin, items.begin() + end, by_index))
        std::sort(items.begin() + begin, items.begin() + end, by_index);
    // Not value-initialized (zeroing a vector of them took 9 ms of the 1M scan's partition, alone).
    std::unique_ptr<PartitionItem[]> scratch(new PartitionItem[end - begin]);
    return Partitioner(items, scratch.get(), begin, settings, progress).partition(begin, end, key, depth);
}

}  // namespace catpaq::points_detail
