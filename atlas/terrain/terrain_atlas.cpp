// Height-field atlas: chart grid, subsampled chart pyramids with normal maps, parallel writing.
// Based on: Niski, Purnomo, Cohen, "Multi-grained Level of Detail Using a Hierarchical Seamless
// Texture Atlas", I3D 2007, sections 4 and 6 (height-field case: the terrain grid is cut into
// (2^m+1)^2 charts sharing one row/column, and each chart is mip-mapped by subsampling).
#include "atlas/terrain/terrain_atlas.h"

#include "atlas/terrain/planet_grid.h"
#include "core/block_codec.h"
#include "core/progress.h"

#include <algorithm>
#include <atomic>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <mutex>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

namespace gimlod {

namespace fs = std::filesystem;

void validateTerrainAtlasOptions(const TerrainAtlasOptions& o) {
  const uint32_t cs = o.chartSize;
  if (cs < 9 || cs > kMaxTerrainChartSize || !std::has_single_bit(cs - 1))
    throw InputError(optionRef("chartSize") + " " + std::to_string(cs) + " is not 2^m+1 between 9 and " +
                     std::to_string(kMaxTerrainChartSize) + " (e.g. 129, 257, 513, 1025)");
  const uint32_t b = o.blockIntervals;
  if (b < 4 || b > 1024 || !std::has_single_bit(b))
    throw InputError(optionRef("blockIntervals") + " " + std::to_string(b) +
                     " is not a power of two between 4 and 1024 (e.g. 32, 64, 128)");
  if (b > cs - 1)
    throw InputError(optionRef("blockIntervals") + " " + std::to_string(b) + " exceeds " + optionRef("chartSize") +
                     " - 1 (" + std::to_string(cs - 1) + ")");
}

double terrainHeightPrecision(const fs::path& input, double requested, bool integerHeights, double fallback, float lo,
                              float hi) {
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

float storedHeight(float h, double precision) { return h == std::nearbyint(h) ? h : quantizeToStep(h, precision); }

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

// The same over the rows held (buildChartPyramid checks they cover what a chart row reads), or
// over a lattice of the DEM (DemRows::stride).
// Columns round a planet wrap into the window held (DemRows::wrapColumns): column x of a window
// [x0, x0 + cols) of a turn of `turn` columns (all in the same units: samples, or lattice samples).
inline int64_t wrappedColumn(int64_t x, int64_t x0, int64_t cols, int64_t turn) {
  return x < x0 ? x + turn : x >= x0 + cols ? x - turn : x;
}

inline float clampedHeight(const DemRows& dem, int64_t gx, int64_t gy) {
  const int64_t s = dem.stride;
  const int64_t cols = dem.cols > 0 ? dem.cols : dem.width;
  if (s > 1) {
    const int64_t i = dem.wrapColumns > 0 ? wrappedColumn(gx / s, dem.x0 / s, cols, dem.wrapColumns / s)
                                          : std::clamp<int64_t>(gx, 0, (dem.width - 2 + s) / s * s) / s;
    const int64_t j = std::clamp<int64_t>(gy, 0, (dem.height - 2 + s) / s * s) / s;
    return dem.heights[static_cast<size_t>(j - dem.y0 / s) * static_cast<size_t>(dem.cols) +
                       static_cast<size_t>(i - dem.x0 / s)];
  }
  gx = dem.wrapColumns > 0 ? wrappedColumn(gx, dem.x0, cols, dem.wrapColumns)
                           : std::clamp<int64_t>(gx, 0, dem.width - 1);
  gy = std::clamp<int64_t>(gy, 0, dem.height - 1);
  return dem.heights[static_cast<size_t>(gy - dem.y0) * static_cast<size_t>(cols) + static_cast<size_t>(gx - dem.x0)];
}

uint32_t chartsAlong(uint32_t samples, uint32_t m) {
  return std::max<uint32_t>(1, (samples - 1 + m - 1) / m);  // ceil((samples-1)/m)
}

}  // namespace

std::vector<float> extractChart(const DemRaster& dem, int32_t gridX, int32_t gridY, uint32_t chartSize) {
  const int64_t m = int64_t{chartSize} - 1;
  std::vector<float> out(size_t{chartSize} * chartSize);
  for (uint32_t v = 0; v < chartSize; ++v)
    for (uint32_t u = 0; u < chartSize; ++u)
      out[size_t{v} * chartSize + u] = clampedHeight(dem, gridX * m + u, gridY * m + v);
  return out;
}

ChartPyramid buildChartPyramid(const DemRaster& dem, int32_t gridX, int32_t gridY, uint32_t chartSize, bool keepRing) {
  if (dem.width == 0 || dem.height == 0 || dem.heights.size() != size_t{dem.width} * dem.height)
    throw std::invalid_argument("buildChartPyramid: empty or inconsistent DEM");
  return buildChartPyramid(wholeRows(dem), gridX, gridY, chartSize, keepRing);
}

DemRows wholeRows(const DemRaster& dem) {
  DemRows rows;
  rows.heights = dem.heights.data();
  rows.rows = rows.height = dem.height;
  rows.width = dem.width;
  rows.spacing = dem.spacing;
  rows.wrapColumns = dem.planet.wrapColumns;
  return rows;
}

std::array<int64_t, 2> chartRowSpan(int64_t gridY, uint32_t chartSize, int64_t height) {
  const int64_t m = int64_t{chartSize} - 1;
  return {std::max<int64_t>(0, gridY * m - m), std::min<int64_t>(height, gridY * m + 2 * m + 1)};
}

ChartPyramid buildChartPyramid(const DemRows& dem, int32_t gridX, int32_t gridY, uint32_t chartSize, bool keepRing) {
  if (chartSize < 3 || !std::has_single_bit(chartSize - 1))
    throw std::invalid_argument("buildChartPyramid: chartSize is not 2^m+1");
  const auto span = chartRowSpan(gridY, chartSize, dem.height);
  const auto columns = chartRowSpan(gridX, chartSize, dem.width);
  const int64_t cols = dem.cols > 0 ? dem.cols : dem.width;
  // Round a planet, a window narrower than the DEM holds the columns past its ends the chart reads.
  const int64_t m = int64_t{chartSize} - 1;
  const std::array<int64_t, 2> reach =
      dem.wrapColumns > 0 && cols < dem.width ? std::array<int64_t, 2>{gridX * m - m, gridX * m + 2 * m + 1} : columns;
  if (dem.width <= 0 || dem.height <= 0 || dem.stride != 1 || dem.y0 > span[0] || dem.y0 + dem.rows < span[1] ||
      dem.x0 > reach[0] || dem.x0 + cols < reach[1])
    throw std::invalid_argument("buildChartPyramid: the window held does not cover the chart");
  return buildPyramidLevels(dem, {gridX * m, gridY * m, chartSize - 1}, 0, uint32_t(std::countr_zero(chartSize - 1)),
                            keepRing);
}

ChartPyramid buildPyramidLevels(const DemRows& dem, const DemSquare& square, uint32_t first, uint32_t last,
                                bool keepRing) {
  const uint32_t intervals = square.intervals;
  if (!std::has_single_bit(intervals) || last > uint32_t(std::countr_zero(intervals)) || first > last ||
      (dem.stride > 1 && (!std::has_single_bit(uint64_t(dem.stride)) || dem.stride > (int64_t{1} << first))))
    throw std::invalid_argument("buildPyramidLevels: bad levels or lattice");
  HeightFieldFrame frame;
  frame.originX = square.originX;
  frame.originY = square.originY;
  frame.maxX = int64_t{dem.width} - 1;
  frame.maxY = int64_t{dem.height} - 1;
  frame.spacing = dem.spacing;
  frame.wrapX = dem.wrapColumns > 0;
  ChartPyramid p;
  p.heights.resize(last + 1);
  // With the ring, a compressed file derives the normals on reading: none are computed.
  if (keepRing) {
    p.ringHeights.resize(last + 1);
    p.frame = frame;
  } else {
    p.normals.resize(last + 1);
  }
  std::vector<float> ring;
  for (uint32_t k = first; k <= last; ++k) {
    const uint32_t s = (intervals >> k) + 1;
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
    for (uint32_t v = 0; v < s; ++v) std::copy_n(ring.data() + (v + 1) * rs + 1, s, h.data() + size_t{v} * s);
    if (keepRing) {
      p.ringHeights[k] = std::move(ring);
      ring = {};
    } else {
      p.normals[k].resize(size_t{s} * s);
      heightFieldNormals(ring.data() + rs + 1, rs, {k, 0, 0, s, s}, frame, p.normals[k].data());
    }
  }
  return p;
}

ChartTiling chartTiling(uint32_t chartSize, uint32_t blockIntervals, uint32_t maxTile) {
  const uint32_t m = chartSize - 1;
  if (!std::has_single_bit(m) || !std::has_single_bit(blockIntervals) || !std::has_single_bit(maxTile) ||
      maxTile < 2 * blockIntervals)
    throw std::invalid_argument("chartTiling: sizes must be powers of two, the tile at least two blocks");
  ChartTiling t;
  t.tile = std::min(m, maxTile);
  t.tilesPerSide = m / t.tile;
  const uint32_t levels = uint32_t(std::countr_zero(m)) + 1;
  t.coarseLevel =
      t.tiled() ? uint32_t(std::countr_zero(t.tile)) - uint32_t(std::countr_zero(blockIntervals)) + 1 : levels;
  return t;
}

std::array<int64_t, 4> tileSpan(const TiledChart& c, uint32_t tx, uint32_t ty, int64_t width, int64_t height) {
  const ChartTiling& t = c.tiling;
  const int64_t m = int64_t{c.chartSize} - 1, margin = t.margin();
  const int64_t ox = c.gridX * m + int64_t{tx} * t.tile, oy = c.gridY * m + int64_t{ty} * t.tile;
  auto span = [&](int64_t o, int64_t n) {
    const int64_t lo = std::clamp<int64_t>(o - margin, 0, n - 1);
    return std::array<int64_t, 2>{lo, std::clamp<int64_t>(o + t.tile + margin + 1, lo + 1, n)};
  };
  const auto x = span(ox, width), y = span(oy, height);
  return {x[0], y[0], x[1], y[1]};
}

namespace {

// Where a pyramid's level goes in a chart file: its `side` samples a side start at block (bx0, by0)
// of the file's level `level`.
struct LevelSquare {
  uint32_t level = 0, side = 0;
  uint32_t bx0 = 0, by0 = 0;
};

// Codes the blocks of level sq.level of a pyramid for `file` (blocks of its blockIntervals),
// appending them to `out`.
void codePyramidLevel(const ChartPyramid& p, const LevelSquare& sq, const ChartFileWriter& file, bool ring,
                      std::vector<ChartFileWriter::CodedBlock>& out) {
  const uint32_t k = sq.level, side = sq.side, bx0 = sq.bx0, by0 = sq.by0;
  const uint32_t b = std::min(file.blockIntervals(), side - 1);
  const uint32_t blocks = (side - 1) / b;
  const size_t rs = size_t{side} + 2;
  for (uint32_t by = 0; by < blocks; ++by)
    for (uint32_t bx = 0; bx < blocks; ++bx) {
      const size_t at = size_t{by * b} * side + size_t{bx} * b;
      BlockData d;
      d[kChannelHeights] = {p.heights[k].data() + at, side};
      if (ring)
        d[kChannelHeights] = {p.ringHeights[k].data() + size_t{by * b} * rs + size_t{bx} * b, rs};
      else
        d[kChannelNormals] = {p.normals[k].data() + at, side};
      out.push_back(file.code(k, bx0 + bx, by0 + by, d));
    }
}

}  // namespace

std::vector<ChartFileWriter::CodedBlock> codeChartTile(const DemRows& dem, const TiledChart& c, uint32_t tx,
                                                       uint32_t ty, const ChartFileWriter& file, bool ring) {
  const ChartTiling& t = c.tiling;
  const int64_t m = int64_t{c.chartSize} - 1;
  const ChartPyramid p =
      buildPyramidLevels(dem, {c.gridX * m + int64_t{tx} * t.tile, c.gridY * m + int64_t{ty} * t.tile, t.tile}, 0,
                         t.coarseLevel - 1, ring);
  const uint32_t blockIntervals = file.blockIntervals();
  std::vector<ChartFileWriter::CodedBlock> out;
  for (uint32_t k = 0; k < t.coarseLevel; ++k) {
    const uint32_t perTile = (t.tile >> k) / blockIntervals;
    codePyramidLevel(p, {k, (t.tile >> k) + 1, tx * perTile, ty * perTile}, file, ring, out);
  }
  return out;
}

void writeChartCoarseLevels(const DemRows& dem, const TiledChart& c, ChartFileWriter& file, bool ring) {
  const ChartTiling& t = c.tiling;
  const int64_t m = int64_t{c.chartSize} - 1;
  const uint32_t last = uint32_t(std::countr_zero(c.chartSize - 1));
  if (t.coarseLevel > last) return;
  const ChartPyramid p =
      buildPyramidLevels(dem, {c.gridX * m, c.gridY * m, c.chartSize - 1}, t.coarseLevel, last, ring);
  std::vector<ChartFileWriter::CodedBlock> blocks;
  for (uint32_t k = t.coarseLevel; k <= last; ++k) {
    blocks.clear();
    codePyramidLevel(p, {k, uint32_t(m >> k) + 1, 0, 0}, file, ring, blocks);
    for (const auto& b : blocks) file.append(b);
  }
}

std::unique_ptr<ChartFileWriter> openTerrainChart(const fs::path& path, const AtlasManifest& manifest,
                                                  const ChartInfo& c, const TerrainAtlasOptions& o) {
  std::optional<HeightFieldFrame> frame;
  const uint32_t chartSize = manifest.chartSize;
  if (o.coding.compressed) {
    const int64_t m = int64_t{chartSize} - 1;
    frame = HeightFieldFrame{c.gridX * m,
                             c.gridY * m,
                             int64_t{manifest.samplesX} - 1,
                             int64_t{manifest.samplesY} - 1,
                             manifest.spacing,
                             manifest.planet.wrapColumns > 0};
  }
  const ChartFileShape shape{chartSize, o.blockIntervals, uint32_t(std::countr_zero(chartSize - 1)) + 1,
                             (1u << kChannelHeights) | (1u << kChannelNormals)};
  return std::make_unique<ChartFileWriter>(path, shape, o.coding, frame);
}

void fillTerrainManifest(const DemRaster& dem, const TerrainAtlasOptions& options, AtlasManifest& manifest) {
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
  manifest.planet = dem.planet;
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
        c.neighbours[e] =
            present ? RootNeighbour{static_cast<int32_t>(other), otherEdge, true} : RootNeighbour{-1, 0, true};
      };
      link(kEdgeBottom, y > 0, id - cx, kEdgeTop);
      link(kEdgeRight, x + 1 < cx, id + 1, kEdgeLeft);
      link(kEdgeTop, y + 1 < cy, id + cx, kEdgeBottom);
      link(kEdgeLeft, x > 0, id - 1, kEdgeRight);
    }
  }
  linkPlanetSeam(manifest);
}

struct TiledChartWriter::Chart {
  std::unique_ptr<ChartFileWriter> file;
  std::mutex mutex;
  uint32_t next = 0;  // the tile to append next
  std::map<uint32_t, std::vector<ChartFileWriter::CodedBlock>> waiting;
};

TiledChartWriter::TiledChartWriter(const fs::path& dir, const AtlasManifest& manifest,
                                   const TerrainAtlasOptions& options, const ChartTiling& tiling)
    : manifest_(manifest), options_(options), tiling_(tiling) {
  for (const ChartInfo& c : manifest.charts) {
    charts_.push_back(std::make_unique<Chart>());
    charts_.back()->file = openTerrainChart(dir / c.file, manifest, c, options);
  }
}

TiledChartWriter::~TiledChartWriter() = default;

void TiledChartWriter::writeTile(const DemRows& dem, uint32_t chart, uint32_t tx, uint32_t ty) {
  const ChartInfo& c = manifest_.charts.at(chart);
  Chart& out = *charts_[chart];
  std::vector<ChartFileWriter::CodedBlock> blocks = codeChartTile(dem, {c.gridX, c.gridY, manifest_.chartSize, tiling_},
                                                                  tx, ty, *out.file, options_.coding.compressed);
  const std::lock_guard<std::mutex> lock(out.mutex);
  out.waiting.emplace(ty * tiling_.tilesPerSide + tx, std::move(blocks));
  for (auto it = out.waiting.begin(); it != out.waiting.end() && it->first == out.next; it = out.waiting.erase(it)) {
    for (const auto& b : it->second) out.file->append(b);
    ++out.next;
  }
}

uint64_t TiledChartWriter::finish(const DemRows& coarse) {
  std::atomic<uint64_t> bytes{0};
  tbb::parallel_for(size_t{0}, charts_.size(), [&](size_t i) {
    const ChartInfo& c = manifest_.charts[i];
    Chart& out = *charts_[i];
    if (out.next != tiling_.tilesPerSide * tiling_.tilesPerSide)
      throw std::logic_error("TiledChartWriter: chart " + std::to_string(i) + " lacks tiles");
    writeChartCoarseLevels(coarse, {c.gridX, c.gridY, manifest_.chartSize, tiling_}, *out.file,
                           options_.coding.compressed);
    bytes += out.file->commit();
    out.file.reset();
  });
  return bytes.load();
}

uint64_t writeTiledCharts(const DemRaster& dem, const fs::path& dir, const AtlasManifest& manifest,
                          const TerrainAtlasOptions& options, const ChartTiling& tiling, int concurrency) {
  const DemRows rows = wholeRows(dem);
  TiledChartWriter writer(dir, manifest, options, tiling);
  const uint32_t perChart = tiling.tilesPerSide * tiling.tilesPerSide;
  const size_t total = manifest.charts.size() * perChart;
  // Workers take the tiles in order, so a chart's tiles arrive nearly in turn.
  std::atomic<size_t> next{0};
  tbb::task_arena arena(concurrency);
  const progress::ProgressStage stage("chart tiles", total);
  arena.execute([&] {
    tbb::parallel_for(0, concurrency, [&](int) {
      for (size_t i; (i = next++) < total;) {
        const uint32_t tile = uint32_t(i % perChart);
        writer.writeTile(rows, uint32_t(i / perChart), tile % tiling.tilesPerSide, tile / tiling.tilesPerSide);
        progress::advance();
      }
    });
  });
  return arena.execute([&] { return writer.finish(rows); });
}

TerrainAtlasStats writeTerrainCharts(const DemRaster& dem, const TerrainAtlasOptions& options, const fs::path& dir,
                                     AtlasManifest& manifest) {
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
    throw InputError(chartDir.string() +
                     ": cannot create directory: " + (ec ? ec.message() : std::string("not a directory")));

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
      kMemoryBudget / perChartBytes, 1, static_cast<uint64_t>(tbb::this_task_arena::max_concurrency())));
  std::atomic<uint64_t> bytes{0};
  const ChartTiling tiling = chartTiling(cs, options.blockIntervals);
  if (tiling.tiled()) {
    // A tile in flight holds its pyramid with ring heights and its coded blocks: about 24 bytes per
    // level-0 sample.
    const uint64_t perTile = uint64_t{tiling.tile + 1} * (tiling.tile + 1) * 24;
    bytes = writeTiledCharts(
        dem, dir, manifest, options, tiling,
        int(std::clamp<uint64_t>(kMemoryBudget / perTile, 1, uint64_t(tbb::this_task_arena::max_concurrency()))));
  } else {
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
  }

  TerrainAtlasStats st;
  st.charts = uint32_t(manifest.charts.size());
  st.samples = uint64_t{dem.width} * dem.height;
  st.storedSamples = perChart * st.charts;
  st.bytesOnDisk = bytes.load();
  st.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return st;
}

}  // namespace gimlod
