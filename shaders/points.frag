#version 330 core
in float v_layer;
out vec4 f_colour;
void main() {
    vec2 d = gl_PointCoord * 2.0 - 1.0;
    float r2 = dot(d, d);
    if (r2 > 1.0) discard;
    vec3 base = v_layer < 0.5 ? vec3(0.10, 0.55, 0.20) : vec3(0.85, 0.45, 0.10);
    float shade = 0.55 + 0.45 * sqrt(1.0 - r2);
    f_colour = vec4(base * shade, 1.0);
}
