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
in vec3 v_crinkle;  // slope tensor of the sub-grid crinkle, xx xy yy over the rest plane, rad²
                    // (render.crinkle; leafsim.sim.crinkle.crinkle_slopes)

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
uniform vec2 u_crinkle_oriented[4];  // where each oriented field samples it (CRINKLE_ORIENTED_OFFSETS)
const float CRINKLE_CREST = 3.0;   // a one-way crinkle's crest length ÷ spacing (mottle.CRINKLE_CREST)
const float CRINKLE_STEP = 0.78539816339;  // π / 4: the oriented fields' spacing in angle
const vec2 CRINKLE_DIRS[4] = vec2[4](vec2(1.0, 0.0), vec2(0.70710678, 0.70710678), vec2(0.0, 1.0),
                                     vec2(-0.70710678, 0.70710678));  // their compression directions

uniform sampler2DShadow u_shadow;
uniform mat4 u_light_mat;
uniform float u_shadow_offset;  // world-space offset towards the light (avoids self-acne)

out vec4 f_colour;

void main() {
    vec3 N = normalize(v_nrm);
#if LS_CRINKLE
    // The sub-grid crinkle: a height field h over the rest plane whose mean squared slope along
    // a rest direction u is uᵀSu (S = v_crinkle).  Its gradient mixes the field's central
    // differences (precomputed as a texture, normalised) read as they are with the same
    // differences read stretched CRINKLE_CREST times along the crests, in the two of four
    // fixed orientations nearest the compression (weights cos, sin: variance kept), the share
    // of the oriented ones growing with how one-sided the compression is; the mix is then
    // whitened by its own covariance and given S's (leafsim.appearance.mottle.crinkle_height_gradient
    // is the same in numpy).  It is carried to the screen by the chain rule and turned into a
    // normal by Mikkelsen's surface gradient (bump mapping without tangents).  The fetches take
    // the coordinates' analytic derivatives, so a minified leaf reads a blurred mip level and
    // the crinkle fades where the pixels cannot show it, with no seam where the orientation
    // pair changes.  (First, and with no branch: screen derivatives need the whole 2×2 quad,
    // before any discard; on the front face's normal, then turned with it, so the back of the
    // blade shows the same sheet's relief from behind.)
    {
        vec3 S = v_crinkle;
        float half_tr = 0.5 * (S.x + S.z);
        float dev = sqrt(0.25 * (S.x - S.z) * (S.x - S.z) + S.y * S.y);
        float l1 = max(half_tr + dev, 0.0);
        float l2 = max(half_tr - dev, 0.0);
        float dx = S.x - S.z;
        float ang = 0.5 * atan(2.0 * S.y, (abs(dx) + abs(S.y) > 0.0) ? dx : 1.0);
        vec2 d = vec2(cos(ang), sin(ang));
        vec2 t = vec2(-d.y, d.x);
        float a = clamp((l1 + l2 > 0.0) ? (l1 - l2) / (l1 + l2) : 0.0, 0.0, 1.0);
        vec2 rx = dFdx(v_rest) * u_crinkle_scale;
        vec2 ry = dFdy(v_rest) * u_crinkle_scale;
        vec2 q = v_rest * u_crinkle_scale;
        vec2 g_iso = u_crinkle_norm * textureGrad(u_crinkle_grad, q + u_crinkle_offset, rx, ry).rg;
        float x = mod(ang, 3.14159265359) / CRINKLE_STEP;
        float fl = floor(x);
        float f = x - fl;
        int ka = int(fl) & 3;
        vec2 g_or = vec2(0.0);
        float Ed = 1.0 - a;
        float Et = 1.0 - a;
        float Edt = 0.0;
        for (int j = 0; j < 2; ++j) {
            int k = (ka + j) & 3;
            float w = (j == 0) ? cos(1.57079632679 * f) : sin(1.57079632679 * f);
            float delta = (f - float(j)) * CRINKLE_STEP;
            vec2 dk = CRINKLE_DIRS[k];
            vec2 tk = vec2(-dk.y, dk.x);
            vec2 scale_k = vec2(1.0, 1.0 / CRINKLE_CREST);
            vec2 qk = vec2(dot(q, dk), dot(q, tk)) * scale_k + u_crinkle_oriented[k];
            vec2 gxk = vec2(dot(rx, dk), dot(rx, tk)) * scale_k;
            vec2 gyk = vec2(dot(ry, dk), dot(ry, tk)) * scale_k;
            vec2 g = u_crinkle_norm * textureGrad(u_crinkle_grad, qk, gxk, gyk).rg;
            g_or += w * (g.x * dk + g.y / CRINKLE_CREST * tk);
            float cd = cos(delta);
            float sd = sin(delta);
            Ed += a * w * w * (cd * cd + sd * sd / (CRINKLE_CREST * CRINKLE_CREST));
            Et += a * w * w * (sd * sd + cd * cd / (CRINKLE_CREST * CRINKLE_CREST));
            Edt += a * w * w * sd * cd * (1.0 / (CRINKLE_CREST * CRINKLE_CREST) - 1.0);
        }
        vec2 G = sqrt(1.0 - a) * g_iso + sqrt(a) * g_or;
        // the mix's covariance Σ over (d, t) whitened (Σ^(−1/2): √Σ = (Σ + r I) / n, r = √det,
        // n = √(tr + 2r)) and given the slopes asked for, so the drawn covariance is S itself
        float xd = dot(G, d);
        float xt = dot(G, t);
        float r = sqrt(max(Ed * Et - Edt * Edt, 0.0));
        float nrm = sqrt(Ed + Et + 2.0 * r);
        float m11 = Ed + r;
        float m22 = Et + r;
        float mdet = m11 * m22 - Edt * Edt;
        float yd = nrm * (m22 * xd - Edt * xt) / mdet;
        float yt = nrm * (m11 * xt - Edt * xd) / mdet;
        vec2 grad_h = sqrt(l1) * yd * d + sqrt(l2) * yt * t;  // dh/d(rest)
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
