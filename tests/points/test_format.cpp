// Point metadata: version 2's packed node table (tree shape, boxes as steps of their parent's
// box, radii as rounded-up bfloat16) against what the converter and the client rely on.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <algorithm>
#include <deque>
#include <map>

#include "base/error.h"
#include "points/format.h"
#include "support.h"

namespace catpaq {
namespace {

// A random full binary tree listed by depth, then id (as the index lists it), with nested boxes
// that hold each node's children, and random radii.
PointsMeta random_meta(uint64_t seed, size_t target_nodes) {
    uint64_t state = seed;
    PointsMeta meta;
    meta.origin[0] = 1e7;
    meta.input_points = 12345;
    meta.node_points = 4096;
    PointNodeInfo root;
    root.key = 1;
    for (int a = 0; a < 3; ++a) {
        root.box_min[a] = float(-10 * test::random_unit(state));
        root.box_max[a] = float(10 * test::random_unit(state));
    }
    root.mean_radius = 0.25f;
    std::deque<PointNodeInfo> queue{root};
    while (!queue.empty()) {
        PointNodeInfo node = queue.front();
        queue.pop_front();
        meta.nodes.push_back(node);
        if (meta.nodes.size() + queue.size() + 2 > target_nodes || (node.key > 1 && test::random_unit(state) < 0.2)) continue;
        for (int side = 0; side < 2; ++side) {
            PointNodeInfo child;
            child.key = point_node_child(node.key, side);
            for (int a = 0; a < 3; ++a) {
                const float lo = node.box_min[a], hi = node.box_max[a];
                float u = float(test::random_unit(state)), v = float(test::random_unit(state));
                if (u > v) std::swap(u, v);
                if (test::random_unit(state) < 0.3) u = 0, v = 1;  // the parent's side: the extremes
                child.box_min[a] = std::max(lo, lo + (hi - lo) * u);
                child.box_max[a] = std::min(hi, std::max(child.box_min[a], lo + (hi - lo) * v));
            }
            child.mean_radius = node.mean_radius * float(0.3 + 0.6 * test::random_unit(state));
            queue.push_back(child);
        }
    }
    return meta;
}

TEST(PointsMeta, Version2KeepsKeysAndRoundsBoxesAndRadiiOutwardsWhileStayingNested) {
    for (uint64_t seed = 1; seed <= 20; ++seed) {
        const PointsMeta meta = random_meta(seed, 3 + seed * 37);
        const std::vector<uint8_t> bytes = encode_points_meta(meta);
        PointsMeta out;
        ASSERT_EQ(decode_points_meta(bytes.data(), bytes.size(), out), "") << "seed " << seed;
        ASSERT_EQ(out.nodes.size(), meta.nodes.size());
        EXPECT_EQ(out.input_points, meta.input_points);
        EXPECT_EQ(out.origin[0], meta.origin[0]);
        std::map<uint64_t, size_t> by_key;
        for (size_t i = 0; i < out.nodes.size(); ++i) by_key[out.nodes[i].key] = i;
        for (size_t i = 0; i < meta.nodes.size(); ++i) {
            const PointNodeInfo &a = meta.nodes[i], &b = out.nodes[i];
            ASSERT_EQ(a.key, b.key);
            EXPECT_GE(b.mean_radius, a.mean_radius);
            EXPECT_LE(b.mean_radius, a.mean_radius * (1 + 0x1p-7f));
            const PointNodeInfo* up = i == 0 ? nullptr : &out.nodes[by_key.at(point_node_parent(b.key))];
            for (int k = 0; k < 3; ++k) {
                EXPECT_LE(b.box_min[k], a.box_min[k]);
                EXPECT_GE(b.box_max[k], a.box_max[k]);
                if (!up) {
                    EXPECT_EQ(b.box_min[k], a.box_min[k]);
                    EXPECT_EQ(b.box_max[k], a.box_max[k]);
                    continue;
                }
                EXPECT_GE(b.box_min[k], up->box_min[k]);
                EXPECT_LE(b.box_max[k], up->box_max[k]);
                // At most one step of the parent's side looser (and float rounding).
                const float step = (up->box_max[k] - up->box_min[k]) / 255 * 1.001f + 1e-6f;
                EXPECT_LE(a.box_min[k] - b.box_min[k], step);
                EXPECT_LE(b.box_max[k] - a.box_max[k], step);
            }
        }
        // Writing what was read gives the same bytes: decoded boxes sit on their steps.
        EXPECT_EQ(encode_points_meta(out), bytes);
    }
}

TEST(PointsMeta, Version2IsSmallerThanVersion1ByAFactorOfFourOrMore) {
    const PointsMeta meta = random_meta(7, 2000);
    ASSERT_GT(meta.nodes.size(), 1000u);
    EXPECT_LE(4 * encode_points_meta(meta).size(), encode_points_meta(meta, 1).size());
}

TEST(PointsMeta, Version1StillReadsExactly) {
    const PointsMeta meta = random_meta(3, 300);
    const std::vector<uint8_t> bytes = encode_points_meta(meta, 1);
    uint32_t version;
    std::memcpy(&version, bytes.data() + 8, 4);
    ASSERT_EQ(version, 1u);
    PointsMeta out;
    ASSERT_EQ(decode_points_meta(bytes.data(), bytes.size(), out), "");
    ASSERT_EQ(out.nodes.size(), meta.nodes.size());
    for (size_t i = 0; i < meta.nodes.size(); ++i) {
        EXPECT_EQ(out.nodes[i].key, meta.nodes[i].key);
        EXPECT_EQ(out.nodes[i].mean_radius, meta.nodes[i].mean_radius);
        for (int k = 0; k < 3; ++k) EXPECT_EQ(out.nodes[i].box_max[k], meta.nodes[i].box_max[k]);
    }
}

TEST(PointsMeta, WriterRefusesWhatVersion2CannotHold) {
    const PointsMeta good = random_meta(5, 100);
    ASSERT_GT(good.nodes.size(), 5u);
    {  // an inner node with one child
        PointsMeta bad = good;
        bad.nodes.pop_back();
        EXPECT_THROW(encode_points_meta(bad), Error);
        EXPECT_NO_THROW(encode_points_meta(bad, 1));
    }
    {  // not breadth first
        PointsMeta bad = good;
        std::swap(bad.nodes[1], bad.nodes[2]);
        EXPECT_THROW(encode_points_meta(bad), Error);
    }
    {  // a box outside its parent's
        PointsMeta bad = good;
        bad.nodes[1].box_max[0] = bad.nodes[0].box_max[0] + 1;
        EXPECT_THROW(encode_points_meta(bad), Error);
    }
    {  // a negative radius
        PointsMeta bad = good;
        bad.nodes[2].mean_radius = -1;
        EXPECT_THROW(encode_points_meta(bad), Error);
    }
    EXPECT_THROW(encode_points_meta(good, 3), Error);
}

TEST(PointsMeta, ReaderRefusesTruncatedAndForgedTablesWithAMessage) {
    const std::vector<uint8_t> bytes = encode_points_meta(random_meta(11, 500));
    PointsMeta out;
    for (size_t size = 0; size < bytes.size(); ++size)
        EXPECT_NE(decode_points_meta(bytes.data(), size, out), "") << size;
    // The node count sits before the deflated table, at byte 104: claim more and fewer nodes
    // than the table holds, and far more than its bytes could inflate to.
    for (uint32_t count : {0u, 1u, 3u, 501u, 100000u, 0xffffffffu}) {
        std::vector<uint8_t> forged = bytes;
        std::memcpy(forged.data() + 104, &count, 4);
        EXPECT_NE(decode_points_meta(forged.data(), forged.size(), out), "") << count;
    }
    // Bytes changed anywhere either still decode to a tree or are refused: never a crash.
    for (size_t at = 108; at < bytes.size(); ++at) {
        std::vector<uint8_t> forged = bytes;
        forged[at] ^= 0x5a;
        PointsMeta any;
        (void)decode_points_meta(forged.data(), forged.size(), any);
    }
}

}  // namespace
}  // namespace catpaq
