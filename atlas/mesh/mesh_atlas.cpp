// Based on: Niski, Purnomo, Cohen, I3D 2007, sections 3 and 5.
#include "atlas/mesh/mesh_atlas.h"
#include "atlas/mesh/portable_math.h"
#include "core/block_codec.h"
#include "core/level_surface.h"
#include "core/progress.h"

#include <glm/geometric.hpp>

#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <unordered_map>

#include <tbb/parallel_for.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_sort.h>

namespace gimlod {

namespace fs = std::filesystem;

namespace {

// Every step-th sample of a side^2 row-major image, both ways ((side - 1) / step + 1)^2; empty
// stays empty.
template <typename T>
std::vector<T> subsampled(const std::vector<T>& image, uint32_t side, uint32_t step) {
  if (image.empty()) return {};
  const uint32_t s = (side - 1) / step + 1;
  std::vector<T> out(size_t(s) * s);
  for (uint32_t v = 0; v < s; ++v)
    for (uint32_t u = 0; u < s; ++u) out[size_t(v) * s + u] = image[size_t(v * step) * side + u * step];
  return out;
}

// The surface drawn from a chart's stored finest level (side^2 samples, level finestLevel of the
// chart) at its level-0 sample (u, v), as the render grids triangulate it.
glm::vec3 drawnAt(const std::vector<glm::vec3>& stored, uint32_t side, uint32_t finestLevel, uint32_t u, uint32_t v) {
  const uint32_t s = 1u << finestLevel, n = side - 1;
  const uint32_t cx = std::min(u >> finestLevel, n - 1), cy = std::min(v >> finestLevel, n - 1);
  const float inv = 1.0f / float(s);
  const float fx = float(u - cx * s) * inv, fy = float(v - cy * s) * inv;
  return cellSurface(stored[size_t(cy) * side + cx], stored[size_t(cy) * side + cx + 1],
                     stored[size_t(cy + 1) * side + cx], stored[size_t(cy + 1) * side + cx + 1], fx, fy);
}

// Whether the (s + 1)^2 samples of the square at (x0, y0) of an image `side` samples wide are all
// at distinct positions.
bool distinctSamples(const std::vector<glm::vec3>& image, uint32_t side, uint32_t x0, uint32_t y0, uint32_t s) {
  std::vector<std::array<float, 3>> p;
  p.reserve(size_t(s + 1) * (s + 1));
  for (uint32_t dy = 0; dy <= s; ++dy)
    for (uint32_t dx = 0; dx <= s; ++dx) {
      const glm::vec3& q = image[size_t(y0 + dy) * side + x0 + dx];
      p.push_back({q.x, q.y, q.z});
    }
  std::sort(p.begin(), p.end());
  return std::adjacent_find(p.begin(), p.end()) == p.end();
}

// Whether a triangle of the square at (x0, y0), s intervals wide, has no area (three samples on one
// line, as the lattice's rounding may put them in a square a few steps wide), as the renderer draws
// it at this level or at a coarser one within the square: each texel split along its (0,0)-(1,1)
// diagonal, at strides 1, 2, ... s.
bool flatTriangles(const std::vector<glm::vec3>& image, uint32_t side, uint32_t x0, uint32_t y0, uint32_t s) {
  auto at = [&](uint32_t x, uint32_t y) { return glm::dvec3(image[size_t(y0 + y) * side + x0 + x]); };
  auto flat = [](const glm::dvec3& a, const glm::dvec3& b, const glm::dvec3& c) {
    const glm::dvec3 n = glm::cross(b - a, c - a);
    return n.x == 0.0 && n.y == 0.0 && n.z == 0.0;
  };
  for (uint32_t t = 1; t <= s; t *= 2)
    for (uint32_t y = 0; y < s; y += t)
      for (uint32_t x = 0; x < s; x += t) {
        const glm::dvec3 p00 = at(x, y), p10 = at(x + t, y), p01 = at(x, y + t), p11 = at(x + t, y + t);
        if (flat(p00, p10, p11) || flat(p00, p11, p01)) return true;
      }
  return false;
}

// The samples of `placed` that moved (they differ from `before`) onto the position of another
// sample of `placed`.
std::vector<size_t> movedOntoOthers(const std::vector<glm::vec3>& placed, const std::vector<glm::vec3>& before) {
  std::vector<std::pair<std::array<float, 3>, size_t>> p(placed.size());
  for (size_t i = 0; i < placed.size(); ++i) p[i] = {{placed[i].x, placed[i].y, placed[i].z}, i};
  std::sort(p.begin(), p.end());
  std::vector<size_t> out;
  for (size_t a = 0; a < p.size();) {
    size_t b = a + 1;
    while (b < p.size() && p[b].first == p[a].first) ++b;
    if (b - a > 1)
      for (size_t k = a; k < b; ++k)
        if (placed[p[k].second] != before[p[k].second]) out.push_back(p[k].second);
    a = b;
  }
  return out;
}

// geometryPyramid's planar squares: moves the samples of the squares of `stored` (the settled
// finest level, finestLevel of the chartSize^2 level 0 `P0`) that may move onto their squares'
// triangles.
uint64_t placeOnPlanarSquares(const std::vector<glm::vec3>& P0, uint32_t chartSize, uint32_t finestLevel, double step,
                              const PlanarPlacement& planar, std::vector<glm::vec3>& stored) {
  const uint32_t M = (chartSize - 1) >> finestLevel, side = M + 1, scale = 1u << finestLevel;
  const uint32_t B = std::min(planar.blockIntervals, M);
  if (B < 2 || !std::has_single_bit(B)) return 0;
  const uint32_t sizes = uint32_t(std::countr_zero(B));  // squares of B >> l intervals, l < sizes
  // The whole chart's drawn surface, as the hierarchy measures it (the squares' own check below
  // evaluates it sample by sample, drawnAt).
  auto drawnEverywhere = [&](const std::vector<glm::vec3>& image) {
    if (finestLevel == 0) return image;
    std::vector<glm::vec3> h(P0.size());
    for (uint32_t v = 0; v < side; ++v)
      for (uint32_t u = 0; u < side; ++u) h[size_t(v * scale) * chartSize + u * scale] = image[size_t(v) * side + u];
    return geometryLevelSurface(h, chartSize, finestLevel);
  };
  std::vector<float> allowed(P0.size());
  {
    const std::vector<glm::vec3> d = drawnEverywhere(stored);
    for (size_t i = 0; i < P0.size(); ++i) allowed[i] = std::max(float(planar.budget), glm::length(P0[i] - d[i]));
  }
  // A sample's lattice point (the samples, settled, lie on the lattice).
  auto lattice = [&](const glm::vec3& p, int c) { return int64_t(std::llround(double(p[c]) / step)); };
  std::vector<std::vector<uint8_t>> forbidden(sizes), isPlanar(sizes);
  for (uint32_t l = 0; l < sizes; ++l) forbidden[l].assign(size_t(M / (B >> l)) * (M / (B >> l)), 0);
  for (;;) {
    std::vector<glm::vec3> G = stored;
    std::vector<uint8_t> known(stored.size(), 0);
    for (uint32_t y = 0; y <= M; ++y)
      for (uint32_t x = 0; x <= M; ++x) known[size_t(y) * side + x] = x == 0 || y == 0 || x == M || y == M;
    for (uint32_t l = 0; l < sizes; ++l) {
      const uint32_t s = B >> l, n = M / s;
      isPlanar[l].assign(size_t(n) * n, 0);
      for (uint32_t sy = 0; sy < n; ++sy)
        for (uint32_t sx = 0; sx < n; ++sx) {
          const size_t k = size_t(sy) * n + sx;
          if (l > 0 && isPlanar[l - 1][size_t(sy / 2) * (n / 2) + sx / 2] != 0) {
            isPlanar[l][k] = 2;  // inside a planar square
            continue;
          }
          if (forbidden[l][k]) continue;
          const uint32_t x0 = sx * s, y0 = sy * s;
          const glm::vec3 c00 = G[size_t(y0) * side + x0], c10 = G[size_t(y0) * side + x0 + s],
                          c01 = G[size_t(y0 + s) * side + x0], c11 = G[size_t(y0 + s) * side + x0 + s];
          std::vector<size_t> moved;  // unknown until now, so `stored` holds what they were
          for (uint32_t dy = 0; dy <= s; ++dy)
            for (uint32_t dx = 0; dx <= s; ++dx) {
              const size_t i = size_t(y0 + dy) * side + x0 + dx;
              if (known[i] || (dx % s == 0 && dy % s == 0)) continue;
              for (int c = 0; c < 3; ++c)
                G[i][c] = float(double(planarSquareSample(lattice(c00, c), lattice(c10, c), lattice(c01, c),
                                                          lattice(c11, c), s, dx, dy)) *
                                step);
              moved.push_back(i);
            }
          // No two samples of the square may round to one lattice point, nor three onto one line (a
          // square a few lattice steps wide, in a densely sampled chart): two samples of the chart
          // welded into one, or a triangle of no area.
          bool within = distinctSamples(G, side, x0, y0, s) && !flatTriangles(G, side, x0, y0, s);
          // The square's footprint, drawn from the moved samples.
          for (uint32_t v = y0 * scale; within && v <= (y0 + s) * scale; ++v)
            for (uint32_t u = x0 * scale; u <= (x0 + s) * scale; ++u) {
              const size_t i = size_t(v) * chartSize + u;
              if (glm::length(P0[i] - drawnAt(G, side, finestLevel, u, v)) > allowed[i]) {
                within = false;
                break;
              }
            }
          if (!within) {
            for (const size_t i : moved) G[i] = stored[i];
            continue;
          }
          isPlanar[l][k] = 1;
          for (const size_t i : moved) known[i] = 1;
        }
    }
    // The whole result: squares beside a sample over its allowance stay as they were.
    const std::vector<glm::vec3> d = drawnEverywhere(G);
    bool over = false;
    // Every planar square holding stored sample (x, y) stays as it was.
    auto keepSquaresAt = [&](uint32_t x, uint32_t y) {
      for (uint32_t l = 0; l < sizes; ++l) {
        const uint32_t span = B >> l, n = M / span;
        for (uint32_t sy = y > 0 ? (y - 1) / span : 0; sy <= std::min(y / span, n - 1); ++sy)
          for (uint32_t sx = x > 0 ? (x - 1) / span : 0; sx <= std::min(x / span, n - 1); ++sx)
            if (isPlanar[l][size_t(sy) * n + sx] == 1) forbidden[l][size_t(sy) * n + sx] = 1, over = true;
      }
    };
    for (uint32_t v = 0; v < chartSize; ++v)
      for (uint32_t u = 0; u < chartSize; ++u) {
        const size_t i = size_t(v) * chartSize + u;
        if (glm::length(P0[i] - d[i]) <= allowed[i]) continue;
        // Every planar square that placed a stored sample the surface there is drawn from stays as
        // it was: the sample itself at the finest level 0, else the corners of its stored cell.
        const uint32_t cx = std::min(u >> finestLevel, M - 1), cy = std::min(v >> finestLevel, M - 1);
        for (uint32_t k = 0; k < 4; ++k)
          keepSquaresAt(finestLevel == 0 ? u : cx + (k & 1), finestLevel == 0 ? v : cy + (k >> 1));
      }
    // And every square that moved a sample onto another sample of the chart (a square squeezed
    // to a few lattice steps, or one over a fold of the chart): two samples welded into one.
    for (const size_t i : movedOntoOthers(G, stored)) keepSquaresAt(uint32_t(i % side), uint32_t(i / side));
    if (!over) {
      uint64_t moved = 0;
      for (size_t i = 0; i < G.size(); ++i) moved += G[i] != stored[i];
      stored = std::move(G);
      return moved;
    }
  }
}

}  // namespace

ChartPyramid geometryPyramid(const GeometryImage& image, uint32_t chartSize, const ChartCoding& coding,
                             uint32_t finestLevel, const PlanarPlacement& planar, uint64_t* planarSamples) {
  if (planarSamples) *planarSamples = 0;
  if (!isChartSizeValid(chartSize) || image.positions.size() != size_t(chartSize) * chartSize ||
      image.normals.size() != image.positions.size() ||
      (!image.colours.empty() && image.colours.size() != image.positions.size()))
    throw std::invalid_argument("geometryPyramid: chart images do not match the chart size");
  if (((chartSize - 1) >> finestLevel) == 0)
    throw std::invalid_argument("geometryPyramid: a finest level past the chart's pyramid");
  // The finest level kept, as it will be stored: subsampled before it is settled (the settling then
  // fits its own neighbours); the other levels subsample it.
  const uint32_t M = (chartSize - 1) >> finestLevel, size = M + 1;
  std::vector<glm::vec3> positions = subsampled(image.positions, chartSize, 1u << finestLevel);
  std::vector<PackedNormal> normals = subsampled(image.normals, chartSize, 1u << finestLevel);
  const std::vector<glm::u8vec4> colours = subsampled(image.colours, chartSize, 1u << finestLevel);
  if (coding.compressed) {
    // The nearest lattice points (kept apart), the planar squares on them, then every sample off
    // the border settled in the interpolation order, the squares' too: interpolation predicts a
    // planar square's samples as it predicts any smooth surface's. The drawn surface so stays
    // within the sampling bound plus the tolerance, as it does off the squares.
    for (glm::vec3& q : positions)  // the nearest lattice points (the settling below keeps them apart)
      q = {quantizeToStep(q.x, coding.positionStep), quantizeToStep(q.y, coding.positionStep),
           quantizeToStep(q.z, coding.positionStep)};
    if (planar.budget > 0.0) {
      const uint64_t moved =
          placeOnPlanarSquares(image.positions, chartSize, finestLevel, coding.positionStep, planar, positions);
      if (planarSamples) *planarSamples = moved;
    }
    const std::vector<float> s =
        settlePositions({reinterpret_cast<const float*>(positions.data()), 3 * positions.size()}, size,
                        coding.positionStep, coding.positionTolerance);
    std::memcpy(positions.data(), s.data(), s.size() * sizeof(float));
  }
  ChartPyramid p;
  // The first level one block holds whole: the coarser ones subsample it in every channel, so a
  // compressed chart file stores none of them (writeChartFile's flag 8).
  const uint32_t single = M >= 2 ? firstSingleBlockLevel(size, std::min(planar.blockIntervals, M)) : 0;
  for (uint32_t k = 0; (M >> k) >= 1; ++k) {
    p.positions.push_back(subsampled(positions, size, 1u << k));
    if (k > single) {
      p.normals.push_back(subsampled(p.normals[single], (M >> single) + 1, 1u << (k - single)));
    } else {
      p.normals.push_back(subsampled(normals, size, 1u << k));
      // Stored normals are settled level by level, in the blocks each level is coded in, down to
      // that level: a level of several blocks subsampled from a settled finer one would predict
      // badly. Shared borders never move.
      if (coding.compressed && !coding.deriveGeometryNormals && (M >> k) >= 2)
        settleNormals(p.normals.back(), (M >> k) + 1, coding.normalTolerance, planar.blockIntervals);
    }
    if (!colours.empty()) {
      std::vector<PackedColour> col;
      for (const glm::u8vec4& c : subsampled(colours, size, 1u << k)) col.push_back({c.r, c.g, c.b, c.a});
      p.colours.push_back(std::move(col));
    }
    if ((M >> k) == 1) break;
  }
  return p;
}

namespace {

constexpr double kAngleBin = 0.01;  // degrees
constexpr size_t kAngleBins = size_t(180.0 / kAngleBin) + 1;

// Adds to `bins` the angle, per sample off level 0's block borders, between the normal a reader
// derives from the stored positions and the resampled normal.
void addNormalAngles(const ChartPyramid& p, uint32_t chartSize, uint32_t blockIntervals, std::vector<uint64_t>& bins) {
  const uint32_t side = chartSize;
  std::vector<PackedNormal> derived(p.normals[0]);
  geometryImageNormals(reinterpret_cast<const float*>(p.positions[0].data()), side, derived.data());
  for (uint32_t v = 1; v + 1 < side; ++v)
    for (uint32_t u = 1; u + 1 < side; ++u) {
      if (u % blockIntervals == 0 || v % blockIntervals == 0) continue;  // stored on block borders
      const size_t i = size_t(v) * side + u;
      const auto a = unpackNormal(derived[i]), b = unpackNormal(p.normals[0][i]);
      const double la = std::sqrt(double(a[0]) * a[0] + double(a[1]) * a[1] + double(a[2]) * a[2]);
      const double lb = std::sqrt(double(b[0]) * b[0] + double(b[1]) * b[1] + double(b[2]) * b[2]);
      const double c =
          la > 0 && lb > 0 ? (double(a[0]) * b[0] + double(a[1]) * b[1] + double(a[2]) * b[2]) / (la * lb) : 1.0;
      const double deg = pmath::acos(std::clamp(c, -1.0, 1.0)) * 180.0 / 3.14159265358979323846;
      ++bins[std::min(kAngleBins - 1, size_t(deg / kAngleBin))];
    }
}

NormalAngles summarize(const std::vector<uint64_t>& bins) {
  NormalAngles a;
  for (uint64_t b : bins) a.samples += b;
  if (a.samples == 0) return a;
  uint64_t seen = 0;
  double sum = 0.0;
  bool median = false, p99 = false;
  for (size_t i = 0; i < bins.size(); ++i) {
    if (!bins[i]) continue;
    const double deg = (double(i) + 0.5) * kAngleBin;
    seen += bins[i];
    sum += deg * double(bins[i]);
    if (!median && 2 * seen >= a.samples) a.median = deg, median = true;
    if (!p99 && 100 * seen >= 99 * a.samples) a.p99 = deg, p99 = true;
    a.max = deg;
  }
  a.mean = sum / double(a.samples);
  return a;
}

}  // namespace

uint32_t chartFinestLevel(const std::vector<glm::vec3>& P, uint32_t chartSize, double sampleError,
                          const ChartCoarsening& c) {
  if (!(c.bound > 0.0) || c.maxFinestLevel == 0 || !(sampleError <= c.bound)) return 0;
  if (!isChartSizeValid(chartSize) || P.size() != size_t(chartSize) * chartSize)
    throw std::invalid_argument("chartFinestLevel: positions do not match the chart size");
  // The levels' errors as the hierarchy measures its nodes', over the whole chart.
  const std::vector<float> levelError =
      geometryLevelErrors(P, chartSize, std::min(c.maxFinestLevel, uint32_t(std::countr_zero(chartSize - 1))));
  uint32_t finest = 0;
  while (finest + 1 < levelError.size() && sampleError + double(levelError[finest + 1]) <= c.bound) ++finest;
  return finest;
}

namespace {

// Chart i's samples: the set's own, or read back from the spill into `back`.
const GeometryImage& chartSamples(const GeometryImageSet& set, size_t i, const ChartSpill* spill, GeometryImage& back) {
  if (set.charts[i].spilled < 0) return set.charts[i];
  if (!spill) throw std::invalid_argument("a chart's samples are spilled, but no spill is given");
  back.spilled = set.charts[i].spilled;
  back.level = set.charts[i].level;
  spill->get(back);
  return back;
}

// The coarsest of the image's own levels down to which no level has more flipped texels than its
// samples (GeometryImage::flippedAtLevel against ImageQuality::flippedTexels): a coarser finest
// level must not fold where the resampled chart did not. No limit (~0u) when every measured level
// passes, or none was measured (an image that was not resampled).
uint32_t levelsWithoutMoreFlips(const GeometryImage& g) {
  uint32_t k = 0;
  while (k < g.flippedAtLevel.size() && g.flippedAtLevel[k] <= g.quality.flippedTexels) ++k;
  return k < g.flippedAtLevel.size() ? k : ~0u;
}

}  // namespace

std::vector<uint32_t> chartFinestLevels(const GeometryImageSet& set, const ChartSpill* spill,
                                        const ChartCoarsening& c) {
  std::vector<uint32_t> out(set.charts.size(), 0);
  for (size_t i = 0; i < set.charts.size(); ++i) out[i] = set.charts[i].level;
  if (!(c.bound > 0.0) || c.maxFinestLevel == 0) return out;
  tbb::parallel_for(size_t(0), set.charts.size(), [&](size_t i) {
    const uint32_t own = set.charts[i].level;
    out[i] = own;
    if (!(set.charts[i].quality.sampleError <= c.bound) || own >= c.maxFinestLevel) return;
    GeometryImage back;
    ChartCoarsening rest = c;
    rest.maxFinestLevel = std::min(c.maxFinestLevel - own, levelsWithoutMoreFlips(set.charts[i]));
    out[i] = own + chartFinestLevel(chartSamples(set, i, spill, back).positions, set.charts[i].side(set.chartSize),
                                    set.charts[i].quality.sampleError, rest);
  });
  return out;
}

GeometryChartsWritten writeGeometryCharts(const GeometryImageSet& set, const fs::path& dir, uint32_t blockIntervals,
                                          AtlasManifest& m, const ChartSpill* spill, const ChartCoding& coding,
                                          const std::vector<uint32_t>& finestLevels, double planarBound) {
  const auto t0 = std::chrono::steady_clock::now();
  if (set.charts.empty()) throw std::invalid_argument("writeGeometryCharts: no charts");
  if (!finestLevels.empty() && finestLevels.size() != set.charts.size())
    throw std::invalid_argument("writeGeometryCharts: one finest level per chart expected");
  if (!std::has_single_bit(blockIntervals) || blockIntervals > set.chartSize - 1)
    throw std::invalid_argument("writeGeometryCharts: blockIntervals must be a power of two <= chartSize - 1");
  std::error_code ec;
  fs::create_directories(dir / "charts", ec);
  if (ec) throw InputError((dir / "charts").string() + ": cannot create directory (" + ec.message() + ")");
  m.kind = AtlasKind::Geometry;
  m.chartSize = set.chartSize;
  m.blockIntervals = blockIntervals;
  m.chartsX = uint32_t(set.charts.size());
  m.chartsY = 1;
  m.samplesX = m.samplesY = 0;
  m.charts.resize(set.charts.size());
  m.compression = CompressionInfo{};
  if (coding.compressed) {
    if (!(coding.positionStep > 0.0))
      throw std::invalid_argument("writeGeometryCharts: compressed positions need a step");
    m.compression.present = true;
    m.compression.positionStep = coding.positionStep;
    m.compression.positionTolerance = coding.positionTolerance;
    m.compression.normalTolerance = coding.normalTolerance;
  }
  std::vector<uint64_t> bytes(set.charts.size(), 0), finestSamples(set.charts.size(), 0),
      planarSamples(set.charts.size(), 0);
  std::vector<std::array<float, 6>> boxes(set.charts.size());
  const bool measureNormals = coding.compressed && coding.deriveGeometryNormals;
  tbb::enumerable_thread_specific<std::vector<uint64_t>> angleBins(
      [&] { return std::vector<uint64_t>(measureNormals ? kAngleBins : 0, 0); });
  const progress::ProgressStage stage("write charts", set.charts.size());
  tbb::parallel_for(size_t(0), set.charts.size(), [&](size_t i) {
    GeometryImage back;  // a spilled chart's samples, read back for this chart only
    const GeometryImage& img = set.charts[i];
    const GeometryImage& samples = chartSamples(set, i, spill, back);
    char name[48];  // "charts/chart_" + up to 20 digits + ".bin"
    std::snprintf(name, sizeof(name), "charts/chart_%04zu.bin", i);
    ChartInfo& c = m.charts[i];
    c.id = uint32_t(i);
    c.gridX = int32_t(i);
    c.gridY = 0;
    c.file = name;
    c.neighbours = img.neighbours;
    c.finestLevel = finestLevels.empty() ? img.level : finestLevels[i];
    if (c.finestLevel < img.level)
      throw std::invalid_argument("writeGeometryCharts: a finest level finer than the chart's samples");
    PlanarPlacement planar;
    planar.budget = std::max(0.0, planarBound - img.quality.sampleError);
    planar.blockIntervals = blockIntervals;
    const ChartPyramid pyramid =
        geometryPyramid(samples, img.side(set.chartSize), coding, c.finestLevel - img.level, planar, &planarSamples[i]);
    const uint32_t size = ((set.chartSize - 1) >> c.finestLevel) + 1;
    finestSamples[i] = uint64_t(size) * size;
    glm::vec3 lo(std::numeric_limits<float>::infinity()), hi(-std::numeric_limits<float>::infinity());
    for (const glm::vec3& q : pyramid.positions[0]) {
      lo = {std::min(lo.x, q.x), std::min(lo.y, q.y), std::min(lo.z, q.z)};
      hi = {std::max(hi.x, q.x), std::max(hi.y, q.y), std::max(hi.z, q.z)};
    }
    boxes[i] = {lo.x, lo.y, lo.z, hi.x, hi.y, hi.z};
    const uint32_t blocks = std::min(blockIntervals, size - 1);
    bytes[i] = writeChartFile(dir / name, pyramid, size, blocks, coding);
    if (measureNormals) addNormalAngles(pyramid, size, blocks, angleBins.local());
    progress::advance();
  });
  GeometryChartsWritten w;
  w.bounds = boxes[0];
  for (size_t i = 0; i < boxes.size(); ++i) {
    w.bytes += bytes[i];
    w.finestSamples += finestSamples[i];
    w.planarSamples += planarSamples[i];
    const uint32_t f = m.charts[i].finestLevel;
    if (w.chartsByFinestLevel.size() <= f) w.chartsByFinestLevel.resize(f + 1, 0);
    ++w.chartsByFinestLevel[f];
    for (int a = 0; a < 3; ++a) {
      w.bounds[a] = std::min(w.bounds[a], boxes[i][a]);
      w.bounds[3 + a] = std::max(w.bounds[3 + a], boxes[i][3 + a]);
    }
  }
  m.heightRange = {w.bounds[2], w.bounds[5]};
  if (measureNormals) {
    std::vector<uint64_t> all(kAngleBins, 0);
    for (const auto& b : angleBins)
      for (size_t i = 0; i < kAngleBins; ++i) all[i] += b[i];
    w.normalAngles = summarize(all);
  }
  w.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return w;
}

std::vector<glm::vec3> readDrawnChartLevel(const fs::path& atlasDir, const AtlasManifest& m, size_t i, uint32_t level) {
  // A chart whose finest level is coarser than `level` gives its finest; its neighbours' border
  // samples facing it are stitched onto its lattice, as the renderer stitches them (each moved to
  // the lattice point below it).
  const auto drawnLevel = [&](size_t c) { return std::max(level, m.charts[c].finestLevel); };
  const ChartInfo& c = m.charts[i];
  const ChartFileReader reader(atlasDir / c.file);
  if (!reader.hasChannel(kChannelPositions))
    throw InputError((atlasDir / c.file).string() + ": no positions in a geometry atlas chart");
  if (reader.chartSize() != m.chartFileSize(c.id))
    throw InputError((atlasDir / c.file).string() + ": chart size differs from the manifest's");
  const uint32_t own = drawnLevel(i);
  if (own - c.finestLevel >= reader.levels())
    throw InputError((atlasDir / c.file).string() + ": has no level " + std::to_string(own - c.finestLevel));
  std::vector<glm::vec3> P = reader.readLevelPositions(own - c.finestLevel);
  const uint32_t n = (m.chartSize - 1) >> own;
  for (uint32_t e = 0; e < 4; ++e) {
    const int32_t other = c.neighbours[e].chart;
    if (other < 0 || drawnLevel(size_t(other)) <= own) continue;
    const uint32_t d = drawnLevel(size_t(other)) - own;
    // The edge's sample at coordinate t along +u (bottom, top) or +v (left, right).
    const auto at = [&](uint32_t t) -> glm::vec3& {
      switch (e) {
        case kEdgeBottom: return P[t];
        case kEdgeTop: return P[size_t(n) * (n + 1) + t];
        case kEdgeLeft: return P[size_t(t) * (n + 1)];
        default: return P[size_t(t) * (n + 1) + n];
      }
    };
    for (uint32_t t = 0; t <= n; ++t) at(t) = at((t >> d) << d);
  }
  return P;
}

// Chart i of a planet atlas at `level`: its heights placed on the sphere (PlanetFrame::position),
// so that samples shared by charts (their borders, the antimeridian, the poles) are identical.
std::vector<glm::vec3> readPlanetChartLevel(const fs::path& atlasDir, const AtlasManifest& m, size_t i,
                                            uint32_t level) {
  const ChartInfo& c = m.charts[i];
  const ChartFileReader reader(atlasDir / c.file);
  if (!reader.hasChannel(kChannelHeights) || reader.chartSize() != m.chartSize || level >= reader.levels())
    throw InputError((atlasDir / c.file).string() + ": not a chart of the planet atlas's size and levels");
  const uint32_t n = (m.chartSize - 1) >> level;
  const std::vector<float> h = reader.readHeightsWindow(level, 0, 0, n);
  const PlanetFrame frame(m.planet, m.samplesX, m.samplesY);
  const int64_t M = m.chartSize - 1, step = int64_t(1) << level;
  std::vector<glm::vec3> P(h.size());
  for (uint32_t v = 0; v <= n; ++v)
    for (uint32_t u = 0; u <= n; ++u) {
      const size_t k = size_t(v) * (n + 1) + u;
      P[k] = glm::vec3(frame.position(c.gridX * M + u * step, c.gridY * M + v * step, h[k]));
    }
  return P;
}

AtlasSurface readAtlasSurface(const fs::path& atlasDir, uint32_t level) {
  const AtlasManifest m = readManifest(atlasDir);
  const bool planet = m.kind == AtlasKind::Heightfield && m.planet.present;
  if (m.kind != AtlasKind::Geometry && !planet)
    throw InputError((atlasDir / kManifestName).string() + ": a " + atlasKindName(m.kind) +
                     " atlas; export reads geometry (mesh) and planet atlases");
  if (level >= m.pyramidLevels())
    throw InputError((atlasDir / kManifestName).string() + ": level " + std::to_string(level) +
                     " does not exist (charts have levels 0.." + std::to_string(m.pyramidLevels() - 1) + ")");
  AtlasSurface out;
  struct Key {
    uint32_t x, y, z;
    bool operator==(const Key&) const = default;
  };
  struct KeyHash {
    size_t operator()(const Key& k) const {
      return size_t((uint64_t(k.x) * 0x9E3779B97F4A7C15ull) ^ (uint64_t(k.y) * 0xC2B2AE3D27D4EB4Full) ^
                    (uint64_t(k.z) * 0x165667B19E3779F9ull));
    }
  };
  // Charts are read in parallel, then welded in chart order.
  const auto drawnLevel = [&](size_t i) { return std::max(level, m.charts[i].finestLevel); };
  std::vector<std::vector<glm::vec3>> levels(m.charts.size());
  tbb::parallel_for(size_t(0), m.charts.size(), [&](size_t i) {
    levels[i] = planet ? readPlanetChartLevel(atlasDir, m, i, level) : readDrawnChartLevel(atlasDir, m, i, level);
  });
  std::unordered_map<Key, uint32_t, KeyHash> weld;
  for (size_t chart = 0; chart < levels.size(); ++chart) {
    const std::vector<glm::vec3> P = std::move(levels[chart]);
    const uint32_t s = ((m.chartSize - 1) >> drawnLevel(chart)) + 1;
    std::vector<uint32_t> ids(P.size());
    for (size_t i = 0; i < P.size(); ++i) {
      Key k;
      std::memcpy(&k, &P[i], sizeof(Key));
      auto [it, inserted] = weld.try_emplace(k, uint32_t(out.positions.size()));
      if (inserted) out.positions.push_back(P[i]);
      ids[i] = it->second;
    }
    out.samples += P.size();
    for (uint32_t v = 0; v + 1 < s; ++v)
      for (uint32_t u = 0; u + 1 < s; ++u) {
        const uint32_t a = ids[v * s + u], b = ids[v * s + u + 1], cc = ids[(v + 1) * s + u + 1],
                       d = ids[(v + 1) * s + u];
        if (a != b && b != cc && a != cc) out.triangles.push_back({a, b, cc});
        if (a != cc && cc != d && a != d) out.triangles.push_back({a, cc, d});
      }
  }
  // Edges used by one triangle only: sorted undirected keys, runs of length 1.
  std::vector<uint64_t> edges;
  edges.reserve(out.triangles.size() * 3);
  for (const auto& t : out.triangles)
    for (int e = 0; e < 3; ++e) {
      const uint32_t a = t[e], b = t[(e + 1) % 3];
      edges.push_back((uint64_t(std::min(a, b)) << 32) | std::max(a, b));
    }
  tbb::parallel_sort(edges.begin(), edges.end());
  for (size_t i = 0; i < edges.size();) {
    size_t j = i + 1;
    while (j < edges.size() && edges[j] == edges[i]) ++j;
    out.boundaryEdges += j - i == 1;
    i = j;
  }
  return out;
}

void writePly(const fs::path& path, const std::vector<glm::vec3>& positions,
              const std::vector<std::array<uint32_t, 3>>& triangles) {
  std::string header = "ply\nformat binary_little_endian 1.0\ncomment gimlod atlas surface\nelement vertex " +
                       std::to_string(positions.size()) +
                       "\nproperty float x\nproperty float y\nproperty float z\nelement face " +
                       std::to_string(triangles.size()) + "\nproperty list uchar int vertex_indices\nend_header\n";
  static_assert(std::endian::native == std::endian::little, "writePly writes native little-endian data");
  std::vector<uint8_t> buf(header.size() + positions.size() * 12 + triangles.size() * 13);
  std::memcpy(buf.data(), header.data(), header.size());
  uint8_t* p = buf.data() + header.size();
  for (const glm::vec3& q : positions) {
    std::memcpy(p, &q, 12);
    p += 12;
  }
  for (const auto& t : triangles) {
    *p++ = 3;
    for (uint32_t i : t) {
      const int32_t v = int32_t(i);
      std::memcpy(p, &v, 4);
      p += 4;
    }
  }
  atomicWriteFile(path, buf.data(), buf.size());
}

}  // namespace gimlod
