#version 330 core
#include "common.glsl"

in vec3 v_pos;
in vec3 v_nrm;
in vec3 v_bnrm;
in vec3 v_side;
in float v_v;
in float v_alpha;
in float v_hd;
in float v_target;
in vec3 v_base;
in vec3 v_tint;
in vec4 v_chroma;
in vec3 v_vein;
in vec2 v_uv;
flat in int v_order;
in vec4 v_conc;
in vec4 v_state;
in vec2 v_extra;
in vec2 v_rest;

// Compile-time switches (see blade.frag): LS_TEX 1 = albedo from the photo (else v_vein),
// LS_CUTOUT 1 = photo mask cut-out, LS_SHADOW 1 = self-shadowing, LS_MOTTLE 1 = the blade's
// sub-grid mottle on the photo albedos (the ribbon redraws the blade under it).
#ifndef LS_TEX
#define LS_TEX 0
#endif
#ifndef LS_CUTOUT
#define LS_CUTOUT 0
#endif
#ifndef LS_SHADOW
#define LS_SHADOW 0
#endif
#ifndef LS_MOTTLE
#define LS_MOTTLE 0
#endif
uniform sampler2D u_noise;
uniform float u_mottle_scale;
uniform float u_mottle;
uniform vec3 u_absorb[5];
uniform vec3 u_base;
uniform int u_absolute;        // vein colours are absolute linear RGB
uniform float u_opacity;       // render.vein_alpha: the veins' opacity over the blade
uniform sampler2D u_tex;
uniform vec3 u_tex_mean;       // mean linear colour of the photo's leaf area (LS_TEX 2)
uniform vec3 u_vein_cols[4];
uniform sampler2DShadow u_shadow;
uniform mat4 u_light_mat;
uniform float u_shadow_offset;

uniform vec3 u_eye;
uniform vec3 u_light_dir;
uniform vec3 u_light_col;
uniform vec3 u_sky_col;
uniform float u_translucency;
uniform float u_specular;
uniform float u_shininess;

out vec4 f_colour;

// A ribbon's sides carry the photo's texture coordinates of where they lie on the blade
// (leafsim.render.geom.VeinRibbons), so the photo is sampled across the ribbon as the blade
// samples it, at the blade's mip level (u_uv_blur 0).  Without the blade's rest positions both
// sides carry the centre line's coordinate: the GPU then sees no change across the ribbon and
// samples sharper than on the blade (texel rows came out as bands across the vein), so it
// samples u_uv_blur = 1.5 mip levels coarser (a 2^1.5 ≈ 3 texel blur).
uniform float u_uv_blur;
#define UV_BLUR u_uv_blur

void main() {
#if LS_TEX
    // over a photo only the main veins and laterals are drawn (with the default veins.photo
    // they are traced from it and lie on its own); the grown finer orders crossed its areoles
    // as pale hairlines, a second pattern
    if (v_order >= 2) discard;
#endif
    float dist = abs(v_v) * v_hd;                   // pixels from the centre line
    float cover = clamp(v_target - dist + 0.5, 0.0, 1.0) * v_alpha * u_opacity;
    if (cover <= 0.0) discard;
    // the rounded cross-section only where the vein is wide enough on screen to show it: on a
    // vein one or two pixels wide the bent normals lit alternate pixels light and dark along
    // the line, which read as stitches
    float a = clamp(dist / max(v_target, 1e-3), 0.0, 1.0) * clamp(v_target - 1.0, 0.0, 1.0);
    // rounded cross-section: bend the normal towards the sides
    vec3 N = normalize(normalize(v_nrm) * sqrt(max(1.0 - a * a, 0.0)) * 1.3 + normalize(v_side) * sign(v_v) * a);
#if LS_TEX
    // over a photo, which shows its veins in their own light, a rounded rod drew a second,
    // darker outline on each side of the photo's vein ("inked"): the vein is lit as the blade
    N = normalize(v_bnrm);
#endif
#if LS_TEX == 2
    // detail: the vertex colour times the photo's detail under the vein (as the blade)
    vec3 base = photo_detail(v_base, texture(u_tex, v_uv, UV_BLUR).rgb, u_tex_mean, v_chroma);
#elif LS_TEX
    vec4 t = texture(u_tex, v_uv, UV_BLUR);
#if LS_CUTOUT
    if (t.a < 0.5) discard;
#endif
    vec3 base = t.rgb * v_tint;
#endif
#if LS_TEX && LS_MOTTLE
    // sampled along the centre line, as the photo is
    base *= mottle_ratio(v_conc, v_state, v_extra, mottle_n(texture(u_noise, v_rest * u_mottle_scale).r), u_mottle, u_absorb, u_base);
#endif
#if !LS_TEX
    vec3 base = v_vein;   // vertex colours: the vein tissue's own
#endif
    vec3 vc = u_vein_cols[clamp(v_order, 0, 3)];
#if LS_TEX
    // the photo shows its own veins (and the model's traced ones lie on them): the vein takes
    // the photo's colour under it and the blade's light, never a second, tinted or shaded line
    vec3 albedo = u_absolute != 0 ? vc : base;
#else
    vec3 albedo = u_absolute != 0 ? vc : clamp(base * vc, 0.0, 1.0);
#endif
    vec3 V = normalize(u_eye - v_pos);
#if LS_SHADOW
    float sh = shadow_pcf4(u_shadow, u_light_mat, v_pos + u_light_dir * u_shadow_offset, 1.5);
#else
    float sh = 1.0;
#endif
#if LS_TEX
    // lit as the blade under it in every respect (its translucency and sheen too: with the
    // light behind the leaf a thicker, less translucent vein drew darker than the photo's own)
    vec3 c = shade_leaf(albedo, N, V, u_light_dir, u_light_col, u_sky_col, sh,
                        u_translucency, u_specular, u_shininess);
#else
    vec3 c = shade_leaf(albedo, N, V, u_light_dir, u_light_col, u_sky_col, sh,
                        u_translucency * 0.6, u_specular * 1.5, u_shininess);
#endif
    f_colour = vec4(linear_to_srgb(c), cover);
}
