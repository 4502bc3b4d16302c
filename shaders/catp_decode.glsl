// CATP vertex decode, shared by the vertex shaders (the loader inserts it after the version
// preamble). Each function mirrors its CPU twin in common_codec:
//   bary_unpack()  common_codec/src/barycentric.cpp  (24-bit tetrahedral index -> 4 weights)
//   oct_decode()   common_codec/src/octahedral.cpp   (8+8-bit octahedral normal -> unit vector)
// Positions are integer sums, so the only rounding is the final float(S) * scale, which the CPU
// does identically: a vertex decodes to the same bits on the GPU as on the CPU, and from every
// tetrahedron that shares it (weights times canonical corners give the same integers).

const uint kBaryGrid = 463u;

uint bary_tet(uint a) { return a * (a + 1u) * (a + 2u) / 6u; }
uint bary_tri(uint b) { return b * (b + 1u) / 2u; }

// Weights (w0, w1, w2, w3) of a position index, w0 = 463 - w1 - w2 - w3. The index is
// Tet(a) + Tri(b) + c with a = w1+w2+w3, b = w2+w3, c = w3. The float estimates only pick the
// start of the integer correction loops, so the result is exact whatever pow/sqrt round to.
// The uploader rejects indices >= kBaryIndexCount, and the loops are bounded anyway.
ivec4 bary_unpack(uint index) {
    // pow(0, y) may be NaN on some GPUs and float-to-uint of NaN is undefined: keep x >= 1 and
    // clamp the integer too, so the loops always start inside [0, 463].
    uint a = min(uint(clamp(pow(max(6.0 * float(index), 1.0), 1.0 / 3.0), 0.0, float(kBaryGrid))), kBaryGrid);
    for (int i = 0; i < 470 && a > 0u && bary_tet(a) > index; ++i) a -= 1u;
    for (int i = 0; i < 470 && a < kBaryGrid && bary_tet(a + 1u) <= index; ++i) a += 1u;
    uint rest = index - bary_tet(a);
    uint b = min(uint(clamp(sqrt(2.0 * float(rest)), 0.0, float(a))), a);
    for (int i = 0; i < 470 && b > 0u && bary_tri(b) > rest; ++i) b -= 1u;
    for (int i = 0; i < 470 && b < a && bary_tri(b + 1u) <= rest; ++i) b += 1u;
    uint c = rest - bary_tri(b);
    return ivec4(int(kBaryGrid - a), int(a - b), int(b - c), int(c));
}

// S = w0*C0 + w1*C1 + w2*C2 + w3*C3 - anchor_times_grid, in 32-bit integers (exact for lattice
// coordinates below 2^22), with the canonical (lexicographically sorted) corners.
ivec3 bary_weighted_sum(ivec4 w, ivec3 c0, ivec3 c1, ivec3 c2, ivec3 c3, ivec3 anchor_times_grid) {
    return w.x * c0 + w.y * c1 + w.z * c2 + w.w * c3 - anchor_times_grid;
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

// The fields of the 64-bit vertex (common_codec/packed_vertex.h).
uint packed_position_index(uvec2 p) { return p.x & 0xffffffu; }
int packed_normal_u(uvec2 p) { return int(p.x) >> 24; }          // arithmetic shift: sign-extends
int packed_normal_v(uvec2 p) { return int(p.y << 24u) >> 24; }
vec3 packed_color(uvec2 p) {
    return vec3(float((p.y >> 8u) & 0xffu), float((p.y >> 16u) & 0xffu), float(p.y >> 24u)) / 255.0;
}
