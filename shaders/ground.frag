#version 330 core
// The ground: lit colour, darkened where the leaf's soft shadow falls, fading into the
// background far from the leaf.  The shadow is one bilinear fetch of a small ground-aligned
// coverage mask (the leaf projected along the sun direction and blurred, made per frame by
// the renderer) instead of percentage-closer filtering of the depth shadow map per pixel:
// under a software rasteriser that per-pixel PCF was most of the frame.  The renderer draws
// the whole ground without the mask (LS_SHADOW 0), then only the mask's rectangle with it.
in vec3 v_pos;

uniform vec3 u_center;
uniform float u_fade0;        // radius where fading to the background starts
uniform float u_fade1;        // radius where the ground has vanished
uniform vec3 u_lit_srgb;      // ground in full sun (display values, precomputed on the CPU)
uniform vec3 u_shade_srgb;    // ground in the leaf's shadow
uniform vec3 u_bg;            // sRGB background
uniform sampler2D u_mask;     // shadow coverage (1 = shadowed) over u_rect
uniform vec4 u_rect;          // (x0, y0, x1, y1) of the mask on the ground [m]
#ifndef LS_SHADOW             // compile-time switch (see blade.frag)
#define LS_SHADOW 0
#endif

out vec4 f_colour;

void main() {
    float r = length(v_pos.xy - u_center.xy);
    float f = smoothstep(u_fade0, u_fade1, r);
    float cover = 0.0;
#if LS_SHADOW
    // the mask's border texels are 0 (padding) and it clamps to its edge: no range test needed
    cover = texture(u_mask, (v_pos.xy - u_rect.xy) / (u_rect.zw - u_rect.xy)).r;
#endif
    f_colour = vec4(mix(mix(u_lit_srgb, u_shade_srgb, cover), u_bg, f), 1.0);
}
