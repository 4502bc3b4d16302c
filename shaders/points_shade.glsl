// Shading of point splats (both shapes): Lambert + ambient with one directional light (eye
// space, towards the light), the normal turned towards the eye; or one flat colour. Splats
// without normals are lit fully (they face the eye).

uniform int flat_mode;
uniform vec3 flat_color;
uniform vec3 light_eye;
uniform float ambient;

vec4 shade_splat(vec3 normal, vec3 position, vec3 color) {
    if (flat_mode != 0) return vec4(flat_color, 1.0);
    if (dot(normal, normal) == 0.0) return vec4(color, 1.0);
    vec3 n = dot(normal, position) > 0.0 ? -normal : normal;
    float diffuse = max(dot(n, light_eye), 0.0);
    return vec4(color * (ambient + (1.0 - ambient) * diffuse), 1.0);
}
