// Shared helpers, pasted into other stages by the Python loader (include directive).

vec3 srgb_to_linear(vec3 c) { return pow(max(c, vec3(0.0)), vec3(2.2)); }

vec3 linear_to_srgb(vec3 c) {
    c = clamp(c, 0.0, 1.0);
    return mix(12.92 * c, 1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055, step(0.0031308, c));
}

// The "detail" albedo of a vertex colour `base` under photo texel t (linear): the texel's
// luminance over the photo's mean (its own brightness, not the vertex's blurred one), and,
// where the tissue still lives, the texel's chromaticity over the vertex's young chromaticity:
// chroma.rgb is the photo's blurred colour at the vertex divided by its luminance, chroma.a the
// weight (living share, 0 = luminance only). The chromaticity factor keeps the colour's
// luminance, so it moves hues only (on a young vertex, whose colour is the young one, the
// result is the texel itself); dead tissue shows the model's colour with the photo's brightness.
vec3 photo_detail(vec3 base, vec3 t, vec3 tex_mean, vec4 chroma) {
    vec3 W = vec3(0.2126, 0.7152, 0.0722);
    float lum = dot(t, W);
    float f = clamp(lum / max(dot(tex_mean, W), 1e-4), 0.0, 3.0);
    vec3 ratio = clamp((t / max(lum, 1e-4)) / max(chroma.rgb, vec3(1e-4)), 0.25, 4.0);
    vec3 b = max(base, vec3(0.0));
    vec3 c = b * pow(ratio, vec3(clamp(chroma.a, 0.0, 1.0)));
    return f * c * (dot(b, W) / max(dot(c, W), 1e-6));
}

// The sub-grid mottle (colour.mottle; leafsim/appearance/reflectance.py, mottle_pigments):
// at field value n every reaction's progress p goes to p + a n p (1 - p), so each pigment's
// amount changes by a n (1 - state) c (chlorophyll and carotenoids are lost, browning and
// necrosis made). conc = (c_chl, c_car, c_ant, c_brn), state = (C, K, B, N) in [0, 1],
// extra = (c_nec, surface reflectance), all interpolated over the triangle as the pigments
// are; k = the absorption per pigment and band, base = pigment-free tissue. Returns the
// Beer-Lambert reflectance there over the one of the interpolated pigments (1 where n g = 0).
// The mottle field's value from its 8-bit texel t = k/255: n = (2k + 1)/256 - 1.
float mottle_n(float t) { return t * (255.0 / 128.0) - (255.0 / 256.0); }

vec3 mottle_ratio(vec4 conc, vec4 state, vec2 extra, float n, float a, vec3 k[5], vec3 base) {
    vec3 x = max(conc.x * k[0] + conc.y * k[1] + conc.z * k[2] + conc.w * k[3] + extra.x * k[4], vec3(0.0));
    vec3 g = a * (-(1.0 - state.x) * conc.x * k[0] - (1.0 - state.y) * conc.y * k[1]
                  + (1.0 - state.z) * conc.w * k[3] + (1.0 - state.w) * extra.x * k[4]);
    vec3 here = extra.y + base * exp(-max(x + n * g, vec3(0.0)));
    vec3 mean = extra.y + base * exp(-x);
    return here / max(mean, vec3(1e-4));
}

// Turbo colour map (polynomial fit by Ruofei Du of Google's turbo); returns sRGB.
vec3 cmap_turbo(float x) {
    const vec4 kr4 = vec4(0.13572138, 4.61539260, -42.66032258, 132.13108234);
    const vec4 kg4 = vec4(0.09140261, 2.19418839, 4.84296658, -14.18503333);
    const vec4 kb4 = vec4(0.10667330, 12.64194608, -60.58204836, 110.36276771);
    const vec2 kr2 = vec2(-152.94239396, 59.28637943);
    const vec2 kg2 = vec2(4.27729857, 2.82956604);
    const vec2 kb2 = vec2(-89.90310912, 27.34824973);
    x = clamp(x, 0.0, 1.0);
    vec4 v4 = vec4(1.0, x, x * x, x * x * x);
    vec2 v2 = v4.zw * v4.z;
    return clamp(vec3(dot(v4, kr4) + dot(v2, kr2), dot(v4, kg4) + dot(v2, kg2),
                      dot(v4, kb4) + dot(v2, kb2)), 0.0, 1.0);
}

// Viridis (polynomial fit by mattz); returns sRGB.
vec3 cmap_viridis(float t) {
    const vec3 c0 = vec3(0.2777273272234177, 0.005407344544966578, 0.3340998053353061);
    const vec3 c1 = vec3(0.1050930431085774, 1.404613529898575, 1.384590162594685);
    const vec3 c2 = vec3(-0.3308618287255563, 0.214847559468213, 0.09509516302823659);
    const vec3 c3 = vec3(-4.634230498983486, -5.799100973351585, -19.33244095627987);
    const vec3 c4 = vec3(6.228269936347081, 14.17993336680509, 56.69055260068105);
    const vec3 c5 = vec3(4.776384997670288, -13.74514537774601, -65.35303263337234);
    const vec3 c6 = vec3(-5.435455855934631, 4.645852612178535, 26.3124352495832);
    t = clamp(t, 0.0, 1.0);
    return clamp(c0 + t * (c1 + t * (c2 + t * (c3 + t * (c4 + t * (c5 + t * c6))))), 0.0, 1.0);
}

// Cheap soft shadow for the leaf's self-shadowing: four hardware 2x2 PCF taps on a rotated
// grid (16 texels) at a fixed pattern -- no per-pixel rotation, no divergent refinement loop,
// which is what a software rasteriser pays for. 1 = lit, 0 = shadowed.
float shadow_pcf4(sampler2DShadow sm, mat4 light_mat, vec3 p, float radius_texels) {
    vec4 lp = light_mat * vec4(p, 1.0);
    vec3 c = lp.xyz / lp.w * 0.5 + 0.5;
    if (c.z > 1.0) return 1.0;
    vec2 r = radius_texels / vec2(textureSize(sm, 0));
    return 0.25 * (texture(sm, vec3(c.xy + vec2(0.4, 1.0) * r, c.z)) + texture(sm, vec3(c.xy + vec2(-1.0, 0.4) * r, c.z))
                 + texture(sm, vec3(c.xy + vec2(-0.4, -1.0) * r, c.z)) + texture(sm, vec3(c.xy + vec2(1.0, -0.4) * r, c.z)));
}

// Thin two-sided leaf lighting. N faces the viewer; light reaching the other side is
// transmitted (translucency), strongest when looking towards the sun through the blade.
vec3 shade_leaf(vec3 albedo, vec3 N, vec3 V, vec3 L, vec3 light_col, vec3 sky_col,
                float shadow, float translucency, float specular, float shininess) {
    float ndl = dot(N, L);
    vec3 amb = albedo * sky_col * (0.75 + 0.25 * N.z);
    vec3 diff = albedo * light_col * max(ndl, 0.0) * shadow;
    vec3 H = normalize(L + V);
    float norm = (shininess + 8.0) / 25.1327;
    float spec = ndl > 0.0 ? specular * norm * pow(max(dot(N, H), 0.0), shininess) * 0.04 : 0.0;
    // transmission: diffuse through the blade + forward scattering towards the viewer
    vec3 transmit = clamp(albedo * vec3(1.5, 1.7, 0.8) + vec3(0.02, 0.02, 0.0), 0.0, 1.0);
    float back = max(-ndl, 0.0);
    float fwd = pow(max(dot(-V, L), 0.0), 6.0);
    vec3 trans = transmit * light_col * translucency * (0.5 * back + 1.2 * fwd) * shadow;
    return amb + diff + trans + spec * light_col * shadow;
}
