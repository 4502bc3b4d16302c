#include "points/format.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <unordered_set>

#include "base/bytes.h"
#include "base/error.h"
#include "common_codec/deflate.h"

namespace catpaq {

const char* point_split_rule_name(PointSplitRule rule) {
    switch (rule) {
        case PointSplitRule::Midpoint: return "midpoint";
        case PointSplitRule::Balanced: return "balanced";
    }
    return "unknown";
}

namespace {

// Version 2's node boxes are steps of their parent's box: 255 per axis, a byte each. A box is
// then at most 1/255 of its parent's side larger on each side than the splats need, which the
// cut engine's distances barely notice, and costs about 4 bytes a node once deflated instead of
// 12 for 16-bit steps (1M-point scan cloud: 2.2 against 6.0 KB for 516 boxes).
constexpr uint32_t kBoxSteps = 255;

// Coordinate of step q on [lo, hi]: monotone in q, exact at both ends, inside [lo, hi]. The
// encoder searches with this same function, so rounding outwards holds for the floats decoded.
float box_step(float lo, float hi, uint32_t q) {
    if (q == 0) return lo;
    if (q >= kBoxSteps) return hi;
    const float v = float(double(lo) + (double(hi) - double(lo)) * double(q) / double(kBoxSteps));
    return std::min(std::max(v, lo), hi);
}

// The largest step at or below v, and the smallest at or above it (lo <= v <= hi).
uint32_t step_at_or_below(float lo, float hi, float v) {
    if (!(hi > lo)) return 0;
    double guess = std::floor((double(v) - double(lo)) / (double(hi) - double(lo)) * kBoxSteps);
    uint32_t q = uint32_t(std::clamp(guess, 0.0, double(kBoxSteps)));
    while (q > 0 && box_step(lo, hi, q) > v) --q;
    while (q < kBoxSteps && box_step(lo, hi, q + 1) <= v) ++q;
    return q;
}

uint32_t step_at_or_above(float lo, float hi, float v) {
    if (!(hi > lo)) return kBoxSteps;
    double guess = std::ceil((double(v) - double(lo)) / (double(hi) - double(lo)) * kBoxSteps);
    uint32_t q = uint32_t(std::clamp(guess, 0.0, double(kBoxSteps)));
    while (q < kBoxSteps && box_step(lo, hi, q) < v) ++q;
    while (q > 0 && box_step(lo, hi, q - 1) >= v) --q;
    return q;
}

// Keys and parents from the tree's shape: nodes listed breadth first (by depth, then id, as the
// index lists them), inner[i] when node i has both children. Empty string when it is a tree.
std::string keys_from_shape(const std::vector<bool>& inner, std::vector<uint64_t>& keys, std::vector<uint32_t>& parent) {
    const size_t n = inner.size();
    keys.assign(n, 0);
    parent.assign(n, 0);
    if (n == 0) return "";
    keys[0] = 1;
    size_t next = 1;
    for (size_t i = 0; i < n; ++i) {
        if (i >= next) return "point metadata: the tree's shape leaves a node without a parent";
        if (!inner[i]) continue;
        if (next + 2 > n) return "point metadata: the tree's shape has more children than nodes";
        if (point_node_depth(keys[i]) >= kPointMaxDepth) return "point metadata: the tree is too deep";
        for (int side = 0; side < 2; ++side) {
            keys[next] = point_node_child(keys[i], side);
            parent[next++] = uint32_t(i);
        }
    }
    return next == n ? "" : "point metadata: the tree's shape has fewer children than nodes";
}

// Radii are stored as their float's high 16 bits (bfloat16), rounded up: a node's radius bounds
// its error from below (client/points), and 8 significant bits are plenty for it.
uint16_t radius_bits_rounded_up(float radius) {
    uint32_t u;
    std::memcpy(&u, &radius, 4);
    return uint16_t((uint64_t(u) + 0xffff) >> 16);
}

float radius_from_bits(uint16_t bits) {
    const uint32_t u = uint32_t(bits) << 16;
    float radius;
    std::memcpy(&radius, &u, 4);
    return radius;
}

bool box_is_valid(const PointNodeInfo& node) {
    for (int a = 0; a < 3; ++a)
        if (!std::isfinite(node.box_min[a]) || !std::isfinite(node.box_max[a]) || !(node.box_min[a] <= node.box_max[a]))
            return false;
    return true;
}

size_t max_node_table_bytes(size_t n) { return (n + 7) / 8 + 24 + 6 * n + 2 * n; }

// Version 2's node table, before deflating: shape bits, root box, boxes as parent steps, radii.
std::vector<uint8_t> node_table(const std::vector<PointNodeInfo>& nodes) {
    const size_t n = nodes.size();
    std::unordered_set<uint64_t> present;
    for (const PointNodeInfo& node : nodes) present.insert(node.key);
    std::vector<bool> inner(n);
    for (size_t i = 0; i < n; ++i) inner[i] = present.count(point_node_child(nodes[i].key, 0)) != 0;
    std::vector<uint64_t> keys;
    std::vector<uint32_t> parent;
    std::string problem = keys_from_shape(inner, keys, parent);
    for (size_t i = 0; problem.empty() && i < n; ++i)
        if (keys[i] != nodes[i].key) problem = strprintf("node %zu is %llu, a breadth-first tree has %llu there", i,
                                                         (unsigned long long)nodes[i].key, (unsigned long long)keys[i]);
    if (!problem.empty()) fail("cannot write point metadata: the nodes are not a full binary tree by depth and id (%s)", problem.c_str());

    ByteWriter w;
    for (size_t i = 0; i < n; i += 8) {
        uint8_t bits = 0;
        for (size_t j = i; j < std::min(n, i + 8); ++j) bits |= uint8_t(inner[j]) << (j - i);
        w.u8(bits);
    }
    std::vector<PointNodeInfo> decoded(n);  // the boxes a reader gets: children round against these
    std::vector<uint8_t> steps(6 * n);        // plane c holds coordinate c (min xyz, max xyz) of nodes 1..n-1
    for (size_t i = 0; i < n; ++i) {
        const PointNodeInfo& node = nodes[i];
        if (!box_is_valid(node)) fail("cannot write point metadata: node %llu has an invalid box", (unsigned long long)node.key);
        if (!(node.mean_radius >= 0) || !std::isfinite(radius_from_bits(radius_bits_rounded_up(node.mean_radius))))
            fail("cannot write point metadata: node %llu has an invalid radius", (unsigned long long)node.key);
        if (i == 0) {
            for (float v : node.box_min) w.f32(v);
            for (float v : node.box_max) w.f32(v);
            decoded[0] = node;
            continue;
        }
        const PointNodeInfo& up = decoded[parent[i]];
        for (int a = 0; a < 3; ++a)
            if (node.box_min[a] < up.box_min[a] || node.box_max[a] > up.box_max[a])
                fail("cannot write point metadata: the box of node %llu is not inside its parent's", (unsigned long long)node.key);
        for (int a = 0; a < 3; ++a) {
            uint32_t lo = step_at_or_below(up.box_min[a], up.box_max[a], node.box_min[a]);
            const uint32_t hi = step_at_or_above(up.box_min[a], up.box_max[a], node.box_max[a]);
            // A flat side on a parent a few ulps wide: several steps decode to the same float, and
            // the searches from both ends cross. Every step between them decodes to that value.
            if (lo > hi) lo = hi;
            decoded[i].box_min[a] = box_step(up.box_min[a], up.box_max[a], lo);
            decoded[i].box_max[a] = box_step(up.box_min[a], up.box_max[a], hi);
            steps[a * n + i] = uint8_t(lo);
            steps[(3 + a) * n + i] = uint8_t(kBoxSteps - hi);  // near 0 like the minima: deflate likes it
        }
    }
    for (int c = 0; c < 6; ++c) w.raw(steps.data() + c * n + 1, n > 0 ? n - 1 : 0);
    for (int plane = 0; plane < 2; ++plane)
        for (const PointNodeInfo& node : nodes) w.u8(uint8_t(radius_bits_rounded_up(node.mean_radius) >> (8 * plane)));
    return std::move(w.bytes());
}

std::string read_node_table(const uint8_t* data, size_t size, std::vector<PointNodeInfo>& nodes) {
    const size_t n = nodes.size();
    ByteReader r(data, size);
    std::vector<bool> inner(n);
    for (size_t i = 0; i < n; i += 8) {
        const uint8_t bits = r.u8();
        for (size_t j = i; j < std::min(n, i + 8); ++j) inner[j] = (bits >> (j - i)) & 1;
    }
    if (!r.ok()) return "point metadata truncated";
    std::vector<uint64_t> keys;
    std::vector<uint32_t> parent;
    if (std::string e = keys_from_shape(inner, keys, parent); !e.empty()) return e;
    if (n == 0) return r.remaining() == 0 ? "" : "point metadata: the node table's size does not match its count";
    PointNodeInfo& root = nodes[0];
    for (float& v : root.box_min) v = r.f32();
    for (float& v : root.box_max) v = r.f32();
    if (!r.ok()) return "point metadata truncated";
    if (!box_is_valid(root)) return "point metadata: bad node box";
    if (r.remaining() != 6 * (n - 1) + 2 * n) return "point metadata: the node table's size does not match its count";
    const uint8_t* steps = r.cursor();
    const uint8_t* radii = steps + 6 * (n - 1);
    for (size_t i = 0; i < n; ++i) {
        PointNodeInfo& node = nodes[i];
        node.key = keys[i];
        node.mean_radius = radius_from_bits(uint16_t(radii[i] | radii[n + i] << 8));
        if (!(node.mean_radius >= 0) || !std::isfinite(node.mean_radius)) return "point metadata: bad node radius";
        if (i == 0) continue;
        const PointNodeInfo& up = nodes[parent[i]];
        for (int a = 0; a < 3; ++a) {
            const uint32_t lo = steps[a * (n - 1) + i - 1], hi = kBoxSteps - steps[(3 + a) * (n - 1) + i - 1];
            if (lo > hi) return "point metadata: bad node box";
            node.box_min[a] = box_step(up.box_min[a], up.box_max[a], lo);
            node.box_max[a] = box_step(up.box_min[a], up.box_max[a], hi);
        }
    }
    return "";
}

}  // namespace

std::vector<uint8_t> encode_points_meta(const PointsMeta& meta, uint32_t version) {
    if (version < 1 || version > kPointsMetaVersion) fail("cannot write point metadata version %u", version);
    ByteWriter w;
    w.raw(kPointsMetaMagic, 8);
    w.u32(version);
    for (double v : meta.origin) w.f64(v);
    for (double v : meta.bounds_min) w.f64(v);
    for (double v : meta.bounds_max) w.f64(v);
    w.u64(meta.input_points);
    w.u32(meta.node_points);
    w.u32(meta.flags);
    w.u8(uint8_t(meta.split));
    w.u8(meta.color_bits.luma);
    w.u8(meta.color_bits.chroma);
    w.u8(meta.up_axis);
    w.u32(uint32_t(meta.nodes.size()));
    if (version >= 2) {
        const std::vector<uint8_t> packed = deflate_bytes(node_table(meta.nodes));
        w.raw(packed.data(), packed.size());
        return std::move(w.bytes());
    }
    for (const PointNodeInfo& node : meta.nodes) {
        w.u64(node.key);
        for (float v : node.box_min) w.f32(v);
        for (float v : node.box_max) w.f32(v);
        w.f32(node.mean_radius);
    }
    return std::move(w.bytes());
}

std::string decode_points_meta(const uint8_t* data, size_t size, PointsMeta& out) {
    if (size < 8 || std::memcmp(data, kPointsMetaMagic, 8) != 0) return "not point metadata (bad magic)";
    ByteReader r(data + 8, size - 8);
    uint32_t version = r.u32();
    if (version < 1 || version > kPointsMetaVersion)
        return strprintf("unsupported point metadata version %u (this build reads 1 to %u)", version, kPointsMetaVersion);
    for (double& v : out.origin) v = r.f64();
    for (double& v : out.bounds_min) v = r.f64();
    for (double& v : out.bounds_max) v = r.f64();
    out.input_points = r.u64();
    out.node_points = r.u32();
    out.flags = r.u32();
    uint8_t split = r.u8();
    out.color_bits.luma = r.u8();
    out.color_bits.chroma = r.u8();
    out.up_axis = r.u8();
    uint32_t count = r.u32();
    if (!r.ok()) return "point metadata truncated";
    if (split > 1) return "unknown split rule";
    if (out.up_axis > 6) return "invalid up axis";
    out.split = PointSplitRule(split);
    for (int a = 0; a < 3; ++a)
        if (!std::isfinite(out.origin[a])) return "point metadata: non-finite origin";
    if (version >= 2) {
        // Each node takes at least two radius bytes of the inflated table.
        if (!deflate_can_hold(2 * uint64_t(count), r.remaining())) return "point metadata: node count larger than its table";
        out.nodes.assign(count, {});
        std::vector<uint8_t> table;
        if (!inflate_bytes(r.cursor(), r.remaining(), max_node_table_bytes(count), table))
            return "point metadata's node table is not a valid deflate stream of the expected size";
        return read_node_table(table.data(), table.size(), out.nodes);
    }
    if (uint64_t(count) * 36 != r.remaining()) return "point metadata: node table size does not match its count";
    out.nodes.resize(count);
    for (PointNodeInfo& node : out.nodes) {
        node.key = r.u64();
        for (float& v : node.box_min) v = r.f32();
        for (float& v : node.box_max) v = r.f32();
        node.mean_radius = r.f32();
        if (node.key == 0 || point_node_depth(node.key) > kPointMaxDepth) return "point metadata: bad node key";
        for (int a = 0; a < 3; ++a)
            if (!(node.box_min[a] <= node.box_max[a])) return "point metadata: bad node box";
    }
    return r.ok() ? "" : "point metadata truncated";
}

}  // namespace catpaq
