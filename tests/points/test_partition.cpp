// The in-core kd-tree partition (points/src/partition.h): what it promises the out-of-core
// converter is that the tree depends only on the set of points, never on their arrangement, and
// that every leaf lists its points by input index.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <numeric>
#include <random>

#include "../../points/src/partition.h"
#include "mesh/generators.h"

using namespace catpaq;
using namespace catpaq::points_detail;

namespace {

// Coordinates with many ties, -0 beside +0 and a few distinct values: the splits by rank must
// tell -0 from +0 as the order keys do and take tied points by input index.
Items tied_items(size_t n, uint64_t seed) {
    std::mt19937_64 random(seed);
    // Zeros are most of x's values, so that medians on x are zeros, and x is the longest side.
    const float values[] = {-0.0f, 0.0f, -0.0f, 0.0f, 100.0f, -100.0f, 50.0f, 200.0f};
    Items items(n);
    for (size_t i = 0; i < n; ++i) {
        for (int a = 0; a < 3; ++a) {
            // Ties on x, a spread on y, a continuum on z.
            const float pick = values[random() % 8];
            items[i].p[a] = a == 0 ? pick : a == 1 ? float(random() % 97) * 0.25f - 12.0f : float(random() % 100000) * 1e-3f;
        }
        items[i].index = uint32_t(i);
    }
    return items;
}

// A sphere's vertices in the generator's order, which follows their position (as a scanner's
// order does): blocks of a large split then often lie all on one side.
Items ordered_items(size_t triangles) {
    const Mesh mesh = make_sphere(triangles, 3);
    Items items(mesh.positions.size());
    for (size_t i = 0; i < items.size(); ++i) {
        for (int a = 0; a < 3; ++a) items[i].p[a] = float(mesh.positions[i][a]);
        items[i].index = uint32_t(i);
    }
    return items;
}

// Each node's set of input indices, by key.
std::map<uint64_t, std::vector<uint32_t>> node_sets(const std::vector<HNode>& nodes, const Items& items) {
    std::map<uint64_t, std::vector<uint32_t>> sets;
    for (const HNode& node : nodes) {
        std::vector<uint32_t>& set = sets[node.key];
        for (uint32_t i = node.begin; i < node.end; ++i) set.push_back(items[i].index);
        std::sort(set.begin(), set.end());
    }
    return sets;
}

PartitionSettings settings_of(PointSplitRule rule, size_t node_points) {
    PartitionSettings settings;
    settings.split = rule;
    settings.node_points = node_points;
    return settings;
}

void check_split_rule(PointSplitRule rule, size_t n, size_t node_points) {
    const PartitionSettings settings = settings_of(rule, node_points);
    Items items = tied_items(n, 7);
    const std::vector<HNode> nodes = partition_items(items, 0, uint32_t(n), 1, 0, settings, nullptr);
    // Leaves list their points by input index.
    for (const HNode& node : nodes) {
        if (node.left >= 0) continue;
        for (uint32_t i = node.begin + 1; i < node.end; ++i) ASSERT_LT(items[i - 1].index, items[i].index);
    }
    // A split by rank on an axis sends left exactly the smallest in (order key, input index).
    for (const HNode& node : nodes) {
        if (node.left < 0) continue;
        const HNode& left = nodes[size_t(node.left)];
        const HNode& right = nodes[size_t(node.right)];
        ASSERT_EQ(left.begin, node.begin);
        ASSERT_EQ(right.end, node.end);
        ASSERT_EQ(left.end, right.begin);
        ASSERT_GT(left.end, left.begin);
        ASSERT_GT(right.end, right.begin);
    }
    // The same tree, node for node and set for set, from the points shuffled (the partition
    // sorts by input index first) and from them reversed.
    for (uint64_t seed : {1u, 2u}) {
        Items shuffled = tied_items(n, 7);
        if (seed == 1) std::shuffle(shuffled.begin(), shuffled.end(), std::mt19937_64(seed));
        else std::reverse(shuffled.begin(), shuffled.end());
        const std::vector<HNode> again = partition_items(shuffled, 0, uint32_t(n), 1, 0, settings, nullptr);
        ASSERT_EQ(again.size(), nodes.size());
        EXPECT_EQ(node_sets(again, shuffled), node_sets(nodes, items));
        for (size_t i = 0; i < n; ++i) ASSERT_EQ(shuffled[i].index, items[i].index);
    }
}

// The left child's input indices by the split rule's definition, computed plainly (sorts, no
// selection, no parallel passes): the tight box; seed 002's midpoint of the longest side, or
// seed 000's most balanced clamped median, a median that needs no clamping splitting by rank
// (the n/2 smallest by coordinate order key, then input index); by rank on the axis when a
// plane leaves a side empty.
std::vector<uint32_t> reference_left(std::vector<PartitionItem> node, const PartitionSettings& settings) {
    const size_t n = node.size();
    float lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (const PartitionItem& item : node)
        for (int a = 0; a < 3; ++a) lo[a] = std::min(lo[a], item.p[a]), hi[a] = std::max(hi[a], item.p[a]);
    auto by_rank = [&](int axis) {
        std::sort(node.begin(), node.end(), [axis](const PartitionItem& x, const PartitionItem& y) {
            return rank_order_key(x, axis) < rank_order_key(y, axis);
        });
        std::vector<uint32_t> left;
        for (size_t i = 0; i < n / 2; ++i) left.push_back(node[i].index);
        return left;
    };
    auto by_plane = [&](int axis, float plane) {
        std::vector<uint32_t> left;
        for (const PartitionItem& item : node)
            if (item.p[axis] < plane) left.push_back(item.index);
        if (left.empty() || left.size() == n) return by_rank(axis);
        return left;
    };
    std::vector<uint32_t> left;
    if (settings.split == PointSplitRule::Midpoint) {
        const int axis = longest_axis(lo, hi);
        left = by_plane(axis, 0.5f * (lo[axis] + hi[axis]));
    } else {
        const float margin = balanced_margin(lo, hi, settings.max_aspect);
        float planes[3] = {0, 0, 0};
        uint64_t imbalance[3] = {UINT64_MAX, UINT64_MAX, UINT64_MAX};
        for (int a = 0; a < 3; ++a) {
            if (hi[a] - lo[a] < 2 * margin) continue;
            std::vector<float> values;
            for (const PartitionItem& item : node) values.push_back(item.p[a]);
            std::sort(values.begin(), values.end());
            const float median = values[n / 2];
            planes[a] = std::clamp(median, lo[a] + margin, hi[a] - margin);
            uint64_t below = 0;
            for (float v : values) below += v < planes[a];
            imbalance[a] = planes[a] == median ? 0 : split_imbalance(below, n);
        }
        const int axis = balanced_axis(lo, hi, imbalance);
        if (axis < 0) {
            const int longest = longest_axis(lo, hi);
            left = by_plane(longest, 0.5f * (lo[longest] + hi[longest]));
        } else {
            left = imbalance[axis] == 0 ? by_rank(axis) : by_plane(axis, planes[axis]);
        }
    }
    std::sort(left.begin(), left.end());
    return left;
}

// Every split of the tree is the rule's.
void check_splits_follow_the_rule(PointSplitRule rule, Items items, size_t node_points) {
    const PartitionSettings settings = settings_of(rule, node_points);
    const size_t n = items.size();
    const std::vector<HNode> nodes = partition_items(items, 0, uint32_t(n), 1, 0, settings, nullptr);
    for (const HNode& node : nodes) {
        if (node.left < 0) continue;
        const HNode& left = nodes[size_t(node.left)];
        std::vector<uint32_t> got;
        for (uint32_t i = left.begin; i < left.end; ++i) got.push_back(items[i].index);
        std::sort(got.begin(), got.end());
        const std::vector<PartitionItem> points(items.begin() + node.begin, items.begin() + node.end);
        ASSERT_EQ(got, reference_left(points, settings)) << "node " << node.key << " of " << node.end - node.begin;
    }
}

}  // namespace

TEST(PointPartition, TreeDependsOnTheSetOnlyAndLeavesAreByInputIndex) {
    for (PointSplitRule rule : {PointSplitRule::Balanced, PointSplitRule::Midpoint}) {
        check_split_rule(rule, 5000, 64);     // sequential splits
        check_split_rule(rule, 300000, 20000);  // the top splits in parallel (kParallelPoints)
    }
}

TEST(PointPartition, EverySplitIsTheRulesComputedPlainly) {
    for (PointSplitRule rule : {PointSplitRule::Balanced, PointSplitRule::Midpoint}) {
        check_splits_follow_the_rule(rule, tied_items(5000, 11), 64);       // sequential splits
        check_splits_follow_the_rule(rule, tied_items(300000, 11), 20000);  // the top splits in parallel
        check_splits_follow_the_rule(rule, ordered_items(400000), 20000);   // blocks on one side
    }
}
