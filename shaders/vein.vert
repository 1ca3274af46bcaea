#version 330 core
// One ribbon vertex: the centre line point expanded sideways by +-half width (in_v = +-1).
in vec3 in_center;
in vec3 in_side;      // unit, in the blade's tangent plane, across the vein
in vec3 in_nrm;       // blade normal at the point
in float in_hw;       // half width, metres
in float in_v;        // -1 or +1
in vec3 in_base;      // blade albedo under the vein (linear colour x tint)
in vec3 in_tint;      // tint alone (multiplies the photo)
in vec4 in_chroma;    // detail albedo: young chromaticity under the vein, living weight
in vec2 in_uv;
in float in_order;

uniform mat4 u_viewproj;
uniform vec3 u_eye;
uniform vec2 u_viewport;
uniform float u_lift;       // offset along the normal towards the viewer, metres
uniform float u_min_px;     // minimum full width on screen, pixels
uniform float u_width_scale;

out vec3 v_pos;
out vec3 v_nrm;
out vec3 v_side;
out float v_v;
out float v_alpha;
out float v_hd;
out float v_target;
out vec3 v_base;
out vec3 v_tint;
out vec4 v_chroma;
out vec2 v_uv;
flat out int v_order;

void main() {
    float hw = in_hw * u_width_scale;
    float s = dot(in_nrm, u_eye - in_center) >= 0.0 ? 1.0 : -1.0;
    vec3 n = in_nrm * s;
    vec3 c = in_center + n * (u_lift + 0.5 * hw);
    vec4 c0 = u_viewproj * vec4(c, 1.0);
    vec4 c1 = u_viewproj * vec4(c + in_side * hw, 1.0);
    float px = length((c1.xy / c1.w - c0.xy / c0.w) * 0.5 * u_viewport);
    float half_min = 0.5 * u_min_px;
    float target_px = max(px, half_min);            // drawn half width, pixels
    float hd = target_px + 1.0;                     // geometry: one extra pixel for AA
    float scale = min(hd / max(px, 1e-6), 60.0);
    v_alpha = clamp(px / half_min, 0.0, 1.0);       // sub-pixel veins fade instead of shrinking
    v_hd = hd;
    v_target = target_px;
    vec3 p = c + in_side * (hw * scale * in_v);
    v_pos = p;
    v_nrm = n;
    v_side = in_side;
    v_v = in_v;
    v_base = in_base;
    v_tint = in_tint;
    v_chroma = in_chroma;
    v_uv = in_uv;
    v_order = int(in_order + 0.5);
    gl_Position = u_viewproj * vec4(p, 1.0);
}
