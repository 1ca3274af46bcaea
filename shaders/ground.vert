#version 330 core
in vec2 in_xy;          // unit quad corner in [-1, 1]^2

uniform mat4 u_viewproj;
uniform vec4 u_quad;    // (centre x, centre y, half width, half height) of this quad [m]
uniform float u_ground_z;

out vec3 v_pos;

void main() {
    v_pos = vec3(u_quad.xy + in_xy * u_quad.zw, u_ground_z);
    gl_Position = u_viewproj * vec4(v_pos, 1.0);
}
