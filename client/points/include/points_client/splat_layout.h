#pragma once
// The GPU layout of a point node's splats, decoded by the vertex shader (shaders/points.vert):
// 8 bytes per splat in nodes with colours, 6 in nodes without. Packing runs on the fetcher's
// workers (PointsFormat::decode), so the render thread only copies the halves into a buffer.
// Stored as 16-bit halves, little end first (one uvec4 / uvec3 attribute of unsigned shorts):
//
//   halves 0-1, position: quantized on a grid over the tight box of the node's splat centres,
//           x bits 0-10, y bits 11-21, z bits 22-31 (11 + 11 + 10 bits);
//   8 bytes, halves 2-3: normal, octahedral 6 + 6 bits (bits 0-5 u, 6-11 v); radius code,
//           5 bits (12-16); colour RGB 5-5-5 (bits 17-21 red, 22-26 green, 27-31 blue);
//   6 bytes, half 2: normal as above (bits 0-11); radius code, 4 bits (12-15).
//
// A node of a few thousand splats on a surface is some tens of splat spacings wide, so its
// 2048-step grid lands well within a splat radius (measured: at most 0.06 of the node's smallest
// radius). Whatever a node's shape, the measured error (PackedSplats::position_error) is added to
// every radius, so a packed splat still covers the decoded one, as the codec does with its own
// error; a sparse, wide node only loses sharpness. Radii are coded on a logarithmic scale over the node's range, rounded up: radius =
// radius_base * 2^(code * radius_log2_step) >= the decoded radius + position_error.
// Positions are relative to a per-node origin held in double precision: the renderer subtracts
// the eye from it on the CPU, so nodes 1e7 units from the dataset origin draw as precisely as
// nodes at 0.
#include <array>
#include <cstdint>
#include <vector>

#include "points/codec.h"

namespace catpaq {

constexpr uint32_t kSplatBytesWithColor = 8;
constexpr uint32_t kSplatBytesWithoutColor = 6;

struct PackedSplats {
    size_t count = 0;
    uint32_t stride = kSplatBytesWithColor;  // bytes per splat: 8 with colours, 6 without
    std::vector<uint16_t> halves;         // stride / 2 per splat (layout above)
    std::array<double, 3> origin{};       // world position of grid point (0, 0, 0)
    std::array<float, 3> step{};          // grid step per axis, world units (0 for a flat axis)
    float radius_base = 0;                // radius of code 0
    float radius_log2_step = 0;           // log2 of the ratio of consecutive radius codes
    int radius_bits = 5;                  // 5 (8-byte layout) or 4 (6-byte layout)
    bool has_normals = false, has_colors = false;
    float position_error = 0;             // largest |packed - decoded position| (world units)
    float max_radius = 0;                 // largest packed radius (world units)

    bool operator==(const PackedSplats&) const = default;
};

// Packs a decoded node (the 6-byte layout when it has no colours); `dataset_origin` is the dataset's origin (world = origin + decoded
// position). Decoded nodes hold at least one point (decode_point_node guarantees it).
PackedSplats pack_splats(const DecodedPoints& points, const double dataset_origin[3]);

// The CPU mirror of the vertex shader's decode of splat i: position relative to `origin`
// (computed as the shader does, in float), radius, unit normal (or 0 without normals), RGB.
struct UnpackedSplat {
    std::array<float, 3> position{};
    float radius = 0;
    std::array<float, 3> normal{};
    std::array<uint8_t, 3> color{};
};
UnpackedSplat unpack_splat(const PackedSplats& splats, size_t i);

// Splat i's position (as unpack_splat) and radius code, without the radius's exp2 or the normal
// and colour: for loops over every splat of a node (PointsFormat::data_distance), which look
// the radius up by code.
struct SplatFields {
    std::array<float, 3> position{};
    uint32_t radius_code = 0;  // < 2^radius_bits
};
SplatFields splat_fields(const PackedSplats& splats, size_t i);

// Octahedral code of a unit vector in 6 + 6 bits (u low), and its decode (the shader's mirror).
uint32_t oct6_encode(const float n[3]);
void oct6_decode(uint32_t code, float out[3]);

}  // namespace catpaq
