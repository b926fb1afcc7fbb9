// Writes a deterministic family of test meshes for the mesh stage, shapes far wider than closed
// statues: genus, open boundaries, thin parts, scan noise, CAD slivers, clutter, uneven density.
// Each is a binary little-endian PLY (float x y z, int triangles), vertex-welded, counter-clockwise
// seen from outside, without degenerate or duplicate triangles, every edge shared by two triangles
// of opposite orientation except on open boundaries:
//
//   torus.ply               a torus, R = 1, r = 0.3 (genus 1)
//   genus3.ply              a 3 x 1 x 0.25 plate with 3 round through-holes (genus 3), closed
//   holes_sphere.ply        a unit sphere with 6 round caps cut out (6 boundary loops)
//   thin_parts.ply          a unit sphere, a thin antenna (length 2, radius 0.03) and a thin fin
//                           (1 x 0.6 x 0.01): three closed components that intersect in space
//   noisy_sphere.ply        a unit sphere, every vertex moved radially by up to 0.5% (scan noise)
//   cad_bracket.ply         an L-shaped bracket with chamfers, as CAD exporters triangulate it:
//                           flat faces of few long thin triangles around regularly gridded areas
//   many_pieces.ply         200 small closed cubes and spheres (size 0.02..0.1, any orientation)
//                           over an open floor rectangle, in a 3 x 3 x 1 box (indoor clutter)
//   uneven.ply              a unit sphere, one hemisphere tessellated ~32 times finer (in area)
//                           than the other, crack-free between them
//   wavy_terrain_patch.ply  an open 2 x 2 height field with ridges and a cliff (a terrain scan)
//
//   mesh_family OUT_DIR [--triangles N] [--seed S]
//
// N (default 40000) is the approximate triangle count of each mesh; S (default 1) seeds the noise,
// the clutter and the terrain. Every file is written as NAME.tmp and renamed; one line per mesh
// names it with its vertex and triangle counts.
#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <functional>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <unordered_set>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <glm/glm.hpp>
#include <glm/gtc/quaternion.hpp>

#include "guarded_main.h"

namespace {

namespace fs = std::filesystem;
using glm::dvec2;
using glm::dvec3;

constexpr double kPi = 3.14159265358979323846;

struct Mesh {
  std::vector<dvec3> positions;
  std::vector<std::array<int32_t, 3>> triangles;

  int32_t vertex(const dvec3& p) {
    positions.push_back(p);
    return int32_t(positions.size() - 1);
  }
  void triangle(int32_t a, int32_t b, int32_t c) { triangles.push_back({a, b, c}); }
  // A quad a b c d, counter-clockwise from outside, split along its shorter diagonal.
  void quad(int32_t a, int32_t b, int32_t c, int32_t d) {
    const auto dist = [&](int32_t u, int32_t v) { return glm::distance(positions[u], positions[v]); };
    if (dist(a, c) <= dist(b, d)) {
      triangle(a, b, c);
      triangle(a, c, d);
    } else {
      triangle(a, b, d);
      triangle(b, c, d);
    }
  }
  // Another mesh as a separate component (nothing welded between them).
  void append(const Mesh& other) {
    const auto base = int32_t(positions.size());
    positions.insert(positions.end(), other.positions.begin(), other.positions.end());
    for (const auto& t : other.triangles) triangle(base + t[0], base + t[1], base + t[2]);
  }
};

// Adds vertices to a mesh by position: a point within kTolerance of one already added is that
// vertex, so faces built separately from the same formulas share their edges.
class Welder {
 public:
  explicit Welder(Mesh& mesh) : mesh_(mesh) {}
  int32_t vertex(const dvec3& p) {
    const Key k = key(p);
    for (int dx = -1; dx <= 1; ++dx)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dz = -1; dz <= 1; ++dz) {
          const auto it = cells_.find({k[0] + dx, k[1] + dy, k[2] + dz});
          if (it == cells_.end()) continue;
          for (int32_t v : it->second)
            if (glm::distance(mesh_.positions[v], p) < kTolerance) return v;
        }
    const int32_t v = mesh_.vertex(p);
    cells_[k].push_back(v);
    return v;
  }

 private:
  static constexpr double kTolerance = 1e-7, kCell = 1e-6;
  using Key = std::array<int64_t, 3>;
  struct KeyHash {
    size_t operator()(const Key& k) const {
      return size_t(k[0] * 73856093ll) ^ size_t(k[1] * 19349663ll) ^ size_t(k[2] * 83492791ll);
    }
  };
  static Key key(const dvec3& p) {
    return {std::llround(p.x / kCell), std::llround(p.y / kCell), std::llround(p.z / kCell)};
  }
  Mesh& mesh_;
  std::unordered_map<Key, std::vector<int32_t>, KeyHash> cells_;
};

// splitmix64: the same numbers on every platform (std's distributions are not).
class Random {
 public:
  explicit Random(uint64_t seed) : state_(seed) {}
  uint64_t next() {
    uint64_t z = (state_ += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
  }
  double uniform(double lo = 0, double hi = 1) { return lo + (hi - lo) * double(next() >> 11) * 0x1p-53; }
  // A uniformly distributed rotation (Shoemake's random unit quaternion).
  glm::dmat3 rotation() {
    const double u1 = uniform(), u2 = uniform(0, 2 * kPi), u3 = uniform(0, 2 * kPi);
    const double a = std::sqrt(1 - u1), b = std::sqrt(u1);
    return glm::mat3_cast(glm::dquat(b * std::cos(u3), a * std::sin(u2), a * std::cos(u2), b * std::sin(u3)));
  }

 private:
  uint64_t state_;
};

// A cube face of the lattice [0, nx] x [0, ny] x [0, nz]: coordinate `fixed` at its maximum (top)
// or 0, walked along axes u and v with u x v pointing outward.
struct BoxFace {
  int fixed, u, v;
  bool top;
};
constexpr BoxFace kBoxFaces[6] = {{0, 1, 2, true},  {0, 2, 1, false}, {1, 2, 0, true},
                                  {1, 0, 2, false}, {2, 0, 1, true},  {2, 1, 0, false}};

// The surface of the lattice box with n[0] x n[1] x n[2] cells, closed and welded (a lattice
// point is one vertex whichever face asks for it), each lattice point t / n in [0, 1]^3 placed by
// `place`, which must keep the surface outward (a box, or a box blown up to a sphere).
Mesh latticeBox(std::array<int, 3> n, const std::function<dvec3(const dvec3&)>& place) {
  Mesh mesh;
  std::unordered_map<int64_t, int32_t> ids;
  auto id = [&](const std::array<int, 3>& l) {
    const int64_t key = (int64_t(l[0]) * (n[1] + 1) + l[1]) * (n[2] + 1) + l[2];
    const auto [it, added] = ids.emplace(key, 0);
    if (added) it->second = mesh.vertex(place(dvec3(l[0], l[1], l[2]) / dvec3(n[0], n[1], n[2])));
    return it->second;
  };
  for (const BoxFace& f : kBoxFaces)
    for (int j = 0; j < n[f.v]; ++j)
      for (int i = 0; i < n[f.u]; ++i) {
        auto corner = [&](int di, int dj) {
          std::array<int, 3> l;
          l[f.fixed] = f.top ? n[f.fixed] : 0;
          l[f.u] = i + di;
          l[f.v] = j + dj;
          return id(l);
        };
        mesh.quad(corner(0, 0), corner(1, 0), corner(1, 1), corner(0, 1));
      }
  return mesh;
}

// The unit sphere as a cube of n x n quads a face, with the equal-angle (tangent) warp so that
// all cells are near-uniform: 12 n^2 triangles.
dvec3 cubeToSphere(const dvec3& t) {
  const dvec3 c = glm::tan(kPi / 4 * (2.0 * t - 1.0));
  return glm::normalize(c);
}
Mesh cubeSphere(int n) { return latticeBox({n, n, n}, cubeToSphere); }
int cubeSphereRes(double triangles) { return std::max(2, int(std::lround(std::sqrt(triangles / 12)))); }

Mesh torus(int triangles) {
  const double R = 1.0, r = 0.3;
  // Cells near-square: as many around the tube as its circumference is shorter.
  const int nv = std::max(3, int(std::lround(std::sqrt(triangles / 2.0 * r / R))));
  const int nu = std::max(3, int(std::lround(triangles / 2.0 / nv)));
  Mesh mesh;
  for (int i = 0; i < nu; ++i)
    for (int j = 0; j < nv; ++j) {
      const double u = 2 * kPi * i / nu, v = 2 * kPi * j / nv;
      mesh.vertex({(R + r * std::cos(v)) * std::cos(u), (R + r * std::cos(v)) * std::sin(u), r * std::sin(v)});
    }
  // d/du x d/dv points away from the tube's core circle.
  auto id = [&](int i, int j) { return int32_t((i % nu) * nv + j % nv); };
  for (int i = 0; i < nu; ++i)
    for (int j = 0; j < nv; ++j) mesh.quad(id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
  return mesh;
}

// The plate 3 x 1 x 0.25 with 3 holes of radius 0.3, as three 1 x 1 cells side by side, each an
// annulus between its hole's circle and its square: M points around, K rings across, L layers
// through the thickness. Circle point j (angle 2 pi j / M) joins the square point at arc length
// 4 j / M from the middle of the square's +x side, so that corners fall on j = M/8 + k M/4
// (M a multiple of 8) and the points of a side that two cells share coincide.
Mesh genus3(int triangles) {
  constexpr double halfThickness = 0.125, holeRadius = 0.3;
  // K and L for M: cells near-square, the square's spacing across the annulus (0.2 to 0.41 wide)
  // and the thickness.
  auto counts = [](int m) {
    const double spacing = 4.0 / m;
    return std::array<int, 2>{std::max(2, int(std::lround(0.3 / spacing))),
                              std::max(2, int(std::lround(2 * halfThickness / spacing)))};
  };
  int M = 8;
  auto total = [&](int m) { return double(m) * (12 * counts(m)[0] + 10 * counts(m)[1]); };
  while (std::abs(total(M + 8) - triangles) < std::abs(total(M) - triangles)) M += 8;
  const auto [K, L] = counts(M);

  auto square = [&](int j) {
    double s = std::fmod(4.0 * (j % M) / M + 0.5, 4.0);  // from the corner (0.5, -0.5), counter-clockwise
    const int side = std::min(3, int(s));
    s -= side;
    const dvec2 start[4] = {{0.5, -0.5}, {0.5, 0.5}, {-0.5, 0.5}, {-0.5, -0.5}};
    const dvec2 dir[4] = {{0, 1}, {-1, 0}, {0, -1}, {1, 0}};
    return start[side] + s * dir[side];
  };
  auto circle = [&](int j) { return holeRadius * dvec2(std::cos(2 * kPi * j / M), std::sin(2 * kPi * j / M)); };

  Mesh mesh;
  Welder weld(mesh);
  for (int cell = 0; cell < 3; ++cell) {
    const dvec2 center(cell - 1.0, 0.0);
    auto annulus = [&](int k, int j, double z) {
      const dvec2 c = circle(j), s = square(j);
      return weld.vertex(dvec3(center + c + (s - c) * (double(k) / K), z));
    };
    auto layerZ = [&](int l) { return -halfThickness + 2 * halfThickness * l / L; };
    for (int j = 0; j < M; ++j) {
      // Top (radial x angular is +z) and bottom faces.
      for (int k = 0; k < K; ++k) {
        mesh.quad(annulus(k, j, halfThickness), annulus(k + 1, j, halfThickness), annulus(k + 1, j + 1, halfThickness),
                  annulus(k, j + 1, halfThickness));
        mesh.quad(annulus(k, j, -halfThickness), annulus(k, j + 1, -halfThickness),
                  annulus(k + 1, j + 1, -halfThickness), annulus(k + 1, j, -halfThickness));
      }
      // The hole's wall, facing its axis.
      for (int l = 0; l < L; ++l)
        mesh.quad(annulus(0, j, layerZ(l)), annulus(0, j, layerZ(l + 1)), annulus(0, j + 1, layerZ(l + 1)),
                  annulus(0, j + 1, layerZ(l)));
      // The plate's outer wall, where the square side is not shared with the next cell.
      const double midX = (square(j).x + square(j + 1).x) / 2;
      const bool shared = (midX > 0.5 - 1e-9 && cell < 2) || (midX < -0.5 + 1e-9 && cell > 0);
      if (shared) continue;
      for (int l = 0; l < L; ++l)
        mesh.quad(annulus(K, j, layerZ(l)), annulus(K, j + 1, layerZ(l)), annulus(K, j + 1, layerZ(l + 1)),
                  annulus(K, j, layerZ(l + 1)));
    }
  }
  return mesh;
}

// Drops every triangle whose centroid lies within `angle` of one of the directions, then, while
// some vertex is a bowtie (two separate boundary fans), every triangle at that vertex; unused
// vertices go.
Mesh cutCaps(const Mesh& in, const std::vector<dvec3>& directions, double angle) {
  std::vector<std::array<int32_t, 3>> kept;
  for (const auto& t : in.triangles) {
    const dvec3 c = glm::normalize(in.positions[t[0]] + in.positions[t[1]] + in.positions[t[2]]);
    bool inCap = false;
    for (const dvec3& d : directions) inCap |= glm::dot(c, d) > std::cos(angle);
    if (!inCap) kept.push_back(t);
  }
  for (bool bowtie = true; bowtie;) {
    std::unordered_set<uint64_t> edges;
    for (const auto& t : kept)
      for (int e = 0; e < 3; ++e) edges.insert(uint64_t(uint32_t(t[e])) << 32 | uint32_t(t[(e + 1) % 3]));
    // A boundary edge a -> b has no twin b -> a; a manifold vertex starts at most one.
    std::vector<int> boundaryOut(in.positions.size(), 0);
    for (uint64_t e : edges)
      if (!edges.count(e << 32 | e >> 32)) ++boundaryOut[e >> 32];
    bowtie = false;
    std::vector<std::array<int32_t, 3>> next;
    for (const auto& t : kept) {
      const bool touches = boundaryOut[t[0]] > 1 || boundaryOut[t[1]] > 1 || boundaryOut[t[2]] > 1;
      bowtie |= touches;
      if (!touches) next.push_back(t);
    }
    kept.swap(next);
  }
  Mesh out;
  std::vector<int32_t> id(in.positions.size(), -1);
  for (const auto& t : kept) {
    std::array<int32_t, 3> u;
    for (int e = 0; e < 3; ++e) {
      if (id[t[e]] < 0) id[t[e]] = out.vertex(in.positions[t[e]]);
      u[e] = id[t[e]];
    }
    out.triangle(u[0], u[1], u[2]);
  }
  return out;
}

Mesh holesSphere(int triangles) {
  const double capAngle = 0.35;  // radians; 6 caps take 3 (1 - cos) = 18% of the sphere
  Mesh sphere = cubeSphere(cubeSphereRes(triangles / (1 - 3 * (1 - std::cos(capAngle)))));
  // The octahedron's directions, turned off the cube's face centres and edges.
  const glm::dmat3 turn = glm::mat3_cast(glm::angleAxis(0.4, glm::normalize(dvec3(1, 2, 3))));
  std::vector<dvec3> directions;
  for (int a = 0; a < 3; ++a)
    for (double s : {-1.0, 1.0}) {
      dvec3 d(0.0);
      d[a] = s;
      directions.push_back(turn * d);
    }
  return cutCaps(sphere, directions, capAngle);
}

// A closed cylinder along +z from `base`: side rings and a centre fan at each end.
Mesh cylinder(const dvec3& base, double radius, double length, int segments, int rings) {
  Mesh mesh;
  for (int l = 0; l <= rings; ++l)
    for (int j = 0; j < segments; ++j) {
      const double a = 2 * kPi * j / segments;
      mesh.vertex(base + dvec3(radius * std::cos(a), radius * std::sin(a), length * l / rings));
    }
  const int32_t bottom = mesh.vertex(base), top = mesh.vertex(base + dvec3(0, 0, length));
  auto id = [&](int l, int j) { return int32_t(l * segments + j % segments); };
  for (int j = 0; j < segments; ++j) {
    for (int l = 0; l < rings; ++l) mesh.quad(id(l, j), id(l, j + 1), id(l + 1, j + 1), id(l + 1, j));
    mesh.triangle(bottom, id(0, j + 1), id(0, j));
    mesh.triangle(top, id(rings, j), id(rings, j + 1));
  }
  return mesh;
}

// An axis-aligned box [lo, hi] with n cells along each axis.
Mesh box(const dvec3& lo, const dvec3& hi, std::array<int, 3> n) {
  return latticeBox(n, [&](const dvec3& t) { return lo + t * (hi - lo); });
}

Mesh thinParts(int triangles) {
  Mesh mesh = cubeSphere(cubeSphereRes(0.6 * triangles));
  // The antenna rises from inside the sphere; the fin sticks out of its side.
  const int segments = 24, rings = std::max(1, int(std::lround((0.2 * triangles - 2 * segments) / (2 * segments))));
  mesh.append(cylinder({0, 0, 0.9}, 0.03, 2.0, segments, rings));
  const int nx = std::max(1, int(std::lround(std::sqrt(0.2 * triangles / 4 / 0.6))));
  const int ny = std::max(1, int(std::lround(0.6 * nx)));
  mesh.append(box({0.6, -0.3, -0.005}, {1.6, 0.3, 0.005}, {nx, ny, 1}));
  return mesh;
}

// Radial noise of up to `amplitude`, one draw per vertex.
Mesh noisySphere(int triangles, uint64_t seed) {
  Mesh mesh = cubeSphere(cubeSphereRes(triangles));
  Random random(seed);
  const double amplitude = 0.005;
  for (dvec3& p : mesh.positions) p *= 1 + random.uniform(-amplitude, amplitude);
  return mesh;
}

// Ear clipping of a simple counter-clockwise polygon without collinear vertices.
std::vector<std::array<int32_t, 3>> earClip(const std::vector<dvec2>& polygon) {
  auto cross = [](dvec2 a, dvec2 b, dvec2 c) { return (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x); };
  std::vector<int32_t> left(polygon.size());
  for (size_t i = 0; i < left.size(); ++i) left[i] = int32_t(i);
  std::vector<std::array<int32_t, 3>> out;
  while (left.size() > 3) {
    const size_t n = left.size();
    size_t ear = n;
    for (size_t i = 0; i < n && ear == n; ++i) {
      const int32_t a = left[(i + n - 1) % n], b = left[i], c = left[(i + 1) % n];
      if (cross(polygon[a], polygon[b], polygon[c]) <= 0) continue;  // reflex
      bool empty = true;
      for (int32_t v : left)
        if (v != a && v != b && v != c && cross(polygon[a], polygon[b], polygon[v]) >= 0 &&
            cross(polygon[b], polygon[c], polygon[v]) >= 0 && cross(polygon[c], polygon[a], polygon[v]) >= 0)
          empty = false;
      if (empty) ear = i;
    }
    if (ear == n) throw std::logic_error("earClip: no ear (polygon not simple)");
    out.push_back({left[(ear + n - 1) % n], left[ear], left[(ear + 1) % n]});
    left.erase(left.begin() + ptrdiff_t(ear));
  }
  out.push_back({left[0], left[1], left[2]});
  return out;
}

// A planar rectangle p[0] p[1] p[2] p[3] (counter-clockwise from outside) as a CAD exporter
// meshes a face around a finer area: a regular nu x nv grid inset by `inset`, and between its
// border and the rectangle's edges, fans of long thin triangles to the rectangle's corners.
void insetGridFace(Mesh& mesh, Welder& weld, const std::array<dvec3, 4>& p, double inset, int nu, int nv) {
  const double su = inset / glm::distance(p[0], p[1]), sv = inset / glm::distance(p[0], p[3]);
  auto at = [&](int i, int j) {
    const double s = su + (1 - 2 * su) * i / nu, t = sv + (1 - 2 * sv) * j / nv;
    return weld.vertex((1 - t) * ((1 - s) * p[0] + s * p[1]) + t * ((1 - s) * p[3] + s * p[2]));
  };
  for (int j = 0; j < nv; ++j)
    for (int i = 0; i < nu; ++i) mesh.quad(at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
  // The grid's border, side by side counter-clockwise, each side from the inner corner facing
  // rectangle corner k to the one facing corner k + 1.
  std::array<std::vector<int32_t>, 4> sides;
  for (int i = 0; i <= nu; ++i) sides[0].push_back(at(i, 0));
  for (int j = 0; j <= nv; ++j) sides[1].push_back(at(nu, j));
  for (int i = nu; i >= 0; --i) sides[2].push_back(at(i, nv));
  for (int j = nv; j >= 0; --j) sides[3].push_back(at(0, j));
  for (int k = 0; k < 4; ++k) {
    const int32_t c0 = weld.vertex(p[k]), c1 = weld.vertex(p[(k + 1) % 4]);
    const std::vector<int32_t>& side = sides[k];
    const size_t half = side.size() / 2;
    mesh.triangle(c0, c1, side[half]);
    for (size_t i = 0; i + 1 < side.size(); ++i) mesh.triangle(i < half ? c0 : c1, side[i + 1], side[i]);
  }
}

// An L-shaped bracket: a base 2 x 1 x 0.2 and an upright 0.2 x 1 x 1.5, one solid, chamfered at
// the heel, the inner corner and both free ends: the profile below (x, z) extruded along y. The
// caps and most walls are single big triangles; three walls carry a fine grid inset in them.
Mesh cadBracket(int triangles) {
  const std::vector<dvec2> profile = {{0.1, 0},   {2, 0},      {2, 0.15},   {1.95, 0.2}, {0.3, 0.2},
                                      {0.2, 0.3}, {0.2, 1.45}, {0.15, 1.5}, {0, 1.5},    {0, 0.1}};
  const size_t n = profile.size();
  const double width = 1.0, inset = 0.08;
  auto at = [](dvec2 p, double y) { return dvec3(p.x, y, p.y); };
  // The gridded walls: the base's top (edge 3), the upright's inner face (5) and back (8).
  const std::vector<size_t> gridded = {3, 5, 8};
  double gridArea = 0;
  for (size_t e : gridded)
    gridArea += (glm::distance(profile[e], profile[(e + 1) % n]) - 2 * inset) * (width - 2 * inset);
  const double spacing = std::sqrt(gridArea / std::max(1.0, triangles / 2.0));

  Mesh mesh;
  Welder weld(mesh);
  // The profile is counter-clockwise in (x, z), whose normal x x z is -y: the y = 0 cap as is.
  for (const auto& t : earClip(profile)) {
    mesh.triangle(weld.vertex(at(profile[t[0]], 0)), weld.vertex(at(profile[t[1]], 0)),
                  weld.vertex(at(profile[t[2]], 0)));
    mesh.triangle(weld.vertex(at(profile[t[0]], width)), weld.vertex(at(profile[t[2]], width)),
                  weld.vertex(at(profile[t[1]], width)));
  }
  for (size_t e = 0; e < n; ++e) {
    const dvec2 a = profile[e], b = profile[(e + 1) % n];
    const std::array<dvec3, 4> corners = {at(a, 0), at(a, width), at(b, width), at(b, 0)};
    if (std::find(gridded.begin(), gridded.end(), e) == gridded.end()) {
      mesh.quad(weld.vertex(corners[0]), weld.vertex(corners[1]), weld.vertex(corners[2]), weld.vertex(corners[3]));
      continue;
    }
    const int nu = std::max(1, int(std::lround((width - 2 * inset) / spacing)));
    const int nv = std::max(1, int(std::lround((glm::distance(a, b) - 2 * inset) / spacing)));
    insetGridFace(mesh, weld, corners, inset, nu, nv);
  }
  return mesh;
}

// 200 small closed cubes and spheres, any size from 0.02 to 0.1 and any orientation, above a floor
// rectangle 3 x 3 at z = 0 (open, facing up) that takes the triangles they leave of the budget.
Mesh manyPieces(int triangles, uint64_t seed) {
  const int pieces = 200;
  const int res = std::max(1, int(std::lround(std::sqrt(0.7 * triangles / pieces / 12))));
  Random random(seed ^ 0x5eedc1a77e7ull);
  Mesh mesh;
  for (int i = 0; i < pieces; ++i) {
    const bool sphere = random.uniform() < 0.5;
    const double size = random.uniform(0.02, 0.1);
    const dvec3 center(random.uniform(-1.5 + size, 1.5 - size), random.uniform(-1.5 + size, 1.5 - size),
                       random.uniform(size, 1 - size));
    const glm::dmat3 turn = random.rotation();
    auto place = [&](const dvec3& t) {
      return center + turn * (sphere ? size / 2 * cubeToSphere(t) : size * (t - 0.5));
    };
    mesh.append(latticeBox({res, res, res}, place));
  }
  const double floorTriangles = std::max(2.0, triangles - double(mesh.triangles.size()));
  const int floorRes = std::max(1, int(std::lround(std::sqrt(floorTriangles / 2))));
  const auto base = int32_t(mesh.positions.size());
  for (int j = 0; j <= floorRes; ++j)
    for (int i = 0; i <= floorRes; ++i) mesh.vertex({-1.5 + 3.0 * i / floorRes, -1.5 + 3.0 * j / floorRes, 0});
  auto id = [&](int i, int j) { return base + int32_t(j * (floorRes + 1) + i); };
  for (int j = 0; j < floorRes; ++j)
    for (int i = 0; i < floorRes; ++i) mesh.quad(id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
  return mesh;
}

// Rings of latitude, south to north, each of about 2 pi cos(lat) / spacing vertices, the spacing
// `fine` in the north and sqrt(32) times coarser in the south (the equator is fine); neighbouring
// rings are zipped together whatever their counts, and each pole closes with a fan.
struct Ring {
  double latitude;
  int count;
};
std::vector<Ring> unevenRings(double fine) {
  const double coarse = fine * std::sqrt(32.0);
  const int south = std::max(2, int(std::lround(kPi / 2 / coarse)));
  const int north = std::max(2, int(std::lround(kPi / 2 / fine)));
  auto ring = [](double lat, double spacing) {
    return Ring{lat, std::max(3, int(std::lround(2 * kPi * std::cos(lat) / spacing)))};
  };
  std::vector<Ring> rings;
  for (int i = 1; i < south; ++i) rings.push_back(ring(-kPi / 2 + kPi / 2 * i / south, coarse));
  for (int i = 0; i < north; ++i) rings.push_back(ring(kPi / 2 * i / north, fine));
  return rings;
}

Mesh uneven(int triangles) {
  auto count = [](const std::vector<Ring>& rings) {
    double sum = rings.front().count + rings.back().count;
    for (size_t k = 0; k + 1 < rings.size(); ++k) sum += rings[k].count + rings[k + 1].count;
    return sum;
  };
  double fine = std::sqrt(4 * kPi / triangles);
  for (int step = 0; step < 20; ++step) fine *= std::sqrt(count(unevenRings(fine)) / triangles);
  const std::vector<Ring> rings = unevenRings(fine);

  Mesh mesh;
  std::vector<int32_t> first;
  const int32_t southPole = mesh.vertex({0, 0, -1});
  for (const Ring& r : rings) {
    first.push_back(int32_t(mesh.positions.size()));
    for (int j = 0; j < r.count; ++j) {
      const double lon = 2 * kPi * j / r.count;
      mesh.vertex({std::cos(r.latitude) * std::cos(lon), std::cos(r.latitude) * std::sin(lon), std::sin(r.latitude)});
    }
  }
  const int32_t northPole = mesh.vertex({0, 0, 1});
  auto id = [&](size_t k, int j) { return first[k] + j % rings[k].count; };
  // Counter-clockwise from outside: east (+longitude), then north.
  for (int j = 0; j < rings.front().count; ++j) mesh.triangle(southPole, id(0, j + 1), id(0, j));
  for (size_t k = 0; k + 1 < rings.size(); ++k) {
    const int nl = rings[k].count, nu = rings[k + 1].count;
    for (int i = 0, j = 0; i < nl || j < nu;) {
      // Advance along whichever ring's next vertex comes first eastward.
      if (j == nu || (i < nl && double(i + 1) / nl <= double(j + 1) / nu)) {
        mesh.triangle(id(k, i), id(k, i + 1), id(k + 1, j));
        ++i;
      } else {
        mesh.triangle(id(k, i), id(k + 1, j + 1), id(k + 1, j));
        ++j;
      }
    }
  }
  const size_t last = rings.size() - 1;
  for (int j = 0; j < rings.back().count; ++j) mesh.triangle(id(last, j), id(last, j + 1), northPole);
  return mesh;
}

// z = f(x, y) over [-1, 1]^2, facing up: rolling hills, sharp ridges and a cliff 0.25 high whose
// face is about 0.02 wide, along a wavy line.
Mesh wavyTerrainPatch(int triangles, uint64_t seed) {
  Random random(seed ^ 0x7e44a1full);
  const double p1 = random.uniform(0, 2 * kPi), p2 = random.uniform(0, 2 * kPi), p3 = random.uniform(0, 2 * kPi);
  auto height = [&](double x, double y) {
    const double hills = 0.08 * std::sin(3 * x + 2 * y + p1) + 0.04 * std::cos(4 * y - x + p2);
    const double ridges = 0.06 * (1 - std::abs(std::sin(5 * y - 2 * x + p3)));
    const double cliffLine = 0.1 + 0.2 * std::sin(2 * y + p1);
    return hills + ridges + 0.125 * (1 + std::tanh((x - cliffLine) / 0.01));
  };
  const int n = std::max(2, int(std::lround(std::sqrt(triangles / 2.0))));
  Mesh mesh;
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) {
      const double x = -1 + 2.0 * i / n, y = -1 + 2.0 * j / n;
      mesh.vertex({x, y, height(x, y)});
    }
  auto id = [&](int i, int j) { return int32_t(j * (n + 1) + i); };
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) mesh.quad(id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
  return mesh;
}

// Refuses a mesh that breaks the family's promises: a triangle with a repeated or out-of-range
// vertex or no area, the same triangle twice, or an edge used twice in one direction (two
// triangles of the same orientation across it, or more than two at it).
void checkMesh(const std::string& name, const Mesh& mesh) {
  std::unordered_set<uint64_t> directed;
  std::unordered_set<std::string> seen;
  for (const auto& t : mesh.triangles) {
    for (int32_t v : t)
      if (v < 0 || size_t(v) >= mesh.positions.size()) throw std::logic_error(name + ": vertex out of range");
    const dvec3 a = mesh.positions[t[0]], b = mesh.positions[t[1]], c = mesh.positions[t[2]];
    if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2] || glm::length(glm::cross(b - a, c - a)) < 1e-14)
      throw std::logic_error(name + ": degenerate triangle");
    std::array<int32_t, 3> sorted = t;
    std::sort(sorted.begin(), sorted.end());
    if (!seen.insert(fmt::format("{},{},{}", sorted[0], sorted[1], sorted[2])).second)
      throw std::logic_error(name + ": duplicate triangle");
    for (int e = 0; e < 3; ++e)
      if (!directed.insert(uint64_t(uint32_t(t[e])) << 32 | uint32_t(t[(e + 1) % 3])).second)
        throw std::logic_error(name + ": edge used twice in one direction");
  }
}

// Binary little-endian PLY, float x y z and uchar-int triangle lists, via NAME.tmp and a rename.
void writePly(const fs::path& path, const Mesh& mesh) {
  std::string bytes = fmt::format(
      "ply\nformat binary_little_endian 1.0\ncomment gimlod mesh_family {}\nelement vertex {}\n"
      "property float x\nproperty float y\nproperty float z\nelement face {}\n"
      "property list uchar int vertex_indices\nend_header\n",
      path.stem().string(), mesh.positions.size(), mesh.triangles.size());
  auto append = [&](const void* data, size_t size) { bytes.append(static_cast<const char*>(data), size); };
  for (const dvec3& p : mesh.positions) {
    const float q[3] = {float(p.x), float(p.y), float(p.z)};
    append(q, sizeof q);
  }
  for (const auto& t : mesh.triangles) {
    const uint8_t three = 3;
    append(&three, 1);
    append(t.data(), sizeof(int32_t) * 3);
  }
  fs::path tmp = path;
  tmp += ".tmp";
  std::FILE* f = std::fopen(tmp.string().c_str(), "wb");
  if (!f) throw std::runtime_error(tmp.string() + ": cannot write");
  const bool ok = std::fwrite(bytes.data(), 1, bytes.size(), f) == bytes.size() && std::fflush(f) == 0;
  if (std::fclose(f) != 0 || !ok) throw std::runtime_error(tmp.string() + ": write failed");
  fs::rename(tmp, path);
}

int run(int argc, char** argv) {
  CLI::App app{"A deterministic family of test meshes for the mesh stage, as binary PLY files"};
  fs::path outDir;
  int triangles = 40000;
  uint64_t seed = 1;
  app.add_option("out_dir", outDir, "Folder for the meshes (created)")->required();
  app.add_option("--triangles", triangles, "Approximate triangle count of each mesh")
      ->check(CLI::Range(1000, 100'000'000))
      ->capture_default_str();
  app.add_option("--seed", seed, "Seed of the noise, the clutter and the terrain")->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  static_assert(std::endian::native == std::endian::little, "the PLY is written from memory, little-endian");
  fs::create_directories(outDir);

  const std::vector<std::pair<std::string, std::function<Mesh()>>> family = {
      {"torus", [&] { return torus(triangles); }},
      {"genus3", [&] { return genus3(triangles); }},
      {"holes_sphere", [&] { return holesSphere(triangles); }},
      {"thin_parts", [&] { return thinParts(triangles); }},
      {"noisy_sphere", [&] { return noisySphere(triangles, seed); }},
      {"cad_bracket", [&] { return cadBracket(triangles); }},
      {"many_pieces", [&] { return manyPieces(triangles, seed); }},
      {"uneven", [&] { return uneven(triangles); }},
      {"wavy_terrain_patch", [&] { return wavyTerrainPatch(triangles, seed); }},
  };
  for (const auto& [name, make] : family) {
    const Mesh mesh = make();
    checkMesh(name, mesh);
    writePly(outDir / (name + ".ply"), mesh);
    std::printf("%s.ply: %zu vertices, %zu triangles\n", name.c_str(), mesh.positions.size(), mesh.triangles.size());
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) { return guardedMain(argc, argv, run); }
