#version 330 core
// Coverage of the ground by the leaf's shadow (1 = shadowed); with the photo cut-out, holes in
// the leaf mask cast none.
in vec2 v_uv;
uniform sampler2D u_tex;
uniform int u_cutout;
out float f_cover;
void main() {
    if (u_cutout != 0 && texture(u_tex, v_uv).a < 0.5) discard;
    f_cover = 1.0;
}
