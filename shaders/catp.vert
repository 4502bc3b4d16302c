// The CATP vertex shader: one 64-bit vertex in, decoded on the fly (shaders/catp_decode.glsl).
//
// Per draw (one fragment = one tetrahedron of a diamond):
//   corners[4]      the tetrahedron's corners in canonical order minus the frame's anchor A, an
//                   integer lattice point near the camera (lattice units, |coordinate| <= 2^20)
// Per frame (the dataset's):
//   vertex_layout, grid  the vertex layout and its barycentric grid (common_codec/packed_vertex.h)
//   scale           world units per lattice unit / grid
//   default_color   the colour of layouts without one
//   mvp             projection * view * translate(origin + A * cell), built in double on the
//                   CPU: it maps the anchor-relative position to clip space
// Outputs: v_position (anchor-relative world position, what transform-feedback tests capture),
// v_normal (world, unit), v_color (0..1).

layout(location = 0) in uvec2 a_packed;

uniform ivec3 corners[4];
uniform int vertex_layout;
uniform int grid;
uniform float scale;
uniform vec3 default_color;
uniform mat4 mvp;

out vec3 v_position;
out vec3 v_normal;
out vec3 v_color;

invariant gl_Position;

void main() {
    ivec4 w = vertex_weights(a_packed, vertex_layout, grid);
    PRECISE vec3 p = bary_offset(w, corners[0], corners[1], corners[2], corners[3]) * scale;
    v_position = p;
    v_normal = oct_decode(packed_normal_u(a_packed), packed_normal_v(a_packed));
    v_color = vertex_color(a_packed, vertex_layout, default_color);
    gl_Position = mvp * vec4(p, 1.0);
}
