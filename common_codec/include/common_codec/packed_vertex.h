#pragma once
// The 64-bit CATP vertex, as stored on the GPU and decoded by the vertex shader:
//
//   word0 bits  0..23  barycentric position index (common_codec/barycentric.h)
//   word0 bits 24..31  octahedral normal u
//   word1 bits  0..7   octahedral normal v
//   word1 bits  8..31  colour R, G, B (8 bits each, sRGB)
//
// On the GPU the vertex is one uvec2 attribute (glVertexAttribIPointer, 2 x GL_UNSIGNED_INT).
#include <cstdint>

#include "common_codec/barycentric.h"

namespace catpaq {

struct PackedVertex {
    uint32_t word0 = 0;
    uint32_t word1 = 0;

    uint32_t position_index() const { return word0 & 0xffffffu; }
    uint16_t normal() const { return uint16_t((word0 >> 24) | ((word1 & 0xffu) << 8)); }
    uint8_t r() const { return uint8_t(word1 >> 8); }
    uint8_t g() const { return uint8_t(word1 >> 16); }
    uint8_t b() const { return uint8_t(word1 >> 24); }

    static PackedVertex make(uint32_t position_index, uint16_t normal, uint8_t r, uint8_t g, uint8_t b) {
        PackedVertex v;
        v.word0 = (position_index & 0xffffffu) | (uint32_t(normal & 0xffu) << 24);
        v.word1 = uint32_t(normal >> 8) | (uint32_t(r) << 8) | (uint32_t(g) << 16) | (uint32_t(b) << 24);
        return v;
    }
    bool operator==(const PackedVertex& o) const { return word0 == o.word0 && word1 == o.word1; }
};
static_assert(sizeof(PackedVertex) == 8, "the CATP vertex is 64 bits");

// What the vertex shader computes for one vertex (CPU mirror, bit-exact with the GLSL).
struct DecodedVertex {
    float position[3];  // in the rendering frame (anchor-relative, scaled)
    float normal[3];
    float color[3];  // 0..1
};

// Decodes a packed vertex of a tetrahedron with canonical corners `corners`. Returns false if the
// position index is out of range (corrupt data).
bool decode_packed_vertex(PackedVertex v, const std::array<LatticePoint, 4>& corners,
                          const std::array<int32_t, 3>& anchor_times_grid, float scale, DecodedVertex& out);

}  // namespace catpaq
