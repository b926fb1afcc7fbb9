#version 430 core
// Throughput baseline: the same surface as one static mesh of plain positions (no texture fetch,
// no stitching), shaded by atlas.frag so only the vertex path differs.
#include "interface.h"
layout(location = GIMLOD_ATTRIB_POSITION) in vec3 a_position;
uniform mat4 u_viewProj;
out vec3 v_world;
out vec2 v_pageUv;
flat out int v_pageLayer;
flat out float v_texLod;
flat out int v_node;  // atlas.frag's overlay inputs, unused here (u_overlay is 0)
out vec2 v_nodeUv;
out float v_snapped;  // atlas.frag's inspection view of snapped vertices, unused here (u_views is 0)
void main() {
  v_world = a_position;
  v_pageUv = vec2(0.5);
  v_pageLayer = 0;
  v_texLod = 0.0;
  v_node = 0;
  v_nodeUv = vec2(0.0);
  v_snapped = 0.0;
  gl_Position = u_viewProj * vec4(a_position, 1.0);
}
