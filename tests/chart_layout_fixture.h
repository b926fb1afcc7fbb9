// Hand-built chart layouts for the parameterization and resampling tests: flat grids, a cube (or
// a sphere made from it) as six 4-sided patches, triangulated disks and hemisphere caps with n
// sides. They depend on nothing but atlas/mesh/patch_layout.h.
#pragma once

#include <cmath>
#include <cstdint>
#include <map>
#include <numbers>
#include <tuple>
#include <vector>

#include <glm/geometric.hpp>

#include "atlas/mesh/patch_layout.h"

namespace gimlod::test {

// Links every pair of sides whose vertex runs are reverses of each other.
inline void linkSides(PatchLayout& layout) {
  for (uint32_t p = 0; p < layout.patches.size(); ++p) {
    for (uint32_t i = 0; i < layout.patches[p].sides.size(); ++i) {
      PatchSide& s = layout.patches[p].sides[i];
      for (uint32_t q = 0; q < layout.patches.size(); ++q) {
        for (uint32_t j = 0; j < layout.patches[q].sides.size(); ++j) {
          if (p == q && i == j) continue;
          const auto& o = layout.patches[q].sides[j].vertices;
          if (std::vector<uint32_t>(o.rbegin(), o.rend()) == s.vertices) {
            s.neighbourPatch = int32_t(q);
            s.neighbourSide = j;
            s.reversed = true;
          }
        }
      }
    }
  }
}

// Adds a patch covering grid cells [x0, x1) x [y0, y1) of a grid whose vertex (x, y) has id
// y * (nx + 1) + x; 4 sides: bottom, right, top, left.
inline void addGridPatch(PatchLayout& layout, uint32_t nx, uint32_t x0, uint32_t x1, uint32_t y0, uint32_t y1) {
  auto id = [&](uint32_t x, uint32_t y) { return y * (nx + 1) + x; };
  Patch patch;
  for (uint32_t y = y0; y < y1; ++y) {
    for (uint32_t x = x0; x < x1; ++x) {
      // Alternate the diagonal so the triangulation is not symmetric.
      patch.triangles.push_back(uint32_t(layout.triangles.size()));
      patch.triangles.push_back(uint32_t(layout.triangles.size() + 1));
      if ((x + y) % 2 == 0) {
        layout.triangles.push_back({id(x, y), id(x + 1, y), id(x + 1, y + 1)});
        layout.triangles.push_back({id(x, y), id(x + 1, y + 1), id(x, y + 1)});
      } else {
        layout.triangles.push_back({id(x, y), id(x + 1, y), id(x, y + 1)});
        layout.triangles.push_back({id(x + 1, y), id(x + 1, y + 1), id(x, y + 1)});
      }
    }
  }
  PatchSide bottom, right, top, left;
  for (uint32_t x = x0; x <= x1; ++x) bottom.vertices.push_back(id(x, y0));
  for (uint32_t y = y0; y <= y1; ++y) right.vertices.push_back(id(x1, y));
  for (uint32_t x = x1 + 1; x-- > x0;) top.vertices.push_back(id(x, y1));
  for (uint32_t y = y1 + 1; y-- > y0;) left.vertices.push_back(id(x0, y));
  patch.sides = {bottom, right, top, left};
  layout.patches.push_back(patch);
}

// A flat grid of nx * ny cells over [0, width] x [0, height] at z = 0, cut into patches by the
// vertical lines x = cuts[k] (grid columns). With warp, interior x and y grid lines are bent
// (still a valid, non-uniform planar grid).
inline PatchLayout gridLayout(uint32_t nx, uint32_t ny, float width, float height,
                              const std::vector<uint32_t>& cuts = {}, bool warp = false) {
  PatchLayout layout;
  for (uint32_t y = 0; y <= ny; ++y) {
    for (uint32_t x = 0; x <= nx; ++x) {
      double fx = double(x) / nx, fy = double(y) / ny;
      if (warp) {
        fx = fx + 0.3 * fx * (1 - fx) * (fy - 0.3);
        fy = fy * fy * 0.5 + fy * 0.5;
      }
      layout.positions.emplace_back(float(fx * width), float(fy * height), 0.f);
    }
  }
  std::vector<uint32_t> edges{0};
  edges.insert(edges.end(), cuts.begin(), cuts.end());
  edges.push_back(nx);
  for (size_t k = 0; k + 1 < edges.size(); ++k) addGridPatch(layout, nx, edges[k], edges[k + 1], 0, ny);
  linkSides(layout);
  return layout;
}

// A cube [-0.5, 0.5]^3 with m x m cells per face, one 4-sided patch per face, welded and linked.
// With sphere, vertices are pushed onto the unit sphere (curved patches).
inline PatchLayout cubeLayout(uint32_t m, bool sphere = false) {
  PatchLayout layout;
  std::map<std::tuple<int, int, int>, uint32_t> ids;
  auto vertex = [&](glm::ivec3 g) {
    auto [it, inserted] = ids.try_emplace({g.x, g.y, g.z}, uint32_t(layout.positions.size()));
    if (inserted) {
      glm::dvec3 p = glm::dvec3(g) / double(m) - 0.5;
      if (sphere) p = glm::normalize(p);
      layout.positions.emplace_back(p);
    }
    return it->second;
  };
  const int mm = int(m);
  // Origin, U, V with U x V the outward normal.
  const glm::ivec3 faces[6][3] = {{{0, 0, mm}, {1, 0, 0}, {0, 1, 0}}, {{0, 0, 0}, {0, 1, 0}, {1, 0, 0}},
                                  {{mm, 0, 0}, {0, 1, 0}, {0, 0, 1}}, {{0, 0, 0}, {0, 0, 1}, {0, 1, 0}},
                                  {{0, mm, 0}, {0, 0, 1}, {1, 0, 0}}, {{0, 0, 0}, {1, 0, 0}, {0, 0, 1}}};
  for (const auto& f : faces) {
    auto id = [&](int a, int b) { return vertex(f[0] + a * f[1] + b * f[2]); };
    Patch patch;
    for (int b = 0; b < mm; ++b) {
      for (int a = 0; a < mm; ++a) {
        patch.triangles.push_back(uint32_t(layout.triangles.size()));
        layout.triangles.push_back({id(a, b), id(a + 1, b), id(a + 1, b + 1)});
        patch.triangles.push_back(uint32_t(layout.triangles.size()));
        layout.triangles.push_back({id(a, b), id(a + 1, b + 1), id(a, b + 1)});
      }
    }
    PatchSide s0, s1, s2, s3;
    for (int a = 0; a <= mm; ++a) s0.vertices.push_back(id(a, 0));
    for (int b = 0; b <= mm; ++b) s1.vertices.push_back(id(mm, b));
    for (int a = mm; a >= 0; --a) s2.vertices.push_back(id(a, mm));
    for (int b = mm; b >= 0; --b) s3.vertices.push_back(id(0, b));
    patch.sides = {s0, s1, s2, s3};
    layout.patches.push_back(patch);
  }
  linkSides(layout);
  return layout;
}

// A triangulated disk (a centre fan and `rings` rings of `segments` vertices) as one patch whose
// boundary is split into n sides. With hemisphere, the disk is mapped onto the upper unit
// hemisphere (radius r -> polar angle r * pi / 2); otherwise it is the flat unit disk at z = 0.
// With colours, every vertex gets a colour from its position.
inline PatchLayout diskLayout(uint32_t n, uint32_t rings, uint32_t segments, bool hemisphere, bool colours = false) {
  PatchLayout layout;
  auto place = [&](double r, double theta) {
    glm::dvec3 p;
    if (hemisphere) {
      const double phi = r * std::numbers::pi / 2;
      p = {std::sin(phi) * std::cos(theta), std::sin(phi) * std::sin(theta), std::cos(phi)};
    } else {
      p = {r * std::cos(theta), r * std::sin(theta), 0.0};
    }
    layout.positions.emplace_back(p);
    if (colours) {
      layout.colours.emplace_back(uint8_t(127.5 + 127.5 * p.x), uint8_t(127.5 + 127.5 * p.y), uint8_t(255 * p.z),
                                  uint8_t(255));
    }
  };
  place(0.0, 0.0);
  for (uint32_t r = 1; r <= rings; ++r) {
    for (uint32_t s = 0; s < segments; ++s) {
      place(double(r) / rings, 2 * std::numbers::pi * s / segments);
    }
  }
  auto ring = [&](uint32_t r, uint32_t s) { return 1 + (r - 1) * segments + s % segments; };
  Patch patch;
  for (uint32_t s = 0; s < segments; ++s) {
    layout.triangles.push_back({0, ring(1, s), ring(1, s + 1)});
  }
  for (uint32_t r = 1; r < rings; ++r) {
    for (uint32_t s = 0; s < segments; ++s) {
      layout.triangles.push_back({ring(r, s), ring(r + 1, s), ring(r + 1, s + 1)});
      layout.triangles.push_back({ring(r, s), ring(r + 1, s + 1), ring(r, s + 1)});
    }
  }
  for (uint32_t t = 0; t < layout.triangles.size(); ++t) patch.triangles.push_back(t);
  for (uint32_t i = 0; i < n; ++i) {
    const uint32_t a = uint32_t(std::lround(double(i) * segments / n));
    const uint32_t b = uint32_t(std::lround(double(i + 1) * segments / n));
    PatchSide side;
    for (uint32_t s = a; s <= b; ++s) side.vertices.push_back(ring(rings, s));
    patch.sides.push_back(side);
  }
  layout.patches.push_back(patch);
  return layout;
}

}  // namespace gimlod::test
