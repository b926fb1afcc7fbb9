#version 430 core
in float v_shade;
out vec4 o_colour;
void main() { o_colour = vec4(0.35 * v_shade, 0.55 * v_shade, 0.25 * v_shade, 1.0); }
