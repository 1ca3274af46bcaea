#version 330 core
in vec3 in_pos;
in float in_layer;     // 0 bottom, 1 top
uniform mat4 u_viewproj;
uniform float u_point_size;
out float v_layer;
void main() {
    v_layer = in_layer;
    gl_Position = u_viewproj * vec4(in_pos, 1.0);
    gl_PointSize = u_point_size;
}
