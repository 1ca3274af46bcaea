#version 330 core
// A 3x3 binomial blur ([1 2 1]² / 16) in four bilinear fetches at the texel corners: softens
// the ground shadow's edge by about one and a half mask texels for a quarter of the cost of a
// separable Gaussian (texture fetches are what a software rasteriser pays for).
in vec2 v_uv;
uniform sampler2D u_src;
uniform vec2 u_texel;       // one texel in uv
out float f_value;
void main() {
    vec2 d = 0.5 * u_texel;
    f_value = 0.25 * (texture(u_src, v_uv + vec2(-d.x, -d.y)).r + texture(u_src, v_uv + vec2(d.x, -d.y)).r
                    + texture(u_src, v_uv + vec2(-d.x, d.y)).r + texture(u_src, v_uv + vec2(d.x, d.y)).r);
}
