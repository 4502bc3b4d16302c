#include "common_codec/packed_vertex.h"

#include <cstddef>

#include "common_codec/octahedral.h"

namespace catpaq {

bool vertex_weights(PackedVertex v, const VertexLayout& layout, BaryWeights& w) {
    if (layout.kind != VertexLayoutKind::Position48)
        return bary_unpack(uint32_t(v.payload() & ((uint64_t(1) << layout.color_shift()) - 1)), layout.grid, w);
    const uint64_t p = v.payload();
    const int32_t w1 = int32_t(p & 0xffff), w2 = int32_t((p >> 16) & 0xffff), w3 = int32_t(p >> 32);
    const int32_t rest = layout.grid - w1 - w2 - w3;
    if (rest < 0) return false;  // also catches any weight above the grid
    w = {rest, w1, w2, w3};
    return true;
}

PackedVertex pack_vertex(const VertexLayout& layout, const BaryWeights& w, uint16_t normal, const uint8_t rgb[3]) {
    if (layout.kind == VertexLayoutKind::Position48)
        return PackedVertex::from_payload(uint64_t(w[1]) | (uint64_t(w[2]) << 16) | (uint64_t(w[3]) << 32), normal);
    return PackedVertex::from_payload(bary_pack(w) | color_payload(layout, rgb), normal);
}

uint64_t color_payload(const VertexLayout& layout, const uint8_t rgb[3]) {
    if (layout.kind == VertexLayoutKind::Rgb24)  // 8 bits as they are (the quantizer's hot path)
        return (uint64_t(rgb[0]) << 24) | (uint64_t(rgb[1]) << 32) | (uint64_t(rgb[2]) << 40);
    const int bits = layout.color_bits(), shift = layout.color_shift();
    const uint32_t top = (1u << bits) - 1;
    uint64_t payload = 0;
    for (int c = 0; c < 3 && bits > 0; ++c) payload |= uint64_t((uint32_t(rgb[c]) * top + 127) / 255) << (shift + bits * c);
    return payload;
}

void vertex_color(PackedVertex v, const VertexLayout& layout, float out[3]) {
    const int bits = layout.color_bits(), shift = layout.color_shift();
    const uint32_t top = (1u << bits) - 1;
    const uint64_t payload = v.payload();
    for (int c = 0; c < 3; ++c) out[c] = float(uint32_t(payload >> (shift + bits * c)) & top) / float(top);
}

bool decode_packed_vertex(PackedVertex v, const VertexDecodeParams& params, DecodedVertex& out) {
    BaryWeights w;
    if (!vertex_weights(v, params.layout, w)) return false;
    bary_decode(w, params.offsets, params.scale, out.position);
    oct_decode(v.normal(), out.normal);
    if (params.layout.has_color()) {
        vertex_color(v, params.layout, out.color);
    } else {
        for (int k = 0; k < 3; ++k) out.color[k] = params.default_color[std::size_t(k)];
    }
    return true;
}

}  // namespace catpaq
