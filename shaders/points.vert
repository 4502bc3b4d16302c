// The point splat vertex shader: one 8- or 6-byte splat in (client/points/include/points_client/
// splat_layout.h: 16-bit halves), one point sprite out, large enough to hold the splat's
// projection.
//
// Per node:  node_offset  the node's grid origin minus the eye, world units, computed in double
//                         on the CPU (so nodes 1e7 units from the origin keep their precision)
//            node_step    grid step per axis; radius_base, radius_log2_step, radius_bits: the
//                         radius code's scale and width (5: 8-byte layout, 4: 6-byte layout);
//                         has_normals, has_colors
// Per frame: modelview    eye-relative world -> eye space (a rotation: the eye is at 0)
//            projection, pixels_per_unit (pixels of one unit at distance 1), max_point_size,
//            oriented (1: the sprite must hold the whole ellipse, which the fragment shader
//            ray-casts; 0: a screen-aligned disc of the projected radius), default_color
// Outputs (flat): centre and normal in eye space, colour, radius (world), the disc's radius and
// the sprite's size in pixels.

layout(location = 0) in uvec4 a_splat;

uniform vec3 node_offset;
uniform vec3 node_step;
uniform float radius_base;
uniform float radius_log2_step;
uniform int radius_bits;
uniform int has_normals;
uniform int has_colors;
uniform vec3 default_color;
uniform mat4 modelview;
uniform mat4 projection;
uniform float pixels_per_unit;
uniform float max_point_size;
uniform int oriented;

flat out vec3 v_center;
flat out vec3 v_normal;
flat out vec3 v_color;
flat out float v_radius;
flat out float v_radius_px;
flat out float v_size_px;

vec3 oct6_decode(uint code) {
    float x = float(code & 63u) / 63.0 * 2.0 - 1.0;
    float y = float((code >> 6u) & 63u) / 63.0 * 2.0 - 1.0;
    float z = 1.0 - abs(x) - abs(y);
    if (z < 0.0) {
        float fx = (1.0 - abs(y)) * (x >= 0.0 ? 1.0 : -1.0);
        float fy = (1.0 - abs(x)) * (y >= 0.0 ? 1.0 : -1.0);
        x = fx;
        y = fy;
    }
    return normalize(vec3(x, y, z));
}

void main() {
    uint w0 = a_splat.x | (a_splat.y << 16u);
    uint w1 = a_splat.z | (has_colors != 0 ? a_splat.w << 16u : 0u);
    vec3 q = vec3(float(w0 & 2047u), float((w0 >> 11u) & 2047u), float(w0 >> 22u));
    vec3 relative = node_offset + q * node_step;
    vec4 eye = modelview * vec4(relative, 1.0);
    v_center = eye.xyz;
    uint radius_code = (w1 >> 12u) & ((1u << uint(radius_bits)) - 1u);
    v_radius = radius_base * exp2(float(radius_code) * radius_log2_step);
    v_normal = has_normals != 0 ? mat3(modelview) * oct6_decode(w1 & 4095u) : vec3(0.0);
    v_color = has_colors != 0 ? vec3(float((w1 >> 17u) & 31u), float((w1 >> 22u) & 31u), float(w1 >> 27u)) / 31.0
                              : default_color;
    float d = max(-eye.z, 1e-30);
    v_radius_px = pixels_per_unit * v_radius / d;
    float half_size = v_radius_px;
    if (oriented != 0) {
        // Any point within the radius of the centre projects within this of the centre's
        // projection: r (1 + max(|x|, |y|) / d) / (d - r), in units at distance 1.
        float lateral = max(abs(eye.x), abs(eye.y)) / d;
        half_size = d > v_radius ? pixels_per_unit * v_radius * (1.0 + lateral) / (d - v_radius) : max_point_size;
    }
    v_size_px = min(2.0 * half_size + 2.0, max_point_size);
    gl_PointSize = v_size_px;
    gl_Position = projection * eye;
}
