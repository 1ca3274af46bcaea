#version 330 core
in vec3 v_col;
out vec4 f_colour;
void main() { f_colour = vec4(v_col, 1.0); }
