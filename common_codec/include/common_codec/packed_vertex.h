#pragma once
// The 64-bit CATP vertex, as stored on the GPU and decoded by the vertex shader.
//
//   word0 bits 24..31  octahedral normal u          (every layout)
//   word1 bits  0..7   octahedral normal v
//   the other 48 bits, the *payload*: word0 bits 0..23 (payload bits 0..23) and word1 bits
//   8..31 (payload bits 24..47), hold the position and the colour as the layout says:
//     Rgb24       bits 0..23 barycentric position index (a grid of at most 463 steps),
//                 bits 24..47 colour R, G, B (8 bits each, sRGB)
//     Rgb18       bits 0..29 barycentric position index (a grid of at most 1858 steps, 4 times
//                 finer), bits 30..47 colour R, G, B (6 bits each)
//     Position48  bits 0..15 w1, 16..31 w2, 32..47 w3 (w0 implied; a grid of at most 16383
//                 steps, 35 times finer than 463); no colour (the dataset's default colour)
// A dataset has one layout and one grid (catp/format.h), chosen by the converter from the
// precision asked for: inputs without colours spend the colour bits on position, coloured
// inputs may trade two bits of each channel for four times finer positions. The Rgb24 layout
// with grid 463 is the vertex of version-1 datasets.
//
// On the GPU the vertex is one uvec2 attribute (glVertexAttribIPointer, 2 x GL_UNSIGNED_INT).
#include <array>
#include <cstdint>

#include "common_codec/barycentric.h"

namespace catpaq {

struct PackedVertex {
    uint32_t word0 = 0;
    uint32_t word1 = 0;

    uint16_t normal() const { return uint16_t((word0 >> 24) | ((word1 & 0xffu) << 8)); }
    uint64_t payload() const { return uint64_t(word0 & 0xffffffu) | (uint64_t(word1 >> 8) << 24); }

    // The fields of the Rgb24 layout.
    uint32_t position_index() const { return word0 & 0xffffffu; }
    uint8_t r() const { return uint8_t(word1 >> 8); }
    uint8_t g() const { return uint8_t(word1 >> 16); }
    uint8_t b() const { return uint8_t(word1 >> 24); }

    static PackedVertex from_payload(uint64_t payload, uint16_t normal) {
        PackedVertex v;
        v.word0 = uint32_t(payload & 0xffffffu) | (uint32_t(normal & 0xffu) << 24);
        v.word1 = uint32_t(normal >> 8) | (uint32_t(payload >> 24) << 8);
        return v;
    }
    // An Rgb24 vertex.
    static PackedVertex make(uint32_t position_index, uint16_t normal, uint8_t r, uint8_t g, uint8_t b) {
        return from_payload(uint64_t(position_index & 0xffffffu) | (uint64_t(r) << 24) | (uint64_t(g) << 32) |
                                (uint64_t(b) << 40),
                            normal);
    }
    bool operator==(const PackedVertex& o) const { return word0 == o.word0 && word1 == o.word1; }
};
static_assert(sizeof(PackedVertex) == 8, "the CATP vertex is 64 bits");

enum class VertexLayoutKind : uint8_t { Rgb24 = 0, Position48 = 1, Rgb18 = 2 };

// How a dataset's vertices use their payload, and the barycentric grid of their positions.
struct VertexLayout {
    VertexLayoutKind kind = VertexLayoutKind::Rgb24;
    int32_t grid = kBaryGrid;  // weights sum to this

    static constexpr int32_t max_grid(VertexLayoutKind k) {
        return k == VertexLayoutKind::Rgb24 ? kBaryGrid : k == VertexLayoutKind::Rgb18 ? kMaxIndexGrid : kMaxWideGrid;
    }
    bool has_color() const { return kind != VertexLayoutKind::Position48; }
    // Bits per colour channel (0: no colour) and the payload bit where the colour starts.
    int color_bits() const { return kind == VertexLayoutKind::Rgb24 ? 8 : kind == VertexLayoutKind::Rgb18 ? 6 : 0; }
    int color_shift() const { return 48 - 3 * color_bits(); }
    bool valid() const {
        return uint8_t(kind) <= uint8_t(VertexLayoutKind::Rgb18) && grid >= 1 && grid <= max_grid(kind);
    }
    const char* name() const {
        return kind == VertexLayoutKind::Rgb24 ? "rgb24" : kind == VertexLayoutKind::Rgb18 ? "rgb18" : "position48";
    }
    bool operator==(const VertexLayout& o) const { return kind == o.kind && grid == o.grid; }
    bool operator!=(const VertexLayout& o) const { return !(*this == o); }
};

// The position weights of a vertex; false if its payload is not a valid position of the layout
// (corrupt data).
bool vertex_weights(PackedVertex v, const VertexLayout& layout, BaryWeights& w);
// A vertex of the layout: weights (valid for the layout's grid), normal and colour (8 bits per
// channel, rounded to the layout's bits; ignored without colour).
PackedVertex pack_vertex(const VertexLayout& layout, const BaryWeights& w, uint16_t normal, const uint8_t rgb[3]);
// The payload bits of a colour in a layout (0 without colour): what pack_vertex ORs in.
uint64_t color_payload(const VertexLayout& layout, const uint8_t rgb[3]);

// What the vertex shader computes for one vertex (CPU mirror, bit-exact with the GLSL).
struct DecodedVertex {
    float position[3];  // in the rendering frame (anchor-relative, scaled)
    float normal[3];
    float color[3];  // 0..1
};

// The per-draw inputs of the decode: the vertex shader's uniforms.
struct VertexDecodeParams {
    std::array<LatticePoint, 4> offsets{};  // canonical corners of the tetrahedron minus the anchor
    VertexLayout layout;
    float scale = 1.0f;  // lattice cell in the rendering frame / layout.grid
    std::array<float, 3> default_color{0.7f, 0.7f, 0.7f};  // layouts without colour
};

// The colour of a vertex of a layout with colour, 0..1.
void vertex_color(PackedVertex v, const VertexLayout& layout, float out[3]);
// Decodes a packed vertex. Returns false if the position is corrupt.
bool decode_packed_vertex(PackedVertex v, const VertexDecodeParams& params, DecodedVertex& out);

}  // namespace catpaq
