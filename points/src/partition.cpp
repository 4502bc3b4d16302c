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

// A tight box.
struct Box {
    float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    void add(const float p[3]) {
        for (int a = 0; a < 3; ++a) {
            lo[a] = std::min(lo[a], p[a]);
            hi[a] = std::max(hi[a], p[a]);
        }
    }
    void add(const Box& o) {  // (o may be empty: its lo infinite, its hi minus infinity)
        for (int a = 0; a < 3; ++a) {
            lo[a] = std::min(lo[a], o.lo[a]);
            hi[a] = std::max(hi[a], o.hi[a]);
        }
    }
};

// The tight box of items[begin, end) (in parallel for large ranges).
Box item_bounds(const PartitionItem* items, uint32_t begin, uint32_t end) {
    auto range_box = [items](size_t first, size_t last) {
        Box box;
        for (size_t i = first; i < last; ++i) box.add(items[i].p);
        return box;
    };
    if (end - begin <= kParallelPoints) return range_box(begin, end);
    return tbb::parallel_reduce(
        tbb::blocked_range<size_t>(begin, end, 1 << 15), Box(),
        [&](const tbb::blocked_range<size_t>& r, Box b) {
            b.add(range_box(r.begin(), r.end()));
            return b;
        },
        [](Box x, const Box& y) {
            x.add(y);
            return x;
        });
}

// The values of rank n / 2 of the items' coordinates on the axes wanted (what std::nth_element
// puts at n / 2 of a copy of them; -0 and +0 aside, which compare equal), given the items' tight
// box: one pass counts the items in kSlices equal slices of the box per axis (a slice index is
// monotone in the coordinate, so the rank's value is in the slice where the counts pass it),
// a second gathers that slice's values, and select_rank finds the rank among them. Two passes
// for the three axes, in parallel over blocks for large ranges, where a histogram of order keys
// and a selection per axis took about 20 ms per level of the 1M scan's tree (a tenth of the
// conversion's wall time, mostly before the tree fans out over the cores).
void median_coordinates(const PartitionItem* items, uint32_t begin, uint32_t end, const float lo[3], const float hi[3],
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

// The partition moves the items between two arrays, the caller's and a scratch one of the same
// size, at the same positions: each split reads a node's items from the array they are in and
// writes its children's to the other, each side in the order it had (stable), and finds the
// children's tight boxes on the way. Items in input index order therefore give leaves in that
// order, and a leaf left in the scratch array is copied back. (Splitting in place took more
// passes a level: an nth_element, later a copy back, and one for each child's box.)
class Partitioner {
public:
    Partitioner(Items& items, PartitionItem* scratch, uint32_t base, const PartitionSettings& settings, Progress* progress)
        : settings_(settings), progress_(progress) {
        arrays_[0] = items.data();
        arrays_[1] = scratch - base;  // indexed as the items
    }

    // The subtree of the node holding [begin, end) in array `at` (0: the caller's), whose tight
    // box is `box`.
    std::vector<HNode> partition(uint32_t begin, uint32_t end, uint64_t key, int depth, int at, const Box& box);

private:
    uint32_t choose_split(uint32_t begin, uint32_t end, int depth, int at, const Box& box, Box children[2]) const;
    uint32_t split_midpoint(uint32_t begin, uint32_t end, int at, const Box& box, Box children[2]) const;
    uint32_t split_balanced(uint32_t begin, uint32_t end, int at, const Box& box, Box children[2]) const;
    uint32_t split_by_rank(uint32_t begin, uint32_t end, int at, int axis, float median, Box children[2]) const;
    uint32_t split_by_rank(uint32_t begin, uint32_t end, int at, const Box& box, int axis, Box children[2]) const;
    uint32_t split_by_plane(uint32_t begin, uint32_t end, int at, const Box& box, int axis, float plane,
                            Box children[2]) const;
    template <class Side>
    uint32_t stable_split(uint32_t begin, uint32_t end, int at, size_t left_size, Side side, Box children[2]) const;

    PartitionItem* arrays_[2];
    const PartitionSettings& settings_;
    Progress* progress_;
};

// Moves items[begin, end) from array `at` to the other so that those side() puts left (0) come
// first and those it puts right (2) last, each side in the order it had, ties (1) going left in
// that order until the left side holds left_size (no more than the ties make up; 0: ties go
// right), and sets the two sides' tight boxes. Returns where the right side starts; when a side
// would be empty, nothing is moved. Large ranges in parallel: each block counts its sides, then
// copies its items to their places.
template <class Side>
uint32_t Partitioner::stable_split(uint32_t begin, uint32_t end, int at, size_t left_size, Side side,
                                   Box children[2]) const {
    const PartitionItem* from = arrays_[at];
    PartitionItem* to = arrays_[at ^ 1];
    constexpr uint32_t kBlock = 1 << 14;
    const uint32_t blocks = end - begin > kParallelPoints ? (end - begin + kBlock - 1) / kBlock : 1;
    auto block_range = [&](uint32_t b) {
        return std::pair<uint32_t, uint32_t>(begin + b * kBlock, blocks == 1 ? end : std::min(end, begin + (b + 1) * kBlock));
    };
    std::vector<uint32_t> lefts(blocks), ties(blocks);
    auto count = [&](uint32_t b) {
        const auto [first, last] = block_range(b);
        uint32_t l = 0, t = 0;
        for (uint32_t i = first; i < last; ++i) {
            const int s = side(from[i]);
            l += uint32_t(s == 0);
            t += uint32_t(s == 1);
        }
        lefts[b] = l;
        ties[b] = t;
    };
    if (blocks > 1) tbb::parallel_for(uint32_t(0), blocks, count);
    else count(0);
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
    if (left_total == 0 || left_total == end - begin) return begin + left_total;
    for (uint32_t b = 0, right_total = left_total; b < blocks; ++b) {
        right_at[b] = right_total;
        const auto [first, last] = block_range(b);
        right_total += (last - first) - lefts[b] - ties_taken[b];
    }
    std::vector<Box> boxes(2 * size_t(blocks));
    auto scatter = [&](uint32_t b) {
        const auto [first, last] = block_range(b);
        uint32_t place[2] = {begin + left_at[b], begin + right_at[b]}, taken = ties_taken[b];
        Box* box = &boxes[2 * size_t(b)];
        for (uint32_t i = first; i < last; ++i) {
            const PartitionItem& item = from[i];
            const int s = side(item);
            const bool goes_left = s == 0 || (s == 1 && taken > 0);
            taken -= uint32_t(s == 1 && goes_left);
            const int where = goes_left ? 0 : 1;
            to[place[where]++] = item;
            box[where].add(item.p);
        }
    };
    if (blocks > 1) tbb::parallel_for(uint32_t(0), blocks, scatter);
    else scatter(0);
    children[0] = children[1] = Box();
    for (uint32_t b = 0; b < blocks; ++b) {
        children[0].add(boxes[2 * size_t(b)]);
        children[1].add(boxes[2 * size_t(b) + 1]);
    }
    return begin + left_total;
}

// The n/2 smallest in the order (coordinate, input index) to the left, given the coordinate of
// rank n/2 (as median_coordinates finds it): those whose coordinate's order key is below that
// rank's, then as many of those on it as make n/2, by input index. (median_coordinates's value
// is the rank's in float order, where -0 and +0 are equal; the order keys tell them apart, so
// a zero median is resolved by counting.)
uint32_t Partitioner::split_by_rank(uint32_t begin, uint32_t end, int at, int axis, float median,
                                    Box children[2]) const {
    const PartitionItem* items = arrays_[at];
    const uint32_t half = (end - begin) / 2;
    uint32_t key = float_order_key(median);
    if (median == 0.0f) {
        size_t below = 0;
        for (uint32_t i = begin; i < end; ++i) below += float_order_key(items[i].p[axis]) < float_order_key(0.0f);
        key = below > half ? float_order_key(-0.0f) : float_order_key(0.0f);
    }
    auto side = [axis, key](const PartitionItem& item) {
        const uint32_t k = float_order_key(item.p[axis]);
        return k < key ? 0 : k == key ? 1 : 2;
    };
    return stable_split(begin, end, at, half, side, children);
}

// The same, the median found first.
uint32_t Partitioner::split_by_rank(uint32_t begin, uint32_t end, int at, const Box& box, int axis,
                                    Box children[2]) const {
    const bool wanted[3] = {axis == 0, axis == 1, axis == 2};
    float median[3];
    median_coordinates(arrays_[at], begin, end, box.lo, box.hi, wanted, median);
    return split_by_rank(begin, end, at, axis, median[axis], children);
}

// The points below the plane to the left; by rank if that leaves a side empty.
uint32_t Partitioner::split_by_plane(uint32_t begin, uint32_t end, int at, const Box& box, int axis, float plane,
                                     Box children[2]) const {
    auto side = [axis, plane](const PartitionItem& item) { return item.p[axis] < plane ? 0 : 2; };
    const uint32_t middle = stable_split(begin, end, at, 0, side, children);
    if (middle != begin && middle != end) return middle;
    return split_by_rank(begin, end, at, box, axis, children);
}

// Seed 002: the middle of the longest side of the tight box. A tight box has points on both of
// its faces, so both sides are non-empty unless the box is too thin for floats to hold a plane
// between them.
uint32_t Partitioner::split_midpoint(uint32_t begin, uint32_t end, int at, const Box& box, Box children[2]) const {
    const int axis = longest_axis(box.lo, box.hi);
    return split_by_plane(begin, end, at, box, axis, 0.5f * (box.lo[axis] + box.hi[axis]), children);
}

// Seed 000: among the planes whose children are not thinner (across the plane) than the
// longest side / max_aspect, the most balanced one; on each axis that is the median clamped to
// the acceptable range, and the axis whose plane splits the counts most evenly wins. A median
// that needs no clamping splits by rank (imbalance 0).
uint32_t Partitioner::split_balanced(uint32_t begin, uint32_t end, int at, const Box& box, Box children[2]) const {
    const PartitionItem* items = arrays_[at];
    const float* lo = box.lo;
    const float* hi = box.hi;
    const float margin = balanced_margin(lo, hi, settings_.max_aspect);
    const uint32_t n = end - begin;
    // Each axis's median plane and how unevenly it splits (a plane on the median splits by rank:
    // evenly).
    float planes[3] = {0, 0, 0}, medians[3] = {0, 0, 0};
    uint64_t imbalances[3] = {UINT64_MAX, UINT64_MAX, UINT64_MAX};
    bool wanted[3], clamped[3] = {false, false, false};
    for (int a = 0; a < 3; ++a) wanted[a] = !(hi[a] - lo[a] < 2 * margin);
    median_coordinates(items, begin, end, lo, hi, wanted, medians);
    for (int a = 0; a < 3; ++a) {
        if (!wanted[a]) continue;
        planes[a] = std::clamp(medians[a], lo[a] + margin, hi[a] - margin);
        clamped[a] = planes[a] != medians[a];
        imbalances[a] = 0;
    }
    if (clamped[0] || clamped[1] || clamped[2]) {
        uint64_t below[3] = {0, 0, 0};
        for (uint32_t i = begin; i < end; ++i)
            for (int a = 0; a < 3; ++a) below[a] += items[i].p[a] < planes[a];
        for (int a = 0; a < 3; ++a)
            if (clamped[a]) imbalances[a] = split_imbalance(below[a], n);
    }
    const int axis = balanced_axis(lo, hi, imbalances);
    if (axis < 0) return split_midpoint(begin, end, at, box, children);
    if (imbalances[axis] == 0) return split_by_rank(begin, end, at, axis, planes[axis], children);
    return split_by_plane(begin, end, at, box, axis, planes[axis], children);
}

uint32_t Partitioner::choose_split(uint32_t begin, uint32_t end, int depth, int at, const Box& box,
                                   Box children[2]) const {
    // Deep trees come from points that coincide or nearly do: split them by rank.
    if (depth >= kMidpointMaxDepth) return split_by_rank(begin, end, at, box, 0, children);
    if (settings_.split == PointSplitRule::Balanced) return split_balanced(begin, end, at, box, children);
    return split_midpoint(begin, end, at, box, children);
}

std::vector<HNode> Partitioner::partition(uint32_t begin, uint32_t end, uint64_t key, int depth, int at, const Box& box) {
    HNode node;
    node.begin = begin;
    node.end = end;
    node.key = key;
    node.depth = depth;
    if (end - begin <= settings_.node_points) {  // sorted by input index already (stable_split)
        if (at == 1) std::copy(arrays_[1] + begin, arrays_[1] + end, arrays_[0] + begin);
        if (progress_) progress_->add(end - begin);
        return {node};
    }
    if (depth >= kPointMaxDepth) fail("the point hierarchy would be deeper than %d levels", kPointMaxDepth);
    Box children[2];
    const uint32_t middle = choose_split(begin, end, depth, at, box, children);
    std::vector<HNode> left, right;
    if (end - begin > kParallelPoints) {
        tbb::parallel_invoke([&] { left = partition(begin, middle, 2 * key, depth + 1, at ^ 1, children[0]); },
                             [&] { right = partition(middle, end, 2 * key + 1, depth + 1, at ^ 1, children[1]); });
    } else {
        left = partition(begin, middle, 2 * key, depth + 1, at ^ 1, children[0]);
        right = partition(middle, end, 2 * key + 1, depth + 1, at ^ 1, children[1]);
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
    const bool in_order = tbb::parallel_reduce(
        tbb::blocked_range<size_t>(begin, end, 1 << 16), true,
        [&](const tbb::blocked_range<size_t>& r, bool sorted) {
            // Each range checks its own pairs and the one across its start.
            const size_t first = r.begin() > begin ? r.begin() - 1 : r.begin();
            return sorted && std::is_sorted(items.begin() + ptrdiff_t(first), items.begin() + ptrdiff_t(r.end()), by_index);
        },
        [](bool x, bool y) { return x && y; });
    if (!in_order) std::sort(items.begin() + begin, items.begin() + end, by_index);
    // Not value-initialized (zeroing a vector of them took 9 ms of the 1M scan's partition alone).
    std::unique_ptr<PartitionItem[]> scratch(new PartitionItem[end - begin]);
    const Box box = item_bounds(items.data(), begin, end);
    return Partitioner(items, scratch.get(), begin, settings, progress).partition(begin, end, key, depth, 0, box);
}

}  // namespace catpaq::points_detail
