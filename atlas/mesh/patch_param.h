// Parameterization of one n-sided patch of a chart layout onto a regular n-gon: the boundary is
// fixed (corners on the polygon's vertices, each side's vertices by normalized arc length along
// its polygon edge), the interior comes from Floater's mean-value weights (a Tutte embedding:
// positive weights and a convex border give no flipped triangles), then optional stretch
// reduction: iterative reweighting, which keeps the weights positive and so the embedding valid,
// and local L2 stretch minimization, whose energy is infinite on a flipped triangle.
// The quads of the conforming quad layout (atlas/mesh/resample.h) are kites of this polygon.
// Based on: Niski, Purnomo, Cohen, I3D 2007, section 5 (parameterize); Floater, "Mean value
// coordinates", CAGD 2003; Sander, Snyder, Gortler, Hoppe, "Texture mapping progressive meshes",
// SIGGRAPH 2001 (L2 / Linf stretch); Yoshizawa, Belyaev, Seidel, "A fast and simple
// stretch-minimizing mesh parameterization", SMI 2004 (reweighting).
#pragma once

#include <array>
#include <cmath>
#include <cstdint>
#include <unordered_map>
#include <vector>

#include <glm/vec2.hpp>
#include <glm/vec3.hpp>

#include "atlas/mesh/patch_layout.h"

namespace gimlod {

struct ParamOptions {
  // Global stretch reweighting passes after the mean-value solve (Yoshizawa et al.; each one a
  // sparse solve); stops at the first pass that does not lower the L2 stretch. 0 skips it.
  uint32_t stretchIterations = 4;
  // Reweighting exponent eta in w_ij <- w_ij / sigma_j^eta; 0 < eta <= 1 (smaller is steadier).
  double stretchExponent = 0.5;
  // Local L2 stretch minimization sweeps (Sander et al.: per-vertex line searches that never
  // flip a triangle), until the energy drops by less than 0.01% in a sweep; this is the most
  // sweeps run. 0 skips it. Most patches stop after 5-15 sweeps. A patch that is far from
  // developable (a cup closed round a tip: a hoof, an ear) needs a few hundred, since moving area
  // across the whole patch goes a ring at a time; cut short (this was 30), its tip stayed squeezed
  // into a corner of the polygon and its texels were about twice as wide as the chart's mean
  // (horse: a hoof's chart 8.2 times the mean chart area, param L2 2.86 where 1.75 is reached).
  uint32_t stretchSweeps = 500;
  // The local sweeps minimize the symmetric Dirichlet energy (squeezing and spreading both cost,
  // so no triangle is left strongly anisotropic next to a bend) instead of Sander's L2 stretch
  // (which only penalizes squeezing).
  bool symmetricEnergy = true;
  // Domain polygon: corners on the unit circle with central angles proportional to the sides' 3D
  // lengths (clamped, see patchPolygon), so long and short sides get parameter length in
  // proportion; false gives the regular n-gon whatever the side lengths.
  bool proportionalPolygon = true;
  // The inner vertices of open sides (hole rims, borders) slide along their polygon edge in the
  // local sweeps instead of staying where their arc length puts them, and the resampler samples
  // open sides through the parameterization (an open side has no neighbour to match). A scan's
  // hole rim zigzags; pinned by arc length, its triangles are sheared flat against the straight
  // edge, and the texels beside it fold.
  bool slideOpenSides = true;
  // The polygon for the sides quad layout (atlas/mesh/resample.h): with an even n >= 6, sides 2j
  // and 2j+1 bound one quad with the centre, so their corners are placed in pairs (patchPolygon).
  // resampleLayout sets it from its quad layout.
  bool pairedSides = false;
  // Patches with at least this many inner vertices are factored in single precision and the
  // solution refined in double (as exact as a double factorization, in about 0.6 times the
  // memory); smaller ones in double precision, whose factors are under about 100 MiB.
  uint32_t singlePrecisionFrom = 100000;
};

// Quality of a parameterization (param -> surface map), in the style of xatlas' per-chart
// figures. Stretch follows Sander et al. 2001: per triangle L2 = sqrt((G^2 + g^2) / 2) and
// Linf = G (G >= g the singular values of the Jacobian), normalized by sqrt(area3D / areaParam)
// so that 1 is an isometry up to a global scale (and the minimum).
struct ParamQuality {
  double stretchL2 = 1.0;            // sqrt(sum_T A3D(T) L2(T)^2 / sum A3D), normalized; >= 1
  double stretchLinf = 1.0;          // max_T Linf(T), normalized
  uint32_t flippedTriangles = 0;     // negative parameter area (0 for a valid embedding)
  uint32_t degenerateTriangles = 0;  // zero parameter or 3D area (excluded from the stretch)
  double area3D = 0.0;               // surface area of the valid triangles
  double areaParam = 0.0;            // parameter area of the valid triangles
};

// One patch mapped onto a convex n-gon inscribed in the unit circle (corners[i] = corner i),
// whose centre, the origin, is strictly inside.
struct PatchParameterization {
  uint32_t patch = 0;
  uint32_t sides = 0;                              // n, 3..kMaxPatchSides
  std::vector<glm::dvec2> corners;                 // n domain corners, CCW
  std::vector<uint32_t> vertices;                  // local -> PatchLayout vertex id
  std::vector<glm::dvec2> uv;                      // per local vertex, in the n-gon
  std::vector<std::array<uint32_t, 3>> triangles;  // local ids, patch triangle order
  std::vector<uint32_t> boundary;                  // local ids of the boundary loop (CCW),
                                                   // starting at corner 0
  std::vector<uint32_t> cornerIndex;               // n entries: position in `boundary`
  ParamQuality initial;                            // the mean-value embedding
  ParamQuality quality;                            // the result
  uint32_t iterationsUsed = 0;                     // reweighting passes kept
  uint32_t sweepsUsed = 0;                         // local optimization sweeps run
};

// A triangle's 3D edges from its first vertex, e1 = q1 - q0 and e2 = q2 - q0, as their Gram
// matrix G: all the stretch energy needs of them (the map's metric is P^-T G P^-1, P the
// parameter edges).
struct TriangleGram {
  double g11 = 0.0, g12 = 0.0, g22 = 0.0;  // e1.e1, e1.e2, e2.e2
  double det = 0.0;                        // det G = |e1 x e2|^2
  double area3D = 0.0;                     // |e1 x e2| / 2
};
TriangleGram triangleGram(const glm::dvec3& q0, const glm::dvec3& q1, const glm::dvec3& q2);

// The stretch energy of one triangle with parameter points p0..p2 and surface points q0..q2 (g
// their Gram matrix), as the local sweeps minimize it: with k2 > 0 the symmetric Dirichlet energy
// area3D * (tr M + tr M^-1) of the scaled metric M = k2 J^T J (J the map's Jacobian), else
// Sander's L2 energy area3D * (|J_s|^2 + |J_t|^2) / 2. Infinite for a triangle flipped or
// squeezed flat in the parameter plane. If gradient is given, it receives the derivative with
// respect to corner `moving` (exact, not differenced). From G alone it takes about a fifth of the
// arithmetic of the Jacobian's 3D columns.
double gramStretchEnergy(const TriangleGram& g, const glm::dvec2& p0, const glm::dvec2& p1, const glm::dvec2& p2,
                         double k2, int moving = 0, glm::dvec2* gradient = nullptr);

// Corner i of the regular n-gon domain.
glm::dvec2 polygonCorner(uint32_t n, uint32_t i);

// The domain polygon for sides of 3D lengths `sideLengths` (n >= 3, all > 0): corner 0 at
// (1, 0), corner i+1 at central angle theta_i past corner i, theta_i = clamp(s * 2 pi L_i / sum L,
// 0.4 * 2 pi / n, min(1.8 * 2 pi / n, 0.9 pi)) with s chosen so the angles sum to 2 pi. No angle
// reaches pi, so the polygon is convex with the origin strictly inside, and every kite (corner i,
// midpoint of side i, origin, midpoint of side i-1) is convex with right angles at the midpoints.
// Equal lengths give the regular n-gon. With paired (an even n >= 6), the same rule gives each
// pair of sides (2j, 2j+1) its angle phi_j, at most 3/4 pi, so every quad (corner 2j+1, corner
// 2j+2, origin, corner 2j) is convex; the pair's middle corner splits phi_j in proportion to the
// two sides' lengths, within [0.2, 0.8] of it. With paired and n = 4 (one quad, the chart itself),
// the square.
std::vector<glm::dvec2> patchPolygon(const std::vector<double>& sideLengths, bool paired = false);

// The local mesh a parameterization of `patch` is numbered in: its layout vertices in the order
// its triangles first use them (PatchParameterization::vertices) and its triangles in those local
// ids (PatchParameterization::triangles); returns the map from layout to local vertex ids.
// Triangle and vertex ids must be in range.
std::unordered_map<uint32_t, uint32_t> numberPatchVertices(const PatchLayout& layout, const Patch& patch,
                                                           std::vector<uint32_t>& vertices,
                                                           std::vector<std::array<uint32_t, 3>>& triangles);

// Parameterizes patch `patch` of `layout`. The patch must be a triangulated disk whose boundary
// loop is exactly its sides' concatenation in order (side i ends where side i+1 starts, edges
// oriented like the triangles), with 3..kMaxPatchSides sides of non-zero length. Throws
// std::invalid_argument("parameterizePatch: patch P: <problem>") otherwise. Deterministic and
// thread-safe (reads `layout` only).
// note: sides are straight polygon edges, so a triangle with all three vertices on one side (an
// "ear" of a zig-zag side) gets zero parameter area: it is counted in degenerateTriangles and
// its surface is squeezed into the side (no flips, no seams; a local sampling distortion).
PatchParameterization parameterizePatch(const PatchLayout& layout, uint32_t patch, const ParamOptions& options = {});

// A triangulated disk (surface points xyz, triangles counter-clockwise in the domain) mapped
// onto a convex domain whose border vertices are given: `fixed` flags them and uv holds their
// positions on entry. The others get the mean-value embedding (no flipped triangles), then the
// local stretch sweeps of `options` (stretchSweeps, symmetricEnergy), kept unless they flip a
// triangle. uv receives every vertex; returns the map's quality. Throws std::invalid_argument if
// the sizes disagree or the system cannot be solved.
ParamQuality mapDiskOntoDomain(const std::vector<glm::dvec3>& xyz,
                               const std::vector<std::array<uint32_t, 3>>& triangles, const std::vector<uint8_t>& fixed,
                               const ParamOptions& options, std::vector<glm::dvec2>& uv);

// Sander et al. stretch of the map from parameter triangles `uv` to surface triangles `xyz`
// (same indexing). Shared by the parameterization and the resampler's image quality.
ParamQuality measureStretch(const std::vector<glm::dvec2>& uv, const std::vector<glm::dvec3>& xyz,
                            const std::vector<std::array<uint32_t, 3>>& triangles);

// The stretch part of combining per-part figures (parts of any type with area3D, stretchL2 and
// stretchLinf, each normalized by its own scale): the 3D-area-weighted RMS of L2, the max of Linf
// (1 with no parts) and the summed area, then `add(out, part)` for the part's other figures.
template <typename Q, typename Add>
Q combineStretch(const std::vector<Q>& parts, Add add) {
  Q q;
  double num = 0.0;
  q.stretchLinf = parts.empty() ? 1.0 : 0.0;
  for (const Q& p : parts) {
    num += p.area3D * p.stretchL2 * p.stretchL2;
    q.area3D += p.area3D;
    q.stretchLinf = q.stretchLinf < p.stretchLinf ? p.stretchLinf : q.stretchLinf;
    add(q, p);
  }
  if (q.area3D > 0.0) q.stretchL2 = std::sqrt(num / q.area3D);
  return q;
}

// Combines per-patch figures, each normalized by its own scale (charts are scaled
// independently): 3D-area-weighted RMS of L2, max of Linf, summed counts and areas.
ParamQuality combineQuality(const std::vector<ParamQuality>& parts);

}  // namespace gimlod
