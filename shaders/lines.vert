#version 330 core
in vec3 in_pos;
in float in_kind;      // spring kind 0..3, or -1 = use u_colour
uniform mat4 u_viewproj;
uniform vec3 u_kind_cols[4];
uniform vec3 u_colour;
uniform vec3 u_eye;
uniform float u_lift;  // pull towards the eye (metres) so lines win over the blade
out vec3 v_col;
void main() {
    int k = int(in_kind + 0.5);
    v_col = in_kind < -0.5 ? u_colour : u_kind_cols[clamp(k, 0, 3)];
    vec3 p = in_pos + normalize(u_eye - in_pos) * u_lift;
    gl_Position = u_viewproj * vec4(p, 1.0);
}
