#version 330 core
in vec2 in_xy;          // unit quad corner in [-1, 1]^2

uniform mat4 u_viewproj;
uniform vec3 u_center;  // ground centre (z = ground height)
uniform float u_extent; // half size, metres

out vec3 v_pos;

void main() {
    v_pos = vec3(u_center.xy + in_xy * u_extent, u_center.z);
    gl_Position = u_viewproj * vec4(v_pos, 1.0);
}
