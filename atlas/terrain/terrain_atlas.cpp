// Height-field atlas: chart grid, subsampled chart pyramids with normal maps, parallel writing.
// Based on: Niski, Purnomo, Cohen, "Multi-grained Level of Detail Using a Hierarchical Seamless
// Texture Atlas", I3D 2007, sections 4 and 6 (height-field case: the terrain grid is cut into
// (2^m+1)^2 charts sharing one row/column, and each chart is mip-mapped by subsampling).
#include "atlas/terrain/terrain_atlas.h"
#include "core/block_codec.h"
#include "core/progress.h"

#include <algorithm>
#include <atomic>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

namespace gimlod {

namespace fs = std::filesystem;

void validateTerrainAtlasOptions(const TerrainAtlasOptions& o) {
  const uint32_t cs = o.chartSize;
  if (cs < 9 || cs > 8193 || !std::has_single_bit(cs - 1))
    throw InputError(optionRef("chartSize") + " " + std::to_string(cs) +
                     " is not 2^m+1 between 9 and 8193 (e.g. 129, 257, 513, 1025)");
  const uint32_t b = o.blockIntervals;
  if (b < 4 || b > 1024 || !std::has_single_bit(b))
    throw InputError(optionRef("blockIntervals") + " " + std::to_string(b) +
                     " is not a power of two between 4 and 1024 (e.g. 32, 64, 128)");
  if (b > cs - 1)
    throw InputError(optionRef("blockIntervals") + " " + std::to_string(b) + " exceeds " + optionRef("chartSize") +
                     " - 1 (" +
                     std::to_string(cs - 1) + ")");
}

double terrainHeightPrecision(const fs::path& input, double requested, bool integerHeights, double fallback,
                              float lo, float hi) {
  const double p = requested > 0.0 ? requested : integerHeights ? 1.0 : fallback;
  const double top = std::max(std::abs(double(lo)), std::abs(double(hi)));
  if (top / p > double(1u << 23)) {
    char text[256];
    std::snprintf(text, sizeof text, ": heights reach %.1f m, more than 2^23 steps of ", top);
    throw InputError(input.string() + text + optionRef("heightPrecision") + " " + std::to_string(p) +
                     " m; give a coarser precision or " + optionRef("compress"));
  }
  return p;
}

float storedHeight(float h, double precision) {
  return h == std::nearbyint(h) ? h : quantizeToStep(h, precision);
}

std::string chartFileName(uint32_t id) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "charts/chart_%04u.bin", id);
  return buf;
}

namespace {

// Height of global sample (gx, gy), edge-clamped to the DEM.
inline float clampedHeight(const DemRaster& dem, int64_t gx, int64_t gy) {
  gx = std::clamp<int64_t>(gx, 0, int64_t{dem.width} - 1);
  gy = std::clamp<int64_t>(gy, 0, int64_t{dem.height} - 1);
  return dem.heights[static_cast<size_t>(gy) * dem.width + static_cast<size_t>(gx)];
}

// The same over the rows held (buildChartPyramid checks they cover what a chart row reads).
inline float clampedHeight(const DemRows& dem, int64_t gx, int64_t gy) {
  gx = std::clamp<int64_t>(gx, 0, dem.width - 1);
  gy = std::clamp<int64_t>(gy, 0, dem.height - 1);
  const int64_t cols = dem.cols > 0 ? dem.cols : dem.width;
  return dem.heights[static_cast<size_t>(gy - dem.y0) * static_cast<size_t>(cols) + static_cast<size_t>(gx - dem.x0)];
}

uint32_t chartsAlong(uint32_t samples, uint32_t m) {
  return std::max<uint32_t>(1, (samples - 1 + m - 1) / m);  // ceil((samples-1)/m)
}

}  // namespace

std::vector<float> extractChart(const DemRaster& dem, int32_t gridX, int32_t gridY,
                                uint32_t chartSize) {
  const int64_t m = int64_t{chartSize} - 1;
  std::vector<float> out(size_t{chartSize} * chartSize);
  for (uint32_t v = 0; v < chartSize; ++v)
    for (uint32_t u = 0; u < chartSize; ++u)
      out[size_t{v} * chartSize + u] = clampedHeight(dem, gridX * m + u, gridY * m + v);
  return out;
}

ChartPyramid buildChartPyramid(const DemRaster& dem, int32_t gridX, int32_t gridY, uint32_t chartSize,
                               bool keepRing) {
  if (dem.width == 0 || dem.height == 0 || dem.heights.size() != size_t{dem.width} * dem.height)
    throw std::invalid_argument("buildChartPyramid: empty or inconsistent DEM");
  DemRows rows;
  rows.heights = dem.heights.data();
  rows.rows = rows.height = dem.height;
  rows.width = dem.width;
  rows.spacing = dem.spacing;
  return buildChartPyramid(rows, gridX, gridY, chartSize, keepRing);
}

std::array<int64_t, 2> chartRowSpan(int64_t gridY, uint32_t chartSize, int64_t height) {
  const int64_t m = int64_t{chartSize} - 1;
  return {std::max<int64_t>(0, gridY * m - m), std::min<int64_t>(height, gridY * m + 2 * m + 1)};
}

ChartPyramid buildChartPyramid(const DemRows& dem, int32_t gridX, int32_t gridY, uint32_t chartSize,
                               bool keepRing) {
  if (chartSize < 3 || !std::has_single_bit(chartSize - 1))
    throw std::invalid_argument("buildChartPyramid: chartSize is not 2^m+1");
  const auto span = chartRowSpan(gridY, chartSize, dem.height);
  const auto columns = chartRowSpan(gridX, chartSize, dem.width);
  const int64_t cols = dem.cols > 0 ? dem.cols : dem.width;
  if (dem.width <= 0 || dem.height <= 0 || dem.y0 > span[0] || dem.y0 + dem.rows < span[1] ||
      dem.x0 > columns[0] || dem.x0 + cols < columns[1])
    throw std::invalid_argument("buildChartPyramid: the window held does not cover the chart");

  const int64_t m = int64_t{chartSize} - 1;
  const uint32_t levels = static_cast<uint32_t>(std::countr_zero(chartSize - 1)) + 1;
  HeightFieldFrame frame;
  frame.originX = gridX * m;
  frame.originY = gridY * m;
  frame.maxX = int64_t{dem.width} - 1;
  frame.maxY = int64_t{dem.height} - 1;
  frame.spacing = dem.spacing;
  ChartPyramid p;
  p.heights.resize(levels);
  p.normals.resize(levels);
  if (keepRing) {
    p.ringHeights.resize(levels);
    p.frame = frame;
  }
  std::vector<float> ring;
  for (uint32_t k = 0; k < levels; ++k) {
    const uint32_t s = static_cast<uint32_t>(m >> k) + 1;
    const size_t rs = size_t{s} + 2;
    // The level's heights with a one-sample ring of the neighbouring lattice, edge-clamped to the
    // DEM; the normals are differences over it (heightFieldNormals).
    ring.resize(rs * rs);
    for (size_t v = 0; v < rs; ++v) {
      const int64_t gy = frame.originY + ((int64_t(v) - 1) * (int64_t{1} << k));
      for (size_t u = 0; u < rs; ++u)
        ring[v * rs + u] = clampedHeight(dem, frame.originX + (int64_t(u) - 1) * (int64_t{1} << k), gy);
    }
    auto& h = p.heights[k];
    h.resize(size_t{s} * s);
    for (uint32_t v = 0; v < s; ++v)
      std::copy_n(ring.data() + (v + 1) * rs + 1, s, h.data() + size_t{v} * s);
    p.normals[k].resize(size_t{s} * s);
    heightFieldNormals(ring.data() + rs + 1, rs, 0, 0, s, s, k, frame, p.normals[k].data());
    if (keepRing) p.ringHeights[k] = ring;
  }
  return p;
}

void fillTerrainManifest(const DemRaster& dem, const TerrainAtlasOptions& options,
                         AtlasManifest& manifest) {
  validateTerrainAtlasOptions(options);
  const uint32_t cs = options.chartSize;
  const uint32_t cx = chartsAlong(dem.width, cs - 1), cy = chartsAlong(dem.height, cs - 1);
  manifest.kind = AtlasKind::Heightfield;
  manifest.chartSize = cs;
  manifest.blockIntervals = options.blockIntervals;
  manifest.chartsX = cx;
  manifest.chartsY = cy;
  manifest.samplesX = dem.width;
  manifest.samplesY = dem.height;
  manifest.spacing = dem.spacing;
  manifest.heightRange = {dem.minHeight, dem.maxHeight};
  manifest.georef = dem.georef;
  manifest.voidsFilled = dem.voidsFilled;
  manifest.voidFillMethod = dem.voidFillMethod;
  const uint32_t blockLog2 = static_cast<uint32_t>(std::countr_zero(options.blockIntervals));
  manifest.maxNodeResLog2 = std::min(manifest.maxNodeResLog2, blockLog2);
  manifest.minNodeResLog2 = std::min(manifest.minNodeResLog2, manifest.maxNodeResLog2);
  manifest.depth = std::clamp(manifest.depth, 1u, manifest.intervalsLog2() + 1);

  manifest.charts.assign(size_t{cx} * cy, ChartInfo{});
  for (uint32_t y = 0; y < cy; ++y) {
    for (uint32_t x = 0; x < cx; ++x) {
      const uint32_t id = y * cx + x;
      ChartInfo& c = manifest.charts[id];
      c.id = id;
      c.gridX = static_cast<int32_t>(x);
      c.gridY = static_cast<int32_t>(y);
      c.file = chartFileName(id);
      auto link = [&](Edge e, bool present, uint32_t other, Edge otherEdge) {
        c.neighbours[e] = present ? RootNeighbour{static_cast<int32_t>(other), otherEdge, true}
                                  : RootNeighbour{-1, 0, true};
      };
      link(kEdgeBottom, y > 0, id - cx, kEdgeTop);
      link(kEdgeRight, x + 1 < cx, id + 1, kEdgeLeft);
      link(kEdgeTop, y + 1 < cy, id + cx, kEdgeBottom);
      link(kEdgeLeft, x > 0, id - 1, kEdgeRight);
    }
  }
}

TerrainAtlasStats writeTerrainCharts(const DemRaster& dem, const TerrainAtlasOptions& options,
                                     const fs::path& dir, AtlasManifest& manifest) {
  const auto start = std::chrono::steady_clock::now();
  validateTerrainAtlasOptions(options);
  if (dem.width == 0 || dem.height == 0 || dem.heights.size() != size_t{dem.width} * dem.height)
    throw std::invalid_argument("writeTerrainCharts: empty or inconsistent DEM");
  const uint32_t cs = options.chartSize;
  const uint32_t m = cs - 1;
  std::error_code ec;
  const fs::path chartDir = dir / "charts";
  fs::create_directories(chartDir, ec);
  if (ec || !fs::is_directory(chartDir))
    throw InputError(chartDir.string() + ": cannot create directory: " +
                     (ec ? ec.message() : std::string("not a directory")));

  fillTerrainManifest(dem, options, manifest);
  manifest.compression = CompressionInfo{};
  if (options.coding.compressed) {
    manifest.compression.present = true;
    manifest.compression.heightPrecision = options.coding.heightPrecision;
  }

  uint64_t perChart = 0;  // samples in one chart's pyramid
  for (uint32_t k = 0; k <= manifest.intervalsLog2(); ++k) {
    const uint64_t s = (m >> k) + 1;
    perChart += s * s;
  }
  // note: each chart in flight holds its pyramid and its file image (8 + 8 bytes per sample:
  // about 1.4 GB for chartSize 8193), so concurrency is capped by a memory budget.
  constexpr uint64_t kMemoryBudget = uint64_t{4} << 30;
  const uint64_t perChartBytes = perChart * 2 * (sizeof(float) + sizeof(PackedNormal));
  const int concurrency = static_cast<int>(std::clamp<uint64_t>(
      kMemoryBudget / perChartBytes, 1,
      static_cast<uint64_t>(tbb::this_task_arena::max_concurrency())));
  std::atomic<uint64_t> bytes{0};
  tbb::task_arena arena(concurrency);
  const progress::ProgressStage stage("charts", manifest.charts.size());
  arena.execute([&] {
    tbb::parallel_for(size_t{0}, manifest.charts.size(), [&](size_t i) {
      const ChartInfo& c = manifest.charts[i];
      const ChartPyramid p = buildChartPyramid(dem, c.gridX, c.gridY, cs, options.coding.compressed);
      bytes += writeChartFile(dir / c.file, p, cs, options.blockIntervals, options.coding);
      progress::advance();
    });
  });

  TerrainAtlasStats st;
  st.charts = uint32_t(manifest.charts.size());
  st.samples = uint64_t{dem.width} * dem.height;
  st.storedSamples = perChart * st.charts;
  st.bytesOnDisk = bytes.load();
  st.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return st;
}

}  // namespace gimlod
