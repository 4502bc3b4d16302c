#include "points/format.h"

#include <cmath>
#include <cstring>

#include "base/bytes.h"
#include "base/error.h"

namespace catpaq {

const char* point_split_rule_name(PointSplitRule rule) {
    switch (rule) {
        case PointSplitRule::Midpoint: return "midpoint";
        case PointSplitRule::Balanced: return "balanced";
    }
    return "unknown";
}

std::vector<uint8_t> encode_points_meta(const PointsMeta& meta) {
    ByteWriter w;
    w.raw(kPointsMetaMagic, 8);
    w.u32(kPointsMetaVersion);
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
    if (version != kPointsMetaVersion)
        return strprintf("unsupported point metadata version %u (this build reads %u)", version, kPointsMetaVersion);
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
    if (uint64_t(count) * 36 != r.remaining()) return "point metadata: node table size does not match its count";
    for (int a = 0; a < 3; ++a)
        if (!std::isfinite(out.origin[a])) return "point metadata: non-finite origin";
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
