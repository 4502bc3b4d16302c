// CATP vertex decode, shared by the vertex shaders (the loader inserts it after the version
// preamble). Each function mirrors its CPU twin in common_codec:
//   bary_unpack()    common_codec/src/barycentric.cpp  (tetrahedral index -> 4 weights)
//   vertex_weights() common_codec/src/packed_vertex.cpp (the layouts' position bits -> weights)
//   bary_offset()    common_codec/src/barycentric.cpp  (bary_decode)
//   oct_decode()     common_codec/src/octahedral.cpp   (8+8-bit octahedral normal -> unit vector)
// Positions are integer sums, then the same few float operations the CPU does: a vertex decodes
// to the same bits on the GPU as on the CPU, and from every tetrahedron that shares it (the
// same weights times the same canonical corners give the same integers).

const int kLayoutRgb24 = 0;
const int kLayoutPosition48 = 1;
const int kLayoutRgb18 = 2;

// Tet(a) = a (a + 1) (a + 2) / 6 without overflowing 32 bits for a <= 1860 (the 30-bit index's
// grid): a (a + 1) / 2 is exact, and a (a + 1) (a + 2) / 2 is a multiple of 3.
uint bary_tet(uint a) { return ((a * (a + 1u)) / 2u) * (a + 2u) / 3u; }
uint bary_tri(uint b) { return b * (b + 1u) / 2u; }

// Weights (w0, w1, w2, w3) of a position index, w0 = grid - w1 - w2 - w3. The index is
// Tet(a) + Tri(b) + c with a = w1+w2+w3, b = w2+w3, c = w3. The float estimates only pick the
// start of the integer correction loops, so the result is exact whatever pow/sqrt round to.
// The uploader rejects indices beyond the grid, and the loops are bounded anyway.
ivec4 bary_unpack(uint index, int grid) {
    uint g = uint(grid);
    // pow(0, y) may be NaN on some GPUs and float-to-uint of NaN is undefined: keep x >= 1 and
    // clamp the integer too, so the loops always start inside [0, grid].
    uint a = min(uint(clamp(pow(max(6.0 * float(index), 1.0), 1.0 / 3.0), 0.0, float(g))), g);
    for (int i = 0; i < 2000 && a > 0u && bary_tet(a) > index; ++i) a -= 1u;
    for (int i = 0; i < 2000 && a < g && bary_tet(a + 1u) <= index; ++i) a += 1u;
    uint rest = index - bary_tet(a);
    uint b = min(uint(clamp(sqrt(2.0 * float(rest)), 0.0, float(a))), a);
    for (int i = 0; i < 2000 && b > 0u && bary_tri(b) > rest; ++i) b -= 1u;
    for (int i = 0; i < 2000 && b < a && bary_tri(b + 1u) <= rest; ++i) b += 1u;
    uint c = rest - bary_tri(b);
    return ivec4(grid - int(a), int(a - b), int(b - c), int(c));
}

// The 48 payload bits beside the normal: word0 bits 0..23 (low) and word1 bits 8..31 (high).
uint payload_low(uvec2 p) { return p.x & 0xffffffu; }
uint payload_high(uvec2 p) { return p.y >> 8u; }

// The position weights of a vertex in the dataset's layout (common_codec/packed_vertex.h).
ivec4 vertex_weights(uvec2 p, int kind, int grid) {
    uint lo = payload_low(p), hi = payload_high(p);
    if (kind == kLayoutPosition48) {
        uint w1 = lo & 0xffffu, w2 = (lo >> 16u) | ((hi & 0xffu) << 8u), w3 = hi >> 8u;
        return ivec4(grid - int(w1 + w2 + w3), int(w1), int(w2), int(w3));
    }
    uint index = kind == kLayoutRgb18 ? lo | ((hi & 0x3fu) << 24u) : lo;
    return bary_unpack(index, grid);
}

// The vertex's colour (0..1): 8 or 6 bits per channel, or the dataset's default colour.
vec3 vertex_color(uvec2 p, int kind, vec3 default_color) {
    uint hi = payload_high(p);
    if (kind == kLayoutRgb24)
        return vec3(float(hi & 0xffu), float((hi >> 8u) & 0xffu), float(hi >> 16u)) / 255.0;
    if (kind == kLayoutRgb18)
        return vec3(float((hi >> 6u) & 0x3fu), float((hi >> 12u) & 0x3fu), float(hi >> 18u)) / 63.0;
    return default_color;
}

// The position relative to the anchor in units of 1 / grid lattice cells, from the weights and
// the canonical corners minus the anchor (|d| <= 2^20): with w = 128 hi + lo, both sums are exact
// in 32-bit integers for grids below 2^14, and float(high) * 128 is exact.
vec3 bary_offset(ivec4 w, ivec3 d0, ivec3 d1, ivec3 d2, ivec3 d3) {
    ivec3 high = (w.x >> 7) * d0 + (w.y >> 7) * d1 + (w.z >> 7) * d2 + (w.w >> 7) * d3;
    ivec3 low = (w.x & 127) * d0 + (w.y & 127) * d1 + (w.z & 127) * d2 + (w.w & 127) * d3;
    PRECISE vec3 sum = vec3(high) * 128.0 + vec3(low);
    return sum;
}

// Octahedral normal from the signed bytes cu, cv in [-127, 127] (two's complement, value/127).
// Not `precise`: normals only shade, and on llvmpipe `precise` here made the whole vertex stage
// about 5x slower. A driver may then fuse the length's multiply-adds and differ from the CPU
// mirror in the last bit (llvmpipe does not: client_gl_tests finds them bit-identical and bounds
// the difference at 2e-7 either way). Positions, which must match across tetrahedra, stay exact.
vec3 oct_decode(int cu, int cv) {
    float u = float(cu) / 127.0;
    float v = float(cv) / 127.0;
    float z = 1.0 - abs(u) - abs(v);
    float x = u;
    float y = v;
    if (z < 0.0) {
        x = (1.0 - abs(v)) * (u < 0.0 ? -1.0 : 1.0);
        y = (1.0 - abs(u)) * (v < 0.0 ? -1.0 : 1.0);
    }
    float len = sqrt(x * x + y * y + z * z);
    return vec3(x / len, y / len, z / len);
}

// The normal's fields of the 64-bit vertex (common_codec/packed_vertex.h).
int packed_normal_u(uvec2 p) { return int(p.x) >> 24; }          // arithmetic shift: sign-extends
int packed_normal_v(uvec2 p) { return int(p.y << 24u) >> 24; }
