// Shading for both vertex paths: Lambert + ambient with one directional light (world space,
// pointing towards the light), two-sided; or one flat colour (silhouette and crack tests).

in vec3 v_position;
in vec3 v_normal;
in vec3 v_color;

uniform int flat_mode;
uniform vec3 flat_color;
uniform vec3 light_direction;
uniform float ambient;

out vec4 frag_color;

void main() {
    if (flat_mode != 0) {
        frag_color = vec4(flat_color, 1.0);
        return;
    }
    vec3 n = normalize(v_normal);
    if (!gl_FrontFacing) n = -n;
    float diffuse = max(dot(n, light_direction), 0.0);
    frag_color = vec4(v_color * (ambient + (1.0 - ambient) * diffuse), 1.0);
}
