#version 330 core
in vec3 in_pos;
in vec3 in_nrm;
in vec3 in_col;
in vec3 in_tint;
in vec4 in_chroma;
in vec2 in_uv;
in float in_scalar;
in vec4 in_conc;
in vec4 in_state;
in vec2 in_extra;
in vec2 in_rest;
in vec3 in_crinkle;

uniform mat4 u_viewproj;

out vec3 v_pos;
out vec3 v_nrm;
out vec3 v_col;
out vec3 v_tint;
out vec4 v_chroma;
out vec2 v_uv;
out float v_scalar;
out vec4 v_conc;
out vec4 v_state;
out vec2 v_extra;
out vec2 v_rest;
out vec3 v_crinkle;

void main() {
    v_pos = in_pos;
    v_nrm = in_nrm;
    v_col = in_col;
    v_tint = in_tint;
    v_chroma = in_chroma;
    v_uv = in_uv;
    v_scalar = in_scalar;
    v_conc = in_conc;
    v_state = in_state;
    v_extra = in_extra;
    v_rest = in_rest;
    v_crinkle = in_crinkle;
    gl_Position = u_viewproj * vec4(in_pos, 1.0);
}
