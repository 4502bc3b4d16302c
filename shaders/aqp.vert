// The AQP vertex shader: one template grid per level (aqp_client/stitch.h), sample (i, j) =
// (gl_VertexID % size, gl_VertexID / size) fetched from the patch level's textures.
//
// Per draw (one patch at one level):
//   level           the patch's drawn level: size = 2^level + 1 samples per side
//   edge_level      the level each edge 0..3 is drawn at (<= level): a sample on edge e snaps to
//                   the nearest multiple of 2^(level - edge_level[e]) along it, ties up, exactly
//                   as snap_sample (client/aqp/src/stitch.cpp), so both patches sharing an edge
//                   end on the same samples
//   patch_offset    the patch's origin minus the frame's anchor, in quantization steps
//   samples         RGBA16UI: local x, y, z (steps from the patch origin), octahedral normal code
//   colors          RGBA8 colours (has_colors), else default_color
// Per frame:
//   step            world units per quantization step
//   mvp             projection * view * translate(origin + anchor * step), built in double on the
//                   CPU
// A position is an integer sum (the same integers for a sample in every patch showing it) and
// one float multiply: a shared sample lands on the same bits in every patch.

uniform highp usampler2D samples;
uniform highp sampler2D colors;
uniform int has_colors;
uniform vec3 default_color;
uniform int level;
uniform ivec4 edge_level;
uniform ivec3 patch_offset;
uniform float step;
uniform mat4 mvp;

out vec3 v_position;
out vec3 v_normal;
out vec3 v_color;

invariant gl_Position;

// t snapped to the nearest multiple of 2^shift, ties up.
int snap(int t, int shift) {
    if (shift <= 0) return t;
    int half_step = (1 << shift) / 2;
    return ((t + half_step) >> shift) << shift;
}

// common_codec/src/octahedral.cpp: 8+8-bit octahedral code (u: low byte, v: high byte, two's
// complement) to a unit vector.
vec3 oct_decode_code(int code) {
    int cu = (code << 24) >> 24;
    int cv = (code << 16) >> 24;
    float u = float(cu) / 127.0;
    float v = float(cv) / 127.0;
    float z = 1.0 - abs(u) - abs(v);
    float x = u;
    float y = v;
    if (z < 0.0) {
        x = (1.0 - abs(v)) * (u < 0.0 ? -1.0 : 1.0);
        y = (1.0 - abs(u)) * (v < 0.0 ? -1.0 : 1.0);
    }
    return normalize(vec3(x, y, z));
}

void main() {
    int size = (1 << level) + 1;
    int last = size - 1;
    int i = gl_VertexID % size;
    int j = gl_VertexID / size;
    if (j == 0) i = snap(i, level - edge_level.x);
    else if (j == last) i = snap(i, level - edge_level.z);
    if (i == last) j = snap(j, level - edge_level.y);
    else if (i == 0) j = snap(j, level - edge_level.w);
    uvec4 s = texelFetch(samples, ivec2(i, j), 0);
    ivec3 g = patch_offset + ivec3(s.xyz);
    PRECISE vec3 p = vec3(g) * step;
    v_position = p;
    v_normal = oct_decode_code(int(s.w));
    v_color = has_colors != 0 ? texelFetch(colors, ivec2(i, j), 0).rgb : default_color;
    gl_Position = mvp * vec4(p, 1.0);
}
