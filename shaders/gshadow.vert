#version 330 core
// Ground shadow mask: each leaf vertex projected along the sun direction onto the ground
// plane z = u_ground_z, placed in the mask's rectangle u_rect = (x0, y0, x1, y1) [m].
in vec3 in_pos;
in vec2 in_uv;
uniform vec3 u_light_dir;   // towards the sun, normalised, z > 0
uniform float u_ground_z;
uniform vec4 u_rect;
out vec2 v_uv;
void main() {
    v_uv = in_uv;
    vec2 q = in_pos.xy - u_light_dir.xy * ((in_pos.z - u_ground_z) / u_light_dir.z);
    gl_Position = vec4((q - u_rect.xy) / (u_rect.zw - u_rect.xy) * 2.0 - 1.0, 0.0, 1.0);
}
