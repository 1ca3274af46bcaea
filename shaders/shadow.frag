#version 330 core
// Depth only; with the photo cut-out, holes in the leaf mask cast no shadow.
in vec2 v_uv;
uniform sampler2D u_tex;
uniform int u_cutout;
void main() {
    if (u_cutout != 0 && texture(u_tex, v_uv).a < 0.5) discard;
}
