// The CATP vertex shader: one 64-bit vertex in, decoded on the fly (shaders/catp_decode.glsl).
//
// Per draw (one fragment = one tetrahedron of a diamond):
//   corners[4]          the tetrahedron's corners in canonical order, lattice coordinates (< 2^21)
// Per frame:
//   anchor_times_grid   463 x an integer lattice point A near the camera, so sums stay small
//   scale               world units per lattice unit / 463 (the dataset's cell / kBaryGrid)
//   mvp                 projection * view * translate(origin + A * cell), built in double on the
//                       CPU: it maps the anchor-relative position float(S) * scale to clip space
// Outputs: v_position (anchor-relative world position, what transform-feedback tests capture),
// v_normal (world, unit), v_color (0..1).

layout(location = 0) in uvec2 a_packed;

uniform ivec3 corners[4];
uniform ivec3 anchor_times_grid;
uniform float scale;
uniform mat4 mvp;

out vec3 v_position;
out vec3 v_normal;
out vec3 v_color;

invariant gl_Position;

void main() {
    ivec4 w = bary_unpack(packed_position_index(a_packed));
    ivec3 s = bary_weighted_sum(w, corners[0], corners[1], corners[2], corners[3], anchor_times_grid);
    PRECISE vec3 p = vec3(s) * scale;
    v_position = p;
    v_normal = oct_decode(packed_normal_u(a_packed), packed_normal_v(a_packed));
    v_color = packed_color(a_packed);
    gl_Position = mvp * vec4(p, 1.0);
}
