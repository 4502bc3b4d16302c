// Round splats: a screen-aligned disc of the projected radius, at the depth of the centre.

flat in vec3 v_center;
flat in vec3 v_normal;
flat in vec3 v_color;
flat in float v_radius;
flat in float v_radius_px;
flat in float v_size_px;

out vec4 frag_color;

void main() {
    vec2 offset = (gl_PointCoord - vec2(0.5)) * v_size_px;  // pixels from the centre
    float r = max(v_radius_px, 0.5);                        // at least the pixel it lands on
    if (dot(offset, offset) > r * r) discard;
    frag_color = shade_splat(v_normal, v_center, v_color);
}
