// Oriented splats (seed 002, section 4.1; Botsch and Kobbelt 2003): the pixel's ray from the eye
// is intersected with the splat's plane; pixels whose hit lies outside the splat's disc are
// discarded (the disc projects to an ellipse), the others take the hit's depth, so overlapping
// splats blend into one surface by depth rather than by the order of their centres. Splats
// without a normal are drawn as round ones.
//
// viewport: the image size in pixels; projection_scale: projection[0][0], projection[1][1]
// (a symmetric perspective: a pixel's ray is ((ndc.x / P00), (ndc.y / P11), -1) in eye space);
// depth_coefficients: projection[2][2], projection[3][2].

flat in vec3 v_center;
flat in vec3 v_normal;
flat in vec3 v_color;
flat in float v_radius;
flat in float v_radius_px;
flat in float v_size_px;

uniform vec2 viewport;
uniform vec2 projection_scale;
uniform vec2 depth_coefficients;

out vec4 frag_color;

void main() {
    vec2 ndc = gl_FragCoord.xy / viewport * 2.0 - 1.0;
    vec3 ray = vec3(ndc.x / projection_scale.x, ndc.y / projection_scale.y, -1.0);
    vec3 hit;
    if (dot(v_normal, v_normal) == 0.0) {
        vec2 offset = (gl_PointCoord - vec2(0.5)) * v_size_px;
        float r = max(v_radius_px, 0.5);
        if (dot(offset, offset) > r * r) discard;
        hit = ray * -v_center.z;  // the centre's depth
    } else {
        float facing = dot(ray, v_normal);
        if (abs(facing) < 1e-7) discard;  // a ray in the plane
        float t = dot(v_center, v_normal) / facing;
        hit = ray * t;
        vec3 away = hit - v_center;
        if (t <= 0.0 || dot(away, away) > v_radius * v_radius) discard;
    }
    float ndc_depth = (depth_coefficients.x * hit.z + depth_coefficients.y) / -hit.z;
    gl_FragDepth = clamp(ndc_depth * 0.5 + 0.5, 0.0, 1.0);
    frag_color = shade_splat(v_normal, hit, v_color);
}
