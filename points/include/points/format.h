#pragma once
// The point dataset: an archive (common_codec/archive.h) of kind Points whose nodes are the
// nodes of a binary kd-tree of splats. Byte tables: docs/formats/points.md.
//
// Node ids are implicit, as in a full binary tree stored in an array (seed 002 section 4): the
// root is 1 and node k has children 2k and 2k + 1, so a node's depth is the index of its highest
// set bit. An inner node always has both children. Index entries: key = node id, level = depth,
// flags = kPointLeafFlag for leaves, count = points, error = object-space error bound (every
// input point the node stands for lies within `error` of one of the node's splat centres;
// monotone: a parent's is at least its children's).
//
// Meta (little-endian; version 2 is written, version 1 still reads):
//   char[8] "CPQPOINT" | u32 version
//   f64 origin[3]              world = origin + decoded position (decoded positions are floats
//                              relative to this: the bounds' centre, so 1e7 offsets keep precision)
//   f64 bounds_min[3], f64 bounds_max[3]   of the input, world units
//   u64 input_points | u32 node_points (the target per node) | u32 flags (kPointsMeta*)
//   u8 split rule | u8 colour luma bits | u8 colour chroma bits | u8 up axis (0 unknown, 1-6 =
//                              +x +y +z -x -y -z: catp/format.h's UpAxis; LAS input +z, else convert --up)
//   u32 node_count, then the node table:
//   version 1, per index entry in index order: u64 key | f32 box_min[3] | f32 box_max[3] | f32 mean_radius
//   version 2, one zlib stream: the tree's shape (a bit per node: inner), the root's box as
//     f32[6], every other node's box as 16-bit steps of its parent's box rounded outwards
//     (varints), the radii as four byte planes. Keys follow from the shape, because the index
//     lists nodes by depth, then id (breadth first). docs/formats/points.md has the layout.
//   The box (relative to origin) holds the splat balls (centre +- radius) of the node and of all
//   its descendants: boxes are nested.
#include <cstdint>
#include <string>
#include <vector>

#include "points/codec.h"

namespace catpaq {

constexpr uint32_t kPointsMetaVersion = 2;
constexpr char kPointsMetaMagic[8] = {'C', 'P', 'Q', 'P', 'O', 'I', 'N', 'T'};
constexpr uint16_t kPointLeafFlag = 1u << 0;
constexpr uint32_t kPointsMetaInputNormals = 1u << 0;  // the input had normals (else estimated)
constexpr uint32_t kPointsMetaInputColors = 1u << 1;
constexpr uint32_t kPointsMetaInputRadii = 1u << 2;    // the input had radii (else estimated)

// How the kd-tree splits a node of more than node_points points.
enum class PointSplitRule : uint8_t {
    Midpoint = 0,  // seed 002: the middle of the longest side of the node's box
    Balanced = 1,  // seed 000: the most balanced plane whose children keep an aspect bound
};
const char* point_split_rule_name(PointSplitRule rule);

inline int point_node_depth(uint64_t key) { return 63 - __builtin_clzll(key); }
inline uint64_t point_node_child(uint64_t key, int side) { return 2 * key + uint64_t(side); }
inline uint64_t point_node_parent(uint64_t key) { return key >> 1; }
constexpr int kPointMaxDepth = 62;

struct PointNodeInfo {
    uint64_t key = 0;
    float box_min[3] = {0, 0, 0}, box_max[3] = {0, 0, 0};  // relative to the origin
    float mean_radius = 0;
};

struct PointsMeta {
    double origin[3] = {0, 0, 0};
    double bounds_min[3] = {0, 0, 0}, bounds_max[3] = {0, 0, 0};
    uint64_t input_points = 0;
    uint32_t node_points = 0;
    uint32_t flags = 0;
    PointSplitRule split = PointSplitRule::Balanced;
    ColorBits color_bits;
    uint8_t up_axis = 0;
    std::vector<PointNodeInfo> nodes;  // in index order
};

// Version 2 rounds each box but the root's outwards to its parent's 16-bit grid (a decoded box
// still holds its splats, and still nests in its parent's). Throws Error when the nodes are not
// a tree listed breadth first whose inner nodes have both children, or when boxes do not nest
// (version 2), or for an unknown version. Version 1 (tests of older readers) stores everything.
std::vector<uint8_t> encode_points_meta(const PointsMeta& meta, uint32_t version = kPointsMetaVersion);
// Empty string on success, else what is wrong. Safe on any bytes.
std::string decode_points_meta(const uint8_t* data, size_t size, PointsMeta& out);

}  // namespace catpaq
