// Based on: Niski, Purnomo, Cohen, I3D 2007, section 5 (quadrangulate, resample); Purnomo, Cohen,
// Kumar, "Seamless Texture Atlases", SGP 2004 (shared boundary sampling).
#include "atlas/mesh/resample.h"
#include "atlas/mesh/portable_math.h"
#include "core/progress.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <mutex>
#include <numeric>
#include <optional>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <unordered_set>

#include <glm/common.hpp>
#include <glm/geometric.hpp>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/partitioner.h>
#include <tbb/task_arena.h>

namespace gimlod {
namespace {

uint64_t undirectedKey(uint32_t a, uint32_t b) { return a < b ? (uint64_t{a} << 32) | b : (uint64_t{b} << 32) | a; }

// Attributes of the layout's surface: positions, area-weighted unit vertex normals, colours.
struct Surface {
  const PatchLayout& layout;
  const std::vector<glm::dvec3>& normals;  // unit, or zero where undefined
  bool hasColours = false;
};

}  // namespace

std::vector<glm::dvec3> layoutVertexNormals(const PatchLayout& layout) {
  std::vector<glm::dvec3> n(layout.positions.size(), glm::dvec3(0.0));
  for (const auto& t : layout.triangles) {
    if (t[0] >= n.size() || t[1] >= n.size() || t[2] >= n.size()) {
      throw std::invalid_argument("resampleLayout: triangle vertex out of range");
    }
    const glm::dvec3 a(layout.positions[t[0]]), b(layout.positions[t[1]]), c(layout.positions[t[2]]);
    const glm::dvec3 w = glm::cross(b - a, c - a);  // twice the area times the unit normal
    for (uint32_t v : t) n[v] += w;
  }
  for (glm::dvec3& x : n) {
    const double l = glm::length(x);
    x = l > 0.0 && std::isfinite(l) ? x / l : glm::dvec3(0.0);
  }
  return n;
}

uint32_t patchQuadCount(uint32_t sides, QuadLayout quads) {
  if (quads == QuadLayout::kKites) return sides;
  if (sides % 2 != 0)
    throw std::invalid_argument("a patch of " + std::to_string(sides) +
                                " sides in the sides quad layout (which needs an even count)");
  return sides == 4 ? 1 : sides / 2;
}

namespace {

// One surface sample before packing.
struct Sample {
  glm::vec3 p{0.f};
  glm::vec3 n{0.f, 0.f, 1.f};
  glm::u8vec4 c{255, 255, 255, 255};
  uint32_t triangle = ~0u;            // the layout triangle it was located in; ~0u for side samples
  uint32_t edgeA = ~0u, edgeB = ~0u;  // side samples: the side segment (vertex ids) it lies on
};

// Interpolates the attributes of vertices v[0..2] with barycentric weights b (sum 1).
Sample interpolate(const Surface& s, const std::array<uint32_t, 3>& v, const glm::dvec3& b) {
  Sample out;
  glm::dvec3 p(0.0), n(0.0);
  glm::dvec4 col(0.0);
  for (int k = 0; k < 3; ++k) {
    p += b[k] * glm::dvec3(s.layout.positions[v[k]]);
    n += b[k] * s.normals[v[k]];
    if (s.hasColours) col += b[k] * glm::dvec4(s.layout.colours[v[k]]);
  }
  out.p = glm::vec3(p);
  double l = glm::length(n);
  if (!(l > 1e-12)) {  // opposite vertex normals cancel: use the face normal
    const glm::dvec3 a(s.layout.positions[v[0]]), bb(s.layout.positions[v[1]]), cc(s.layout.positions[v[2]]);
    n = glm::cross(bb - a, cc - a);
    l = glm::length(n);
  }
  if (l > 0.0 && std::isfinite(l)) out.n = glm::vec3(n / l);
  if (s.hasColours) {
    for (int k = 0; k < 4; ++k) {
      out.c[k] = uint8_t(std::clamp(std::lround(col[k]), 0l, 255l));
    }
  }
  return out;
}

// The sample at layout vertex v: its position bit for bit and its unit vertex normal. Every
// sample that lands on a vertex (corners above all) comes from here, so it is the same bytes in
// every chart that holds it.
Sample vertexSample(const Surface& s, uint32_t v) {
  Sample out;
  out.p = s.layout.positions[v];
  if (glm::dot(s.normals[v], s.normals[v]) > 0.0) out.n = glm::vec3(s.normals[v]);
  if (s.hasColours) out.c = s.layout.colours[v];
  return out;
}

// Samples at fractions k / (count - 1) of the arc length of a 3D polyline (vertex ids), k =
// 0..count-1. The end samples are the end vertices exactly.
std::vector<Sample> sampleSide(const Surface& s, const std::vector<uint32_t>& poly, uint32_t count) {
  std::vector<double> cum(1, 0.0);
  for (size_t k = 0; k + 1 < poly.size(); ++k) {
    cum.push_back(cum.back() +
                  glm::length(glm::dvec3(s.layout.positions[poly[k + 1]]) - glm::dvec3(s.layout.positions[poly[k]])));
  }
  const double total = cum.back();
  const size_t segments = poly.size() - 1;
  std::vector<Sample> out(count);
  for (uint32_t k = 0; k < count; ++k) {
    size_t seg = 0;
    double lambda = 0.0;
    if (k + 1 == count) {
      seg = segments - 1;
      lambda = 1.0;
    } else if (k > 0) {
      const double target = total * double(k) / double(count - 1);
      seg = size_t(std::upper_bound(cum.begin(), cum.end(), target) - cum.begin());
      seg = std::clamp<size_t>(seg, 1, segments) - 1;
      const double len = cum[seg + 1] - cum[seg];
      lambda = len > 0.0 ? std::clamp((target - cum[seg]) / len, 0.0, 1.0) : 0.0;
    }
    const uint32_t a = poly[seg], b = poly[seg + 1];
    if (lambda == 0.0) {
      out[k] = vertexSample(s, a);
    } else if (lambda == 1.0) {
      out[k] = vertexSample(s, b);
    } else {
      out[k] = interpolate(s, {a, b, b}, {1.0 - lambda, lambda, 0.0});
    }
    out[k].edgeA = a;
    out[k].edgeB = b;
  }
  return out;
}

// Point location in a planar triangulation (a patch's parameterization, a quad chart's map)
// through a uniform grid.
class Locator {
 public:
  explicit Locator(const PatchParameterization& pp) : Locator(pp.uv, pp.triangles) {}
  Locator(const std::vector<glm::dvec2>& uv, const std::vector<std::array<uint32_t, 3>>& triangles)
      : uv_(uv), triangles_(triangles) {
    glm::dvec2 lo(1e300), hi(-1e300);
    for (const glm::dvec2& q : uv) lo = glm::min(lo, q), hi = glm::max(hi, q);
    const size_t nt = triangles.size();
    const uint32_t side = std::max<uint32_t>(1, uint32_t(std::sqrt(double(nt))));
    valid_.assign(nt, 0);
    lo_ = lo;
    cell_ = std::max(hi.x - lo.x, hi.y - lo.y) / side * (1.0 + 1e-9);
    if (!(cell_ > 0.0)) cell_ = 1.0;
    nx_ = side;
    ny_ = side;
    std::vector<std::vector<uint32_t>> cells(size_t(nx_) * ny_);
    for (uint32_t t = 0; t < nt; ++t) {
      const auto& tri = triangles[t];
      const glm::dvec2 a = uv[tri[0]], b = uv[tri[1]], c = uv[tri[2]];
      const double twice = (b.x - a.x) * (c.y - a.y) - (c.x - a.x) * (b.y - a.y);
      if (!(twice > 0.0)) continue;  // degenerate or flipped: never returned
      valid_[t] = 1;
      const glm::dvec2 tlo = glm::min(a, glm::min(b, c)), thi = glm::max(a, glm::max(b, c));
      const auto [x0, y0] = cellOf(tlo);
      const auto [x1, y1] = cellOf(thi);
      for (uint32_t y = y0; y <= y1; ++y) {
        for (uint32_t x = x0; x <= x1; ++x) cells[size_t(y) * nx_ + x].push_back(t);
      }
    }
    start_.assign(cells.size() + 1, 0);
    for (size_t i = 0; i < cells.size(); ++i) start_[i + 1] = start_[i] + uint32_t(cells[i].size());
    tris_.reserve(start_.back());
    for (const auto& c : cells) tris_.insert(tris_.end(), c.begin(), c.end());
  }

  // The triangle (local ids) containing p and its barycentric weights, clamped to the triangle.
  // `hint` is a triangle to try first, updated to the result.
  void locate(const glm::dvec2& p, uint32_t& hint, std::array<uint32_t, 3>& tri, glm::dvec3& bary) const {
    double best = -1e300;
    uint32_t bestTri = 0;
    glm::dvec3 bestBary(1.0, 0.0, 0.0);
    auto test = [&](uint32_t t) {
      const glm::dvec3 b = barycentric(t, p);
      const double m = std::min(b.x, std::min(b.y, b.z));
      if (m > best) best = m, bestTri = t, bestBary = b;
    };
    if (hint < triangles_.size() && valid_[hint]) test(hint);
    constexpr double kInside = -1e-12;
    if (best < kInside) {
      const auto [cx, cy] = cellOf(p);
      // note: a point of the domain lies in a triangle listed in its own cell; the rings catch
      // points outside the polygon (a rounding error, or a sample the unfolding slides past
      // the border). Those take the best of the two rings past the first that lists a triangle:
      // a cell farther out is farther from the point than the triangle found, and searching on
      // to the grid's edge made every such point cost the whole patch.
      uint32_t lastRing = std::max(nx_, ny_);
      bool listed = false;  // some ring so far lists a triangle
      for (uint32_t ring = 0; ring <= lastRing && best < kInside; ++ring) {
        const int64_t x0 = int64_t(cx) - ring, x1 = int64_t(cx) + ring;
        const int64_t y0 = int64_t(cy) - ring, y1 = int64_t(cy) + ring;
        auto cell = [&](int64_t x, int64_t y) {
          if (x < 0 || x >= int64_t(nx_)) return;
          const size_t c = size_t(y) * nx_ + size_t(x);
          for (uint32_t k = start_[c]; k < start_[c + 1]; ++k) test(tris_[k]);
          if (start_[c + 1] > start_[c] && !listed) listed = true, lastRing = ring + 2;
        };
        // The ring's cells only: whole rows at its top and bottom, its two ends between.
        for (int64_t y = std::max<int64_t>(y0, 0); y <= std::min<int64_t>(y1, ny_ - 1); ++y) {
          if (y == y0 || y == y1) {
            for (int64_t x = std::max<int64_t>(x0, 0); x <= std::min<int64_t>(x1, nx_ - 1); ++x) cell(x, y);
          } else {
            cell(x0, y);
            cell(x1, y);
          }
        }
        if (ring >= 1 && best > -1e-6) break;  // near the border: the closest is good enough
      }
    }
    hint = bestTri;
    tri = triangles_[bestTri];
    bary = glm::max(bestBary, glm::dvec3(0.0));
    bary /= bary.x + bary.y + bary.z;
  }

 private:
  std::pair<uint32_t, uint32_t> cellOf(const glm::dvec2& p) const {
    const double fx = std::floor((p.x - lo_.x) / cell_), fy = std::floor((p.y - lo_.y) / cell_);
    return {uint32_t(std::clamp(fx, 0.0, double(nx_ - 1))), uint32_t(std::clamp(fy, 0.0, double(ny_ - 1)))};
  }
  glm::dvec3 barycentric(uint32_t t, const glm::dvec2& p) const {
    const auto& tri = triangles_[t];
    const glm::dvec2 a = uv_[tri[0]], b = uv_[tri[1]], c = uv_[tri[2]];
    const double d = (b.x - a.x) * (c.y - a.y) - (c.x - a.x) * (b.y - a.y);
    const double la = ((b.x - p.x) * (c.y - p.y) - (c.x - p.x) * (b.y - p.y)) / d;
    const double lb = ((c.x - p.x) * (a.y - p.y) - (a.x - p.x) * (c.y - p.y)) / d;
    return {la, lb, 1.0 - la - lb};
  }

  const std::vector<glm::dvec2>& uv_;
  const std::vector<std::array<uint32_t, 3>>& triangles_;
  glm::dvec2 lo_{0.0};
  double cell_ = 1.0;
  uint32_t nx_ = 1, ny_ = 1;
  std::vector<uint8_t> valid_;  // positive parameter area
  std::vector<uint32_t> start_;
  std::vector<uint32_t> tris_;
};

// How one patch is cut into quads (see QuadLayout): per quad, where each edge's samples come from.
// A side run is m + 1 samples of side `index` from sample `offset` in the patch's direction; a
// spoke runs from its target on the border to the centre.
struct EdgeSource {
  bool spoke = false;
  uint32_t index = 0;
  uint32_t offset = 0;
};
// Samples of a whole patch side: kites halve it (2m + 1), sides take it whole (m + 1).
uint32_t sideSampleCount(uint32_t m, QuadLayout mode) { return mode == QuadLayout::kKites ? 2 * m + 1 : m + 1; }

struct PatchQuads {
  uint32_t sideSamples = 0;                      // sideSampleCount
  bool single = false;                           // one quad, all four edges sides (a 4-sided patch, sides layout)
  std::vector<std::array<EdgeSource, 4>> quads;  // by Edge
  std::vector<EdgeSource> spokeTargets;          // the border sample each spoke starts at
};

PatchQuads patchQuads(uint32_t n, uint32_t m, QuadLayout mode) {
  PatchQuads pq;
  const uint32_t count = patchQuadCount(n, mode);
  pq.sideSamples = sideSampleCount(m, mode);
  pq.quads.resize(count);
  auto side = [](uint32_t i, uint32_t offset) { return EdgeSource{false, i, offset}; };
  auto spoke = [](uint32_t k) { return EdgeSource{true, k, 0}; };
  if (mode == QuadLayout::kKites) {
    for (uint32_t j = 0; j < n; ++j) {
      pq.spokeTargets.push_back(side(j, m));
      pq.quads[j] = {side(j, 0), spoke(j), spoke((j + n - 1) % n), side((j + n - 1) % n, m)};
    }
  } else if (n == 4) {
    pq.single = true;
    pq.quads[0] = {side(0, 0), side(1, 0), side(2, 0), side(3, 0)};
  } else {
    for (uint32_t j = 0; j < count; ++j) {
      pq.spokeTargets.push_back(side(2 * j, 0));
      pq.quads[j] = {side(2 * j + 1, 0), spoke((j + 1) % count), spoke(j), side(2 * j, 0)};
    }
  }
  return pq;
}

// For each patch side: -1 if it has no neighbour, else whether its vertex run is the reverse of
// the neighbour's. Validates the links.
struct SideLinks {
  std::vector<uint32_t> offsets;               // first chart of each patch
  std::vector<std::vector<uint8_t>> opposite;  // [patch][side]: runs opposite to the neighbour
};

SideLinks validateLinks(const PatchLayout& layout, QuadLayout mode, const char* fn) {
  auto fail = [&](uint32_t p, uint32_t i, const std::string& what) {
    throw std::invalid_argument(std::string(fn) + ": patch " + std::to_string(p) + " side " + std::to_string(i) + ": " +
                                what);
  };
  SideLinks links;
  try {
    links.offsets = quadChartOffsets(layout, mode);
  } catch (const std::invalid_argument& e) {
    throw std::invalid_argument(std::string(fn) + ": " + e.what());
  }
  links.opposite.resize(layout.patches.size());
  for (uint32_t p = 0; p < layout.patches.size(); ++p) {
    const Patch& patch = layout.patches[p];
    links.opposite[p].assign(patch.sides.size(), 1);
    for (uint32_t i = 0; i < patch.sides.size(); ++i) {
      const PatchSide& s = patch.sides[i];
      if (s.neighbourPatch < 0) continue;
      const uint32_t q = uint32_t(s.neighbourPatch);
      if (q >= layout.patches.size() || s.neighbourSide >= layout.patches[q].sides.size()) {
        fail(p, i, "neighbour out of range");
      }
      if (q == p && s.neighbourSide == i) fail(p, i, "is its own neighbour");
      const PatchSide& o = layout.patches[q].sides[s.neighbourSide];
      if (o.neighbourPatch != int32_t(p) || o.neighbourSide != i) {
        fail(p, i, "link is not reciprocal");
      }
      if (o.reversed != s.reversed) fail(p, i, "reversed flags differ across the side");
      const bool same = o.vertices == s.vertices;
      const bool rev = std::equal(o.vertices.begin(), o.vertices.end(), s.vertices.rbegin(), s.vertices.rend()) &&
                       o.vertices.size() == s.vertices.size();
      if (s.reversed ? !rev : !same) fail(p, i, "vertex run does not match the neighbour's");
      links.opposite[p][i] = s.reversed ? 1 : 0;
    }
  }
  return links;
}

std::vector<std::array<RootNeighbour, 4>> neighboursFrom(const PatchLayout& layout, const SideLinks& links,
                                                         QuadLayout mode) {
  const uint32_t m = 2;  // any: only the runs' relative offsets matter here
  std::vector<PatchQuads> plans;
  plans.reserve(layout.patches.size());
  size_t total = 0;
  for (const Patch& patch : layout.patches) {
    plans.push_back(patchQuads(uint32_t(patch.sides.size()), m, mode));
    total += plans.back().quads.size();
  }
  // The chart edge holding each run of a side: [patch][side] -> (offset, chart, edge).
  struct Run {
    uint32_t offset, chart;
    uint8_t edge;
  };
  std::vector<std::vector<std::vector<Run>>> runs(layout.patches.size());
  for (uint32_t p = 0; p < layout.patches.size(); ++p) {
    runs[p].resize(layout.patches[p].sides.size());
    for (uint32_t j = 0; j < plans[p].quads.size(); ++j) {
      for (uint8_t e = 0; e < 4; ++e) {
        const EdgeSource& src = plans[p].quads[j][e];
        if (!src.spoke) runs[p][src.index].push_back({src.offset, links.offsets[p] + j, e});
      }
    }
  }
  std::vector<std::array<RootNeighbour, 4>> out(total);
  for (uint32_t p = 0; p < layout.patches.size(); ++p) {
    const PatchQuads& pq = plans[p];
    const uint32_t count = uint32_t(pq.quads.size());
    for (uint32_t j = 0; j < count; ++j) {
      auto& nb = out[links.offsets[p] + j];
      for (uint8_t e = 0; e < 4; ++e) {
        const EdgeSource& src = pq.quads[j][e];
        if (src.spoke) {
          // The right edge's spoke is the top edge's of the next quad.
          nb[e] = e == kEdgeRight
                      ? RootNeighbour{int32_t(links.offsets[p] + (j + 1) % count), kEdgeTop, true}
                      : RootNeighbour{int32_t(links.offsets[p] + (j + count - 1) % count), kEdgeRight, true};
          continue;
        }
        const PatchSide& side = layout.patches[p].sides[src.index];
        if (side.neighbourPatch < 0) continue;
        const uint32_t q = uint32_t(side.neighbourPatch);
        const uint32_t offset = side.reversed ? plans[q].sideSamples - 1 - (src.offset + m) : src.offset;
        for (const Run& r : runs[q][side.neighbourSide]) {
          if (r.offset == offset) nb[e] = RootNeighbour{int32_t(r.chart), r.edge, side.reversed};
        }
      }
    }
  }
  return out;
}

}  // namespace

std::vector<uint32_t> quadChartOffsets(const PatchLayout& layout, QuadLayout quads) {
  std::vector<uint32_t> offsets(layout.patches.size());
  uint32_t next = 0;
  for (size_t p = 0; p < layout.patches.size(); ++p) {
    offsets[p] = next;
    next += patchQuadCount(uint32_t(layout.patches[p].sides.size()), quads);
  }
  return offsets;
}

std::vector<std::array<RootNeighbour, 4>> quadNeighbours(const PatchLayout& layout, QuadLayout quads) {
  return neighboursFrom(layout, validateLinks(layout, quads, "quadNeighbours"), quads);
}

ImageQuality measureImage(const std::vector<glm::vec3>& positions, const std::vector<glm::vec3>& normals,
                          uint32_t chartSize, std::vector<uint32_t>* flippedAt,
                          const std::vector<glm::vec3>* faceNormals) {
  ImageQuality q;
  const uint32_t m = chartSize - 1;
  const double scale = double(m);  // d(position)/d(s) = difference * m
  double l2sum = 0.0, gammaMax = 0.0;
  // Sander et al.: L2 weighted by 3D area, normalized by sqrt(area3D / parameter area).
  auto triangle = [&](const glm::dvec3& ss, const glm::dvec3& st) {
    const double a = glm::dot(ss, ss), b = glm::dot(ss, st), c = glm::dot(st, st);
    const double area = 0.5 * glm::length(glm::cross(ss, st)) / (scale * scale);
    q.area3D += area;
    l2sum += area * 0.5 * (a + c);
    gammaMax = std::max(gammaMax, 0.5 * ((a + c) + std::sqrt((a - c) * (a - c) + 4.0 * b * b)));
  };
  for (uint32_t v = 0; v < m; ++v) {
    for (uint32_t u = 0; u < m; ++u) {
      const size_t i00 = size_t(v) * chartSize + u, i10 = i00 + 1, i01 = i00 + chartSize, i11 = i01 + 1;
      const glm::dvec3 p00(positions[i00]), p10(positions[i10]), p01(positions[i01]), p11(positions[i11]);
      // Triangles (00, 10, 11) and (00, 11, 01), each of parameter area 1 / (2 m^2).
      q.shortestTexelSide = std::min({q.shortestTexelSide, glm::length(p10 - p00), glm::length(p01 - p00)});
      triangle((p10 - p00) * scale, (p11 - p10) * scale);
      triangle((p11 - p01) * scale, (p01 - p00) * scale);
      const glm::dvec3 d1 = p11 - p00, d2 = p01 - p10;
      const glm::dvec3 cr = glm::cross(d1, d2);
      const double cl = glm::length(cr);
      if (!(cl > 1e-8 * (glm::dot(d1, d1) + glm::dot(d2, d2)))) {
        ++q.degenerateTexels;
        continue;
      }
      const glm::dvec3 n =
          glm::dvec3(normals[i00]) + glm::dvec3(normals[i10]) + glm::dvec3(normals[i01]) + glm::dvec3(normals[i11]);
      const bool againstNormals = glm::dot(cr, n) < 0.0;
      bool againstFaces = againstNormals;
      if (faceNormals) {
        // Flipped: facing away from every input face under its corners. A texel that agrees
        // with one of them follows the input, where the input itself folds or turns by more
        // than a right angle within the texel (a fin of a scan), which no flat texel can follow
        // both ways.
        bool any = false, agrees = false;
        for (const size_t k : {i00, i10, i01, i11}) {
          const glm::dvec3 fn((*faceNormals)[k]);
          if (glm::dot(fn, fn) == 0.0) continue;
          any = true;
          agrees = agrees || glm::dot(cr, fn) >= 0.0;
        }
        if (any) againstFaces = !agrees;
      }
      q.texelsAgainstNormals += againstNormals;
      if (againstFaces) {
        ++q.flippedTexels;
        if (flippedAt) flippedAt->push_back(uint32_t(i00));
      }
    }
  }
  if (m > 0 && q.area3D > 0.0) {
    const double s = std::sqrt(q.area3D);  // parameter area is 1
    q.stretchL2 = std::sqrt(l2sum / q.area3D) / s;
    q.stretchLinf = std::sqrt(gammaMax) / s;
  }
  return q;
}

ImageQuality combineImageQuality(const std::vector<ImageQuality>& parts) {
  return combineStretch(parts, [](ImageQuality& q, const ImageQuality& p) {
    q.flippedTexels += p.flippedTexels;
    q.texelsAgainstNormals += p.texelsAgainstNormals;
    q.degenerateTexels += p.degenerateTexels;
    q.texelsUnfolded += p.texelsUnfolded;
    q.samplesPastQuad += p.samplesPastQuad;
    q.shortestTexelSide = std::min(q.shortestTexelSide, p.shortestTexelSide);
    if (p.sampleError > q.sampleError) q.sampleError = p.sampleError, q.sampleErrorVertex = p.sampleErrorVertex;
  });
}

std::vector<uint8_t> patchesOverSampleError(const GeometryImageSet& set, size_t patches, double maxError) {
  std::vector<uint8_t> over(patches, 0);
  for (const GeometryImage& g : set.charts) over[g.patch] |= g.quality.sampleError > maxError;
  return over;
}

namespace {

// The domain corners of a quad chart: (0,0) a, (1,0) b, (1,1) c, (0,1) e.
using QuadCorners = std::array<glm::dvec2, 4>;

// The quad of a patch's parameterization holding domain point d, and d's coordinates (s, t) in
// it: the inverse of the bilinear map of its corners, by Newton's method (the quads are convex, so
// it converges from the middle), clamped to the unit square. Quads round the centre lie between
// the spokes to their corners e and b.
struct QuadPoint {
  uint32_t quad = 0;
  glm::dvec2 st{0.0};
};
QuadPoint quadOf(const std::vector<QuadCorners>& quads, const glm::dvec2& d) {
  constexpr double kTwoPi = 6.283185307179586;
  auto angle = [](const glm::dvec2& x) { return pmath::atan2(x.y, x.x); };
  auto ccw = [&](double from, double to) {  // angle from `from` to `to`, counter-clockwise, in [0, 2pi)
    double a = to - from;
    while (a < 0.0) a += kTwoPi;
    while (a >= kTwoPi) a -= kTwoPi;
    return a;
  };
  QuadPoint out;
  if (quads.size() > 1) {
    const double ad = angle(d);
    for (uint32_t i = 0; i < quads.size(); ++i) {
      const double a0 = angle(quads[i][3]);
      if (ccw(a0, ad) <= ccw(a0, angle(quads[i][1]))) {
        out.quad = i;
        break;
      }
    }
  }
  const auto& [a, b, c, e] = quads[out.quad];
  glm::dvec2 st(0.5);
  for (int it = 0; it < 20; ++it) {
    const double s = st.x, t = st.y;
    const glm::dvec2 f = (1 - s) * (1 - t) * a + s * (1 - t) * b + s * t * c + (1 - s) * t * e - d;
    const glm::dvec2 ds = (1 - t) * (b - a) + t * (c - e), dt = (1 - s) * (e - a) + s * (c - b);
    const double det = ds.x * dt.y - ds.y * dt.x;
    if (!(std::abs(det) > 1e-300)) break;
    const glm::dvec2 step((f.x * dt.y - f.y * dt.x) / det, (ds.x * f.y - ds.y * f.x) / det);
    st -= step;
    if (glm::dot(step, step) < 1e-28) break;
  }
  out.st = glm::clamp(st, glm::dvec2(0.0), glm::dvec2(1.0));
  return out;
}

// A quad chart's least-stretch map (QuadMap::kStretch): the patch's triangles clipped to the quad,
// as a mesh with a position in the unit square and one in the patch's domain per vertex.
struct QuadWarp {
  std::vector<glm::dvec2> square;
  std::vector<glm::dvec2> domain;
  std::vector<std::array<uint32_t, 3>> triangles;
  std::vector<uint32_t> ofPatchVertex;  // per patch-local vertex: its warp vertex, ~0u if outside
};

// Builds quad q's warp from the patch's parameterization pp (surface points xyz per local vertex,
// surfaceAt giving the surface point at a domain point). The quad is convex with its two border
// edges on the patch's polygon, so clipping the patch's triangles against the half-planes of its
// two spokes (edges b -> c and c -> e) gives it exactly. A vertex is shared between the pieces of
// neighbouring triangles by its origin: a patch vertex, a patch edge crossing a spoke, or the
// centre. Returns false (and the bilinear map stays) when the clip or the map is degenerate.
template <typename SurfaceAt>
bool buildQuadWarp(const PatchParameterization& pp, const std::vector<glm::dvec3>& xyz, const QuadCorners& q,
                   const ParamOptions& options, SurfaceAt surfaceAt, QuadWarp& w) {
  // note: named references, not a structured binding, since the lambdas below use them (clang
  // before 16 cannot capture structured bindings).
  const glm::dvec2 &qa = q[0], &qb = q[1], &qc = q[2], &qe = q[3];
  const std::array<glm::dvec2, 2> from{qb, qc}, to{qc, qe};
  const double scale =
      std::max({glm::length(qb - qa), glm::length(qc - qb), glm::length(qe - qc), glm::length(qa - qe)});
  const double eps = 1e-10 * scale;
  auto side = [&](int l, const glm::dvec2& p) {  // signed distance, > 0 inside; snapped to 0 near the line
    const glm::dvec2 d = to[l] - from[l];
    const double s = (d.x * (p.y - from[l].y) - d.y * (p.x - from[l].x)) / glm::length(d);
    return std::abs(s) < eps ? 0.0 : s;
  };
  w = QuadWarp{};
  w.ofPatchVertex.assign(pp.uv.size(), ~0u);
  std::array<std::unordered_map<uint64_t, uint32_t>, 2> crossings;
  uint32_t centre = ~0u;
  std::vector<glm::dvec3> wxyz;
  auto addVertex = [&](const glm::dvec2& d, const glm::dvec3& x) {
    w.domain.push_back(d);
    wxyz.push_back(x);
    return uint32_t(w.domain.size() - 1);
  };
  // A point of a clipped piece: its warp vertex, domain point, and the support of the edge to
  // the next point (a patch edge a < b, or spoke line `line` when b == ~0u).
  struct Point {
    uint32_t id;
    glm::dvec2 d;
    uint32_t a, b;
  };
  auto patchVertex = [&](uint32_t v) {
    if (w.ofPatchVertex[v] == ~0u) w.ofPatchVertex[v] = addVertex(pp.uv[v], xyz[v]);
    return w.ofPatchVertex[v];
  };
  auto crossing = [&](int l, const Point& p, const Point& nextPoint) -> Point {
    if (p.b == ~0u) {  // along the other spoke: the centre
      if (centre == ~0u) centre = addVertex(qc, surfaceAt(qc));
      return {centre, qc, 0, 0};
    }
    const uint32_t a = std::min(p.a, p.b), b = std::max(p.a, p.b);
    const uint64_t key = (uint64_t{a} << 32) | b;
    auto [it, fresh] = crossings[l].try_emplace(key, 0u);
    if (fresh) {
      const double sa = side(l, pp.uv[a]), sb = side(l, pp.uv[b]);
      glm::dvec2 d;
      glm::dvec3 x;
      if (sa != sb) {
        const double t = sa / (sa - sb);
        d = pp.uv[a] + (pp.uv[b] - pp.uv[a]) * t;
        x = xyz[a] + (xyz[b] - xyz[a]) * t;
      } else {  // only a rounding error can get here
        const double sp = side(l, p.d), sn = side(l, nextPoint.d);
        d = p.d + (nextPoint.d - p.d) * (sp / (sp - sn));
        x = surfaceAt(d);
      }
      it->second = addVertex(d, x);
    }
    return {it->second, w.domain[it->second], 0, 0};
  };
  const glm::dvec2 lo = glm::min(glm::min(qa, qb), glm::min(qc, qe)) - glm::dvec2(eps);
  const glm::dvec2 hi = glm::max(glm::max(qa, qb), glm::max(qc, qe)) + glm::dvec2(eps);
  std::vector<Point> poly, next;
  for (const auto& t : pp.triangles) {
    const glm::dvec2 tlo = glm::min(pp.uv[t[0]], glm::min(pp.uv[t[1]], pp.uv[t[2]]));
    const glm::dvec2 thi = glm::max(pp.uv[t[0]], glm::max(pp.uv[t[1]], pp.uv[t[2]]));
    if (thi.x < lo.x || thi.y < lo.y || tlo.x > hi.x || tlo.y > hi.y) continue;
    bool outside = false;
    for (int l = 0; l < 2 && !outside; ++l) {
      outside = side(l, pp.uv[t[0]]) < 0.0 && side(l, pp.uv[t[1]]) < 0.0 && side(l, pp.uv[t[2]]) < 0.0;
    }
    if (outside) continue;
    poly.clear();
    for (int c = 0; c < 3; ++c) poly.push_back({~0u, pp.uv[t[c]], t[c], t[(c + 1) % 3]});
    for (int l = 0; l < 2 && poly.size() >= 3; ++l) {
      next.clear();
      for (size_t i = 0; i < poly.size(); ++i) {
        const Point& p = poly[i];
        const Point& r = poly[(i + 1) % poly.size()];
        const double sp = side(l, p.d), sr = side(l, r.d);
        if (sp >= 0.0) {
          Point keep = p;
          if (sp == 0.0 && sr < 0.0) keep.a = uint32_t(l), keep.b = ~0u;  // leaves along the spoke
          next.push_back(keep);
        }
        if ((sp > 0.0 && sr < 0.0) || (sp < 0.0 && sr > 0.0)) {
          Point x = crossing(l, p, r);
          if (sp > 0.0) {
            x.a = uint32_t(l), x.b = ~0u;  // leaving: on along the spoke
          } else {
            x.a = p.a, x.b = p.b;  // entering: on along the edge
          }
          next.push_back(x);
        }
      }
      poly.swap(next);
    }
    if (poly.size() < 3) continue;
    // Patch vertices get their warp vertex only now that they are known to be in the quad.
    std::vector<uint32_t> ids;
    for (const Point& p : poly) {
      uint32_t id = p.id;
      if (id == ~0u) {
        for (int c = 0; c < 3; ++c) {
          if (p.d == pp.uv[t[c]]) id = patchVertex(t[c]);
        }
      }
      if (id == ~0u) return false;
      if (ids.empty() || (ids.back() != id && ids.front() != id)) ids.push_back(id);
    }
    // A convex piece, fanned; slivers of no area (a spoke through a vertex) are left out.
    for (size_t i = 1; i + 1 < ids.size(); ++i) {
      const glm::dvec2 a = w.domain[ids[0]], b = w.domain[ids[i]], c = w.domain[ids[i + 1]];
      const double twice = (b.x - a.x) * (c.y - a.y) - (c.x - a.x) * (b.y - a.y);
      if (twice > eps * scale) w.triangles.push_back({ids[0], ids[i], ids[i + 1]});
    }
  }
  if (w.triangles.empty()) return false;
  // The border: vertices on an edge used once, placed on the square's edge where the bilinear
  // map puts them (each quad edge is straight and evenly parameterized in the domain).
  std::unordered_map<uint64_t, int> edgeUses;
  for (const auto& t : w.triangles) {
    for (int c = 0; c < 3; ++c) {
      const uint32_t a = std::min(t[c], t[(c + 1) % 3]), b = std::max(t[c], t[(c + 1) % 3]);
      ++edgeUses[(uint64_t{a} << 32) | b];
    }
  }
  const size_t nv = w.domain.size();
  std::vector<uint8_t> fixed(nv, 0);
  w.square.assign(nv, glm::dvec2(0.5));
  const std::array<glm::dvec2, 4> dom{qa, qb, qc, qe};
  const std::array<glm::dvec2, 4> sq{glm::dvec2(0, 0), glm::dvec2(1, 0), glm::dvec2(1, 1), glm::dvec2(0, 1)};
  for (const auto& [key, uses] : edgeUses) {
    if (uses != 1) continue;
    for (const uint32_t v : {uint32_t(key >> 32), uint32_t(key & 0xffffffffu)}) {
      if (fixed[v]) continue;
      double best = 1e300;
      glm::dvec2 at(0.5);
      for (int e = 0; e < 4; ++e) {
        const glm::dvec2 a = dom[e], b = dom[(e + 1) % 4];
        const double t = std::clamp(glm::dot(w.domain[v] - a, b - a) / glm::dot(b - a, b - a), 0.0, 1.0);
        const double dist = glm::length(a + (b - a) * t - w.domain[v]);
        if (dist < best) best = dist, at = sq[e] + (sq[(e + 1) % 4] - sq[e]) * t;
      }
      // note: an edge used once off the quad's border (a sliver left out) leaves its vertices free.
      if (best < 1e-6 * scale) fixed[v] = 1, w.square[v] = at;
    }
  }
  try {
    const ParamQuality quality = mapDiskOntoDomain(wxyz, w.triangles, fixed, options, w.square);
    return quality.flippedTriangles == 0;
  } catch (const std::invalid_argument&) {
    return false;
  }
}

// The unfolding of flipped texels (resampleLayout): sweeps at most, how far a sample may slide
// (in texels of the map), the cosine between a texel's normal and its input faces that it is
// pushed to reach, and how far from its neighbours a sample may end (times the farthest of them
// as mapped). Without that last bound a sample in a squeezed fold can slide across it, far from
// its neighbours in 3D: a texel across the fold, and a coarse node's error (the distance from the
// fine samples to its grid) of tens of pixels on the turbine blade.
constexpr uint32_t kUnfoldSweeps = 24;
constexpr double kUnfoldReach = 1.0;
constexpr double kUnfoldMargin = 0.1;
constexpr double kUnfoldLength = 1.5;

// The point of triangle abc closest to p (Ericson, Real-Time Collision Detection, 5.1.5).
glm::dvec3 closestOnTriangle(const glm::dvec3& p, const glm::dvec3& a, const glm::dvec3& b, const glm::dvec3& c) {
  const glm::dvec3 ab = b - a, ac = c - a, ap = p - a;
  const double d1 = glm::dot(ab, ap), d2 = glm::dot(ac, ap);
  if (d1 <= 0.0 && d2 <= 0.0) return a;
  const glm::dvec3 bp = p - b;
  const double d3 = glm::dot(ab, bp), d4 = glm::dot(ac, bp);
  if (d3 >= 0.0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) return a + ab * (d1 / (d1 - d3));
  const glm::dvec3 cp = p - c;
  const double d5 = glm::dot(ab, cp), d6 = glm::dot(ac, cp);
  if (d6 >= 0.0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) return a + ac * (d2 / (d2 - d6));
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0) return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
  const double denom = va + vb + vc;
  if (!(std::abs(denom) > 0.0)) return a;  // degenerate: any vertex
  return a + ab * (vb / denom) + ac * (vc / denom);
}

// The distance from x to a chart's surface, as the renderer triangulates it (each texel split along
// its (0,0)-(1,1) diagonal), near chart coordinates st in the unit square: the nearest of the
// triangles of the texel holding st and of the texels up to `reach` round it. Where the parameterization
// shifts x along the surface by less than a texel this is its distance across the surface.
double chartSurfaceDistance(const std::vector<glm::vec3>& positions, uint32_t size, const glm::dvec2& st,
                            const glm::dvec3& x, int64_t reach) {
  const int64_t m = int64_t(size) - 1;
  const int64_t ix = std::min<int64_t>(int64_t(st.x * double(m)), m - 1);
  const int64_t iy = std::min<int64_t>(int64_t(st.y * double(m)), m - 1);
  auto at = [&](int64_t u, int64_t v) { return glm::dvec3(positions[size_t(v) * size + size_t(u)]); };
  double best = std::numeric_limits<double>::infinity();
  for (int64_t v = std::max<int64_t>(iy - reach, 0); v <= std::min<int64_t>(iy + reach, m - 1); ++v) {
    for (int64_t u = std::max<int64_t>(ix - reach, 0); u <= std::min<int64_t>(ix + reach, m - 1); ++u) {
      const glm::dvec3 p00 = at(u, v), p10 = at(u + 1, v), p01 = at(u, v + 1), p11 = at(u + 1, v + 1);
      best = std::min({best, glm::length(x - closestOnTriangle(x, p00, p10, p11)),
                       glm::length(x - closestOnTriangle(x, p00, p11, p01))});
    }
  }
  return best;
}

// Whether side i of patch `patch`, at index p, is sampled in its own direction (it owns the
// side): open sides, and shared sides whose (patch, side) is the smaller of the two.
bool ownsSide(const Patch& patch, uint32_t p, uint32_t i) {
  const PatchSide& s = patch.sides[i];
  return s.neighbourPatch < 0 || p < uint32_t(s.neighbourPatch) ||
         (p == uint32_t(s.neighbourPatch) && i < s.neighbourSide);
}

}  // namespace

bool patchSamplesAlike(const Patch& x, const Patch& y, uint32_t p) {
  if (x.sides.size() != y.sides.size() || x.triangles != y.triangles) return false;
  for (uint32_t i = 0; i < x.sides.size(); ++i) {
    const PatchSide& s = x.sides[i];
    const PatchSide& t = y.sides[i];
    if (s.vertices != t.vertices || (s.neighbourPatch < 0) != (t.neighbourPatch < 0) ||
        (s.neighbourPatch >= 0 && s.reversed != t.reversed) || ownsSide(x, p, i) != ownsSide(y, p, i)) {
      return false;
    }
  }
  return true;
}

namespace {

// Throws std::invalid_argument where resampleLayout's input is malformed (the side links are
// checked by validateLinks).
void checkResampleInput(const PatchLayout& layout, const ResampleOptions& options, const ResampleReuse& reuse) {
  const uint32_t size = options.chartSize;
  if (!isChartSizeValid(size)) {
    throw std::invalid_argument("resampleLayout: chart size " + std::to_string(size) + " is not 2^k + 1");
  }
  if (!layout.colours.empty() && layout.colours.size() != layout.positions.size()) {
    throw std::invalid_argument("resampleLayout: colours must be empty or one per position");
  }
  if (reuse.only && reuse.only->size() != layout.patches.size()) {
    throw std::invalid_argument("resampleLayout: the patch selection must have one flag per patch");
  }
  if (reuse.normals && reuse.normals->size() != layout.positions.size()) {
    throw std::invalid_argument("resampleLayout: the vertex normals must be one per position");
  }
}

// What each patch does: 0 skip (not selected), 1 resample, 2 + k take from source k.
std::vector<uint32_t> patchActions(const PatchLayout& layout, const ResampleOptions& options,
                                   const ResampleReuse& reuse) {
  const uint32_t size = options.chartSize;
  std::vector<uint32_t> action(layout.patches.size(), 1);
  for (uint32_t p = 0; p < layout.patches.size(); ++p) {
    if (reuse.only && !(*reuse.only)[p]) {
      action[p] = 0;
      continue;
    }
    for (size_t k = 0; k < reuse.earlier.size(); ++k) {
      const ResampleReuse::Source& src = reuse.earlier[k];
      if (!src.patches || !src.set || p >= src.patches->size() ||
          !patchSamplesAlike((*src.patches)[p], layout.patches[p], p)) {
        continue;
      }
      if (p >= src.set->patches.size()) continue;
      const PatchResampleStats& st = src.set->patches[p];
      if (st.sides != layout.patches[p].sides.size() || st.quads != patchQuadCount(st.sides, options.quads) ||
          st.firstChart + st.quads > src.set->charts.size() || !src.set->charts[st.firstChart].hasSamples(size)) {
        continue;
      }
      action[p] = 2 + uint32_t(k);
      break;
    }
  }
  return action;
}

// Canonical owner of each side: the (patch, side) with the smaller ids; sampled in its order.
struct SideRef {
  uint32_t patch, side;
};
struct SideOwners {
  std::vector<SideRef> owners;
  std::vector<uint8_t> ownerNeeded;              // some patch that resamples holds it
  std::vector<std::vector<uint32_t>> sideIndex;  // [patch][side]: its owner, an index into owners
};

// Finds the owner of every patch side, and which owners the patches that resample (action 1)
// need. Throws std::invalid_argument on a side with a vertex out of range or fewer than 2.
SideOwners sideOwners(const PatchLayout& layout, const std::vector<uint32_t>& action) {
  SideOwners so;
  std::vector<SideRef>& owners = so.owners;
  std::vector<uint8_t>& ownerNeeded = so.ownerNeeded;
  std::vector<std::vector<uint32_t>>& sideIndex = so.sideIndex;
  sideIndex.resize(layout.patches.size());
  for (uint32_t p = 0; p < layout.patches.size(); ++p) {
    const Patch& patch = layout.patches[p];
    sideIndex[p].resize(patch.sides.size());
    for (uint32_t i = 0; i < patch.sides.size(); ++i) {
      for (uint32_t v : patch.sides[i].vertices) {
        if (v >= layout.positions.size()) {
          throw std::invalid_argument("resampleLayout: patch " + std::to_string(p) + " side " + std::to_string(i) +
                                      ": vertex out of range");
        }
      }
      if (patch.sides[i].vertices.size() < 2) {
        throw std::invalid_argument("resampleLayout: patch " + std::to_string(p) + " side " + std::to_string(i) +
                                    " has < 2 vertices");
      }
      if (ownsSide(layout.patches[p], p, i)) {
        sideIndex[p][i] = uint32_t(owners.size());
        owners.push_back({p, i});
        ownerNeeded.push_back(0);
      }
    }
  }
  for (uint32_t p = 0; p < layout.patches.size(); ++p) {
    for (uint32_t i = 0; i < layout.patches[p].sides.size(); ++i) {
      const PatchSide& s = layout.patches[p].sides[i];
      if (!ownsSide(layout.patches[p], p, i)) sideIndex[p][i] = sideIndex[uint32_t(s.neighbourPatch)][s.neighbourSide];
      if (action[p] == 1) ownerNeeded[sideIndex[p][i]] = 1;
    }
  }
  return so;
}

// What the patches of one resampleLayout call share: its input, the samples of the patch sides
// (by owner), and the set the patches fill (each its own charts and stats).
struct ResampleContext {
  const PatchLayout& layout;
  const ResampleOptions& options;
  const ResampleReuse& reuse;
  const Surface& surface;
  const SideLinks& links;
  const SideOwners& owners;
  const std::vector<std::array<RootNeighbour, 4>>& neighbours;  // by chart
  const std::vector<std::vector<Sample>>& sides;                // by owner
  uint32_t size;                                                // options.chartSize
  uint32_t m;                                                   // size - 1
  uint32_t sideCount;                                           // samples of a whole patch side (sideSampleCount)
  GeometryImageSet& set;
};

// A patch not selected (action 0): its stats and charts get their ids and neighbours, no samples.
void keepUnsampled(const ResampleContext& c, uint32_t p, uint32_t n, uint32_t nq) {
  GeometryImageSet& set = c.set;
  const SideLinks& links = c.links;
  set.patches[p].firstChart = links.offsets[p];
  set.patches[p].sides = n;
  set.patches[p].quads = nq;
  for (uint32_t i = 0; i < nq; ++i) {
    set.charts[links.offsets[p] + i].patch = p;
    set.charts[links.offsets[p] + i].quad = i;
    set.charts[links.offsets[p] + i].neighbours = c.neighbours[links.offsets[p] + i];
  }
}

// A patch that samples as in earlier resampling `source` (action 2 + source): its stats and
// charts are moved from there, with their ids and neighbours set anew.
void takeEarlierCharts(const ResampleContext& c, uint32_t p, uint32_t source, uint32_t nq) {
  GeometryImageSet& set = c.set;
  const SideLinks& links = c.links;
  GeometryImageSet& src = *c.reuse.earlier[source].set;
  set.patches[p] = src.patches[p];
  const uint32_t first = src.patches[p].firstChart;
  set.patches[p].firstChart = links.offsets[p];
  for (uint32_t i = 0; i < nq; ++i) {
    GeometryImage& img = set.charts[links.offsets[p] + i];
    img = std::move(src.charts[first + i]);
    img.patch = p;
    img.neighbours = c.neighbours[links.offsets[p] + i];
  }
}

// The parameterization options of every patch: options.param, with paired sides for the sides
// layout.
ParamOptions patchParamOptions(const ResampleOptions& options) {
  ParamOptions paramOptions = options.param;
  paramOptions.pairedSides = options.quads == QuadLayout::kSides;
  return paramOptions;
}

// Patch p's parameterization: `cached` (what the reuse's cache held of a patch alike) where
// given, else made, and put there.
std::shared_ptr<const PatchParameterization> parameterization(const ResampleContext& c, uint32_t p,
                                                              std::shared_ptr<const PatchParameterization> cached) {
  if (cached) return cached;
  const Patch& patch = c.layout.patches[p];
  auto pp = std::make_shared<const PatchParameterization>(parameterizePatch(c.layout, p, patchParamOptions(c.options)));
  if (c.reuse.params) c.reuse.params->put(patch, p, pp);
  return pp;
}

// A patch being resampled (action 1): its parameterization, and what its quad charts share: the
// samples of its sides and spokes, its quads' domain corners and least-stretch maps, the faces
// along its sides and the input vertices each quad stands for. Built step by step by
// resamplePatch; sampleAt keeps one locator hint for the whole patch, so the order of the steps
// is part of the result.
struct PatchSampler {
  PatchSampler(const ResampleContext& context, uint32_t patchId, const PatchQuads& quads,
               std::shared_ptr<const PatchParameterization> cached)
      : c(context),
        p(patchId),
        patch(context.layout.patches[patchId]),
        n(uint32_t(patch.sides.size())),
        plan(quads),
        nq(uint32_t(quads.quads.size())),
        held(parameterization(context, patchId, std::move(cached))),
        pp(*held),
        openSides(n),
        locator(pp) {}
  PatchSampler(const PatchSampler&) = delete;
  PatchSampler& operator=(const PatchSampler&) = delete;

  const ResampleContext& c;
  const uint32_t p;
  const Patch& patch;
  const uint32_t n;  // sides
  const PatchQuads& plan;
  const uint32_t nq;  // quads
  const std::shared_ptr<const PatchParameterization> held;
  const PatchParameterization& pp;
  // Samples of the open sides taken through the parameterization (sampleOpenSides); empty for
  // others.
  std::vector<std::vector<Sample>> openSides;
  const Locator locator;
  uint32_t hint = 0;
  std::vector<std::vector<Sample>> spokes;  // by spoke, from its border sample to the centre
  std::vector<QuadCorners> quadCorners;     // by quad
  // Each quad's least-stretch map (QuadMap), made when first asked for (ensureWarp).
  std::vector<QuadWarp> warps;
  std::vector<uint8_t> warpTried, warped;
  std::vector<glm::dvec3> xyz;
  std::unordered_map<uint64_t, uint32_t> sideFace;                         // findSideFaces
  std::vector<std::vector<std::pair<uint32_t, glm::dvec2>>> quadVertices;  // placeVertices

  // Side sample k of side i in this patch's direction (0 = corner i, sideCount - 1 = corner i+1).
  const Sample& sideSample(uint32_t i, uint32_t k) const {
    const uint32_t sideCount = c.sideCount;
    const std::vector<std::vector<uint32_t>>& sideIndex = c.owners.sideIndex;
    const std::vector<SideRef>& owners = c.owners.owners;
    if (!openSides[i].empty()) return openSides[i][k];
    const std::vector<Sample>& s = c.sides[sideIndex[p][i]];
    const bool flipped = owners[sideIndex[p][i]].patch != p || owners[sideIndex[p][i]].side != i;
    return s[flipped && c.links.opposite[p][i] ? sideCount - 1 - k : k];
  }

  // The surface sample at domain point d.
  Sample sampleAt(const glm::dvec2& d) {
    std::array<uint32_t, 3> tri;
    glm::dvec3 b;
    locator.locate(d, hint, tri, b);
    Sample r = interpolate(c.surface, {pp.vertices[tri[0]], pp.vertices[tri[1]], pp.vertices[tri[2]]}, b);
    r.triangle = patch.triangles[hint];  // the parameterization keeps the patch's order
    return r;
  }

  // The domain point of sample k of side i (as the side's samples run along its polygon edge).
  glm::dvec2 sidePoint(uint32_t i, uint32_t k) const {
    const uint32_t sideCount = c.sideCount;
    const std::vector<glm::dvec2>& corner = pp.corners;
    const glm::dvec2 c0 = corner[i], c1 = corner[(i + 1) % n];
    if (k == 0) return c0;
    if (k + 1 == sideCount) return c1;
    if (2 * k + 1 == sideCount) return 0.5 * (c0 + c1);
    return c0 + (c1 - c0) * (double(k) / double(sideCount - 1));
  }

  // Open sides whose vertices slid in the parameterization are sampled through it, at even
  // steps along their polygon edge; their ends are the corner vertices themselves, as every
  // patch meeting there has them.
  void sampleOpenSides() {
    const uint32_t sideCount = c.sideCount;
    const std::vector<glm::dvec2>& corner = pp.corners;
    if (c.options.param.slideOpenSides) {
      for (uint32_t i = 0; i < n; ++i) {
        const PatchSide& side = patch.sides[i];
        if (side.neighbourPatch >= 0) continue;
        std::vector<Sample>& out = openSides[i];
        out.resize(sideCount);
        out.front() = vertexSample(c.surface, side.vertices.front());
        out.back() = vertexSample(c.surface, side.vertices.back());
        const glm::dvec2 c1 = corner[(i + 1) % n];
        for (uint32_t k = 1; k + 1 < sideCount; ++k) {
          out[k] = sampleAt(corner[i] + (c1 - corner[i]) * (double(k) / double(sideCount - 1)));
        }
      }
    }
  }

  // Spoke j: from its border sample (t = 0) to the centre (t = m), shared by the two quads
  // beside it.
  void sampleSpokes() {
    const uint32_t m = c.m;
    const glm::dvec2 centre(0.0);
    const size_t spokeCount = plan.spokeTargets.size();
    spokes.assign(spokeCount, std::vector<Sample>(m + 1));
    if (spokeCount > 0) {
      const Sample centreSample = sampleAt(centre);
      for (size_t j = 0; j < spokeCount; ++j) {
        const EdgeSource& target = plan.spokeTargets[j];
        const glm::dvec2 from = sidePoint(target.index, target.offset);
        spokes[j][0] = sideSample(target.index, target.offset);
        spokes[j][m] = centreSample;
        for (uint32_t t = 1; t < m; ++t) spokes[j][t] = sampleAt(from + (centre - from) * (double(t) / m));
      }
    }
  }

  // Each quad's domain corners.
  void placeQuads() {
    const uint32_t m = c.m;
    const glm::dvec2 centre(0.0);
    quadCorners.resize(nq);
    for (uint32_t j = 0; j < nq; ++j) {
      const auto& e = plan.quads[j];
      quadCorners[j] = {sidePoint(e[kEdgeBottom].index, e[kEdgeBottom].offset),
                        sidePoint(e[kEdgeBottom].index, e[kEdgeBottom].offset + m),
                        plan.single ? sidePoint(e[kEdgeTop].index, e[kEdgeTop].offset) : centre,
                        sidePoint(e[kEdgeLeft].index, e[kEdgeLeft].offset)};
    }
    warps.resize(nq);
    warpTried.assign(nq, 0);
    warped.assign(nq, 0);
  }

  // Whether quad j has its least-stretch map, making it on the first call.
  bool ensureWarp(uint32_t j) {
    const PatchLayout& layout = c.layout;
    if (plan.single || warpTried[j]) return bool(warped[j]);
    warpTried[j] = 1;
    if (xyz.empty()) {
      xyz.resize(pp.vertices.size());
      for (size_t v = 0; v < xyz.size(); ++v) xyz[v] = glm::dvec3(layout.positions[pp.vertices[v]]);
    }
    auto surfaceAt = [&](const glm::dvec2& d) {
      std::array<uint32_t, 3> tri;
      glm::dvec3 b;
      locator.locate(d, hint, tri, b);
      return b.x * xyz[tri[0]] + b.y * xyz[tri[1]] + b.z * xyz[tri[2]];
    };
    warped[j] = buildQuadWarp(pp, xyz, quadCorners[j], c.options.param, surfaceAt, warps[j]);
    return bool(warped[j]);
  }

  // The patch's triangle along each side segment: the input face a side sample lies on,
  // seen from this patch (for the flipped-texel test).
  void findSideFaces() {
    const PatchLayout& layout = c.layout;
    std::unordered_set<uint64_t> sideEdges;
    for (const PatchSide& side : patch.sides) {
      for (size_t k = 0; k + 1 < side.vertices.size(); ++k) {
        sideEdges.insert(undirectedKey(side.vertices[k], side.vertices[k + 1]));
      }
    }
    for (uint32_t t : patch.triangles) {
      const auto& tri = layout.triangles[t];
      for (int c = 0; c < 3; ++c) {
        const uint64_t key = undirectedKey(tri[c], tri[(c + 1) % 3]);
        if (sideEdges.contains(key)) sideFace.emplace(key, t);
      }
    }
  }

  // The unit normal of layout triangle t, or `otherwise` when t is ~0u or degenerate.
  glm::dvec3 faceNormalOr(uint32_t t, const glm::dvec3& otherwise) const {
    const PatchLayout& layout = c.layout;
    if (t == ~0u) return otherwise;
    const auto& tri = layout.triangles[t];
    const glm::dvec3 a(layout.positions[tri[0]]);
    const glm::dvec3 cr =
        glm::cross(glm::dvec3(layout.positions[tri[1]]) - a, glm::dvec3(layout.positions[tri[2]]) - a);
    const double l = glm::length(cr);
    return l > 0.0 && std::isfinite(l) ? cr / l : otherwise;
  }

  // The layout triangle sample s lies on: where it was located, or for a side sample the
  // patch's face along its side segment (~0u when none is known).
  uint32_t faceOf(const Sample& s) const {
    if (s.triangle != ~0u || s.edgeA == ~0u) return s.triangle;
    const auto it = sideFace.find(undirectedKey(s.edgeA, s.edgeB));
    return it == sideFace.end() ? ~0u : it->second;
  }

  // Every vertex of the patch but those of its shared sides, placed in its quad, for the
  // sampling error. (A vertex of a shared side lies on the side's polyline, which both patches
  // sample alike by arc length; the chart across covers it as much as this one, so neither
  // alone tells its distance to the atlas.)
  void placeVertices() {
    std::unordered_set<uint32_t> seamVertices;
    for (const PatchSide& side : patch.sides) {
      if (side.neighbourPatch >= 0) seamVertices.insert(side.vertices.begin(), side.vertices.end());
    }
    quadVertices.resize(nq);
    for (uint32_t v = 0; v < pp.vertices.size(); ++v) {
      if (seamVertices.contains(pp.vertices[v])) continue;
      const QuadPoint k = quadOf(quadCorners, pp.uv[v]);
      quadVertices[k.quad].push_back({v, k.st});
    }
  }
};

// What is known of a chart's samples beside its image, one entry a sample; the charts of a
// patch take turns with one set.
struct ChartBuffers {
  explicit ChartBuffers(uint32_t size)
      : floatNormals(size_t(size) * size),
        triangles(size_t(size) * size, ~0u),
        domain(size_t(size) * size),
        faceNormals(size_t(size) * size) {}
  std::vector<glm::vec3> floatNormals;
  std::vector<uint32_t> triangles;
  // The domain point of each inner sample (for the unfolding).
  std::vector<glm::dvec2> domain;
  std::vector<glm::vec3> faceNormals;
};

// One quad chart of a patch being sampled: its image, what is known of its samples, and the ways
// of placing them (the bilinear map or the quad's warp, the unfolding) tried on it.
struct ChartSampler {
  ChartSampler(PatchSampler& patchSampler, ChartBuffers& buffers, uint32_t quad, GeometryImage& image)
      : ps(patchSampler),
        i(quad),
        size(patchSampler.c.size),
        m(patchSampler.c.m),
        img(image),
        floatNormals(buffers.floatNormals),
        triangles(buffers.triangles),
        domain(buffers.domain),
        faceNormals(buffers.faceNormals) {}

  PatchSampler& ps;
  const uint32_t i;  // the quad
  const uint32_t size, m;
  GeometryImage& img;
  std::vector<glm::vec3>& floatNormals;
  std::vector<uint32_t>& triangles;
  std::vector<glm::dvec2>& domain;
  std::vector<glm::vec3>& faceNormals;
  bool unfolded = false;          // some inner samples slid off the map (unfold below)
  std::vector<uint32_t> flipped;  // the flipped texels, as their (0,0) samples

  // The chart's samples and what is known of them, to try another placement and go back.
  struct Placement {
    GeometryImage img;
    std::vector<glm::vec3> normals;
    std::vector<uint32_t> triangles, flipped;
    std::vector<glm::dvec2> domain;
    bool unfolded;
  };
  Placement keep() const { return Placement{img, floatNormals, triangles, flipped, domain, unfolded}; }
  void restore(Placement&& s) {
    img = std::move(s.img);
    floatNormals = std::move(s.normals);
    triangles = std::move(s.triangles);
    flipped = std::move(s.flipped);
    domain = std::move(s.domain);
    unfolded = s.unfolded;
  }

  // Writes sample s at index `at` of the image and of what is known of it.
  void putAt(size_t at, const Sample& s) {
    img.positions[at] = s.p;
    img.normals[at] = packNormal(s.n.x, s.n.y, s.n.z);
    floatNormals[at] = s.n;
    triangles[at] = ps.faceOf(s);
    if (ps.c.surface.hasColours) img.colours[at] = s.c;
  }

  // The border: side runs along the edges' counter-clockwise parameter; spokes from the
  // border to the centre ((1,0) -> (1,1) on the right, (0,1) -> (1,1) on the top).
  void fillBorder() {
    for (uint8_t e = 0; e < 4; ++e) {
      const EdgeSource& src = ps.plan.quads[i][e];
      for (uint32_t k = 0; k <= m; ++k) {
        if (!src.spoke) {
          putAt(edgeSampleIndex(size, e, k), ps.sideSample(src.index, src.offset + k));
        } else if (e == kEdgeRight) {
          putAt(size_t(k) * size + m, ps.spokes[src.index][k]);
        } else {
          putAt(size_t(m) * size + k, ps.spokes[src.index][k]);
        }
      }
    }
  }

  // The inside, through the bilinear map or the quad's warp.
  void fillInside(bool warp) {
    const std::vector<QuadWarp>& warps = ps.warps;
    const glm::dvec2 &qa = ps.quadCorners[i][0], &qb = ps.quadCorners[i][1], &qc = ps.quadCorners[i][2],
                     &qe = ps.quadCorners[i][3];
    std::optional<Locator> warpLocator;
    if (warp) warpLocator.emplace(warps[i].square, warps[i].triangles);
    uint32_t warpHint = 0;
    for (uint32_t v = 1; v < m; ++v) {
      const double t = double(v) / m;
      for (uint32_t u = 1; u < m; ++u) {
        const double s = double(u) / m;
        glm::dvec2 d;
        if (warpLocator) {
          std::array<uint32_t, 3> tri;
          glm::dvec3 b;
          warpLocator->locate(glm::dvec2(s, t), warpHint, tri, b);
          d = b.x * warps[i].domain[tri[0]] + b.y * warps[i].domain[tri[1]] + b.z * warps[i].domain[tri[2]];
        } else {
          d = (1 - s) * (1 - t) * qa + s * (1 - t) * qb + s * t * qc + (1 - s) * t * qe;
        }
        domain[size_t(v) * size + u] = d;
        putAt(size_t(v) * size + u, ps.sampleAt(d));
      }
    }
  }

  // The chart's quality as its samples stand; its flipped texels into flippedAt.
  ImageQuality measure(bool warp, std::vector<uint32_t>& flippedAt) {
    const PatchLayout& layout = ps.c.layout;
    const std::vector<QuadWarp>& warps = ps.warps;
    const PatchParameterization& pp = ps.pp;
    // The input faces under the samples (zero where none is known).
    for (size_t k = 0; k < faceNormals.size(); ++k)
      faceNormals[k] = glm::vec3(ps.faceNormalOr(triangles[k], glm::dvec3(0.0)));
    flippedAt.clear();
    ImageQuality q = measureImage(img.positions, floatNormals, size, &flippedAt, &faceNormals);
    // How far the chart's surface passes from the input vertices it stands for, each at its
    // chart coordinates under the map used.
    for (auto [v, st] : ps.quadVertices[i]) {
      if (warp && warps[i].ofPatchVertex[v] != ~0u) st = warps[i].square[warps[i].ofPatchVertex[v]];
      const double e =
          chartSurfaceDistance(img.positions, size, st, glm::dvec3(layout.positions[pp.vertices[v]]), unfolded ? 2 : 1);
      if (e > q.sampleError) {
        q.sampleError = e;
        q.sampleErrorVertex = pp.vertices[v];
      }
    }
    if (size < ps.c.options.chordsBelow) measureSharedSides(q);
    return q;
  }

  // How far the vertices of the chart's shared sides lie from the side's samples (the polyline
  // through them) at this chart's count (ResampleOptions::chordsBelow). A side's vertices are
  // left out of quadVertices since both patches sample the side alike; where they sample it at
  // different counts the seam is stitched to the coarser one's, whose own charts so carry the
  // error, and a chart of few samples along a curved or kinked side (a small patch) cuts chords
  // across the vertices between them.
  void measureSharedSides(ImageQuality& q) const {
    const PatchLayout& layout = ps.c.layout;
    const double last = double(ps.c.sideCount - 1);
    for (uint8_t e = 0; e < 4; ++e) {
      const EdgeSource& src = ps.plan.quads[i][e];
      if (src.spoke || ps.patch.sides[src.index].neighbourPatch < 0) continue;
      const std::vector<uint32_t>& run = ps.patch.sides[src.index].vertices;
      std::vector<double> arc(run.size(), 0.0);
      for (size_t k = 1; k < run.size(); ++k)
        arc[k] =
            arc[k - 1] + glm::length(glm::dvec3(layout.positions[run[k]]) - glm::dvec3(layout.positions[run[k - 1]]));
      if (!(arc.back() > 0.0)) continue;
      for (size_t k = 1; k + 1 < run.size(); ++k) {
        const double t = arc[k] / arc.back() * last;  // where the vertex lies among the side's samples
        if (t < double(src.offset) || t > double(src.offset + m)) continue;
        const uint32_t a = std::min(uint32_t(t), ps.c.sideCount - 2);
        const glm::dvec3 x(layout.positions[run[k]]);
        const glm::dvec3 p0(ps.sideSample(src.index, a).p), p1(ps.sideSample(src.index, a + 1).p);
        const glm::dvec3 d = p1 - p0;
        const double len2 = glm::dot(d, d);
        const double f = len2 > 0.0 ? std::clamp(glm::dot(x - p0, d) / len2, 0.0, 1.0) : 0.0;
        const double dist = glm::length(x - (p0 + f * d));
        if (dist > q.sampleError) {
          q.sampleError = dist;
          q.sampleErrorVertex = run[k];
        }
      }
    }
  }

  // Places the samples through the map options.quadMap asks for and measures the chart.
  // Returns whether the quad's warp was used.
  bool placeByMap() {
    const ResampleOptions& options = ps.c.options;
    bool warp = options.quadMap == QuadMap::kStretch && ps.ensureWarp(i);
    fillInside(warp);
    img.quality = measure(warp, flipped);
    // kFolding: a chart that folds under the bilinear map takes the warp if it folds less.
    if (options.quadMap == QuadMap::kFolding && img.quality.flippedTexels > 0 && ps.ensureWarp(i)) {
      Placement bilinear = keep();
      fillInside(true);
      const ImageQuality q = measure(true, flipped);
      if (q.flippedTexels < bilinear.img.quality.flippedTexels) {
        img.quality = q;
        warp = true;
      } else {
        restore(std::move(bilinear));
      }
    }
    return warp;
  }

  void unfold(bool warp);  // below (Unfolding)

  // Where the chart folds, as layout triangles (one per flipped texel, a few per chart).
  void findFoldTriangles() {
    for (uint32_t at : flipped) {
      for (const size_t k : {size_t(at), size_t(at) + 1, size_t(at) + size, size_t(at) + size + 1}) {
        if (triangles[k] != ~0u) {
          img.foldTriangles.push_back(triangles[k]);
          break;
        }
      }
      if (img.foldTriangles.size() >= 8) break;
    }
  }

  // The flipped texels of each coarser pyramid level of the chart (GeometryImage::flippedAtLevel),
  // measured as level 0's are: every 2^k-th sample, with the input faces under them.
  void measureLevels() {
    img.flippedAtLevel.clear();
    for (uint32_t k = 1; (m >> k) >= 1 && (m >> k << k) == m; ++k) {
      const uint32_t s = (m >> k) + 1, step = 1u << k;
      std::vector<glm::vec3> p(size_t(s) * s), n(size_t(s) * s), f(size_t(s) * s);
      for (uint32_t v = 0; v < s; ++v) {
        for (uint32_t u = 0; u < s; ++u) {
          const size_t from = size_t(v) * step * size + size_t(u) * step, to = size_t(v) * s + u;
          p[to] = img.positions[from];
          n[to] = floatNormals[from];
          f[to] = glm::vec3(ps.faceNormalOr(triangles[from], glm::dvec3(0.0)));
        }
      }
      img.flippedAtLevel.push_back(measureImage(p, n, s, nullptr, &f).flippedTexels);
    }
  }
};

// One unfolding of a chart (ChartSampler::unfold): where its samples stood when it began, and the
// measures a sample's slide is judged by.
struct Unfolding {
  explicit Unfolding(ChartSampler& chart)
      : ch(chart),
        size(chart.size),
        m(chart.m),
        gap(chart.ps.c.options.minSampleGap),
        start(chart.domain),
        startPositions(chart.img.positions) {}

  ChartSampler& ch;
  const uint32_t size, m;
  const double gap;  // ResampleOptions::minSampleGap
  const std::vector<glm::dvec2> start;
  const std::vector<glm::vec3> startPositions;

  // How far from its four neighbours a sample may end: kUnfoldLength times the farthest
  // of them as the map put them (so that no texel grows long across the surface).
  double longest(size_t k) const {
    double l = 0.0;
    for (const size_t j : {k - 1, k + 1, k - size, k + size})
      l = std::max(l, glm::distance(glm::dvec3(startPositions[j]), glm::dvec3(startPositions[k])));
    return kUnfoldLength * l;
  }
  // Whether x is within l of the sample's four neighbours as they now stand.
  bool within(size_t k, const glm::dvec3& x, double l) const {
    for (const size_t j : {k - 1, k + 1, k - size, k + size}) {
      if (glm::distance(glm::dvec3(ch.img.positions[j]), x) > l) return false;
    }
    return true;
  }
  // Whether x keeps apart from every other sample a slide could bring it to (those up to
  // two texels away): two samples at one point make a texel of no area. Also as stored (single
  // precision), and as coded (ResampleOptions::minSampleGap).
  bool apart(size_t k, const glm::dvec3& x, double l) const {
    const int64_t u0 = int64_t(k % size), v0 = int64_t(k / size);
    const glm::vec3 stored(x);
    for (int64_t v = std::max<int64_t>(v0 - 2, 0); v <= std::min<int64_t>(v0 + 2, m); ++v) {
      for (int64_t u = std::max<int64_t>(u0 - 2, 0); u <= std::min<int64_t>(u0 + 2, m); ++u) {
        const size_t j = size_t(v) * size + size_t(u);
        if (j != k && (ch.img.positions[j] == stored ||
                       glm::distance(glm::dvec3(ch.img.positions[j]), x) <= std::max(1e-4 * l, gap)))
          return false;
      }
    }
    return true;
  }
  // Whether domain point d lies inside the chart's quad (convex, its corners
  // counter-clockwise or clockwise alike). Where the map's texels are longer one way than
  // the other, a sample next to the border may slide past it (less than a texel), where a
  // fold runs along the border; such samples are counted (ImageQuality::samplesPastQuad).
  bool inQuad(const glm::dvec2& d) const {
    const QuadCorners& quad = ch.ps.quadCorners[ch.i];
    int sign = 0;
    for (int e = 0; e < 4; ++e) {
      const glm::dvec2 a = quad[e], b = quad[(e + 1) % 4];
      const double c = (b.x - a.x) * (d.y - a.y) - (b.y - a.y) * (d.x - a.x);
      const int s = c > 0.0 ? 1 : c < 0.0 ? -1 : 0;
      if (s == 0) return false;
      if (sign != 0 && s != sign) return false;
      sign = s;
    }
    return true;
  }
  // The domain's texel spacing at each inner sample, from the map.
  double spacing(size_t k) const {
    return 0.25 * (glm::distance(start[k - 1], start[k]) + glm::distance(start[k + 1], start[k]) +
                   glm::distance(start[k - size], start[k]) + glm::distance(start[k + size], start[k]));
  }
  // A texel's agreement with the input: the largest cosine between its normal (the cross of
  // its diagonals) and the faces under its corners (below 0: flipped), with sample `moved`
  // at x on face normal fn.
  double agreement(size_t t00, size_t moved, const glm::dvec3& x, const glm::dvec3& fn) const {
    const size_t c[4] = {t00, t00 + 1, t00 + size, t00 + size + 1};
    auto at = [&](int j) { return c[j] == moved ? x : glm::dvec3(ch.img.positions[c[j]]); };
    const glm::dvec3 cr = glm::cross(at(3) - at(0), at(2) - at(1));
    const double l = glm::length(cr);
    if (!(l > 0.0)) return -1.0;
    double best = -1.0;
    for (int j = 0; j < 4; ++j)
      best = std::max(
          best, glm::dot(cr, c[j] == moved ? fn : ch.ps.faceNormalOr(ch.triangles[c[j]], ch.floatNormals[c[j]])) / l);
    return best;
  }
  // What inner sample k at x (face normal fn) costs its four texels: their agreement short
  // of kUnfoldMargin.
  double cost(size_t k, const glm::dvec3& x, const glm::dvec3& fn) const {
    double e = 0.0;
    for (const size_t t : {k, k - 1, k - size, k - size - 1})
      e += std::max(0.0, kUnfoldMargin - agreement(t, k, x, fn));
    return e;
  }

  // The inner samples within `ring` texels of the flipped texels, in index order.
  std::vector<size_t> samplesRound(uint32_t ring) const {
    std::vector<uint8_t> mark(size_t(size) * size, 0);
    std::vector<size_t> moving;
    for (const uint32_t at : ch.flipped) {
      const int64_t u0 = at % size, v0 = at / size;
      for (int64_t v = std::max<int64_t>(v0 - ring, 1); v <= std::min<int64_t>(v0 + 1 + ring, m - 1); ++v) {
        for (int64_t u = std::max<int64_t>(u0 - ring, 1); u <= std::min<int64_t>(u0 + 1 + ring, m - 1); ++u) {
          const size_t k = size_t(v) * size + size_t(u);
          if (!mark[k]) mark[k] = 1, moving.push_back(k);
        }
      }
    }
    std::sort(moving.begin(), moving.end());
    return moving;
  }

  // The pattern search's 8 directions, at multiples of a quarter turn's half.
  static inline const std::array<glm::dvec2, 8> kDirections = [] {
    std::array<glm::dvec2, 8> d;
    for (int i = 0; i < 8; ++i) {
      const double angle = i * (3.14159265358979323846 / 4.0);
      d[size_t(i)] = {pmath::cos(angle), pmath::sin(angle)};
    }
    return d;
  }();

  // Slides the samples `moving` (a pattern search, in sweeps until none moves).
  void slide(const std::vector<size_t>& moving) {
    std::vector<glm::dvec2>& domain = ch.domain;
    for (uint32_t sweep = 0; sweep < kUnfoldSweeps; ++sweep) {
      bool any = false;
      for (const size_t k : moving) {
        const double h = spacing(k), reach3D = longest(k);
        double best = cost(k, glm::dvec3(ch.img.positions[k]), ch.ps.faceNormalOr(ch.triangles[k], ch.floatNormals[k]));
        if (best == 0.0) continue;
        glm::dvec2 bestAt = domain[k];
        Sample bestSample;
        bool found = false;
        for (const double scale : {0.5, 0.25, 0.125}) {
          for (const glm::dvec2& dir : kDirections) {
            glm::dvec2 to = domain[k] + (scale * h) * dir;
            const glm::dvec2 off = to - start[k];
            const double reach = kUnfoldReach * h, len = glm::length(off);
            if (len > reach) to = start[k] + off * (reach / len);
            const Sample cand = ch.ps.sampleAt(to);
            if (!within(k, cand.p, reach3D) || !apart(k, cand.p, reach3D)) continue;
            const double e = cost(k, cand.p, ch.ps.faceNormalOr(ch.ps.faceOf(cand), cand.n));
            if (e < best * (1.0 - 1e-6)) best = e, bestAt = to, bestSample = cand, found = true;
          }
          if (found) break;
        }
        if (!found) continue;
        domain[k] = bestAt;
        ch.putAt(k, bestSample);
        any = true;
      }
      if (!any) break;
    }
  }
};

// Unfolding (options.unfold): the inner samples round the flipped texels slide over the
// surface, through the patch's parameterization, each to where its four texels agree best
// with the input faces under their corners (a pattern search of 8 directions at 1/2, 1/4
// and 1/8 of a texel, in sweeps until none moves), at most kUnfoldReach texels from where
// the map put it and kUnfoldLength times its farthest neighbour as mapped from its
// neighbours. The samples stay on the input surface and the border does not move, so
// the seams are unchanged. Tried on a ring of 2 texels round the flipped ones, then 4,
// then 8; each kept if fewer texels fold.
void ChartSampler::unfold(bool warp) {
  const uint32_t flippedBefore = img.quality.flippedTexels;
  Unfolding unfolding(*this);
  for (const uint32_t ring : {2u, 4u, 8u}) {
    Placement before = keep();
    unfolding.slide(unfolding.samplesRound(ring));
    unfolded = true;
    std::vector<uint32_t> now;
    const ImageQuality q = measure(warp, now);
    if (q.flippedTexels < before.img.quality.flippedTexels) {
      img.quality = q;
      img.quality.texelsUnfolded = flippedBefore - q.flippedTexels;
      for (uint32_t v = 1; v < m; ++v) {
        for (uint32_t u = 1; u < m; ++u) img.quality.samplesPastQuad += !unfolding.inQuad(domain[size_t(v) * size + u]);
      }
      flipped = now;
      if (q.flippedTexels == 0) return;
      continue;
    }
    restore(std::move(before));
  }
}

// Samples quad chart i of a patch: its border from the shared side and spoke samples, its inside
// through the chosen map, unfolded where it folds, measured; then hands it to the spill, if any.
void sampleChart(PatchSampler& ps, ChartBuffers& buffers, uint32_t i) {
  const ResampleContext& c = ps.c;
  const uint32_t size = c.size;
  GeometryImage& img = c.set.charts[c.links.offsets[ps.p] + i];
  img.patch = ps.p;
  img.quad = i;
  img.neighbours = c.neighbours[c.links.offsets[ps.p] + i];
  img.positions.resize(size_t(size) * size);
  img.normals.resize(size_t(size) * size);
  if (c.surface.hasColours) img.colours.resize(size_t(size) * size);
  ChartSampler chart(ps, buffers, i, img);
  chart.fillBorder();
  const bool warp = chart.placeByMap();
  if (c.options.unfold && img.quality.flippedTexels > 0) chart.unfold(warp);
  chart.findFoldTriangles();
  chart.measureLevels();
  if (c.options.spill) c.options.spill->put(img);
}

// The working memory of resampling patch p (held at the gate through its parameterization and
// sampling): its parameterization's, or where it is `cached` the local mesh the cache makes again
// (about 48 bytes a triangle with its vertex map), and the point location's grid, about 64 bytes
// a triangle while it is built.
uint64_t patchWorkingBytes(const ResampleContext& c, uint32_t p, bool cached) {
  const Patch& patch = c.layout.patches[p];
  const uint64_t triangles = patch.triangles.size();
  return (cached ? 48 * triangles : paramWorkingBytes(triangles, c.options.param.singlePrecisionFrom)) + 64 * triangles;
}

// Resamples patch p (action 1): parameterizes it, samples what its quads share, then each quad
// chart.
void resamplePatch(const ResampleContext& c, uint32_t p, const PatchQuads& plan) {
  // Taken from the cache before the gate, so that what the gate counts is what runs.
  std::shared_ptr<const PatchParameterization> cached =
      c.reuse.params ? c.reuse.params->find(c.layout, c.layout.patches[p], p) : nullptr;
  std::optional<ParamGate::Hold> hold;
  if (c.options.gate) hold.emplace(*c.options.gate, patchWorkingBytes(c, p, cached != nullptr));
  PatchSampler ps(c, p, plan, std::move(cached));
  PatchResampleStats& st = c.set.patches[p];
  st.paramInitial = ps.pp.initial;
  st.param = ps.pp.quality;
  st.stretchIterations = ps.pp.iterationsUsed;
  st.firstChart = c.links.offsets[p];
  st.sides = ps.n;
  st.quads = ps.nq;

  ps.sampleOpenSides();
  ps.sampleSpokes();
  ps.placeQuads();
  ps.findSideFaces();
  ps.placeVertices();
  ChartBuffers buffers(c.size);
  for (uint32_t i = 0; i < ps.nq; ++i) sampleChart(ps, buffers, i);
}

// The set's figures: the parameterizations and charts of the patches it holds (action != 0)
// combined, and the triangles this resampling parameterized.
void combineSetFigures(const PatchLayout& layout, const std::vector<uint32_t>& action, GeometryImageSet& set) {
  std::vector<ParamQuality> initial, final;
  for (uint32_t p = 0; p < set.patches.size(); ++p) {
    if (action[p] == 0) continue;
    initial.push_back(set.patches[p].paramInitial);
    final.push_back(set.patches[p].param);
  }
  set.paramInitial = combineQuality(initial);
  set.param = combineQuality(final);
  std::vector<ImageQuality> images;
  for (const GeometryImage& g : set.charts) {
    if (action[g.patch] != 0) images.push_back(g.quality);
  }
  set.image = combineImageQuality(images);
  for (uint32_t p = 0; p < layout.patches.size(); ++p) {
    if (action[p] == 1) set.trianglesParameterized += layout.patches[p].triangles.size();
  }
}

}  // namespace

GeometryImageSet resampleLayout(const PatchLayout& layout, const ResampleOptions& options) {
  return resampleLayout(layout, options, ResampleReuse{});
}

namespace {

// The sides of two versions of a patch parameterize alike: the same vertex runs, and the same
// ones open.
bool sidesAlike(const std::vector<PatchSide>& a, const std::vector<PatchSide>& b) {
  if (a.size() != b.size()) return false;
  for (size_t i = 0; i < a.size(); ++i) {
    if (a[i].vertices != b[i].vertices || (a[i].neighbourPatch < 0) != (b[i].neighbourPatch < 0)) return false;
  }
  return true;
}

// SplitMix64's finalizer (Steele, Lea, Flood, "Fast splittable pseudorandom number generators").
uint64_t finalizeDigest(uint64_t x) {
  x ^= x >> 30;
  x *= 0xbf58476d1ce4e5b9ull;
  x ^= x >> 27;
  x *= 0x94d049bb133111ebull;
  return x ^ (x >> 31);
}

}  // namespace

bool patchParamAlike(const Patch& a, const Patch& b) {
  return a.triangles == b.triangles && sidesAlike(a.sides, b.sides);
}

std::array<uint64_t, 2> patchDigest(const Patch& patch) {
  // Lane 0 mixes each index into its state; lane 1 is a polynomial in the indices (mod 2^64,
  // an odd base), so a difference that one lane misses the other sees independently.
  uint64_t a = 0x243f6a8885a308d3ull ^ patch.triangles.size(), b = patch.triangles.size();
  for (const uint32_t t : patch.triangles) {
    a = finalizeDigest(a ^ (uint64_t(t) + 0x9e3779b97f4a7c15ull));
    b = b * 0xff51afd7ed558ccdull + t + 1;
  }
  return {a, finalizeDigest(b)};
}

ParamCache::Order::iterator ParamCache::entryFor(const Patch& patch, const std::array<uint64_t, 2>& digest,
                                                 uint32_t p) const {
  const auto [first, last] = byPatch_.equal_range(p);
  for (auto it = first; it != last; ++it) {
    const Entry& e = *it->second;
    if (e.triangles != patch.triangles.size() || e.digest != digest || !sidesAlike(e.sides, patch.sides)) continue;
    order_.splice(order_.begin(), order_, it->second);
    return it->second;
  }
  return order_.end();
}

std::shared_ptr<const PatchParameterization> ParamCache::find(const PatchLayout& layout, const Patch& patch,
                                                              uint32_t p) const {
  const std::array<uint64_t, 2> digest = patchDigest(patch);
  std::shared_ptr<const PatchParameterization> kept;
  {
    const std::lock_guard<std::mutex> lock(mutex_);
    const auto e = entryFor(patch, digest, p);
    if (e == order_.end()) return nullptr;
    ++hits_;
    kept = e->pp;
  }
  auto pp = std::make_shared<PatchParameterization>(*kept);
  numberPatchVertices(layout, patch, pp->vertices, pp->triangles);
  if (pp->vertices.size() != pp->uv.size())
    throw std::logic_error("ParamCache::find: patch " + std::to_string(p) + " has other vertices than its entry");
  return pp;
}

void ParamCache::put(const Patch& patch, uint32_t p, std::shared_ptr<const PatchParameterization> pp) {
  const std::array<uint64_t, 2> digest = patchDigest(patch);
  // Kept without the local vertex and triangle lists, which find makes again.
  // (Swapped out, not cleared: a cleared vector keeps its memory.)
  auto stripped = std::make_shared<PatchParameterization>(*pp);
  std::vector<uint32_t>().swap(stripped->vertices);
  std::vector<std::array<uint32_t, 3>>().swap(stripped->triangles);
  uint64_t bytes = sizeof(Entry) + pp->uv.size() * sizeof(glm::dvec2) + pp->boundary.size() * sizeof(uint32_t);
  for (const PatchSide& s : patch.sides) bytes += sizeof(PatchSide) + s.vertices.size() * sizeof(uint32_t);
  pp = std::move(stripped);
  const std::lock_guard<std::mutex> lock(mutex_);
  auto erase = [&](Order::iterator e) {
    const auto [first, last] = byPatch_.equal_range(e->p);
    for (auto it = first; it != last; ++it) {
      if (it->second == e) {
        byPatch_.erase(it);
        break;
      }
    }
    bytes_ -= e->bytes;
    order_.erase(e);
  };
  if (const auto same = entryFor(patch, digest, p); same != order_.end()) erase(same);
  if (bytes > maxBytes_) return;
  while (!order_.empty() && bytes_ + bytes > maxBytes_) erase(std::prev(order_.end()));
  order_.push_front(Entry{p, patch.triangles.size(), digest, patch.sides, std::move(pp), bytes});
  byPatch_.emplace(p, order_.begin());
  bytes_ += bytes;
}

uint64_t paramWorkingBytes(uint64_t triangles, uint32_t singlePrecisionFrom) {
  const double n = double(triangles / 2 + 1);
  const double perEntry = n >= double(singlePrecisionFrom) ? 72.0 : 110.0;
  return uint64_t(n * (perEntry * pmath::log2(std::max(n, 2.0)) + 640.0));
}

ParamGate::Hold::Hold(ParamGate& gate, uint64_t bytes) : gate_(gate), bytes_(bytes) {
  std::unique_lock<std::mutex> lock(gate_.mutex_);
  const auto fits = [&] { return gate_.running_ == 0 || gate_.held_ + bytes_ <= gate_.budget_; };
  if (!fits()) {
    ++gate_.waits_;
    gate_.freed_.wait(lock, fits);
  }
  gate_.held_ += bytes_;
  ++gate_.running_;
}

bool ParamGate::fitsNow(uint64_t bytes) {
  const std::lock_guard<std::mutex> lock(mutex_);
  return running_ == 0 || held_ + bytes <= budget_;
}

ParamGate::Hold::~Hold() {
  {
    const std::lock_guard<std::mutex> lock(gate_.mutex_);
    gate_.held_ -= bytes_;
    --gate_.running_;
  }
  gate_.freed_.notify_all();
}

uint64_t ParamCache::bytes() const {
  const std::lock_guard<std::mutex> lock(mutex_);
  return bytes_;
}

namespace {

// The order resampleLayout takes its patches in: those it resamples (action 1) by their triangles,
// most first, then the others (charts kept or taken from an earlier set), each set in patch order.
std::vector<uint32_t> resampleOrder(const PatchLayout& layout, const std::vector<uint32_t>& action) {
  std::vector<uint32_t> order(layout.patches.size());
  std::iota(order.begin(), order.end(), 0u);
  const auto work = [&](uint32_t p) { return action[p] == 1 ? layout.patches[p].triangles.size() + 1 : size_t{0}; };
  std::stable_sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) { return work(a) > work(b); });
  return order;
}

}  // namespace

GeometryImageSet resampleLayout(const PatchLayout& layout, const ResampleOptions& options, const ResampleReuse& reuse) {
  const auto start = std::chrono::steady_clock::now();
  checkResampleInput(layout, options, reuse);
  const uint32_t size = options.chartSize;
  const SideLinks links = validateLinks(layout, options.quads, "resampleLayout");
  std::vector<glm::dvec3> ownNormals;
  if (!reuse.normals) ownNormals = layoutVertexNormals(layout);
  const Surface surface{layout, reuse.normals ? *reuse.normals : ownNormals, !layout.colours.empty()};
  const uint32_t m = size - 1;
  const uint32_t sideCount = sideSampleCount(m, options.quads);

  GeometryImageSet set;
  set.chartSize = size;
  const auto neighbours = neighboursFrom(layout, links, options.quads);
  set.charts.resize(neighbours.size());
  set.patches.resize(layout.patches.size());

  const std::vector<uint32_t> action = patchActions(layout, options, reuse);
  const SideOwners owners = sideOwners(layout, action);

  const int concurrency = options.threads ? int(options.threads) : tbb::this_task_arena::max_concurrency();
  tbb::task_arena arena(concurrency);
  std::vector<std::vector<Sample>> sides(owners.owners.size());
  const ResampleContext context{layout,     options, reuse, surface, links,     owners,
                                neighbours, sides,   size,  m,       sideCount, set};
  arena.execute([&] {
    tbb::parallel_for(size_t{0}, owners.owners.size(), [&](size_t k) {
      if (!owners.ownerNeeded[k]) return;
      sides[k] =
          sampleSide(surface, layout.patches[owners.owners[k].patch].sides[owners.owners[k].side].vertices, sideCount);
    });
    const progress::ProgressStage stage("resample", layout.patches.size());
    // The patches to resample, largest first, each taken by the next free thread (longest
    // processing time first): the last to start are the smallest, so the threads finish about
    // together. Under a gate, a thread takes the largest patch whose working memory fits beside
    // those running, so small patches run beside a large one instead of a thread waiting at the
    // gate for the next large one. A patch's charts do not depend on the order.
    std::vector<uint32_t> remaining = resampleOrder(layout, action);
    size_t toResample = size_t(std::count(action.begin(), action.end(), 1u));  // remaining's first
    std::mutex picking;
    const auto pick = [&](uint32_t& p) {
      const std::lock_guard<std::mutex> lock(picking);
      if (remaining.empty()) return false;
      size_t k = 0;
      if (options.gate && toResample > 0) {
        // The first of the patches to resample that fits, found by bisection (their estimates
        // fall along the list but for a step down where the factors turn single precision, past
        // which a fitting patch may be passed over: a choice of order only, the gate still
        // holds), else the first whose charts are kept or taken, else the largest, which then
        // waits at the gate.
        size_t lo = 0, hi = toResample;
        while (lo < hi) {
          const size_t mid = (lo + hi) / 2;
          if (options.gate->fitsNow(patchWorkingBytes(context, remaining[mid], false))) {
            hi = mid;
          } else {
            lo = mid + 1;
          }
        }
        k = lo < remaining.size() ? lo : 0;
      }
      if (k < toResample) --toResample;
      p = remaining[k];
      remaining.erase(remaining.begin() + ptrdiff_t(k));
      return true;
    };
    // One task per thread (ranges of one, never merged), each taking patches until none is left.
    tbb::parallel_for(
        tbb::blocked_range<int>(0, concurrency, 1),
        [&](const tbb::blocked_range<int>&) {
          for (uint32_t p = 0; pick(p);) {
            const progress::Tick tick;
            const uint32_t n = uint32_t(layout.patches[p].sides.size());
            const PatchQuads plan = patchQuads(n, m, options.quads);
            const uint32_t nq = uint32_t(plan.quads.size());
            if (action[p] == 0) {
              keepUnsampled(context, p, n, nq);
            } else if (action[p] >= 2) {
              takeEarlierCharts(context, p, action[p] - 2, nq);
            } else {
              resamplePatch(context, p, plan);
            }
          }
        },
        tbb::simple_partitioner());
  });

  combineSetFigures(layout, action, set);
  set.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return set;
}

ChartSpill::ChartSpill(const std::filesystem::path& file, bool colours) : file_(file), colours_(colours) {
  fd_ = ::open(file.c_str(), O_RDWR | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd_ < 0) throw InputError(file.string() + ": cannot create (" + std::strerror(errno) + ")");
}

ChartSpill::~ChartSpill() {
  ::close(fd_);
  std::error_code ec;
  std::filesystem::remove(file_, ec);
}

void ChartSpill::put(GeometryImage& image) {
  const uint32_t side = uint32_t(std::llround(std::sqrt(double(image.positions.size()))));
  const size_t n = size_t(side) * side;
  if (!isChartSizeValid(side) || image.positions.size() != n || image.normals.size() != n ||
      image.colours.size() != (colours_ ? n : 0))
    throw std::invalid_argument(
        "ChartSpill::put: the image's samples are not a (2^k+1)^2 image with the spill's colours");
  const size_t bytes =
      sizeof(uint32_t) + n * (sizeof(glm::vec3) + sizeof(PackedNormal) + (colours_ ? sizeof(glm::u8vec4) : 0));
  const uint64_t at = end_.fetch_add(bytes);
  std::vector<uint8_t> buf(bytes);
  uint8_t* out = buf.data();
  std::memcpy(out, &side, sizeof(uint32_t));
  out += sizeof(uint32_t);
  std::memcpy(out, image.positions.data(), n * sizeof(glm::vec3));
  std::memcpy(out + n * sizeof(glm::vec3), image.normals.data(), n * sizeof(PackedNormal));
  if (colours_)
    std::memcpy(out + n * (sizeof(glm::vec3) + sizeof(PackedNormal)), image.colours.data(), n * sizeof(glm::u8vec4));
  for (size_t done = 0; done < bytes;) {
    const ssize_t w = ::pwrite(fd_, buf.data() + done, bytes - done, off_t(at + done));
    if (w <= 0) {
      if (w < 0 && errno == EINTR) continue;
      throw InputError(file_.string() + ": cannot write chart samples (" + (w < 0 ? std::strerror(errno) : "no space") +
                       ")");
    }
    done += size_t(w);
  }
  std::vector<glm::vec3>().swap(image.positions);
  std::vector<PackedNormal>().swap(image.normals);
  std::vector<glm::u8vec4>().swap(image.colours);
  image.spilled = int64_t(at);
}

void ChartSpill::get(GeometryImage& image) const {
  if (image.spilled < 0) return;
  auto read = [&](void* out, size_t bytes, uint64_t at) {
    for (size_t done = 0; done < bytes;) {
      const ssize_t r = ::pread(fd_, static_cast<uint8_t*>(out) + done, bytes - done, off_t(at + done));
      if (r <= 0) {
        if (r < 0 && errno == EINTR) continue;
        throw InputError(file_.string() + ": cannot read chart samples back (" +
                         (r < 0 ? std::strerror(errno) : "short file") + ")");
      }
      done += size_t(r);
    }
  };
  uint32_t side = 0;
  read(&side, sizeof(uint32_t), uint64_t(image.spilled));
  if (!isChartSizeValid(side)) throw InputError(file_.string() + ": a chart record with a bad size");
  const size_t n = size_t(side) * side;
  image.positions.resize(n);
  image.normals.resize(n);
  image.colours.resize(colours_ ? n : 0);
  const uint64_t at = uint64_t(image.spilled) + sizeof(uint32_t);
  read(image.positions.data(), n * sizeof(glm::vec3), at);
  read(image.normals.data(), n * sizeof(PackedNormal), at + n * sizeof(glm::vec3));
  if (colours_)
    read(image.colours.data(), n * sizeof(glm::u8vec4), at + n * (sizeof(glm::vec3) + sizeof(PackedNormal)));
  image.spilled = -1;
}

}  // namespace gimlod
