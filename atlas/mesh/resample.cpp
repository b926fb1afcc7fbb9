// Based on: Niski, Purnomo, Cohen, I3D 2007, section 5 (quadrangulate, resample); Purnomo, Cohen,
// Kumar, "Seamless Texture Atlases", SGP 2004 (shared boundary sampling).
#include "atlas/mesh/resample.h"
#include "core/progress.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <unordered_set>

#include <glm/common.hpp>
#include <glm/geometric.hpp>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

namespace gimlod {
namespace {

uint64_t undirectedKey(uint32_t a, uint32_t b) {
  return a < b ? (uint64_t{a} << 32) | b : (uint64_t{b} << 32) | a;
}

// Attributes of the layout's surface: positions, area-weighted unit vertex normals, colours.
struct Surface {
  const ChartLayout& layout;
  const std::vector<glm::dvec3>& normals;  // unit, or zero where undefined
  bool hasColours = false;
};

}  // namespace

std::vector<glm::dvec3> layoutVertexNormals(const ChartLayout& layout) {
  std::vector<glm::dvec3> n(layout.positions.size(), glm::dvec3(0.0));
  for (const auto& t : layout.triangles) {
    if (t[0] >= n.size() || t[1] >= n.size() || t[2] >= n.size()) {
      throw std::invalid_argument("resampleLayout: triangle vertex out of range");
    }
    const glm::dvec3 a(layout.positions[t[0]]), b(layout.positions[t[1]]),
        c(layout.positions[t[2]]);
    const glm::dvec3 w = glm::cross(b - a, c - a);  // twice the area times the unit normal
    for (uint32_t v : t) n[v] += w;
  }
  for (glm::dvec3& x : n) {
    const double l = glm::length(x);
    x = l > 0.0 && std::isfinite(l) ? x / l : glm::dvec3(0.0);
  }
  return n;
}

namespace {

// One surface sample before packing.
struct Sample {
  glm::vec3 p{0.f};
  glm::vec3 n{0.f, 0.f, 1.f};
  glm::u8vec4 c{255, 255, 255, 255};
  uint32_t triangle = ~0u;  // the layout triangle it was located in; ~0u for side samples
  uint32_t edgeA = ~0u, edgeB = ~0u;  // side samples: the side segment (vertex ids) it lies on
};

// Interpolates the attributes of vertices v[0..2] with barycentric weights b (sum 1).
Sample interpolate(const Surface& s, const std::array<uint32_t, 3>& v, const glm::dvec3& b) {
  Sample out;
  glm::dvec3 p(0.0), n(0.0), c(0.0);
  glm::dvec4 col(0.0);
  for (int k = 0; k < 3; ++k) {
    p += b[k] * glm::dvec3(s.layout.positions[v[k]]);
    n += b[k] * s.normals[v[k]];
    if (s.hasColours) col += b[k] * glm::dvec4(s.layout.colours[v[k]]);
  }
  out.p = glm::vec3(p);
  double l = glm::length(n);
  if (!(l > 1e-12)) {  // opposite vertex normals cancel: use the face normal
    const glm::dvec3 a(s.layout.positions[v[0]]), bb(s.layout.positions[v[1]]),
        cc(s.layout.positions[v[2]]);
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
    cum.push_back(cum.back() + glm::length(glm::dvec3(s.layout.positions[poly[k + 1]]) -
                                           glm::dvec3(s.layout.positions[poly[k]])));
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

// Point location in a patch's parameter triangulation through a uniform grid.
class Locator {
 public:
  explicit Locator(const PatchParameterization& pp) : pp_(pp) {
    glm::dvec2 lo(1e300), hi(-1e300);
    for (const glm::dvec2& q : pp.uv) lo = glm::min(lo, q), hi = glm::max(hi, q);
    const size_t nt = pp.triangles.size();
    const uint32_t side = std::max<uint32_t>(1, uint32_t(std::sqrt(double(nt))));
    valid_.assign(nt, 0);
    lo_ = lo;
    cell_ = std::max(hi.x - lo.x, hi.y - lo.y) / side * (1.0 + 1e-9);
    if (!(cell_ > 0.0)) cell_ = 1.0;
    nx_ = side;
    ny_ = side;
    std::vector<std::vector<uint32_t>> cells(size_t(nx_) * ny_);
    for (uint32_t t = 0; t < nt; ++t) {
      const auto& tri = pp.triangles[t];
      const glm::dvec2 a = pp.uv[tri[0]], b = pp.uv[tri[1]], c = pp.uv[tri[2]];
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
  void locate(const glm::dvec2& p, uint32_t& hint, std::array<uint32_t, 3>& tri,
              glm::dvec3& bary) const {
    double best = -1e300;
    uint32_t bestTri = 0;
    glm::dvec3 bestBary(1.0, 0.0, 0.0);
    auto test = [&](uint32_t t) {
      const glm::dvec3 b = barycentric(t, p);
      const double m = std::min(b.x, std::min(b.y, b.z));
      if (m > best) best = m, bestTri = t, bestBary = b;
    };
    if (hint < pp_.triangles.size() && valid_[hint]) test(hint);
    constexpr double kInside = -1e-12;
    if (best < kInside) {
      const auto [cx, cy] = cellOf(p);
      // note: a point of the domain lies in a triangle listed in its own cell; the rings only
      // catch points a rounding error outside the polygon.
      for (uint32_t ring = 0; ring <= std::max(nx_, ny_) && best < kInside; ++ring) {
        const int64_t x0 = int64_t(cx) - ring, x1 = int64_t(cx) + ring;
        const int64_t y0 = int64_t(cy) - ring, y1 = int64_t(cy) + ring;
        for (int64_t y = std::max<int64_t>(y0, 0); y <= std::min<int64_t>(y1, ny_ - 1); ++y) {
          for (int64_t x = std::max<int64_t>(x0, 0); x <= std::min<int64_t>(x1, nx_ - 1); ++x) {
            if (x != x0 && x != x1 && y != y0 && y != y1) continue;  // ring cells only
            const size_t c = size_t(y) * nx_ + size_t(x);
            for (uint32_t k = start_[c]; k < start_[c + 1]; ++k) test(tris_[k]);
          }
        }
        if (ring >= 1 && best > -1e-6) break;  // near the border: the closest is good enough
      }
    }
    hint = bestTri;
    tri = pp_.triangles[bestTri];
    bary = glm::max(bestBary, glm::dvec3(0.0));
    bary /= bary.x + bary.y + bary.z;
  }

 private:
  std::pair<uint32_t, uint32_t> cellOf(const glm::dvec2& p) const {
    const double fx = std::floor((p.x - lo_.x) / cell_), fy = std::floor((p.y - lo_.y) / cell_);
    return {uint32_t(std::clamp(fx, 0.0, double(nx_ - 1))),
            uint32_t(std::clamp(fy, 0.0, double(ny_ - 1)))};
  }
  glm::dvec3 barycentric(uint32_t t, const glm::dvec2& p) const {
    const auto& tri = pp_.triangles[t];
    const glm::dvec2 a = pp_.uv[tri[0]], b = pp_.uv[tri[1]], c = pp_.uv[tri[2]];
    const double d = (b.x - a.x) * (c.y - a.y) - (c.x - a.x) * (b.y - a.y);
    const double la = ((b.x - p.x) * (c.y - p.y) - (c.x - p.x) * (b.y - p.y)) / d;
    const double lb = ((c.x - p.x) * (a.y - p.y) - (a.x - p.x) * (c.y - p.y)) / d;
    return {la, lb, 1.0 - la - lb};
  }

  const PatchParameterization& pp_;
  glm::dvec2 lo_{0.0};
  double cell_ = 1.0;
  uint32_t nx_ = 1, ny_ = 1;
  std::vector<uint8_t> valid_;  // positive parameter area
  std::vector<uint32_t> start_;
  std::vector<uint32_t> tris_;
};

// For each patch side: -1 if it has no neighbour, else whether its vertex run is the reverse of
// the neighbour's. Validates the links.
struct SideLinks {
  std::vector<uint32_t> offsets;                 // first chart of each patch
  std::vector<std::vector<uint8_t>> opposite;    // [patch][side]: runs opposite to the neighbour
};

SideLinks validateLinks(const ChartLayout& layout, const char* fn) {
  auto fail = [&](uint32_t p, uint32_t i, const std::string& what) {
    throw std::invalid_argument(std::string(fn) + ": patch " + std::to_string(p) + " side " +
                                std::to_string(i) + ": " + what);
  };
  SideLinks links;
  links.offsets = quadChartOffsets(layout);
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
      const bool rev = std::equal(o.vertices.begin(), o.vertices.end(), s.vertices.rbegin(),
                                  s.vertices.rend()) &&
                       o.vertices.size() == s.vertices.size();
      if (s.reversed ? !rev : !same) fail(p, i, "vertex run does not match the neighbour's");
      links.opposite[p][i] = s.reversed ? 1 : 0;
    }
  }
  return links;
}

std::vector<std::array<RootNeighbour, 4>> neighboursFrom(const ChartLayout& layout,
                                                         const SideLinks& links) {
  std::vector<std::array<RootNeighbour, 4>> out(
      layout.patches.empty() ? 0 : links.offsets.back() + layout.patches.back().sides.size());
  for (uint32_t p = 0; p < layout.patches.size(); ++p) {
    const Patch& patch = layout.patches[p];
    const uint32_t n = uint32_t(patch.sides.size());
    for (uint32_t i = 0; i < n; ++i) {
      auto& nb = out[links.offsets[p] + i];
      nb[kEdgeRight] = {int32_t(links.offsets[p] + (i + 1) % n), kEdgeTop, true};
      nb[kEdgeTop] = {int32_t(links.offsets[p] + (i + n - 1) % n), kEdgeRight, true};
      // Bottom: first half of side i. Left: second half of side i-1.
      const PatchSide& si = patch.sides[i];
      if (si.neighbourPatch >= 0) {
        const uint32_t q = uint32_t(si.neighbourPatch), j = si.neighbourSide;
        const uint32_t nq = uint32_t(layout.patches[q].sides.size());
        nb[kEdgeBottom] = si.reversed
                              ? RootNeighbour{int32_t(links.offsets[q] + (j + 1) % nq), kEdgeLeft, true}
                              : RootNeighbour{int32_t(links.offsets[q] + j), kEdgeBottom, false};
      }
      const PatchSide& sp = patch.sides[(i + n - 1) % n];
      if (sp.neighbourPatch >= 0) {
        const uint32_t q = uint32_t(sp.neighbourPatch), j = sp.neighbourSide;
        const uint32_t nq = uint32_t(layout.patches[q].sides.size());
        nb[kEdgeLeft] = sp.reversed
                            ? RootNeighbour{int32_t(links.offsets[q] + j), kEdgeBottom, true}
                            : RootNeighbour{int32_t(links.offsets[q] + (j + 1) % nq), kEdgeLeft, false};
      }
    }
  }
  return out;
}

}  // namespace

std::vector<uint32_t> quadChartOffsets(const ChartLayout& layout) {
  std::vector<uint32_t> offsets(layout.patches.size());
  uint32_t next = 0;
  for (size_t p = 0; p < layout.patches.size(); ++p) {
    offsets[p] = next;
    next += uint32_t(layout.patches[p].sides.size());
  }
  return offsets;
}

std::vector<std::array<RootNeighbour, 4>> quadNeighbours(const ChartLayout& layout) {
  return neighboursFrom(layout, validateLinks(layout, "quadNeighbours"));
}

ImageQuality measureImage(const std::vector<glm::vec3>& positions,
                          const std::vector<glm::vec3>& normals, uint32_t chartSize,
                          std::vector<uint32_t>* flippedAt,
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
      const size_t i00 = size_t(v) * chartSize + u, i10 = i00 + 1, i01 = i00 + chartSize,
                   i11 = i01 + 1;
      const glm::dvec3 p00(positions[i00]), p10(positions[i10]), p01(positions[i01]),
          p11(positions[i11]);
      // Triangles (00, 10, 11) and (00, 11, 01), each of parameter area 1 / (2 m^2).
      triangle((p10 - p00) * scale, (p11 - p10) * scale);
      triangle((p11 - p01) * scale, (p01 - p00) * scale);
      const glm::dvec3 d1 = p11 - p00, d2 = p01 - p10;
      const glm::dvec3 cr = glm::cross(d1, d2);
      const double cl = glm::length(cr);
      if (!(cl > 1e-8 * (glm::dot(d1, d1) + glm::dot(d2, d2)))) {
        ++q.degenerateTexels;
        continue;
      }
      const glm::dvec3 n = glm::dvec3(normals[i00]) + glm::dvec3(normals[i10]) +
                           glm::dvec3(normals[i01]) + glm::dvec3(normals[i11]);
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
    if (p.sampleError > q.sampleError) q.sampleError = p.sampleError, q.sampleErrorVertex = p.sampleErrorVertex;
  });
}

std::vector<uint8_t> patchesOverSampleError(const GeometryImageSet& set, size_t patches, double maxError) {
  std::vector<uint8_t> over(patches, 0);
  for (const GeometryImage& g : set.charts) over[g.patch] |= g.quality.sampleError > maxError;
  return over;
}

namespace {

// The kite of an n-gon parameterization holding domain point d (kite i lies between the spokes to
// the midpoints of sides i-1 and i), and d's coordinates (s, t) in it: the inverse of the bilinear
// map (0,0) corner i, (1,0) midpoint i, (1,1) centre, (0,1) midpoint i-1, by Newton's method
// (the kites are convex, so it converges from the middle), clamped to the unit square.
struct KitePoint {
  uint32_t kite = 0;
  glm::dvec2 st{0.0};
};
KitePoint kiteOf(const std::vector<glm::dvec2>& corner, const std::vector<glm::dvec2>& mid, const glm::dvec2& d) {
  const uint32_t n = uint32_t(corner.size());
  constexpr double kTwoPi = 6.283185307179586;
  auto angle = [](const glm::dvec2& x) { return std::atan2(x.y, x.x); };
  auto ccw = [&](double from, double to) {  // angle from `from` to `to`, counter-clockwise, in [0, 2pi)
    double a = to - from;
    while (a < 0.0) a += kTwoPi;
    while (a >= kTwoPi) a -= kTwoPi;
    return a;
  };
  const double ad = angle(d);
  KitePoint out;
  for (uint32_t i = 0; i < n; ++i) {
    const double a0 = angle(mid[(i + n - 1) % n]);
    if (ccw(a0, ad) <= ccw(a0, angle(mid[i]))) {
      out.kite = i;
      break;
    }
  }
  const uint32_t i = out.kite, prev = (i + n - 1) % n;
  const glm::dvec2 a = corner[i], b = mid[i], c(0.0), e = mid[prev];
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
// triangles of the texel holding st and of the eight texels round it. Where the parameterization
// shifts x along the surface by less than a texel this is its distance across the surface.
double chartSurfaceDistance(const std::vector<glm::vec3>& positions, uint32_t size, const glm::dvec2& st,
                            const glm::dvec3& x) {
  const int64_t m = int64_t(size) - 1;
  const int64_t ix = std::min<int64_t>(int64_t(st.x * double(m)), m - 1);
  const int64_t iy = std::min<int64_t>(int64_t(st.y * double(m)), m - 1);
  auto at = [&](int64_t u, int64_t v) { return glm::dvec3(positions[size_t(v) * size + size_t(u)]); };
  double best = std::numeric_limits<double>::infinity();
  for (int64_t v = std::max<int64_t>(iy - 1, 0); v <= std::min<int64_t>(iy + 1, m - 1); ++v) {
    for (int64_t u = std::max<int64_t>(ix - 1, 0); u <= std::min<int64_t>(ix + 1, m - 1); ++u) {
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

GeometryImageSet resampleLayout(const ChartLayout& layout, const ResampleOptions& options) {
  return resampleLayout(layout, options, ResampleReuse{});
}

GeometryImageSet resampleLayout(const ChartLayout& layout, const ResampleOptions& options,
                                const ResampleReuse& reuse) {
  const auto start = std::chrono::steady_clock::now();
  const uint32_t size = options.chartSize;
  if (!isChartSizeValid(size)) {
    throw std::invalid_argument("resampleLayout: chart size " + std::to_string(size) +
                                " is not 2^k + 1");
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
  const SideLinks links = validateLinks(layout, "resampleLayout");
  std::vector<glm::dvec3> ownNormals;
  if (!reuse.normals) ownNormals = layoutVertexNormals(layout);
  const Surface surface{layout, reuse.normals ? *reuse.normals : ownNormals, !layout.colours.empty()};
  const uint32_t m = size - 1;
  const uint32_t sideCount = 2 * m + 1;

  GeometryImageSet set;
  set.chartSize = size;
  const auto neighbours = neighboursFrom(layout, links);
  set.charts.resize(neighbours.size());
  set.patches.resize(layout.patches.size());

  // What each patch does: 0 skip (not selected), 1 resample, 2 + k take from source k.
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
      if (st.sides != layout.patches[p].sides.size() || st.firstChart + st.sides > src.set->charts.size() ||
          !src.set->charts[st.firstChart].hasSamples(size)) {
        continue;
      }
      action[p] = 2 + uint32_t(k);
      break;
    }
  }

  // Canonical owner of each side: the (patch, side) with the smaller ids; sampled in its order.
  struct SideRef {
    uint32_t patch, side;
  };
  std::vector<SideRef> owners;
  std::vector<uint8_t> ownerNeeded;  // some patch that resamples holds it
  std::vector<std::vector<uint32_t>> sideIndex(layout.patches.size());
  for (uint32_t p = 0; p < layout.patches.size(); ++p) {
    const Patch& patch = layout.patches[p];
    sideIndex[p].resize(patch.sides.size());
    for (uint32_t i = 0; i < patch.sides.size(); ++i) {
      for (uint32_t v : patch.sides[i].vertices) {
        if (v >= layout.positions.size()) {
          throw std::invalid_argument("resampleLayout: patch " + std::to_string(p) + " side " +
                                      std::to_string(i) + ": vertex out of range");
        }
      }
      if (patch.sides[i].vertices.size() < 2) {
        throw std::invalid_argument("resampleLayout: patch " + std::to_string(p) + " side " +
                                    std::to_string(i) + " has < 2 vertices");
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

  const int concurrency =
      options.threads ? int(options.threads) : tbb::this_task_arena::max_concurrency();
  tbb::task_arena arena(concurrency);
  std::vector<std::vector<Sample>> sides(owners.size());
  arena.execute([&] {
    tbb::parallel_for(size_t{0}, owners.size(), [&](size_t k) {
      if (!ownerNeeded[k]) return;
      sides[k] = sampleSide(surface,
                            layout.patches[owners[k].patch].sides[owners[k].side].vertices,
                            sideCount);
    });
    const progress::ProgressStage stage("resample", layout.patches.size());
    tbb::parallel_for(uint32_t{0}, uint32_t(layout.patches.size()), [&](uint32_t p) {
      const progress::Tick tick;
      const Patch& patch = layout.patches[p];
      const uint32_t n = uint32_t(patch.sides.size());
      if (action[p] == 0) {
        set.patches[p].firstChart = links.offsets[p];
        set.patches[p].sides = n;
        for (uint32_t i = 0; i < n; ++i) {
          set.charts[links.offsets[p] + i].patch = p;
          set.charts[links.offsets[p] + i].quad = i;
          set.charts[links.offsets[p] + i].neighbours = neighbours[links.offsets[p] + i];
        }
        return;
      }
      if (action[p] >= 2) {
        GeometryImageSet& src = *reuse.earlier[action[p] - 2].set;
        set.patches[p] = src.patches[p];
        const uint32_t first = src.patches[p].firstChart;
        set.patches[p].firstChart = links.offsets[p];
        for (uint32_t i = 0; i < n; ++i) {
          GeometryImage& img = set.charts[links.offsets[p] + i];
          img = std::move(src.charts[first + i]);
          img.patch = p;
          img.neighbours = neighbours[links.offsets[p] + i];
        }
        return;
      }
      const PatchParameterization pp = parameterizePatch(layout, p, options.param);
      PatchResampleStats& st = set.patches[p];
      st.paramInitial = pp.initial;
      st.param = pp.quality;
      st.stretchIterations = pp.iterationsUsed;
      st.firstChart = links.offsets[p];
      st.sides = n;

      // Samples of the open sides taken through the parameterization (below); empty for others.
      std::vector<std::vector<Sample>> openSides(n);
      // Side sample k of side i in this patch's direction (0 = corner i, 2m = corner i+1).
      auto sideSample = [&](uint32_t i, uint32_t k) -> const Sample& {
        if (!openSides[i].empty()) return openSides[i][k];
        const std::vector<Sample>& s = sides[sideIndex[p][i]];
        const bool flipped = owners[sideIndex[p][i]].patch != p ||
                             owners[sideIndex[p][i]].side != i;
        return s[flipped && links.opposite[p][i] ? 2 * m - k : k];
      };

      const Locator locator(pp);
      uint32_t hint = 0;
      auto sampleAt = [&](const glm::dvec2& d) {
        std::array<uint32_t, 3> tri;
        glm::dvec3 b;
        locator.locate(d, hint, tri, b);
        Sample r = interpolate(surface, {pp.vertices[tri[0]], pp.vertices[tri[1]], pp.vertices[tri[2]]},
                               b);
        r.triangle = patch.triangles[hint];  // the parameterization keeps the patch's order
        return r;
      };
      std::vector<glm::dvec2> corner(n), mid(n);
      for (uint32_t i = 0; i < n; ++i) corner[i] = pp.corners[i];
      for (uint32_t i = 0; i < n; ++i) mid[i] = 0.5 * (corner[i] + pp.corners[(i + 1) % n]);
      // Open sides whose vertices slid in the parameterization are sampled through it, at even
      // steps along their polygon edge; their ends are the corner vertices themselves, as every
      // patch meeting there has them.
      if (options.param.slideOpenSides) {
        for (uint32_t i = 0; i < n; ++i) {
          const PatchSide& side = patch.sides[i];
          if (side.neighbourPatch >= 0) continue;
          std::vector<Sample>& out = openSides[i];
          out.resize(sideCount);
          out.front() = vertexSample(surface, side.vertices.front());
          out.back() = vertexSample(surface, side.vertices.back());
          const glm::dvec2 c1 = corner[(i + 1) % n];
          for (uint32_t k = 1; k + 1 < sideCount; ++k) {
            out[k] = sampleAt(corner[i] + (c1 - corner[i]) * (double(k) / double(sideCount - 1)));
          }
        }
      }
      const glm::dvec2 centre(0.0);
      const Sample centreSample = sampleAt(centre);
      // Spoke i: midpoint of side i (t = 0) to the centre (t = m), shared by quads i and i+1.
      std::vector<std::vector<Sample>> spokes(n, std::vector<Sample>(m + 1));
      for (uint32_t i = 0; i < n; ++i) {
        spokes[i][0] = sideSample(i, m);
        spokes[i][m] = centreSample;
        for (uint32_t t = 1; t < m; ++t) {
          spokes[i][t] = sampleAt(mid[i] + (centre - mid[i]) * (double(t) / m));
        }
      }

      // The patch's triangle along each side segment: the input face a side sample lies on,
      // seen from this patch (for the flipped-texel test).
      std::unordered_map<uint64_t, uint32_t> sideFace;
      {
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
      auto faceOf = [&](const Sample& s) {
        if (s.triangle != ~0u || s.edgeA == ~0u) return s.triangle;
        const auto it = sideFace.find(undirectedKey(s.edgeA, s.edgeB));
        return it == sideFace.end() ? ~0u : it->second;
      };
      // Every vertex of the patch but those of its shared sides, placed in its kite, for the
      // sampling error. (A vertex of a shared side lies on the side's polyline, which both patches
      // sample alike by arc length; the chart across covers it as much as this one, so neither
      // alone tells its distance to the atlas.)
      std::unordered_set<uint32_t> seamVertices;
      for (const PatchSide& side : patch.sides) {
        if (side.neighbourPatch >= 0) seamVertices.insert(side.vertices.begin(), side.vertices.end());
      }
      std::vector<std::vector<std::pair<uint32_t, glm::dvec2>>> kiteVertices(n);
      for (uint32_t v = 0; v < pp.vertices.size(); ++v) {
        if (seamVertices.contains(pp.vertices[v])) continue;
        const KitePoint k = kiteOf(corner, mid, pp.uv[v]);
        kiteVertices[k.kite].push_back({v, k.st});
      }
      std::vector<glm::vec3> floatNormals(size_t(size) * size);
      std::vector<uint32_t> triangles(size_t(size) * size, ~0u);
      std::vector<glm::vec3> faceNormals(size_t(size) * size);
      for (uint32_t i = 0; i < n; ++i) {
        GeometryImage& img = set.charts[links.offsets[p] + i];
        img.patch = p;
        img.quad = i;
        img.neighbours = neighbours[links.offsets[p] + i];
        img.positions.resize(size_t(size) * size);
        img.normals.resize(size_t(size) * size);
        if (surface.hasColours) img.colours.resize(size_t(size) * size);
        const uint32_t prev = (i + n - 1) % n;
        auto put = [&](uint32_t u, uint32_t v, const Sample& s) {
          const size_t at = size_t(v) * size + u;
          img.positions[at] = s.p;
          img.normals[at] = packNormal(s.n.x, s.n.y, s.n.z);
          floatNormals[at] = s.n;
          triangles[at] = faceOf(s);
          if (surface.hasColours) img.colours[at] = s.c;
        };
        for (uint32_t k = 0; k <= m; ++k) {
          put(k, 0, sideSample(i, k));             // bottom: corner i -> midpoint i
          put(0, k, sideSample(prev, 2 * m - k));  // left: corner i -> midpoint i-1
          put(m, k, spokes[i][k]);                 // right: midpoint i -> centre
          put(k, m, spokes[prev][k]);              // top: midpoint i-1 -> centre
        }
        for (uint32_t v = 1; v < m; ++v) {
          const double t = double(v) / m;
          for (uint32_t u = 1; u < m; ++u) {
            const double s = double(u) / m;
            const glm::dvec2 d = (1 - s) * (1 - t) * corner[i] + s * (1 - t) * mid[i] +
                                 s * t * centre + (1 - s) * t * mid[prev];
            put(u, v, sampleAt(d));
          }
        }
        // The input faces under the samples (zero where none is known).
        for (size_t k = 0; k < faceNormals.size(); ++k) {
          faceNormals[k] = glm::vec3(0.f);
          if (triangles[k] == ~0u) continue;
          const auto& t = layout.triangles[triangles[k]];
          const glm::dvec3 a(layout.positions[t[0]]), b(layout.positions[t[1]]), c(layout.positions[t[2]]);
          const glm::dvec3 cr = glm::cross(b - a, c - a);
          const double l = glm::length(cr);
          if (l > 0.0 && std::isfinite(l)) faceNormals[k] = glm::vec3(cr / l);
        }
        std::vector<uint32_t> flipped;
        img.quality = measureImage(img.positions, floatNormals, size, &flipped, &faceNormals);
        // How far the chart's surface passes from the input vertices it stands for.
        for (const auto& [v, st] : kiteVertices[i]) {
          const double e = chartSurfaceDistance(img.positions, size, st, glm::dvec3(layout.positions[pp.vertices[v]]));
          if (e > img.quality.sampleError) {
            img.quality.sampleError = e;
            img.quality.sampleErrorVertex = pp.vertices[v];
          }
        }
        // Where the chart folds, as layout triangles (one per flipped texel, a few per chart).
        for (uint32_t at : flipped) {
          for (const size_t k : {size_t(at), size_t(at) + 1, size_t(at) + size, size_t(at) + size + 1}) {
            if (triangles[k] != ~0u) {
              img.foldTriangles.push_back(triangles[k]);
              break;
            }
          }
          if (img.foldTriangles.size() >= 8) break;
        }
        if (options.spill) options.spill->put(img);
      }
    });
  });

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
  set.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return set;
}

ChartSpill::ChartSpill(const std::filesystem::path& file, uint32_t chartSize, bool colours)
    : file_(file), chartSize_(chartSize), colours_(colours) {
  fd_ = ::open(file.c_str(), O_RDWR | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd_ < 0) throw InputError(file.string() + ": cannot create (" + std::strerror(errno) + ")");
}

ChartSpill::~ChartSpill() {
  ::close(fd_);
  std::error_code ec;
  std::filesystem::remove(file_, ec);
}

void ChartSpill::put(GeometryImage& image) {
  const size_t n = size_t(chartSize_) * chartSize_;
  if (image.positions.size() != n || image.normals.size() != n || image.colours.size() != (colours_ ? n : 0))
    throw std::invalid_argument("ChartSpill::put: the image's samples do not match the spill's chart size and colours");
  const size_t bytes = n * (sizeof(glm::vec3) + sizeof(PackedNormal) + (colours_ ? sizeof(glm::u8vec4) : 0));
  const uint64_t at = end_.fetch_add(bytes);
  std::vector<uint8_t> buf(bytes);
  std::memcpy(buf.data(), image.positions.data(), n * sizeof(glm::vec3));
  std::memcpy(buf.data() + n * sizeof(glm::vec3), image.normals.data(), n * sizeof(PackedNormal));
  if (colours_)
    std::memcpy(buf.data() + n * (sizeof(glm::vec3) + sizeof(PackedNormal)), image.colours.data(), n * sizeof(glm::u8vec4));
  for (size_t done = 0; done < bytes;) {
    const ssize_t w = ::pwrite(fd_, buf.data() + done, bytes - done, off_t(at + done));
    if (w <= 0) {
      if (w < 0 && errno == EINTR) continue;
      throw InputError(file_.string() + ": cannot write chart samples (" + (w < 0 ? std::strerror(errno) : "no space") + ")");
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
  const size_t n = size_t(chartSize_) * chartSize_;
  image.positions.resize(n);
  image.normals.resize(n);
  image.colours.resize(colours_ ? n : 0);
  auto read = [&](void* out, size_t bytes, uint64_t at) {
    for (size_t done = 0; done < bytes;) {
      const ssize_t r = ::pread(fd_, static_cast<uint8_t*>(out) + done, bytes - done, off_t(at + done));
      if (r <= 0) {
        if (r < 0 && errno == EINTR) continue;
        throw InputError(file_.string() + ": cannot read chart samples back (" + (r < 0 ? std::strerror(errno) : "short file") + ")");
      }
      done += size_t(r);
    }
  };
  const uint64_t at = uint64_t(image.spilled);
  read(image.positions.data(), n * sizeof(glm::vec3), at);
  read(image.normals.data(), n * sizeof(PackedNormal), at + n * sizeof(glm::vec3));
  if (colours_) read(image.colours.data(), n * sizeof(glm::u8vec4), at + n * (sizeof(glm::vec3) + sizeof(PackedNormal)));
  image.spilled = -1;
}

}  // namespace gimlod
