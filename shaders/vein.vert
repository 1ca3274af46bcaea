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
in vec3 in_vein;      // the vein tissue's own albedo (linear colour x tint): the vertex-colour albedo's
in vec2 in_uv;
in float in_order;
in vec4 in_conc;      // the blade's sub-grid mottle pigments under the vein (blade.vert)
in vec4 in_state;
in vec2 in_extra;
in vec2 in_rest;

uniform mat4 u_viewproj;
uniform vec3 u_eye;
uniform vec2 u_viewport;
uniform float u_lift;       // offset along the normal towards the viewer, metres
uniform float u_min_px;     // minimum full width on screen, pixels
uniform float u_width_scale;
uniform float u_pull_max;   // the most the depth test pulls a ribbon toward the eye beyond its half width, metres

out vec3 v_pos;
out vec3 v_nrm;
out vec3 v_bnrm;
out vec3 v_side;
out float v_v;
out float v_alpha;
out float v_hd;
out float v_target;
out vec3 v_base;
out vec3 v_tint;
out vec4 v_chroma;
out vec3 v_vein;
out vec2 v_uv;
flat out int v_order;
out vec4 v_conc;
out vec4 v_state;
out vec2 v_extra;
out vec2 v_rest;

void main() {
    float hw = in_hw * u_width_scale;
    vec3 V = u_eye - in_center;
    float s = dot(in_nrm, V) >= 0.0 ? 1.0 : -1.0;
    vec3 n = in_nrm * s;
    vec3 c = in_center + n * (u_lift + 0.5 * hw);
    // A vein is a rod: its silhouette is as wide as the rod from any side. So the ribbon is
    // spread across the vein perpendicular to the view (e), not in the blade's tangent plane,
    // which seen edge-on (a stalk from the side, a lobe's flank) narrowed it to dots.
    vec3 t = cross(in_side, in_nrm);
    vec3 e = cross(t, V);
    float le = length(e);
    e = le > 1e-6 * length(V) ? e / le : in_side;   // t runs along the polyline, so e turns smoothly
    vec3 m = normalize(cross(e, t));                 // the rod's normal facing the viewer
    if (dot(m, V) < 0.0) m = -m;
    vec4 c0 = u_viewproj * vec4(c, 1.0);
    vec4 c1 = u_viewproj * vec4(c + e * hw, 1.0);
    float px = length((c1.xy / c1.w - c0.xy / c0.w) * 0.5 * u_viewport);
    float half_min = 0.5 * u_min_px;
    float target_px = max(px, half_min);            // drawn half width, pixels
    float hd = target_px + 1.0;                     // geometry: one extra pixel for AA
    float scale = min(hd / max(px, 1e-6), 60.0);
    v_alpha = clamp(px / half_min, 0.0, 1.0);       // sub-pixel veins fade instead of shrinking
    v_hd = hd;
    v_target = target_px;
    vec3 p = c + e * (hw * scale * in_v);
    v_pos = p;
    v_nrm = m;
    v_bnrm = n;     // the blade's normal, facing the eye
    v_side = e;
    v_v = in_v;
    v_base = in_base;
    v_tint = in_tint;
    v_chroma = in_chroma;
    v_vein = in_vein;
    v_uv = in_uv;
    v_order = int(in_order + 0.5);
    v_conc = in_conc;
    v_state = in_state;
    v_extra = in_extra;
    v_rest = in_rest;
    // Depth only: the ribbon is tested as if it lay nearer the eye by half its width and two
    // pixels, at most u_pull_max, so the blade cannot cover it where the surface bulges above
    // a straight segment between two vein points (a lobe curved across a 2.4 mm segment sags
    // 0.07 mm, more than the lift: the veins broke into dashes).  Its pixels stay where they
    // are, and a surface more than that far in front still hides it (a leaf lying on another).
    vec4 clip = u_viewproj * vec4(p, 1.0);
    float pull = u_lift + 0.5 * hw + min(2.0 * hw / max(px, 1e-6), u_pull_max);
    vec4 near = u_viewproj * vec4(p + normalize(u_eye - p) * pull, 1.0);
    gl_Position = vec4(clip.xy, near.z / near.w * clip.w, clip.w);
}
