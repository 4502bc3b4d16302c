// The comparison path: the same fragments decoded on the CPU to 3 floats of position (relative
// to the dataset origin), 3 floats of normal and 4 normalized bytes of colour (28 bytes/vertex).
// mvp = projection * view * translate(origin), built in double on the CPU.

layout(location = 0) in vec3 a_position;
layout(location = 1) in vec3 a_normal;
layout(location = 2) in vec4 a_color;

uniform mat4 mvp;

out vec3 v_position;
out vec3 v_normal;
out vec3 v_color;

invariant gl_Position;

void main() {
    v_position = a_position;
    v_normal = a_normal;
    v_color = a_color.rgb;
    gl_Position = mvp * vec4(a_position, 1.0);
}
