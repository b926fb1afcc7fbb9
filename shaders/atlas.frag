#version 430 core
// Atlas fragment shader: normal map and Lambert + ambient lighting with light distance fog;
// terrain atlases also clip to the valid extent and colour with their imagery where it covers,
// else a hypsometric ramp; mesh atlases (GIMLOD_GEOMETRY) draw their vertex colours or neutral clay. With u_overlay, a per-node colour replaces the material and
// chart borders are drawn over it: seams dark, open borders red (runtime/overlay.h).

#include "interface.h"

in vec3 v_world;
in vec2 v_pageUv;
flat in int v_pageLayer;
flat in float v_texLod;  // mip of the normal map: the node's attribute resolution (paper 7.1, 7.3),
                         // between two mips as the need moves between them
flat in int v_node;
in vec2 v_nodeUv;
in float v_snapped;
#ifdef GIMLOD_PLANET
in vec3 v_east;
in vec3 v_up;
#endif

struct NodeOverlay {
  uint rgba;              // RGBA8
  uint chartBorderSides;  // bit s: side s (0 bottom, 1 right, 2 top, 3 left) on the chart border
  uint openSides;         // of those, without a neighbouring chart
  uint flags;             // bit 0: the node stands in for finer pages still loading
};
layout(std430, binding = GIMLOD_OVERLAY_BINDING) readonly buffer Overlay { NodeOverlay u_overlays[]; };
uniform int u_overlay;         // 0: none; else u_overlays[v_node]'s colour and borders apply
uniform int u_overlayRecords;  // u_overlays holds a record per node (for their flags)

uniform sampler2DArray u_normals;  // RGBA8, n * 0.5 + 0.5, bilinear, with mips
uniform sampler2DArray u_colours;  // vertex colours or terrain imagery: RGBA8, with mips
uniform int u_hasColours;          // draw u_colours instead of the neutral material / height ramp
uniform float u_colourScale;       // colour texels per page sample interval (terrain imagery: 1, 2 or 4)
uniform sampler2DArray u_samples;  // R32F page heights (terrain only here), bilinear (texelFetch in the vertex shader)
uniform vec2 u_spacing;
uniform vec2 u_validSamples;  // samples per axis; 0 = unlimited
uniform vec2 u_heightRange;
uniform vec3 u_lightDir;      // towards the light, normalized
uniform vec3 u_eye;
uniform vec3 u_background;
uniform float u_fogDistance;  // 0 = no fog
// Inspection views, bits: 1 node borders (thin dark lines), 2 normals as colours (n * 0.5 + 0.5
// instead of the material), 4 the stitching's snapped border vertices (orange round each), 8 nodes
// standing in for pages still loading (magenta stripes).
uniform int u_views;

out vec4 o_colour;

// The overlay's colour for a fragment lit by `light` (0..1): the node's colour, and its chart
// borders as lines: seams dark (about 1.5 pixels across both sides), open borders red (2 pixels).
vec3 overlayColour(float light) {
  NodeOverlay o = u_overlays[v_node];
  vec3 c = unpackUnorm4x8(o.rgba).rgb * (0.35 + 0.65 * light);
  vec2 w = max(fwidth(v_nodeUv), vec2(1e-6));
  float d[4] = float[4](v_nodeUv.y / w.y, (1.0 - v_nodeUv.x) / w.x, (1.0 - v_nodeUv.y) / w.y, v_nodeUv.x / w.x);
  for (int s = 0; s < 4; ++s) {
    if (((o.openSides >> uint(s)) & 1u) != 0u && d[s] < 2.0) return vec3(0.9, 0.1, 0.1);
    if (((o.chartBorderSides >> uint(s)) & 1u) != 0u && d[s] < 0.75) c = vec3(0.08);
  }
  return c;
}

// The inspection views over a lit colour `c` with normal `n`.
vec3 inspectionViews(vec3 c, vec3 n) {
  if ((u_views & 2) != 0) c = n * 0.5 + 0.5;
  if ((u_views & 1) != 0) {
    vec2 w = max(fwidth(v_nodeUv), vec2(1e-6));
    vec2 d = min(v_nodeUv, 1.0 - v_nodeUv) / w;
    if (min(d.x, d.y) < 0.6) c = mix(c, vec3(0.05), 0.8);
  }
  if ((u_views & 4) != 0 && v_snapped > 0.02) c = mix(c, vec3(1.0, 0.45, 0.0), 0.35 + 0.65 * v_snapped);
  if ((u_views & 8) != 0 && u_overlayRecords != 0 && (u_overlays[v_node].flags & 1u) != 0u &&
      mod(floor((gl_FragCoord.x + gl_FragCoord.y) / 6.0), 2.0) < 1.0)
    c = mix(c, vec3(1.0, 0.0, 0.85), 0.6);
  return c;
}

vec3 hypsometric(float t) {
  const vec3 kLow = vec3(0.18, 0.42, 0.16);
  const vec3 kMid = vec3(0.45, 0.55, 0.25);
  const vec3 kBrown = vec3(0.50, 0.38, 0.24);
  const vec3 kRock = vec3(0.55, 0.53, 0.50);
  const vec3 kSnow = vec3(0.95, 0.95, 0.97);
  if (t < 0.25) return mix(kLow, kMid, t / 0.25);
  if (t < 0.55) return mix(kMid, kBrown, (t - 0.25) / 0.30);
  if (t < 0.80) return mix(kBrown, kRock, (t - 0.55) / 0.25);
  return mix(kRock, kSnow, (t - 0.80) / 0.20);
}

bool outsideValid(float g, float valid) {
  return valid > 0.0 && g > valid - 1.0 + (1e-3 + 1e-6 * valid);
}

void main() {
#if !defined(GIMLOD_GEOMETRY) && !defined(GIMLOD_PLANET)
  // (A planet's samples past the DEM's last fold onto it: nothing to discard.)
  vec2 g = v_world.xy / u_spacing;
  if (outsideValid(g.x, u_validSamples.x) || outsideValid(g.y, u_validSamples.y)) discard;
#endif

  vec3 n = textureLod(u_normals, vec3(v_pageUv, float(v_pageLayer)), v_texLod).rgb * 2.0 - 1.0;
  n = length(n) > 1e-4 ? normalize(n) : vec3(0.0, 0.0, 1.0);
  vec3 lightDir = u_lightDir;
#ifdef GIMLOD_PLANET
  // The height field's normal in the local east, north and up; its east slope measured at the
  // equator's spacing is steeper by 1 / cos(latitude). The light keeps its place in the local sky.
  vec3 up = normalize(v_up), east = normalize(v_east - dot(v_east, up) * up), north = cross(up, east);
  float cosLat = max(length(up.xy), 0.05);
  n = normalize(east * (n.x / cosLat) + north * n.y + up * n.z);
  lightDir = normalize(east * u_lightDir.x + north * u_lightDir.y + up * u_lightDir.z);
#endif
#ifdef GIMLOD_GEOMETRY
  // Mesh atlases: the scan's own colours at the node's attribute resolution, or a neutral material;
  // lit from both sides of the light (scans have no up).
  vec3 clay = u_hasColours != 0 ? textureLod(u_colours, vec3(v_pageUv, float(v_pageLayer)), v_texLod).rgb
                                : vec3(0.78, 0.74, 0.68);
  float lambert = abs(dot(n, u_lightDir));
  vec3 lit = u_overlay != 0 ? overlayColour(lambert) : clay * (0.25 + 0.75 * lambert);
  lit = inspectionViews(lit, n);
  if (u_fogDistance > 0.0) {
    float dm = length(v_world - u_eye) / u_fogDistance;
    lit = mix(lit, u_background, 0.6 * (1.0 - exp(-dm * dm)));
  }
  o_colour = vec4(lit, 1.0);
  return;
#endif
  // Below sea level (only when the data goes below 0): bathymetric blues; above: the land ramp.
  // Colour follows the page heights (finer than the drawn grid), like the normal map.
  float h = texture(u_samples, vec3(v_pageUv, float(v_pageLayer))).r;
  float landLow = max(u_heightRange.x, 0.0);
  float span = max(u_heightRange.y - landLow, 1e-6);
  vec3 base = hypsometric(clamp((h - landLow) / span, 0.0, 1.0));
  if (h < 0.0 && u_heightRange.x < 0.0) {
    float depth = clamp(h / u_heightRange.x, 0.0, 1.0);
    base = mix(vec3(0.30, 0.55, 0.75), vec3(0.05, 0.12, 0.35), sqrt(depth));
  }
  if (u_hasColours != 0) {
    // Imagery: the page's sample position on the colour page's finer lattice; mip chosen by the
    // hardware from the screen footprint. Alpha is the imagery's coverage.
    vec2 t = v_pageUv * float(textureSize(u_samples, 0).x) - 0.5;
    vec2 uv = (t * u_colourScale + 0.5) / vec2(textureSize(u_colours, 0).xy);
    vec4 imagery = texture(u_colours, vec3(uv, float(v_pageLayer)));
    base = mix(base, imagery.rgb, imagery.a);
  }
  float light = max(dot(n, lightDir), 0.0);
  vec3 colour = u_overlay != 0 ? overlayColour(light) : base * (0.30 + 0.70 * light);
  colour = inspectionViews(colour, n);
  if (u_fogDistance > 0.0) {
    float d = length(v_world - u_eye) / u_fogDistance;
    colour = mix(colour, u_background, 0.6 * (1.0 - exp(-d * d)));
  }
  o_colour = vec4(colour, 1.0);
}
