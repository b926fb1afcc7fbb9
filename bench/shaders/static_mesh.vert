#version 430 core
// Baseline mesh for throughput comparisons: plain positions, no texture fetch.
#include "interface.h"
layout(location = GIMLOD_ATTRIB_POSITION) in vec3 a_position;
uniform mat4 u_viewProj;
uniform vec2 u_heightRange;
out float v_shade;
void main() {
  gl_Position = u_viewProj * vec4(a_position, 1.0);
  v_shade = 0.4 + 0.6 * clamp((a_position.z - u_heightRange.x) /
                              max(u_heightRange.y - u_heightRange.x, 1e-6), 0.0, 1.0);
}
