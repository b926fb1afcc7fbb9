#version 430 core
// Atlas patch vertex shader (paper sections 7.3-7.4): a reusable (u,v) grid vertex becomes a
// world position by integer sample arithmetic, border stitching against the neighbours' vertex
// spacing, and a fetch from the node's page in the page pool: a height (terrain atlases) or the
// position itself (mesh atlases, GIMLOD_GEOMETRY).

#include "interface.h"

layout(location = GIMLOD_ATTRIB_GRID) in uvec2 a_ij;   // grid vertex (i, j), 0..2^res
// The node record, per instance (divisor 1, selected by the draw's baseinstance):
// a_nodeA = (origin.x, origin.y, sizeLog2, res), a_nodeB = (pageResLog2, pageLayer, index,
// texLod | morph << 8 | texLodFrac << 16), morph the geomorph factor and texLodFrac the blend
// towards the next coarser attribute mip, both in 1/255 steps.
// origin in level-0 samples; sizeLog2 = node side in level-0 intervals; the grid has 2^res
// intervals per side; the page 2^pageResLog2.
layout(location = GIMLOD_ATTRIB_NODE_A) in ivec4 a_nodeA;
layout(location = GIMLOD_ATTRIB_NODE_B) in ivec4 a_nodeB;

// Stitch tables bytes, (node * 4 + side) * entriesPerSide + entry, packed little-endian in words.
layout(std430, binding = GIMLOD_STITCH_BINDING) readonly buffer Stitch { uint u_stitchWords[]; };

uniform mat4 u_viewProj;
uniform vec2 u_spacing;
uniform int u_leafLog2;
uniform int u_entriesPerSide;
uniform int u_morphWords;  // where the neighbours' morph bytes begin in u_stitchWords; -1: none
uniform sampler2DArray u_samples;  // R32F heights (RGB32F positions with GIMLOD_GEOMETRY), texelFetch only

precise out vec3 v_world;  // captured by transform feedback
out vec2 v_pageUv;
flat out int v_pageLayer;
flat out float v_texLod;  // the attributes' mip: texLod + texLodFrac / 255
flat out int v_node;   // the node's index in the cut, for the overlays
out vec2 v_nodeUv;     // (i, j) / 2^res: where in the node, for the overlays' border lines
out float v_snapped;   // 1 at a border vertex the stitching moved onto a coarser neighbour's lattice
invariant gl_Position;
#ifdef GIMLOD_PLANET
out vec3 v_east;      // planet atlases: the local east and up at the vertex (the normals' frame)
out vec3 v_up;

// Planet atlases (core/planet.h): positions relative to an anchor sample near the eye, from the
// integer offsets to it, so that float keeps its precision near the eye at the planet's scale.
uniform ivec2 u_anchor;         // the anchor's column (wrapped) and row
uniform vec4 u_anchorTrig;      // its sin lat, cos lat, sin lon, cos lon
uniform vec2 u_anchorPoles;     // radians from its latitude to the south and north poles
uniform ivec3 u_planetLattice;  // the last column and row, the columns a turn (0: no wrap)
uniform ivec2 u_poleRows;       // the last row on the south pole (-1: none), the first on the north
uniform vec3 u_planetStep;      // radians between columns and rows, the sphere's (equatorial) radius
uniform vec3 u_ellipsoid;       // e^2 (0: a sphere), the anchor's N and w (core/planet.h)

// sin x to float precision relative to x for small x (a GPU's sin has an absolute error near 1e-6).
float planetSin(float x) {
  if (abs(x) > 0.25) return sin(x);
  float x2 = x * x;
  return x * (1.0 - x2 / 6.0 * (1.0 - x2 / 20.0 * (1.0 - x2 / 42.0 * (1.0 - x2 / 72.0))));
}

// sin(a + d) - sin a and cos(a + d) - cos a, from sin a, cos a and d, without cancellation.
vec2 angleDifferences(float sa, float ca, float d) {
  float h = planetSin(0.5 * d), s = planetSin(d);
  float v = 2.0 * h * h;
  return vec2(ca * s - sa * v, -(sa * s) - ca * v);
}

// Sample g's position at height h minus the anchor's (PlanetFrame::position; planetOffset in
// core/planet.cpp is the same arithmetic).
vec3 planetOffset(ivec2 g, float h) {
  int c = clamp(g.x, 0, u_planetLattice.x), r = clamp(g.y, 0, u_planetLattice.y);
  int w = u_planetLattice.z;
  // The offset wraps round the turn (no %: GLSL leaves it undefined for negatives), so column W
  // gives column 0's offset.
  int dx = c - u_anchor.x;
  if (w > 0 && 2 * dx > w) dx -= w;
  if (w > 0 && 2 * dx < -w) dx += w;
  bool south = r <= u_poleRows.x, north = r >= u_poleRows.y;
  float sLat = u_anchorTrig.x, cLat = u_anchorTrig.y, sLon = u_anchorTrig.z, cLon = u_anchorTrig.w;
  float dp = south ? -u_anchorPoles.x : (north ? u_anchorPoles.y : float(r - u_anchor.y) * u_planetStep.y);
  vec2 lat = angleDifferences(sLat, cLat, dp);
  vec3 d;
  if (south || north) {
    d = vec3(-(cLat * cLon), -(cLat * sLon), lat.x);
  } else {
    vec2 lon = angleDifferences(sLon, cLon, float(dx) * u_planetStep.x);
    float cosLat = cLat + lat.y;
    d = vec3(cosLat * lon.y + cLon * lat.y, cosLat * lon.x + sLon * lat.y, lat.x);
  }
  if (u_ellipsoid.x == 0.0) {
    float rho = u_planetStep.z + h;
    return rho * d + h * vec3(cLat * cLon, cLat * sLon, sLat);
  }
  // An ellipsoid: the differences of N and of N sin(lat) from the sine's difference alone.
  float e2 = u_ellipsoid.x, nA = u_ellipsoid.y, wA = u_ellipsoid.z;
  float s = sLat + lat.x;
  float ws = sqrt(1.0 - e2 * s * s);
  float dN = u_planetStep.z * e2 * lat.x * (s + sLat) / (ws * wA * (ws + wA));
  float rho = nA + dN + h;
  return rho * d + (dN + h) * vec3(cLat * cLon, cLat * sLon, sLat) - vec3(0.0, 0.0, e2 * (dN * s + nA * lat.x));
}
#endif

const int kBottom = 0, kRight = 1, kTop = 2, kLeft = 3;

// Byte `table` (0: spacings, else the morphs from word u_morphWords) of the neighbour drawn at
// position t (level-0 intervals from the node origin).
int stitchByte(int node, int side, int t, int table) {
  int e = min(t >> u_leafLog2, u_entriesPerSide - 1);
  int b = (node * 4 + side) * u_entriesPerSide + e;
  return int((u_stitchWords[table + (b >> 2)] >> uint((b & 3) * 8)) & 0xFFu);
}

// log2 spacing of the neighbour drawn at position t.
int neighbourSpacing(int node, int side, int t) { return stitchByte(node, side, t, 0); }

// Moves a border coordinate onto the neighbour's coarser vertex lattice.
int snapToNeighbour(int node, int side, int t, int ownSpacing, int sizeLog2) {
  // note: s is clamped to the node size so corners stay fixed even for a malformed table.
  int s = min(neighbourSpacing(node, side, t), sizeLog2);
  return s > ownSpacing ? (t >> s) << s : t;
}

// Grid vertex (i, j) of a node of 2^res = n intervals per side, vertex spacing 2^so: its position
// in level-0 intervals from the node origin, a border vertex moved onto a coarser neighbour's
// lattice.
ivec2 stitched(int node, int i, int j, int n, int so, int sizeLog2) {
  int tx = i << so, ty = j << so;
  int sx = tx, sy = ty;
  if (j == 0) sx = snapToNeighbour(node, kBottom, tx, so, sizeLog2);
  if (j == n) sx = snapToNeighbour(node, kTop, tx, so, sizeLog2);
  if (i == 0) sy = snapToNeighbour(node, kLeft, ty, so, sizeLog2);
  if (i == n) sy = snapToNeighbour(node, kRight, ty, so, sizeLog2);
  return ivec2(sx, sy);
}

// The world position of the node's sample at t (level-0 intervals from its origin).
vec3 samplePosition(ivec2 origin, ivec2 t, int ps, int pageLayer) {
  ivec2 texel = t >> ps;
#ifdef GIMLOD_GEOMETRY
  // Geometry image: the position is the sample itself (bit-identical across chart seams).
  return texelFetch(u_samples, ivec3(texel, pageLayer), 0).xyz;
#elif defined(GIMLOD_PLANET)
  return planetOffset(origin + t, texelFetch(u_samples, ivec3(texel, pageLayer), 0).r);
#else
  float height = texelFetch(u_samples, ivec3(texel, pageLayer), 0).r;
  // Integer sample first, one conversion, one multiply: bit-identical across nodes.
  return vec3(float(origin.x + t.x) * u_spacing.x, float(origin.y + t.y) * u_spacing.y, height);
#endif
}

// Geomorph of a border vertex (not a corner) at stitched position t along `side`, own position
// tOwn: a vertex odd on the border's drawn lattice (the coarser side's, spacing s) moves towards
// the middle of its two lattice neighbours, by the coarser side's factor, or where both are alike
// by the larger of the two (the vertex goes when either side coarsens). Across a finer neighbour
// the morph byte caps the node's own factor (0 where that neighbour's corners could be odd on the
// node's lattice; StitchTables::morphs). Both sides compute it from the same samples, factor and
// arithmetic, so the border stays bit-identical at every factor.
vec3 borderMorph(vec3 p, int node, int side, int tOwn, int t, int across, int so, int sizeLog2, float own,
                 ivec2 origin, int ps, int pageLayer) {
  if (u_morphWords < 0) return p;
  int sn = min(neighbourSpacing(node, side, tOwn), sizeLog2);
  float theirs = float(stitchByte(node, side, tOwn, u_morphWords)) / 255.0;
  int s = max(so, sn);
  float f = sn > so ? theirs : (sn < so ? min(own, theirs) : max(own, theirs));
  if (!(f > 0.0) || s >= sizeLog2 || ((t >> s) & 1) == 0) return p;
  bool alongX = side == kBottom || side == kTop;
  ivec2 a = alongX ? ivec2(t - (1 << s), across) : ivec2(across, t - (1 << s));
  ivec2 b = alongX ? ivec2(t + (1 << s), across) : ivec2(across, t + (1 << s));
  return mix(p, 0.5 * (samplePosition(origin, a, ps, pageLayer) + samplePosition(origin, b, ps, pageLayer)), f);
}

void main() {
  int node = a_nodeB.z;
  ivec2 origin = a_nodeA.xy;
  int sizeLog2 = a_nodeA.z, res = a_nodeA.w, pageResLog2 = a_nodeB.x, pageLayer = a_nodeB.y;
  int n = 1 << res;
  int i = int(a_ij.x), j = int(a_ij.y);
  int so = sizeLog2 - res;
  int tx = i << so, ty = j << so;
  ivec2 st = stitched(node, i, j, n, so, sizeLog2);
  int sx = st.x, sy = st.y;

  int ps = sizeLog2 - pageResLog2;
  ivec2 texel = ivec2(sx >> ps, sy >> ps);
  v_world = samplePosition(origin, ivec2(sx, sy), ps, pageLayer);
  // Geomorph: an inner vertex that the next coarser grid lacks moves towards the point of that
  // grid's surface under it: the middle of the coarse edge it halves (odd in one direction), or of
  // the coarse quad's diagonal from (i-1, j-1) to (i+1, j+1) (odd in both, the grids' diagonal).
  // Border vertices move with their neighbour's (borderMorph).
  float morph = float((a_nodeB.w >> 8) & 0xFF) / 255.0;
  bool inner = i > 0 && i < n && j > 0 && j < n;
  bool corner = (i == 0 || i == n) && (j == 0 || j == n);
  if (!inner && !corner) {
    int side = j == 0 ? kBottom : (j == n ? kTop : (i == 0 ? kLeft : kRight));
    bool alongX = side == kBottom || side == kTop;
    v_world = borderMorph(v_world, node, side, alongX ? tx : ty, alongX ? sx : sy, alongX ? sy : sx, so, sizeLog2,
                          morph, origin, ps, pageLayer);
  }
  ivec2 odd = ivec2(i & 1, j & 1);
  if (morph > 0.0 && inner && (odd.x | odd.y) != 0) {
    // The two ends as drawn (an end on the border stitched as it is).
    vec3 a = samplePosition(origin, stitched(node, i - odd.x, j - odd.y, n, so, sizeLog2), ps, pageLayer);
    vec3 b = samplePosition(origin, stitched(node, i + odd.x, j + odd.y, n, so, sizeLog2), ps, pageLayer);
    v_world = mix(v_world, 0.5 * (a + b), morph);
  }
  gl_Position = u_viewProj * vec4(v_world, 1.0);
#ifdef GIMLOD_PLANET
  // The local frame: up from the planet's centre (the anchor's direction plus the vertex's offset
  // from it, at unit radius), east along the circle of latitude (the anchor's at a pole).
  vec3 dA = vec3(u_anchorTrig.y * u_anchorTrig.w, u_anchorTrig.y * u_anchorTrig.z, u_anchorTrig.x);
  v_up = normalize(dA + v_world / u_planetStep.z);
  float cosLat = length(v_up.xy);
  v_east = cosLat > 1e-6 ? vec3(-v_up.y, v_up.x, 0.0) / cosLat : vec3(-u_anchorTrig.z, u_anchorTrig.w, 0.0);
#endif
  v_pageUv = (vec2(texel) + 0.5) / float(textureSize(u_samples, 0).x);
  v_pageLayer = pageLayer;
  v_texLod = float(a_nodeB.w & 0xFF) + float((a_nodeB.w >> 16) & 0xFF) / 255.0;
  v_node = node;
  v_nodeUv = vec2(a_ij) / float(n);
  v_snapped = sx != tx || sy != ty ? 1.0 : 0.0;
}
