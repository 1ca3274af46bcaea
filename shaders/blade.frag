#version 330 core
#include "common.glsl"

in vec3 v_pos;
in vec3 v_nrm;
in vec3 v_col;      // vertex colour (linear)
in vec3 v_tint;     // albedo multiplier
in vec4 v_chroma;   // detail albedo: young chromaticity at the vertex, living weight
in vec2 v_uv;
in float v_scalar;
in vec4 v_conc;     // sub-grid mottle: pigment concentrations (common.glsl, mottle_ratio)
in vec4 v_state;    // the reactions' states
in vec2 v_extra;    // necrosis concentration, surface reflectance
in vec2 v_rest;     // where the tissue samples the mottle field (rest position, metres)
in float v_crinkle; // RMS slope of the sub-grid crinkle (render.crinkle; leafsim.sim.crinkle)

// Compile-time switches (the renderer builds one program per combination; a software
// rasteriser runs both sides of a branch on a uniform, so switches must not be uniforms):
// LS_MODE 0 colours, 1 texture, 2 detail, 3 heat map; LS_CMAP 0 turbo, 1 viridis;
// LS_SHADOW 1 = self-shadowing from the shadow map; LS_CUTOUT 1 = discard outside the photo mask;
// LS_MOTTLE 1 = the sub-grid mottle (colour.mottle); LS_CRINKLE 1 = the sub-grid crinkle (render.crinkle).
#ifndef LS_MODE
#define LS_MODE 0
#endif
#ifndef LS_CMAP
#define LS_CMAP 0
#endif
#ifndef LS_SHADOW
#define LS_SHADOW 0
#endif
#ifndef LS_CUTOUT
#define LS_CUTOUT 0
#endif
#ifndef LS_MOTTLE
#define LS_MOTTLE 0
#endif
#ifndef LS_CRINKLE
#define LS_CRINKLE 0
#endif
uniform vec2 u_range;
uniform sampler2D u_tex;       // sRGB photo (decoded by the sampler)
uniform vec3 u_tex_mean;       // mean linear colour of the photo's leaf area

uniform vec3 u_eye;
uniform vec3 u_light_dir;
uniform vec3 u_light_col;
uniform vec3 u_sky_col;
uniform float u_translucency;
uniform float u_specular;
uniform float u_shininess;

uniform sampler2D u_noise;      // the mottle field's 8-bit levels (mottle_n), periodic
uniform float u_mottle_scale;   // its texture coordinates per metre
uniform float u_mottle;         // colour.mottle a
uniform vec3 u_absorb[5];       // absorption per pigment and band
uniform vec3 u_base;            // reflectance of pigment-free tissue (linear)
uniform float u_crinkle_scale;  // the crinkle's texture coordinates per metre (render.crinkle_size)
uniform vec2 u_crinkle_offset;  // where it samples the field, away from the mottle's samples
uniform float u_crinkle_norm;   // 1 / RMS of the field's central difference per texel
uniform sampler2D u_crinkle_grad;  // that central difference along x and y (crinkle_gradient)

uniform sampler2DShadow u_shadow;
uniform mat4 u_light_mat;
uniform float u_shadow_offset;  // world-space offset towards the light (avoids self-acne)

out vec4 f_colour;

void main() {
    vec3 N = normalize(v_nrm);
#if LS_CRINKLE
    // The sub-grid crinkle: a height field h over the rest plane whose slope along each rest
    // direction has the RMS v_crinkle (its gradient: the mottle field's central difference over
    // one texel, precomputed as a texture, normalised), carried to the screen by the chain rule and turned into a normal by
    // Mikkelsen's surface gradient (bump mapping without tangents).  A minified leaf reads a
    // blurred mip level, so the crinkle fades where the pixels cannot show it.
    // (first, and with no branch: screen derivatives and implicit-LOD fetches need the whole
    // 2×2 quad, before any discard; on the front face's normal, then turned with it, so the
    // back of the blade shows the same sheet's relief from behind)
    {
        vec2 g = texture(u_crinkle_grad, v_rest * u_crinkle_scale + u_crinkle_offset).rg;
        vec2 grad_h = max(v_crinkle, 0.0) * u_crinkle_norm * g;  // dh/d(rest), per rest direction
        float dhdx = dot(grad_h, dFdx(v_rest));
        float dhdy = dot(grad_h, dFdy(v_rest));
        vec3 dpdx = dFdx(v_pos);
        vec3 dpdy = dFdy(v_pos);
        vec3 r1 = cross(dpdy, N);
        vec3 r2 = cross(N, dpdx);
        float det = dot(dpdx, r1);
        vec3 Nc = abs(det) * N - sign(det) * (dhdx * r1 + dhdy * r2);
        if (dot(Nc, Nc) > 0.0) N = normalize(Nc);
    }
#endif
    if (!gl_FrontFacing) N = -N;
    vec3 L = u_light_dir;
#if LS_MODE == 3
    float t = (v_scalar - u_range.x) / max(u_range.y - u_range.x, 1e-20);
#if LS_CMAP == 0
    vec3 c = srgb_to_linear(cmap_turbo(t));
#else
    vec3 c = srgb_to_linear(cmap_viridis(t));
#endif
    float lit = 0.55 + 0.45 * abs(dot(N, L));
    f_colour = vec4(linear_to_srgb(c * lit), 1.0);
#else
    vec3 V = normalize(u_eye - v_pos);
#if LS_MODE == 1
    vec4 t = texture(u_tex, v_uv);
#if LS_CUTOUT
    if (t.a < 0.5) discard;
#endif
    vec3 albedo = t.rgb * v_tint;
#elif LS_MODE == 2
    vec3 albedo = photo_detail(v_col * v_tint, texture(u_tex, v_uv).rgb, u_tex_mean, v_chroma);
#else
    vec3 albedo = v_col * v_tint;
#endif
#if LS_MOTTLE
    // the pigments interpolate linearly over the triangle; the field moves them on per pixel
    float n = mottle_n(texture(u_noise, v_rest * u_mottle_scale).r);
    albedo *= mottle_ratio(v_conc, v_state, v_extra, n, u_mottle, u_absorb, u_base);
#endif
#if LS_SHADOW
    float sh = shadow_pcf4(u_shadow, u_light_mat, v_pos + L * u_shadow_offset, 1.5);
#else
    float sh = 1.0;
#endif
    vec3 c = shade_leaf(albedo, N, V, L, u_light_col, u_sky_col, sh,
                        u_translucency, u_specular, u_shininess);
    f_colour = vec4(linear_to_srgb(c), 1.0);
#endif
}
