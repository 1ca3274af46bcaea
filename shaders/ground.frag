#version 330 core
#include "common.glsl"

in vec3 v_pos;

uniform vec3 u_center;
uniform float u_fade0;        // radius where fading to the background starts
uniform float u_fade1;        // radius where the ground has vanished
uniform vec3 u_lit_srgb;      // ground in full sun (display values, precomputed on the CPU)
uniform vec3 u_shade_srgb;    // ground in the leaf's shadow
uniform vec3 u_bg;            // sRGB background
uniform sampler2DShadow u_shadow;
uniform mat4 u_light_mat;
uniform int u_use_shadow;
uniform float u_shadow_radius;  // texels

out vec4 f_colour;

void main() {
    float r = length(v_pos.xy - u_center.xy);
    float f = smoothstep(u_fade0, u_fade1, r);
    if (f >= 1.0) { f_colour = vec4(u_bg, 1.0); return; }
    float sh = u_use_shadow != 0 ? shadow_pcf(u_shadow, u_light_mat, v_pos, u_shadow_radius, 0.0) : 1.0;
    f_colour = vec4(mix(mix(u_shade_srgb, u_lit_srgb, sh), u_bg, f), 1.0);
}
