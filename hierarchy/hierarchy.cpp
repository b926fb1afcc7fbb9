// Based on: Niski, Purnomo, Cohen, I3D 2007, section 6 (hierarchy creation): per-node bounds and
// per-resolution maximum sample deviation, built in parallel.
#include "hierarchy/hierarchy.h"
#include "core/level_surface.h"
#include "core/block_codec.h"
#include "core/progress.h"

#include <atomic>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <optional>
#include <stdexcept>
#include <type_traits>

#include <glm/common.hpp>

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

namespace gimlod {
namespace {

constexpr char kMagic[4] = {'G', 'L', 'M', 'H'};
constexpr uint32_t kHierarchyVersion = 1;            // raw
constexpr uint32_t kCompressedHierarchyVersion = 2;  // the version-1 body regrouped and zstd-coded
constexpr uint32_t kQuantizedHierarchyVersion = 3;   // boxes inset from their parents', errors rounded up

// Reduces a w x rows array of per-cell values by 2x2 blocks with `op` into a (w/2) x (rows/2) array.
template <typename Op>
void reduceRects2x2(const std::vector<float>& in, uint32_t w, uint32_t rows, std::vector<float>& out, Op op) {
  const uint32_t h = w / 2;
  out.resize(size_t(h) * (rows / 2));
  for (uint32_t y = 0; y < rows / 2; ++y) {
    const float* r0 = &in[size_t(2 * y) * w];
    const float* r1 = r0 + w;
    float* o = &out[size_t(y) * h];
    for (uint32_t x = 0; x < h; ++x) o[x] = op(op(r0[2 * x], r0[2 * x + 1]), op(r1[2 * x], r1[2 * x + 1]));
  }
}
// The same for an n x n array.
template <typename Op>
void reduce2x2(const std::vector<float>& in, uint32_t n, std::vector<float>& out, Op op) {
  reduceRects2x2(in, n, n, out, op);
}

// Per-cell max (or min) of the four corner samples of each level-0 cell: M x rows from S x (rows + 1)
// (rows = M: the whole square).
template <typename Op>
void cellReduce(const float* s, uint32_t S, uint32_t rows, std::vector<float>& out, Op op) {
  const uint32_t M = S - 1;
  out.resize(size_t(M) * rows);
  for (uint32_t y = 0; y < rows; ++y) {
    const float* r0 = s + size_t(y) * S;
    const float* r1 = r0 + S;
    float* o = &out[size_t(y) * M];
    for (uint32_t x = 0; x < M; ++x) o[x] = op(op(r0[x], r0[x + 1]), op(r1[x], r1[x + 1]));
  }
}
template <typename Op>
void cellReduce(const std::vector<float>& s, uint32_t S, std::vector<float>& out, Op op) {
  cellReduce(s.data(), S, S - 1, out, op);
}

// Sizes a chart's node arrays: bounds zero, flags clear, every error NaN (resolutions the node
// cannot use stay NaN).
void initChartNodes(const HierarchyParams& p, Hierarchy::ChartNodes& out) {
  const uint32_t nodes = nodesPerChart(p.depth);
  out.bounds.assign(nodes, {});
  out.flags.assign(nodes, 0);
  out.errors.assign(size_t(nodes) * p.resCount(), std::numeric_limits<float>::quiet_NaN());
}

// Writes the per-node values of an M x M per-cell array (and its 2x2 reductions) for every level
// that has a node: out(level, x, y, value).
// Returns the value of the whole array (level 0's).
template <typename Op, typename Out>
// note: `cells` is read, not copied: at a chart of 4097 it is 64 MiB, and a copy a call (a dozen
// calls a chart) was most of a planet hierarchy's time, in copies and page faults.
float forEachNodeReduction(const std::vector<float>& cells, uint32_t L, uint32_t depth, Op op, Out out) {
  std::vector<float> a, b;
  const std::vector<float>* level = &cells;
  for (uint32_t n = 1u << L, l = L;; n /= 2, --l) {
    if (l < depth)
      for (uint32_t y = 0; y < n; ++y)
        for (uint32_t x = 0; x < n; ++x) out(l, x, y, (*level)[size_t(y) * n + x]);
    if (n == 1) break;
    std::vector<float>& next = level == &a ? b : a;
    reduce2x2(*level, n, next, op);
    level = &next;
  }
  return (*level)[0];
}

// Node errors for every usable (level, res): 0 at the source resolution; above it the max over
// the node's samples of the running level error (accumulateLevelError), so errors never
// decrease as resolution drops.
template <typename T, typename Dist>
void fillErrors(const HierarchyParams& p, const std::vector<T>& samples, Dist dist, Hierarchy::ChartNodes& out) {
  const uint32_t L = p.intervalsLog2;
  const uint32_t S = (1u << L) + 1;
  const uint32_t rc = p.resCount();
  for (uint32_t l = 0; l < p.depth; ++l) {
    const uint32_t r = L - l;
    if (r > p.maxResLog2(l) || r < p.minNodeResLog2) continue;
    for (uint32_t i = nodeIndex(l, 0, 0); i < nodeIndex(l, 0, 0) + (1u << 2 * l); ++i)
      out.errors[size_t(i) * rc + (r - p.minNodeResLog2)] = 0.0f;
  }
  auto fmax = [](float a, float b) { return std::max(a, b); };
  const uint32_t kmax = L - p.minNodeResLog2;
  std::vector<float> running(size_t(S) * S, 0.0f), cells;
  for (uint32_t k = 1; k <= kmax; ++k) {
    accumulateLevelError(samples, S, k, running, dist);
    cellReduce(running, S, cells, fmax);
    forEachNodeReduction(cells, L, p.depth, fmax, [&](uint32_t l, uint32_t x, uint32_t y, float v) {
      if (L < l + k) return;
      const uint32_t r = L - l - k;
      if (r >= p.minNodeResLog2 && r <= p.maxResLog2(l))
        out.errors[size_t(nodeIndex(l, x, y)) * rc + (r - p.minNodeResLog2)] = v;
    });
  }
}

// running[(y - y0) * S + x] = max(itself, |h_i - surface_k|) for rows [y0, y1] of an S x S height
// tile, level k's surface as forEachLevelSample gives it, the same floats: each cell's row is split
// where it crosses the diagonal (dx = dy), so that the loops run without a branch a sample.
void accumulateHeightError(const std::vector<float>& h, uint32_t S, uint32_t k, uint32_t y0, uint32_t y1,
                           float* running) {
  const uint32_t M = S - 1, n = M >> k, s = 1u << k;
  const float inv = 1.0f / float(s);
  for (uint32_t y = y0; y <= y1; ++y) {
    const uint32_t cy = std::min(y >> k, n - 1), dy = y - cy * s;
    const float fy = float(dy) * inv;
    const float* row0 = &h[size_t(cy * s) * S];
    const float* row1 = &h[size_t((cy + 1) * s) * S];
    const float* hy = &h[size_t(y) * S];
    float* ry = running + size_t(y - y0) * S;
    for (uint32_t cx = 0; cx < n; ++cx) {
      const uint32_t x0 = cx * s, xend = (cx == n - 1) ? s : s - 1;
      const float h00 = row0[x0], h10 = row0[x0 + s], h01 = row1[x0], h11 = row1[x0 + s];
      const float upper = h00 + fy * (h01 - h00), du = h11 - h01;  // dx < dy
      const float dl = h10 - h00, lower = fy * (h11 - h10);        // dx >= dy
      const uint32_t split = std::min(dy, xend + 1);
      for (uint32_t dx = 0; dx < split; ++dx) {
        const float surface = upper + float(dx) * inv * du;
        ry[x0 + dx] = std::max(ry[x0 + dx], std::fabs(hy[x0 + dx] - surface));
      }
      for (uint32_t dx = split; dx <= xend; ++dx) {
        const float surface = h00 + float(dx) * inv * dl + lower;
        ry[x0 + dx] = std::max(ry[x0 + dx], std::fabs(hy[x0 + dx] - surface));
      }
    }
  }
}

// accumulateHeightError for a geometry image: Euclidean distances (PointDistance), each component
// of the surface computed as cellSurface computes it, the same floats.
void accumulatePointError(const std::vector<glm::vec3>& h, uint32_t S, uint32_t k, uint32_t y0, uint32_t y1,
                          float* running) {
  const uint32_t M = S - 1, n = M >> k, s = 1u << k;
  const float inv = 1.0f / float(s);
  auto dist = [](const glm::vec3& p, float x, float y, float z) {
    const float dx = p.x - x, dy = p.y - y, dz = p.z - z;
    return std::sqrt(dx * dx + dy * dy + dz * dz);
  };
  for (uint32_t y = y0; y <= y1; ++y) {
    const uint32_t cy = std::min(y >> k, n - 1), dy = y - cy * s;
    const float fy = float(dy) * inv;
    const glm::vec3* row0 = &h[size_t(cy * s) * S];
    const glm::vec3* row1 = &h[size_t((cy + 1) * s) * S];
    const glm::vec3* hy = &h[size_t(y) * S];
    float* ry = running + size_t(y - y0) * S;
    for (uint32_t cx = 0; cx < n; ++cx) {
      const uint32_t x0 = cx * s, xend = (cx == n - 1) ? s : s - 1;
      const glm::vec3 h00 = row0[x0], h10 = row0[x0 + s], h01 = row1[x0], h11 = row1[x0 + s];
      const glm::vec3 upper = h00 + fy * (h01 - h00), du = h11 - h01;  // dx < dy
      const glm::vec3 dl = h10 - h00, lower = fy * (h11 - h10);        // dx >= dy
      const uint32_t split = std::min(dy, xend + 1);
      for (uint32_t dx = 0; dx < split; ++dx) {
        const float fx = float(dx) * inv;
        const float d = dist(hy[x0 + dx], upper.x + fx * du.x, upper.y + fx * du.y, upper.z + fx * du.z);
        ry[x0 + dx] = std::max(ry[x0 + dx], d);
      }
      for (uint32_t dx = split; dx <= xend; ++dx) {
        const float fx = float(dx) * inv;
        const float d =
            dist(hy[x0 + dx], h00.x + fx * dl.x + lower.x, h00.y + fx * dl.y + lower.y, h00.z + fx * dl.z + lower.z);
        ry[x0 + dx] = std::max(ry[x0 + dx], d);
      }
    }
  }
}

// A tile of 2^t intervals of a chart of 2^L intervals, at chart sample (ox, oy): its samples h
// ((2^t + 1)^2, row = v), and the chart's pyramid level t (`coarse`, `coarseSide` a side), whose
// samples are the corners of the cells larger than the tile. T: float (heights) or glm::vec3.
template <typename T>
struct TileSamples {
  const std::vector<T>& h;
  const std::vector<T>& coarse;
  uint32_t coarseSide = 0;
  uint32_t L = 0, t = 0, ox = 0, oy = 0;
};

// running[(y - y0) * S + x] = max(itself, dist(h_i, surface_k)) for the samples of rows [y0, y1] of
// `tile`, for a level k > t whose cells are larger than the tile: their corners are samples of the
// chart's level t. The cells and the weights are forEachLevelSample's over the whole chart.
template <typename T, typename Dist>
void accumulateCoarseError(const TileSamples<T>& tile, uint32_t k, uint32_t y0, uint32_t y1, float* running,
                           Dist dist) {
  const std::vector<T>& h = tile.h;
  const std::vector<T>& coarse = tile.coarse;
  const uint32_t coarseSide = tile.coarseSide, ox = tile.ox, oy = tile.oy;
  const uint32_t S = (1u << tile.t) + 1, n = (1u << tile.L) >> k, s = 1u << k, step = 1u << (k - tile.t);
  const float inv = 1.0f / float(s);
  for (uint32_t y = y0; y <= y1; ++y) {
    const uint32_t Y = oy + y, cy = std::min(Y >> k, n - 1);
    const float fy = float(Y - cy * s) * inv;
    const T* row0 = &coarse[size_t(cy * step) * coarseSide];
    const T* row1 = &coarse[size_t((cy + 1) * step) * coarseSide];
    for (uint32_t x = 0; x < S; ++x) {
      const uint32_t X = ox + x, cx = std::min(X >> k, n - 1);
      const float fx = float(X - cx * s) * inv;
      const uint32_t c0 = cx * step, c1 = (cx + 1) * step;
      const T surface = cellSurface(row0[c0], row0[c1], row1[c0], row1[c1], fx, fy);
      float& r = running[size_t(y - y0) * S + x];
      r = std::max(r, dist(h[size_t(y) * S + x], surface));
    }
  }
}

// Errors of the nodes inside tile (tx, ty) of `tile` (tile.t intervals a side): 0 at the source
// resolution, then at res r = L - l - k the largest running error of level k (accumulateLevelError)
// over the node's samples, so errors never decrease as resolution drops; a positive error grows by
// margin[k] where margin is not empty. Writes only the tile's own nodes; returns, per level k, the
// largest running error over the tile's samples (with its margin), for the nodes above the tile.
template <typename Dist, typename T>
std::vector<float> tileErrors(const HierarchyParams& p, Hierarchy::ChartNodes& out, const TileSamples<T>& tile,
                              uint32_t tx, uint32_t ty, const std::vector<float>& margin) {
  const Dist dist;
  const uint32_t L = p.intervalsLog2, t = tile.t, S = (1u << t) + 1, shift = L - t, rc = p.resCount();
  const uint32_t depth = p.depth > shift ? p.depth - shift : 0;  // the tile's own levels
  auto fmax = [](float a, float b) { return std::max(a, b); };
  for (uint32_t l = 0; l < depth; ++l) {
    const uint32_t r = L - l - shift;
    if (r > p.maxResLog2(l + shift) || r < p.minNodeResLog2) continue;
    for (uint32_t y = 0; y < (1u << l); ++y)
      for (uint32_t x = 0; x < (1u << l); ++x)
        out.errors[size_t(nodeIndex(l + shift, (tx << l) + x, (ty << l) + y)) * rc + (r - p.minNodeResLog2)] = 0.0f;
  }
  const uint32_t kmax = L - p.minNodeResLog2;
  auto grown = [&](uint32_t k, float v) { return margin.empty() || !(v > 0.0f) ? v : v + margin[k]; };
  // Node (l, x, y) of the tile at res r = L - l - shift - k takes v, the largest running error of
  // level k over its samples.
  auto put = [&](uint32_t k, uint32_t l, uint32_t x, uint32_t y, float v) {
    if (l >= depth || L < l + shift + k) return;
    const uint32_t r = L - l - shift - k;
    if (r >= p.minNodeResLog2 && r <= p.maxResLog2(l + shift))
      out.errors[size_t(nodeIndex(l + shift, (tx << l) + x, (ty << l) + y)) * rc + (r - p.minNodeResLog2)] =
          grown(k, v);
  };
  // Band by band of B cell rows, every level k in turn, so that a band's running errors and cells
  // stay in cache: the nodes of B cells or fewer a side are finished in their band, the larger
  // ones from each level's blocks of B x B cells (W x W of them).
  const uint32_t b = std::min(t, 5u), B = 1u << b, W = (1u << t) >> b;
  std::vector<std::vector<float>> blocks(kmax + 1, std::vector<float>(size_t(W) * W));
  std::vector<float> running(size_t(B + 1) * S), cells, tmp;
  for (uint32_t band = 0; band < W; ++band) {
    const uint32_t y0 = band * B;
    std::fill(running.begin(), running.end(), 0.0f);
    for (uint32_t k = 1; k <= kmax; ++k) {
      if (k > t)
        accumulateCoarseError(tile, k, y0, y0 + B, running.data(), dist);
      else if constexpr (std::is_same_v<T, float>)
        accumulateHeightError(tile.h, S, k, y0, y0 + B, running.data());
      else
        accumulatePointError(tile.h, S, k, y0, y0 + B, running.data());
      cellReduce(running.data(), S, B, cells, fmax);
      for (uint32_t w = S - 1, rows = B, l = t;; w /= 2, rows /= 2, --l) {
        for (uint32_t y = 0; y < rows; ++y)
          for (uint32_t x = 0; x < w; ++x) put(k, l, x, band * rows + y, cells[size_t(y) * w + x]);
        if (rows == 1) break;
        reduceRects2x2(cells, w, rows, tmp, fmax);
        cells.swap(tmp);
      }
      std::copy(cells.begin(), cells.end(), blocks[k].begin() + std::ptrdiff_t(size_t(band) * W));
    }
  }
  std::vector<float> levelError(kmax + 1, 0.0f);
  for (uint32_t k = 1; k <= kmax; ++k)
    levelError[k] =
        grown(k, forEachNodeReduction(blocks[k], t - b, depth, fmax, [&](uint32_t l, uint32_t x, uint32_t y, float v) {
                if (l < t - b) put(k, l, x, y, v);
              }));
  return levelError;
}

// What the nodes above a tile need of it: its samples' range (heights, or boxes) and, per pyramid
// level k, the largest running error (fillErrors) over its samples.
template <typename T>
struct TileSummary {
  T lo = T(0), hi = T(0);
  std::vector<float> levelError;  // [k], k = 0 .. intervalsLog2 - minNodeResLog2
};
using HeightTileSummary = TileSummary<float>;

// A terrain chart whose nodes are being built: the hierarchy's parameters, the atlas, the chart,
// and its nodes.
struct TerrainChartNodes {
  const HierarchyParams& p;
  const AtlasManifest& m;
  const ChartInfo& chart;
  Hierarchy::ChartNodes& out;
};

// Node (l, x, y)'s bounds and flag, from its place in the chart and its heights' range [lo, hi].
void setNodeBounds(const TerrainChartNodes& c, uint32_t l, uint32_t x, uint32_t y, float lo, float hi) {
  const AtlasManifest& m = c.m;
  const ChartInfo& chart = c.chart;
  Hierarchy::ChartNodes& out = c.out;
  const uint32_t L = c.p.intervalsLog2;
  const uint32_t idx = nodeIndex(l, x, y), size = (1u << L) >> l;
  const int64_t ox = (int64_t(chart.gridX) << L) + int64_t(x) * size,
                oy = (int64_t(chart.gridY) << L) + int64_t(y) * size;
  out.bounds[idx] = {float(double(ox) * m.spacing[0]),        float(double(oy) * m.spacing[1]),        lo,
                     float(double(ox + size) * m.spacing[0]), float(double(oy + size) * m.spacing[1]), hi};
  out.flags[idx] = ox >= int64_t(m.samplesX) - 1 || oy >= int64_t(m.samplesY) - 1 ? kNodeEmpty : 0;
}

// Bounds, flags and errors of the nodes inside tile (tx, ty) of 2^t level-0 intervals of terrain
// chart c, from the tile's heights h ((2^t + 1)^2, row = v); coarse: the chart's pyramid level t, for
// the levels whose cells are larger than the tile (t < intervalsLog2). A whole chart is its one
// tile (t = intervalsLog2). Node error at res r = max over the node's samples of the running level
// error (accumulateLevelError), so errors never decrease as resolution drops. Writes only the
// tile's own nodes; returns what the nodes above it need.
HeightTileSummary buildTerrainTile(const TerrainChartNodes& c, const std::vector<float>& h, uint32_t t, uint32_t tx,
                                   uint32_t ty, const std::vector<float>& coarse) {
  const HierarchyParams& p = c.p;
  const uint32_t L = p.intervalsLog2, S = (1u << t) + 1, shift = L - t;
  const uint32_t depth = p.depth > shift ? p.depth - shift : 0;  // the tile's own levels
  auto fmax = [](float a, float b) { return std::max(a, b); };
  auto fmin = [](float a, float b) { return std::min(a, b); };
  HeightTileSummary sum;
  // Bounds: min/max mips over cells.
  std::vector<float> mn, mx, tmp;
  cellReduce(h, S, mn, fmin);
  cellReduce(h, S, mx, fmax);
  for (uint32_t n = 1u << t, l = t;; n /= 2, --l) {
    if (l < depth)
      for (uint32_t y = 0; y < n; ++y)
        for (uint32_t x = 0; x < n; ++x)
          setNodeBounds(c, l + shift, (tx << l) + x, (ty << l) + y, mn[size_t(y) * n + x], mx[size_t(y) * n + x]);
    if (n == 1) break;
    reduce2x2(mn, n, tmp, fmin);
    mn.swap(tmp);
    reduce2x2(mx, n, tmp, fmax);
    mx.swap(tmp);
  }
  sum.lo = mn[0];
  sum.hi = mx[0];
  const TileSamples<float> tile{h, coarse, (1u << shift) + 1, L, t, tx << t, ty << t};
  sum.levelError = tileErrors<HeightDistance>(p, c.out, tile, tx, ty, {});
  return sum;
}

// Tile (tx, ty) of 2^t level-0 intervals of chart c, past the DEM's last sample (padding of the
// chart grid): its nodes are empty, never drawn, and take no reading; their bounds are flat at the
// lowest height and their errors 0. Its summary leaves the nodes above it to the tiles that hold
// data.
HeightTileSummary emptyTerrainTile(const TerrainChartNodes& c, uint32_t t, uint32_t tx, uint32_t ty) {
  const HierarchyParams& p = c.p;
  const uint32_t L = p.intervalsLog2, shift = L - t, rc = p.resCount();
  const float z = c.m.heightRange[0];
  for (uint32_t l = 0; l + shift < p.depth && l <= t; ++l)
    for (uint32_t y = 0; y < (1u << l); ++y)
      for (uint32_t x = 0; x < (1u << l); ++x) {
        const uint32_t gx = (tx << l) + x, gy = (ty << l) + y;
        setNodeBounds(c, l + shift, gx, gy, z, z);
        for (uint32_t r = p.minNodeResLog2; r <= p.maxResLog2(l + shift); ++r)
          c.out.errors[size_t(nodeIndex(l + shift, gx, gy)) * rc + (r - p.minNodeResLog2)] = 0.0f;
      }
  HeightTileSummary sum;
  sum.lo = std::numeric_limits<float>::infinity();
  sum.hi = -sum.lo;
  sum.levelError.assign(L - p.minNodeResLog2 + 1, 0.0f);
  return sum;
}

// The nodes of a tiled chart above its tiles of 2^t intervals (levels below intervalsLog2 - t), from
// the tiles' summaries (tiles x tiles, row-major): each takes the largest error and the range of
// its tiles; setBounds(l, x, y, summary) sets its bounds from the range.
template <typename T, typename SetBounds>
void buildAboveTiles(const HierarchyParams& p, Hierarchy::ChartNodes& out, uint32_t t, std::vector<TileSummary<T>> grid,
                     SetBounds setBounds) {
  const uint32_t L = p.intervalsLog2, rc = p.resCount();
  std::vector<TileSummary<T>> up;
  for (uint32_t n = 1u << (L - t), l = L - t; n > 1;) {
    n /= 2;
    --l;
    up.assign(size_t(n) * n, {});
    for (uint32_t y = 0; y < n; ++y)
      for (uint32_t x = 0; x < n; ++x) {
        TileSummary<T>& u = up[size_t(y) * n + x];
        u = grid[size_t(2 * y) * 2 * n + 2 * x];
        for (uint32_t i = 1; i < 4; ++i) {
          const TileSummary<T>& c = grid[size_t(2 * y + (i >> 1)) * 2 * n + 2 * x + (i & 1)];
          u.lo = glm::min(u.lo, c.lo);
          u.hi = glm::max(u.hi, c.hi);
          for (size_t k = 0; k < u.levelError.size(); ++k) u.levelError[k] = std::max(u.levelError[k], c.levelError[k]);
        }
        if (l >= p.depth) continue;
        setBounds(l, x, y, u);
        for (uint32_t k = 0; k < u.levelError.size() && k <= L - l; ++k) {
          const uint32_t r = L - l - k;
          if (r >= p.minNodeResLog2 && r <= p.maxResLog2(l))
            out.errors[size_t(nodeIndex(l, x, y)) * rc + (r - p.minNodeResLog2)] = u.levelError[k];
        }
      }
    grid.swap(up);
  }
}

void buildGeometryChart(const HierarchyParams& p, const std::vector<glm::vec3>& P, Hierarchy::ChartNodes& out) {
  const uint32_t L = p.intervalsLog2;
  const uint32_t M = 1u << L;
  const uint32_t S = M + 1;
  initChartNodes(p, out);
  auto fmax = [](float a, float b) { return std::max(a, b); };
  auto fmin = [](float a, float b) { return std::min(a, b); };

  // Bounds: per-component min/max mips over cells.
  std::vector<float> comp(size_t(S) * S), cells;
  for (int c = 0; c < 3; ++c) {
    for (size_t i = 0; i < comp.size(); ++i) comp[i] = P[i][c];
    cellReduce(comp, S, cells, fmin);
    forEachNodeReduction(cells, L, p.depth, fmin,
                         [&](uint32_t l, uint32_t x, uint32_t y, float v) { out.bounds[nodeIndex(l, x, y)][c] = v; });
    cellReduce(comp, S, cells, fmax);
    forEachNodeReduction(cells, L, p.depth, fmax, [&](uint32_t l, uint32_t x, uint32_t y, float v) {
      out.bounds[nodeIndex(l, x, y)][3 + c] = v;
    });
  }

  fillErrors(p, P, PointDistance{}, out);
}

// A build's figures: its samples and the time since t0, on this arena's threads.
void setStats(HierarchyStats* stats, uint64_t samples, std::chrono::steady_clock::time_point t0) {
  if (!stats) return;
  stats->threads = uint32_t(tbb::this_task_arena::max_concurrency());
  stats->samples = samples;
  stats->seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  stats->samplesPerSecond = stats->seconds > 0 ? double(stats->samples) / stats->seconds : 0.0;
}

// Four float steps of the largest coordinate in `points` (relative to their origin): how far a
// float position, or a distance measured between such positions, may be from its exact value.
float floatMargin(const glm::vec3* points, size_t count, float atLeast = 0.0f) {
  float e = 0.0f;
  for (size_t i = 0; i < count; ++i)
    e = std::max({e, std::fabs(points[i].x), std::fabs(points[i].y), std::fabs(points[i].z)});
  return std::max(atLeast, float(4.0 * double(e) * std::ldexp(1.0, -23)));
}

// A tile's error margins per level k (floatMargin, never decreasing with k): its own samples for
// k <= t, and for k > t the corners of the level-k cells its samples lie in (the chart's level t).
std::vector<float> tileMargins(const HierarchyParams& p, const GeometryTile& g, uint32_t t, uint32_t tx, uint32_t ty) {
  const uint32_t L = p.intervalsLog2, kmax = L - p.minNodeResLog2, T = 1u << t, side = ((1u << L) >> t) + 1;
  std::vector<float> margin(kmax + 1, floatMargin(g.positions.data(), g.positions.size()));
  for (uint32_t k = t + 1; k <= kmax; ++k) {
    const uint32_t n = (1u << L) >> k, step = 1u << (k - t);
    float m = margin[k - 1];
    for (const uint32_t Y : {ty * T, ty * T + T})
      for (const uint32_t X : {tx * T, tx * T + T}) {
        const uint32_t cx = std::min(X >> k, n - 1), cy = std::min(Y >> k, n - 1);
        for (const uint32_t j : {cy, cy + 1})
          for (const uint32_t i : {cx, cx + 1}) m = floatMargin(&g.coarse[size_t(j * step) * side + i * step], 1, m);
      }
    margin[k] = m;
  }
  return margin;
}

// Bounds and errors of the nodes inside tile (tx, ty) of 2^t intervals of a geometry chart measured
// in tiles (buildTiledGeometryHierarchy); returns what the nodes above it need.
TileSummary<glm::vec3> buildGeometryTile(const HierarchyParams& p, Hierarchy::ChartNodes& out, const GeometryTile& g,
                                         uint32_t t, uint32_t tx, uint32_t ty) {
  const uint32_t L = p.intervalsLog2, S = (1u << t) + 1, shift = L - t;
  const uint32_t depth = p.depth > shift ? p.depth - shift : 0;  // the tile's own levels
  const std::vector<float> margin = tileMargins(p, g, t, tx, ty);
  const float inf = std::numeric_limits<float>::infinity();
  auto fmax = [](float a, float b) { return std::max(a, b); };
  auto fmin = [](float a, float b) { return std::min(a, b); };
  TileSummary<glm::vec3> sum;
  // Bounds: per-component min/max mips over cells, grown by the margin and rounded outwards.
  std::vector<float> comp(size_t(S) * S), mn, mx, tmp;
  for (int c = 0; c < 3; ++c) {
    for (size_t i = 0; i < comp.size(); ++i) comp[i] = g.positions[i][c];
    cellReduce(comp, S, mn, fmin);
    cellReduce(comp, S, mx, fmax);
    auto lo = [&](float v) { return std::nextafter(float(double(v) - double(margin[0]) + g.origin[c]), -inf); };
    auto hi = [&](float v) { return std::nextafter(float(double(v) + double(margin[0]) + g.origin[c]), inf); };
    for (uint32_t n = 1u << t, l = t;; n /= 2, --l) {
      if (l < depth)
        for (uint32_t y = 0; y < n; ++y)
          for (uint32_t x = 0; x < n; ++x) {
            auto& b = out.bounds[nodeIndex(l + shift, (tx << l) + x, (ty << l) + y)];
            b[c] = lo(mn[size_t(y) * n + x]);
            b[3 + c] = hi(mx[size_t(y) * n + x]);
          }
      if (n == 1) break;
      reduce2x2(mn, n, tmp, fmin);
      mn.swap(tmp);
      reduce2x2(mx, n, tmp, fmax);
      mx.swap(tmp);
    }
    sum.lo[c] = lo(mn[0]);
    sum.hi[c] = hi(mx[0]);
  }
  const TileSamples<glm::vec3> tile{g.positions, g.coarse, ((1u << L) >> t) + 1, L, t, tx << t, ty << t};
  sum.levelError = tileErrors<PointDistance>(p, out, tile, tx, ty, margin);
  return sum;
}

// Tile (tx, ty) past the data: its nodes take no reading, their boxes are empty at the origin and
// their errors 0; its summary leaves the nodes above it to the tiles that hold data.
TileSummary<glm::vec3> emptyGeometryTile(const HierarchyParams& p, Hierarchy::ChartNodes& out, uint32_t t, uint32_t tx,
                                         uint32_t ty) {
  const uint32_t L = p.intervalsLog2, shift = L - t, rc = p.resCount();
  for (uint32_t l = 0; l + shift < p.depth && l <= t; ++l)
    for (uint32_t y = 0; y < (1u << l); ++y)
      for (uint32_t x = 0; x < (1u << l); ++x) {
        const uint32_t i = nodeIndex(l + shift, (tx << l) + x, (ty << l) + y);
        out.bounds[i] = {};
        for (uint32_t r = p.minNodeResLog2; r <= p.maxResLog2(l + shift); ++r)
          out.errors[size_t(i) * rc + (r - p.minNodeResLog2)] = 0.0f;
      }
  TileSummary<glm::vec3> sum;
  sum.lo = glm::vec3(std::numeric_limits<float>::infinity());
  sum.hi = -sum.lo;
  sum.levelError.assign(L - p.minNodeResLog2 + 1, 0.0f);
  return sum;
}

// Throws InputError naming the chart and tile when a tile's arrays are not of their sizes or hold a
// non-finite position.
void checkGeometryTile(const GeometryTile& g, uint32_t chart, uint32_t tx, uint32_t ty, size_t tileSamples,
                       size_t coarseSamples) {
  const std::string where = "chart " + std::to_string(chart) + " tile " + std::to_string(tx) + "," + std::to_string(ty);
  if (g.positions.size() != tileSamples || g.coarse.size() != coarseSamples)
    throw InputError(where + ": expected " + std::to_string(tileSamples) + " positions and " +
                     std::to_string(coarseSamples) + " of the coarse level, got " + std::to_string(g.positions.size()) +
                     " and " + std::to_string(g.coarse.size()));
  for (const auto* v : {&g.positions, &g.coarse})
    for (const glm::vec3& q : *v)
      if (!std::isfinite(q.x) || !std::isfinite(q.y) || !std::isfinite(q.z))
        throw InputError(where + ": non-finite position");
}

void putBytes(std::vector<uint8_t>& b, const void* p, size_t n) {
  const size_t at = b.size();
  b.resize(at + n);
  if (n) std::memcpy(b.data() + at, p, n);
}

template <typename T>
void put(std::vector<uint8_t>& b, const T& v) {
  putBytes(b, &v, sizeof(T));
}

template <typename T>
void putVec(std::vector<uint8_t>& b, const std::vector<T>& v) {
  putBytes(b, v.data(), v.size() * sizeof(T));
}

}  // namespace

void HierarchyParams::validate() const {
  if (depth < 1) throw InputError(optionRef("depth") + " must be at least 1");
  if (minNodeResLog2 > maxNodeResLog2) throw InputError("minimum node resolution exceeds the maximum node resolution");
  if (maxNodeResLog2 > intervalsLog2) throw InputError("maximum node resolution exceeds the chart resolution");
  if (depth - 1 + minNodeResLog2 > intervalsLog2)
    throw InputError(optionRef("depth") + " " + std::to_string(depth) + " is too deep for charts of " +
                     std::to_string((1u << intervalsLog2) + 1) + " samples: leaves would have fewer than 2^" +
                     std::to_string(minNodeResLog2) + " intervals (max depth " +
                     std::to_string(intervalsLog2 - minNodeResLog2 + 1) + ")");
  if (depth > 12) throw InputError(optionRef("depth") + " must be at most 12");
}

HierarchyParams hierarchyParams(const AtlasManifest& m) {
  HierarchyParams p;
  p.intervalsLog2 = m.intervalsLog2();
  p.depth = m.depth;
  p.maxNodeResLog2 = m.maxNodeResLog2;
  p.minNodeResLog2 = m.minNodeResLog2;
  return p;
}

namespace {

// Throws InputError naming the chart when its finest level is over p.maxFinestLevel().
void checkFinestLevel(const HierarchyParams& p, uint32_t chart, uint32_t finest) {
  if (finest > p.maxFinestLevel())
    throw InputError("chart " + std::to_string(chart) + " has finest level " + std::to_string(finest) + ", over " +
                     std::to_string(p.maxFinestLevel()) + ", the most that leaves its leaves " +
                     std::to_string(1u << p.minNodeResLog2) + " intervals");
}

}  // namespace

std::vector<uint8_t> finestLevels(const AtlasManifest& m, const HierarchyParams& p) {
  std::vector<uint8_t> out;
  for (const ChartInfo& c : m.charts) {
    if (c.finestLevel == 0) continue;
    checkFinestLevel(p, c.id, c.finestLevel);
    out.resize(m.charts.size(), 0);
    out[c.id] = uint8_t(c.finestLevel);
  }
  return out;
}

Hierarchy buildTerrainHierarchy(const AtlasManifest& manifest, const ChartHeightSource& source, HierarchyStats* stats) {
  const uint32_t M = manifest.chartSize - 1;
  return buildTerrainHierarchy(
      manifest,
      [&](uint32_t c, uint32_t level, uint32_t u0, uint32_t v0, uint32_t n) {
        if (level != 0 || u0 != 0 || v0 != 0 || n != M)
          throw std::logic_error("buildTerrainHierarchy: a whole chart's heights expected");
        return source(c);
      },
      stats, M);
}

Hierarchy buildTerrainHierarchy(const AtlasManifest& manifest, const ChartWindowSource& source, HierarchyStats* stats,
                                uint32_t maxTile) {
  Hierarchy hier;
  hier.params = hierarchyParams(manifest);
  hier.params.validate();
  const uint32_t count = uint32_t(manifest.charts.size());
  hier.charts.resize(count);
  hier.roots.resize(count);
  for (uint32_t c = 0; c < count; ++c) hier.roots[c] = manifest.charts[c].neighbours;
  if (!std::has_single_bit(maxTile) || maxTile < 2)
    throw std::invalid_argument("buildTerrainHierarchy: the tile must be a power of two");

  const uint32_t L = hier.params.intervalsLog2, M = 1u << L;
  const uint32_t t = std::min(L, uint32_t(std::countr_zero(maxTile))), T = 1u << t, tiles = M / T;
  const uint32_t perChart = tiles * tiles;
  const auto t0 = std::chrono::steady_clock::now();
  const progress::ProgressStage stage("hierarchy", uint64_t(count) * perChart);
  // Each chart's level t, for the levels whose cells span several tiles.
  std::vector<std::vector<float>> coarse(count);
  std::vector<std::vector<HeightTileSummary>> summaries(count, std::vector<HeightTileSummary>(perChart));
  tbb::parallel_for(uint32_t(0), count, [&](uint32_t c) {
    initChartNodes(hier.params, hier.charts[c]);
    if (tiles > 1) coarse[c] = source(c, t, 0, 0, M >> t);
  });
  tbb::parallel_for(uint64_t(0), uint64_t(count) * perChart, [&](uint64_t i) {
    const uint32_t c = uint32_t(i / perChart), tile = uint32_t(i % perChart), tx = tile % tiles, ty = tile / tiles;
    const ChartInfo& chart = manifest.charts[c];
    if (tiles > 1 && ((int64_t(chart.gridX) << L) + int64_t(tx) * T >= int64_t(manifest.samplesX) - 1 ||
                      (int64_t(chart.gridY) << L) + int64_t(ty) * T >= int64_t(manifest.samplesY) - 1)) {
      summaries[c][tile] = emptyTerrainTile({hier.params, manifest, chart, hier.charts[c]}, t, tx, ty);
      progress::advance();
      return;
    }
    const std::vector<float> h = source(c, 0, tx * T, ty * T, T);
    if (h.size() != size_t(T + 1) * (T + 1))
      throw InputError("chart " + std::to_string(c) + ": expected " + std::to_string(T + 1) + "^2 heights");
    summaries[c][tile] = buildTerrainTile({hier.params, manifest, chart, hier.charts[c]}, h, t, tx, ty, coarse[c]);
    progress::advance();
  });
  if (tiles > 1)
    tbb::parallel_for(uint32_t(0), count, [&](uint32_t c) {
      const TerrainChartNodes nodes{hier.params, manifest, manifest.charts[c], hier.charts[c]};
      const float z = manifest.heightRange[0];
      // (Under empty tiles alone: flat at the lowest height, as they are.)
      buildAboveTiles(hier.params, hier.charts[c], t, std::move(summaries[c]),
                      [&](uint32_t l, uint32_t x, uint32_t y, const HeightTileSummary& u) {
                        setNodeBounds(nodes, l, x, y, u.lo <= u.hi ? u.lo : z, u.lo <= u.hi ? u.hi : z);
                      });
    });
  setStats(stats, uint64_t(count) * (M + 1) * (M + 1), t0);
  return hier;
}

Hierarchy buildGeometryHierarchy(const HierarchyParams& params, const std::vector<std::array<RootNeighbour, 4>>& roots,
                                 const ChartPositionSource& source, HierarchyStats* stats,
                                 const std::vector<uint8_t>& finestLevels) {
  Hierarchy hier;
  hier.params = params;
  hier.params.validate();
  const uint32_t count = uint32_t(roots.size());
  hier.charts.resize(count);
  hier.roots = roots;
  if (!finestLevels.empty()) {
    if (finestLevels.size() != count)
      throw std::invalid_argument("buildGeometryHierarchy: one finest level per chart expected");
    hier.finestLevels = finestLevels;
    for (uint32_t c = 0; c < count; ++c) checkFinestLevel(params, c, finestLevels[c]);
  }
  std::atomic<uint64_t> samples{0};
  const auto t0 = std::chrono::steady_clock::now();
  const progress::ProgressStage stage("hierarchy", count);
  tbb::parallel_for(uint32_t(0), count, [&](uint32_t c) {
    // A chart with coarser finest samples is built as a chart of their size: the same nodes, in
    // its own units.
    HierarchyParams own = params;
    own.intervalsLog2 -= hier.finestLevel(c);
    const uint32_t S = (1u << own.intervalsLog2) + 1;
    const std::vector<glm::vec3> P = source(c);
    if (P.size() != size_t(S) * S)
      throw InputError("chart " + std::to_string(c) + ": expected " + std::to_string(S) + "^2 positions, got " +
                       std::to_string(P.size()));
    for (const glm::vec3& q : P)
      if (!std::isfinite(q.x) || !std::isfinite(q.y) || !std::isfinite(q.z))
        throw InputError("chart " + std::to_string(c) + ": non-finite position in the geometry image");
    buildGeometryChart(own, P, hier.charts[c]);
    samples += P.size();
    progress::advance();
  });
  setStats(stats, samples, t0);
  return hier;
}

Hierarchy buildTiledGeometryHierarchy(const HierarchyParams& params,
                                      const std::vector<std::array<RootNeighbour, 4>>& roots,
                                      const GeometryTileSource& source, HierarchyStats* stats, uint32_t maxTile) {
  Hierarchy hier;
  hier.params = params;
  hier.params.validate();
  if (!std::has_single_bit(maxTile) || maxTile < 2)
    throw std::invalid_argument("buildTiledGeometryHierarchy: the tile must be a power of two");
  const uint32_t count = uint32_t(roots.size());
  hier.charts.resize(count);
  hier.roots = roots;
  const uint32_t L = params.intervalsLog2, M = 1u << L;
  const uint32_t t = std::min(L, uint32_t(std::countr_zero(maxTile))), T = 1u << t, tiles = M / T;
  const uint32_t perChart = tiles * tiles;
  const size_t tileSamples = size_t(T + 1) * (T + 1), coarseSamples = size_t(tiles + 1) * (tiles + 1);
  const auto t0 = std::chrono::steady_clock::now();
  const progress::ProgressStage stage("hierarchy", uint64_t(count) * perChart);
  std::vector<std::vector<TileSummary<glm::vec3>>> summaries(count, std::vector<TileSummary<glm::vec3>>(perChart));
  tbb::parallel_for(uint32_t(0), count, [&](uint32_t c) { initChartNodes(params, hier.charts[c]); });
  tbb::parallel_for(uint64_t(0), uint64_t(count) * perChart, [&](uint64_t i) {
    const uint32_t c = uint32_t(i / perChart), tile = uint32_t(i % perChart), tx = tile % tiles, ty = tile / tiles;
    const std::optional<GeometryTile> g = source(c, t, tx, ty);
    if (!g) {
      summaries[c][tile] = emptyGeometryTile(params, hier.charts[c], t, tx, ty);
    } else {
      checkGeometryTile(*g, c, tx, ty, tileSamples, tiles > 1 ? coarseSamples : 0);
      summaries[c][tile] = buildGeometryTile(params, hier.charts[c], *g, t, tx, ty);
    }
    progress::advance();
  });
  tbb::parallel_for(uint32_t(0), count, [&](uint32_t c) {
    Hierarchy::ChartNodes& out = hier.charts[c];
    if (tiles == 1) return;
    // (Under empty tiles alone: an empty box at the origin, as they have.)
    buildAboveTiles(params, out, t, std::move(summaries[c]),
                    [&](uint32_t l, uint32_t x, uint32_t y, const TileSummary<glm::vec3>& u) {
                      auto& b = out.bounds[nodeIndex(l, x, y)];
                      b = {};
                      if (u.lo.x <= u.hi.x) b = {u.lo.x, u.lo.y, u.lo.z, u.hi.x, u.hi.y, u.hi.z};
                    });
  });
  setStats(stats, uint64_t(count) * (M + 1) * (M + 1), t0);
  return hier;
}

namespace {

// Version 2 stores version 1's body (everything after magic and version) regrouped so that like
// bytes lie together: the header and every chart's roots, then every chart's bounds, flags and
// errors, each float array as four byte planes (least significant first); then zstd with its
// checksum. Regrouping is a permutation of the body's bytes: writeHierarchy writes the grouped
// order directly, and reading undoes it and parses version 1.
struct BodyLayout {
  uint32_t count = 0, nodes = 0, resCount = 0;
  static constexpr size_t kHeader = 5 * 4, kRoots = 4 * (4 + 1 + 1);
  size_t boundsBytes() const { return size_t(nodes) * sizeof(std::array<float, 6>); }
  size_t errorBytes() const { return size_t(nodes) * resCount * sizeof(float); }
  size_t perChart() const { return kRoots + boundsBytes() + nodes + errorBytes(); }
  size_t size() const { return kHeader + size_t(count) * perChart(); }
};

// The version-1 order of a grouped body (per chart: roots, bounds, flags, errors), after `prefix`.
std::vector<uint8_t> ungroup(std::span<const uint8_t> prefix, std::span<const uint8_t> in, const BodyLayout& l) {
  std::vector<uint8_t> v1(prefix.size() + in.size());
  std::memcpy(v1.data(), prefix.data(), prefix.size());
  uint8_t* out = v1.data() + prefix.size();
  const size_t charts = l.count, bounds = l.boundsBytes(), errors = l.errorBytes();
  const size_t rootsAt = BodyLayout::kHeader, boundsAt = rootsAt + charts * BodyLayout::kRoots,
               flagsAt = boundsAt + charts * bounds, errorsAt = flagsAt + charts * l.nodes;
  // A float array of `bytes` at v1 offset `at` from the byte planes of the section at `section`,
  // chart c's floats at float index `first`.
  auto planes = [&](size_t at, size_t section, size_t total, size_t first, size_t bytes) {
    const size_t floats = total / 4;
    for (size_t i = 0; i < bytes / 4; ++i)
      for (size_t b = 0; b < 4; ++b) out[at + 4 * i + b] = in[section + b * floats + first + i];
  };
  std::memcpy(out, in.data(), BodyLayout::kHeader);
  for (size_t c = 0; c < charts; ++c) {
    const size_t at = BodyLayout::kHeader + c * l.perChart();
    std::memcpy(out + at, in.data() + rootsAt + c * BodyLayout::kRoots, BodyLayout::kRoots);
    planes(at + BodyLayout::kRoots, boundsAt, charts * bounds, c * bounds / 4, bounds);
    std::memcpy(out + at + BodyLayout::kRoots + bounds, in.data() + flagsAt + c * l.nodes, l.nodes);
    planes(at + BodyLayout::kRoots + bounds + l.nodes, errorsAt, charts * errors, c * errors / 4, errors);
  }
  return v1;
}

BodyLayout layoutOf(const HierarchyParams& p, uint32_t count) { return {count, nodesPerChart(p.depth), p.resCount()}; }

}  // namespace

namespace {

// Version 3 (HierarchyCoding::kQuantized). A node's box below a chart's root is its parent's (as
// decoded) inset on each of its six sides by q / 255 of the parent's extent on that axis, q a
// byte; the root's box is stored whole. Each q is the largest whose inset side still holds the
// node's own box, so a decoded box holds every sample the node's exact box held. Each error is
// rounded up to its top 16 bits (bfloat16: within 2^-7 of it, never below it; NaN stays NaN).
// The insets are computed in double and rounded to float once, with no step a compiler may fuse
// or reorder, so every reader decodes the same floats.
float insetLow(float lo, float hi, uint8_t q) {
  return float(std::fma(double(hi) - double(lo), double(q) / 255.0, double(lo)));
}
float insetHigh(float lo, float hi, uint8_t q) {
  return float(std::fma(double(lo) - double(hi), double(q) / 255.0, double(hi)));
}

// The largest q whose inset side (low: rising from lo; high: falling from hi) does not pass
// `side`; -1 when even q = 0 does (the node's box is not inside its parent's).
int insetFor(float lo, float hi, float side, bool low) {
  auto holds = [&](int q) {
    return low ? insetLow(lo, hi, uint8_t(q)) <= side : insetHigh(lo, hi, uint8_t(q)) >= side;
  };
  if (!holds(0)) return -1;
  const double extent = double(hi) - double(lo);
  int q = extent > 0.0 ? int(std::clamp(std::floor((low ? side - lo : hi - side) / extent * 255.0), 0.0, 255.0)) : 0;
  while (q > 0 && !holds(q)) --q;
  while (q < 255 && holds(q + 1)) ++q;
  return q;
}

uint16_t errorCode(float e) {
  if (std::isnan(e)) return 0x7FC0;
  uint32_t u;
  std::memcpy(&u, &e, 4);
  return uint16_t((uint64_t(u) + 0xFFFF) >> 16);  // (e >= 0: rounds the magnitude up)
}
float errorOfCode(uint16_t c) {
  const uint32_t u = uint32_t(c) << 16;
  float e;
  std::memcpy(&e, &u, 4);
  return e;
}

// The parent of node n of a chart (level order), for n >= 1.
uint32_t parentNode(uint32_t n) {
  uint32_t level = 0;
  while (nodeIndex(level + 1, 0, 0) <= n) ++level;
  const uint32_t i = n - nodeIndex(level, 0, 0), side = 1u << level;
  return nodeIndex(level - 1, (i % side) / 2, (i / side) / 2);
}

struct QuantizedLayout {
  uint32_t count = 0, nodes = 0, resCount = 0;
  static constexpr size_t kHeader = 5 * 4, kRoots = 4 * (4 + 1 + 1), kRootBox = 6 * 4;
  size_t size() const {
    return kHeader + size_t(count) * (kRoots + kRootBox + size_t(nodes - 1) * 6 + nodes + size_t(nodes) * resCount * 2);
  }
};

// The body of version 3 (before zstd), or nothing when some box is not inside its parent's or
// some error is negative (the file is then written as version 2). Layout: the header (as in
// version 1), every chart's roots, the root boxes as 4 byte planes of their floats, the insets as
// 6 planes (low x, y, z, high x, y, z; chart by chart, node by node from 1), the flags, then the
// error codes as 2 planes (high bytes first).
std::optional<std::vector<uint8_t>> quantizedBody(const Hierarchy& h) {
  const uint32_t count = uint32_t(h.charts.size()), nodes = nodesPerChart(h.params.depth);
  const QuantizedLayout l{count, nodes, h.params.resCount()};
  std::vector<uint8_t> insets(size_t(count) * (nodes - 1) * 6);
  const size_t plane = size_t(count) * (nodes - 1);
  std::vector<std::array<float, 6>> decoded(nodes);
  for (uint32_t c = 0; c < count; ++c) {
    const auto& b = h.charts[c].bounds;
    decoded[0] = b[0];
    for (uint32_t n = 1; n < nodes; ++n) {
      const std::array<float, 6>& parent = decoded[parentNode(n)];
      for (uint32_t k = 0; k < 6; ++k) {
        const bool low = k < 3;
        const float lo = parent[k % 3], hi = parent[k % 3 + 3];
        const int q = insetFor(lo, hi, b[n][k], low);
        if (q < 0) return std::nullopt;
        insets[k * plane + size_t(c) * (nodes - 1) + (n - 1)] = uint8_t(q);
        decoded[n][k] = low ? insetLow(lo, hi, uint8_t(q)) : insetHigh(lo, hi, uint8_t(q));
      }
    }
  }
  std::vector<uint8_t> body;
  body.reserve(l.size());
  const uint32_t header[5] = {count, h.params.intervalsLog2, h.params.depth, h.params.maxNodeResLog2,
                              h.params.minNodeResLog2};
  putBytes(body, header, sizeof header);
  for (uint32_t c = 0; c < count; ++c)
    for (const RootNeighbour& n : h.roots[c]) {
      const uint8_t rev = n.reversed;
      putBytes(body, &n.chart, 4);
      putBytes(body, &n.edge, 1);
      putBytes(body, &rev, 1);
    }
  for (uint32_t byte = 0; byte < 4; ++byte)
    for (uint32_t c = 0; c < count; ++c)
      for (const float v : h.charts[c].bounds[0]) body.push_back(reinterpret_cast<const uint8_t*>(&v)[byte]);
  body.insert(body.end(), insets.begin(), insets.end());
  for (const Hierarchy::ChartNodes& n : h.charts) body.insert(body.end(), n.flags.begin(), n.flags.end());
  for (const uint32_t shift : {8u, 0u})
    for (const Hierarchy::ChartNodes& n : h.charts)
      for (const float e : n.errors) {
        if (e < 0.0f) return std::nullopt;
        body.push_back(uint8_t(errorCode(e) >> shift));
      }
  return body;
}

// Version 3's body decoded, after its header's checks (count, params). Throws InputError naming
// the file where a box is inverted.
Hierarchy readQuantizedBody(const std::filesystem::path& path, std::span<const uint8_t> body, uint32_t count,
                            const HierarchyParams& params) {
  const uint32_t nodes = nodesPerChart(params.depth), rc = params.resCount();
  const QuantizedLayout l{count, nodes, rc};
  if (body.size() != l.size())
    throw InputError(path.string() + ": hierarchy file holds " + std::to_string(body.size()) +
                     " bytes once decoded, its header (" + std::to_string(count) + " charts of depth " +
                     std::to_string(params.depth) + ") needs " + std::to_string(l.size()));
  Hierarchy h;
  h.params = params;
  h.charts.resize(count);
  h.roots.resize(count);
  size_t at = QuantizedLayout::kHeader;
  for (uint32_t c = 0; c < count; ++c)
    for (RootNeighbour& n : h.roots[c]) {
      std::memcpy(&n.chart, body.data() + at, 4);
      n.edge = body[at + 4];
      n.reversed = body[at + 5] != 0;
      at += 6;
      if (n.chart >= int32_t(count) || n.edge > 3) throw InputError(path.string() + ": corrupt root neighbour");
    }
  const size_t rootBoxes = at, insets = rootBoxes + size_t(count) * 24, plane = size_t(count) * (nodes - 1);
  const size_t flags = insets + 6 * plane, errors = flags + size_t(count) * nodes;
  const size_t errorPlane = size_t(count) * nodes * rc;
  for (uint32_t c = 0; c < count; ++c) {
    Hierarchy::ChartNodes& cn = h.charts[c];
    cn.bounds.resize(nodes);
    for (uint32_t k = 0; k < 6; ++k) {
      uint8_t v[4];
      for (uint32_t byte = 0; byte < 4; ++byte)
        v[byte] = body[rootBoxes + byte * size_t(count) * 6 + size_t(c) * 6 + k];
      std::memcpy(&cn.bounds[0][k], v, 4);
    }
    for (uint32_t n = 1; n < nodes; ++n) {
      const std::array<float, 6>& parent = cn.bounds[parentNode(n)];
      for (uint32_t k = 0; k < 6; ++k) {
        const uint8_t q = body[insets + k * plane + size_t(c) * (nodes - 1) + (n - 1)];
        cn.bounds[n][k] = k < 3 ? insetLow(parent[k], parent[k + 3], q) : insetHigh(parent[k - 3], parent[k], q);
      }
    }
    for (const std::array<float, 6>& b : cn.bounds)
      if (!(b[0] <= b[3] && b[1] <= b[4] && b[2] <= b[5]))
        throw InputError(path.string() + ": chart " + std::to_string(c) +
                         " has a node box that is inverted or not finite");
    cn.flags.assign(body.begin() + flags + size_t(c) * nodes, body.begin() + flags + size_t(c + 1) * nodes);
    cn.errors.resize(size_t(nodes) * rc);
    for (size_t i = 0; i < cn.errors.size(); ++i) {
      const size_t e = size_t(c) * nodes * rc + i;
      cn.errors[i] = errorOfCode(uint16_t(body[errors + e] << 8 | body[errors + errorPlane + e]));
    }
  }
  return h;
}

}  // namespace

void writeHierarchy(const std::filesystem::path& path, const Hierarchy& h, HierarchyCoding coding) {
  if (coding == HierarchyCoding::kQuantized) {
    for (const Hierarchy::ChartNodes& c : h.charts)
      if (c.bounds.size() != nodesPerChart(h.params.depth) || c.flags.size() != c.bounds.size() ||
          c.errors.size() != c.bounds.size() * h.params.resCount())
        throw std::invalid_argument("writeHierarchy: a chart's arrays do not match the parameters");
    if (const std::optional<std::vector<uint8_t>> body = quantizedBody(h)) {
      std::vector<uint8_t> out;
      putBytes(out, kMagic, 4);
      put(out, kQuantizedHierarchyVersion);
      const std::vector<uint8_t> coded = compressBytes(*body);
      out.insert(out.end(), coded.begin(), coded.end());
      atomicWriteFile(path, out.data(), out.size());
      return;
    }
  }
  writeHierarchy(path, h, coding != HierarchyCoding::kRaw);
}

void writeHierarchy(const std::filesystem::path& path, const Hierarchy& h, bool compressed) {
  // Streamed in pieces of about 1 MiB (coded as they come): the body is never held whole, so an
  // atlas's hierarchy takes about its own size in memory to write, however many charts it has.
  AtomicFileWriter file(path);
  std::vector<uint8_t> head;
  putBytes(head, kMagic, 4);
  put(head, compressed ? kCompressedHierarchyVersion : kHierarchyVersion);
  file.write(head.data(), head.size());
  const uint32_t count = uint32_t(h.charts.size());
  const BodyLayout l = layoutOf(h.params, count);
  for (const Hierarchy::ChartNodes& c : h.charts)
    if (c.bounds.size() != l.nodes || c.flags.size() != l.nodes || c.errors.size() != size_t(l.nodes) * l.resCount)
      throw std::invalid_argument("writeHierarchy: a chart's arrays do not match the parameters");
  std::optional<BytesCompressor> coder;
  if (compressed) coder.emplace(l.size(), [&](const uint8_t* p, size_t n) { file.write(p, n); });
  std::vector<uint8_t> piece;
  auto flush = [&] {
    if (coder)
      coder->add(piece);
    else
      file.write(piece.data(), piece.size());
    piece.clear();
  };
  auto emit = [&](const void* p, size_t n) {
    putBytes(piece, p, n);
    if (piece.size() >= (size_t(1) << 20)) flush();
  };
  auto roots = [&](uint32_t c) {
    for (const RootNeighbour& n : h.roots[c]) {
      const uint8_t rev = n.reversed;
      emit(&n.chart, 4);
      emit(&n.edge, 1);
      emit(&rev, 1);
    }
  };
  // Byte plane b of every chart's float array (the grouped order; see BodyLayout).
  auto planes = [&](auto array) {
    for (size_t b = 0; b < 4; ++b)
      for (uint32_t c = 0; c < count; ++c) {
        const auto& v = array(h.charts[c]);
        const uint8_t* bytes = reinterpret_cast<const uint8_t*>(v.data());
        const size_t floats = v.size() * sizeof(v[0]) / 4;
        const size_t at = piece.size();
        piece.resize(at + floats);
        for (size_t i = 0; i < floats; ++i) piece[at + i] = bytes[4 * i + b];
        if (piece.size() >= (size_t(1) << 20)) flush();
      }
  };
  const uint32_t header[5] = {count, h.params.intervalsLog2, h.params.depth, h.params.maxNodeResLog2,
                              h.params.minNodeResLog2};
  emit(header, sizeof header);
  if (compressed) {
    for (uint32_t c = 0; c < count; ++c) roots(c);
    planes([](const Hierarchy::ChartNodes& n) -> const auto& { return n.bounds; });
    for (const Hierarchy::ChartNodes& n : h.charts) emit(n.flags.data(), n.flags.size());
    planes([](const Hierarchy::ChartNodes& n) -> const auto& { return n.errors; });
  } else {
    for (uint32_t c = 0; c < count; ++c) {
      roots(c);
      emit(h.charts[c].bounds.data(), h.charts[c].bounds.size() * sizeof(h.charts[c].bounds[0]));
      emit(h.charts[c].flags.data(), h.charts[c].flags.size());
      emit(h.charts[c].errors.data(), h.charts[c].errors.size() * sizeof(float));
    }
  }
  flush();
  if (coder) coder->finish();
  file.commit();
}

Hierarchy readHierarchy(const std::filesystem::path& path) {
  std::ifstream f(path, std::ios::binary);
  if (!f) throw InputError(path.string() + ": cannot open hierarchy file");
  std::vector<uint8_t> b((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
  size_t pos = 0;
  auto get = [&](void* dst, size_t n) {
    if (pos + n > b.size()) throw InputError(path.string() + ": hierarchy file is truncated");
    std::memcpy(dst, b.data() + pos, n);
    pos += n;
  };
  char magic[4];
  get(magic, 4);
  if (std::memcmp(magic, kMagic, 4) != 0) throw InputError(path.string() + ": not a gimlod hierarchy file");
  uint32_t version, count;
  get(&version, 4);
  if (version != kHierarchyVersion && version != kCompressedHierarchyVersion && version != kQuantizedHierarchyVersion)
    throw InputError(path.string() + ": unsupported hierarchy version " + std::to_string(version));
  if (version != kHierarchyVersion) {
    // Back to version 1's bytes; the checks below then hold for both versions.
    std::vector<uint8_t> body;
    try {
      // No real body codes more than a few times smaller; a crafted frame header cannot claim more.
      body = decompressBytes({b.data() + pos, b.size() - pos}, 4096 * (b.size() - pos) + (size_t(1) << 20));
    } catch (const CodecError& e) {
      throw InputError(path.string() + ": " + e.what());
    }
    HierarchyParams p;
    if (body.size() < BodyLayout::kHeader) throw InputError(path.string() + ": hierarchy file is truncated");
    std::memcpy(&count, body.data(), 4);
    std::memcpy(&p.intervalsLog2, body.data() + 4, 4);
    std::memcpy(&p.depth, body.data() + 8, 4);
    std::memcpy(&p.maxNodeResLog2, body.data() + 12, 4);
    std::memcpy(&p.minNodeResLog2, body.data() + 16, 4);
    if (p.intervalsLog2 > 16 || p.depth > 12 || p.maxNodeResLog2 > 16 || p.minNodeResLog2 > p.maxNodeResLog2 ||
        count > (1u << 24))
      throw InputError(path.string() + ": corrupt hierarchy header");
    if (version == kQuantizedHierarchyVersion) {
      try {
        p.validate();
      } catch (const InputError& e) {
        throw InputError(path.string() + ": " + e.what());
      }
      return readQuantizedBody(path, body, count, p);
    }
    const BodyLayout l = layoutOf(p, count);
    if (body.size() != l.size())
      throw InputError(path.string() + ": hierarchy file holds " + std::to_string(body.size()) +
                       " bytes once decoded, its header (" + std::to_string(count) + " charts of depth " +
                       std::to_string(p.depth) + ") needs " + std::to_string(l.size()));
    std::vector<uint8_t> v1 = ungroup({b.data(), pos}, body, l);
    body = {};
    b = std::move(v1);
  }
  get(&count, 4);
  Hierarchy h;
  get(&h.params.intervalsLog2, 4);
  get(&h.params.depth, 4);
  get(&h.params.maxNodeResLog2, 4);
  get(&h.params.minNodeResLog2, 4);
  if (h.params.intervalsLog2 > 16 || h.params.depth > 12 || count > (1u << 24))
    throw InputError(path.string() + ": corrupt hierarchy header");
  try {
    h.params.validate();
  } catch (const InputError& e) {
    throw InputError(path.string() + ": " + e.what());
  }
  const uint32_t nodes = nodesPerChart(h.params.depth);
  // The header fixes the file's size: check it before allocating what a corrupt count claims.
  const uint64_t perChart =
      4 * (4 + 1 + 1) + uint64_t(nodes) * (sizeof(std::array<float, 6>) + 1 + sizeof(float) * h.params.resCount());
  if (uint64_t(b.size() - pos) != uint64_t(count) * perChart)
    throw InputError(path.string() + ": hierarchy file holds " + std::to_string(b.size()) + " bytes, its header (" +
                     std::to_string(count) + " charts of depth " + std::to_string(h.params.depth) + ") needs " +
                     std::to_string(pos + uint64_t(count) * perChart));
  h.charts.resize(count);
  h.roots.resize(count);
  for (uint32_t c = 0; c < count; ++c) {
    for (RootNeighbour& n : h.roots[c]) {
      uint8_t rev;
      get(&n.chart, 4);
      get(&n.edge, 1);
      get(&rev, 1);
      n.reversed = rev != 0;
      if (n.chart >= int32_t(count) || n.edge > 3) throw InputError(path.string() + ": corrupt root neighbour");
    }
    auto& cn = h.charts[c];
    cn.bounds.resize(nodes);
    cn.flags.resize(nodes);
    cn.errors.resize(size_t(nodes) * h.params.resCount());
    get(cn.bounds.data(), cn.bounds.size() * sizeof(cn.bounds[0]));
    get(cn.flags.data(), cn.flags.size());
    get(cn.errors.data(), cn.errors.size() * sizeof(float));
  }
  if (pos != b.size()) throw InputError(path.string() + ": trailing bytes in hierarchy file");
  return h;
}

}  // namespace gimlod
