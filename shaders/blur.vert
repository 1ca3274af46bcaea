#version 330 core
in vec2 in_xy;          // unit quad corner in [-1, 1]^2
out vec2 v_uv;
void main() {
    v_uv = in_xy * 0.5 + 0.5;
    gl_Position = vec4(in_xy, 0.0, 1.0);
}
