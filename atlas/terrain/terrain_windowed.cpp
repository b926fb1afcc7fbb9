#include "atlas/terrain/terrain_windowed.h"

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <limits>
#include <map>
#include <string>
#include <vector>

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>
#include <tbb/task_group.h>

#include "atlas/terrain/scratch_raster.h"
#include "atlas/terrain/void_fill.h"
#include "core/block_codec.h"
#include "core/progress.h"

namespace gimlod {

namespace fs = std::filesystem;

namespace {

// Charts over kMaxChartTile + 1 samples, or whose window (a chart and a chart's margin each side)
// exceeds a quarter of the budget, are built in tiles: the largest that fit, a tile's window in a
// quarter of the budget and the tiles in flight in half of it.
ChartTiling windowTiling(uint32_t chartSize, uint32_t blockIntervals, uint64_t budget) {
  const uint64_t m = chartSize - 1;
  auto fits = [&](uint64_t t) {
    const uint64_t w = t + 2 * (t / blockIntervals) + 1;
    return w * w * 4 <= budget / 4 && (t + 1) * (t + 1) * 24 <= budget / 2;
  };
  uint32_t tile = kMaxChartTile;
  while (tile > 2 * blockIntervals && !fits(tile)) tile /= 2;
  if (m <= tile && (3 * m + 1) * (3 * m + 1) * 4 > budget / 4 && m / 2 >= 2 * blockIntervals) tile = uint32_t(m / 2);
  return chartTiling(chartSize, blockIntervals, tile);
}

// The heights of window w of a width x height DEM, as DemRows; wrap: the columns a planet's turn
// (0: none), past whose ends w may reach.
DemRows heldRows(const std::vector<float>& heights, const CellWindow& w, int64_t width, int64_t height,
                 const std::array<double, 2>& spacing, int64_t wrap) {
  DemRows rows;
  rows.wrapColumns = wrap;
  rows.heights = heights.data();
  rows.y0 = w.y0;
  rows.rows = w.height();
  rows.x0 = w.x0;
  rows.cols = w.width();
  rows.width = width;
  rows.height = height;
  rows.spacing = spacing;
  return rows;
}

// Window w of the scratch raster into out (w's cells). Round a planet of `wrap` columns a turn
// (0: none), w may reach past either end of the turn (x < 0, x > wrap): those columns are read
// from the other end.
void readWindow(const ScratchRaster& scratch, const CellWindow& w, int64_t wrap, float* out) {
  if (wrap == 0 || (w.x0 >= 0 && w.x1 <= wrap + 1)) return scratch.read(w, out, nullptr);
  std::vector<float> part;
  for (int64_t a = w.x0; a < w.x1;) {
    // The run of w's columns [a, b) whose columns in the raster are consecutive, a + shift on.
    const int64_t shift = a < 0 ? wrap : a > wrap ? -wrap : 0;
    const int64_t b = shift > 0 ? std::min<int64_t>(w.x1, 0) : shift < 0 ? w.x1 : std::min(w.x1, wrap + 1);
    const CellWindow from{a + shift, w.y0, b + shift, w.y1};
    part.resize(from.cells());
    scratch.read(from, part.data(), nullptr);
    for (int64_t y = 0; y < w.height(); ++y)
      std::copy_n(part.data() + y * from.width(), from.width(), out + y * w.width() + (a - w.x0));
    a = b;
  }
}

// Lattice indices (DemRows::stride) whose samples lie in [lo, hi) of a side of `samples`.
std::vector<int64_t> latticeIndices(int64_t lo, int64_t hi, int64_t samples, int64_t stride) {
  std::vector<int64_t> out;
  const int64_t n = latticeSamples(samples, stride);
  // A lattice sample's column min(i * stride, samples - 1) grows with i and is at most i * stride.
  for (int64_t i = (lo + stride - 1) / stride; i < n && std::min(i * stride, samples - 1) < hi; ++i) out.push_back(i);
  return out;
}

// Runs of consecutive selected chart columns [first, last) in chart row gy, each at most `group`
// long.
std::vector<std::array<uint32_t, 2>> selectedRuns(const std::vector<uint8_t>& selected, uint32_t chartsX, uint32_t gy,
                                                  uint64_t group) {
  std::vector<std::array<uint32_t, 2>> runs;
  for (uint32_t g0 = 0; g0 < chartsX;) {
    if (!selected[size_t(gy) * chartsX + g0]) {
      ++g0;
      continue;
    }
    uint32_t g1 = g0 + 1;
    while (g1 < chartsX && g1 - g0 < group && selected[size_t(gy) * chartsX + g1]) ++g1;
    runs.push_back({g0, g1});
    g0 = g1;
  }
  return runs;
}

// The stored height of a scratch sample (quantized as a compressed atlas stores it).
float storedOf(float h, const WindowedTerrainResult& r, bool compressed) {
  return compressed ? storedHeight(h, r.heightPrecision) : h;
}

// How tiled charts are built window by window: the atlas's options (the heights' step set), the
// tiling, and the memory the windows and the tiles in flight may use.
struct TiledWindows {
  TerrainAtlasOptions atlas;
  ChartTiling tiling;
  uint64_t budget = 0;
};

// The tiled charts of a DEM held in the scratch raster: rows of tiles across the selected charts,
// in groups of tiles from the window they read, then every selected chart's coarse levels from the
// DEM's lattice (gathered from the windows as they pass; the points the windows did not hold, the
// lattice a chart's coarse normals reach into round it, read a scratch tile at a time). Returns the
// files' bytes.
uint64_t writeTiledChartsWindowed(const ScratchRaster& scratch, const fs::path& dir, const AtlasManifest& manifest,
                                  const std::vector<uint8_t>& selected, const TiledWindows& plan,
                                  WindowedTerrainResult& r) {
  const TerrainAtlasOptions& atlas = plan.atlas;
  const ChartTiling& tiling = plan.tiling;
  const uint64_t budget = plan.budget;
  const int64_t width = manifest.samplesX, height = manifest.samplesY;
  const uint32_t cs = manifest.chartSize, tps = tiling.tilesPerSide;
  const uint64_t tilesX = uint64_t(manifest.chartsX) * tps;
  const uint64_t t = tiling.tile, margin = tiling.margin(), windowRows = t + 2 * margin + 1;
  const uint64_t groupTiles = std::clamp<uint64_t>((budget / 4 / (windowRows * 4) - 2 * margin - 1) / t, 1, tilesX);
  const int concurrency = int(std::clamp<uint64_t>(budget / 2 / ((t + 1) * (t + 1) * 24), 1,
                                                   uint64_t(tbb::this_task_arena::max_concurrency())));
  const int64_t stride = int64_t{1} << tiling.coarseLevel;
  const int64_t nx = latticeSamples(width, stride), ny = latticeSamples(height, stride);
  const bool compressed = atlas.coding.compressed;
  const int64_t wrap = manifest.planet.wrapColumns;
  std::vector<float> lattice(size_t(nx * ny));
  std::vector<uint8_t> gathered(lattice.size(), 0);
  // The writer opens the selected charts' files, in the manifest's order.
  AtlasManifest mine = manifest;
  mine.charts.clear();
  std::vector<uint32_t> local(manifest.charts.size(), 0);
  for (size_t c = 0; c < manifest.charts.size(); ++c)
    if (selected[c]) local[c] = uint32_t(mine.charts.size()), mine.charts.push_back(manifest.charts[c]);
  TiledChartWriter writer(dir, mine, atlas, tiling);
  tbb::task_arena arena(concurrency);
  std::vector<float> window;
  const progress::ProgressStage stage("chart tiles", uint64_t(mine.charts.size()) * tps * tps);
  for (uint32_t chartY = 0; chartY < manifest.chartsY; ++chartY)
    for (const auto& run : selectedRuns(selected, manifest.chartsX, chartY, std::max<uint64_t>(groupTiles / tps, 1)))
      for (uint32_t ty = 0; ty < tps; ++ty)
        for (uint64_t g0 = uint64_t(run[0]) * tps; g0 < uint64_t(run[1]) * tps; g0 += groupTiles) {
          const uint64_t g1 = std::min(g0 + groupTiles, uint64_t(run[1]) * tps);
          const auto first =
              tileSpan({int32_t(g0 / tps), int32_t(chartY), cs, tiling}, uint32_t(g0 % tps), ty, width, height);
          const auto last = tileSpan({int32_t((g1 - 1) / tps), int32_t(chartY), cs, tiling}, uint32_t((g1 - 1) % tps),
                                     ty, width, height);
          // Round a planet, the first and last tiles' margins lie past the antimeridian.
          const CellWindow w{wrap && g0 == 0 ? -int64_t(margin) : first[0], first[1],
                             wrap && g1 == tilesX ? width + int64_t(margin) : last[2], last[3]};
          r.bandRows = std::max<uint64_t>(r.bandRows, uint64_t(w.height()));
          r.bandColumns = std::max<uint64_t>(r.bandColumns, uint64_t(w.width()));
          window.resize(w.cells());
          arena.execute([&] { readWindow(scratch, w, wrap, window.data()); });
          for (float& x : window) x = storedOf(x, r, compressed);
          for (int64_t j : latticeIndices(w.y0, w.y1, height, stride)) {
            const int64_t y = std::min(j * stride, height - 1) - w.y0;
            for (int64_t i : latticeIndices(w.x0, w.x1, width, stride)) {
              lattice[size_t(j * nx + i)] = window[size_t(y * w.width() + std::min(i * stride, width - 1) - w.x0)];
              gathered[size_t(j * nx + i)] = 1;
            }
          }
          const DemRows view = heldRows(window, w, width, height, manifest.spacing, wrap);
          std::atomic<uint64_t> next{g0};
          arena.execute([&] {
            tbb::parallel_for(0, concurrency, [&](int) {
              for (uint64_t g; (g = next++) < g1;) {
                writer.writeTile(view, local[chartY * manifest.chartsX + uint32_t(g / tps)], uint32_t(g % tps), ty);
                progress::advance();
              }
            });
          });
        }
  // The lattice a selected chart's coarse levels read (the chart and a chart each side) that the
  // windows did not hold, a scratch tile at a time.
  const int64_t m = cs - 1, side = scratch.tileSide();
  std::map<std::pair<int64_t, int64_t>, std::vector<std::array<int64_t, 2>>> missing;  // by scratch tile
  for (const ChartInfo& c : mine.charts) {
    auto xs =
        latticeIndices(std::max<int64_t>(0, (c.gridX - 1) * m), std::min(width, (c.gridX + 2) * m + 1), width, stride);
    // Round a planet, the charts at the antimeridian reach a chart past it.
    auto reach = [&](int64_t lo, int64_t hi) {
      const auto more = latticeIndices(lo, hi, width, stride);
      xs.insert(xs.end(), more.begin(), more.end());
    };
    if (wrap && c.gridX == 0) reach(wrap - m, width);
    if (wrap && c.gridX + 1 == int32_t(manifest.chartsX)) reach(0, m + 1);
    const auto ys = latticeIndices(std::max<int64_t>(0, (c.gridY - 1) * m), std::min(height, (c.gridY + 2) * m + 1),
                                   height, stride);
    for (int64_t j : ys)
      for (int64_t i : xs) {
        const size_t k = size_t(j * nx + i);
        if (gathered[k]) continue;
        gathered[k] = 1;
        const int64_t x = std::min(i * stride, width - 1), y = std::min(j * stride, height - 1);
        missing[{y / side, x / side}].push_back({i, j});
      }
  }
  std::vector<const std::vector<std::array<int64_t, 2>>*> groups;
  for (const auto& [tile, points] : missing) groups.push_back(&points);
  arena.execute([&] {
    tbb::parallel_for(size_t{0}, groups.size(), [&](size_t g) {
      CellWindow w{width, height, 0, 0};
      for (const auto& [i, j] : *groups[g]) {
        const int64_t x = std::min(i * stride, width - 1), y = std::min(j * stride, height - 1);
        w = {std::min(w.x0, x), std::min(w.y0, y), std::max(w.x1, x + 1), std::max(w.y1, y + 1)};
      }
      std::vector<float> held(w.cells());
      scratch.read(w, held.data(), nullptr);
      for (const auto& [i, j] : *groups[g]) {
        const int64_t x = std::min(i * stride, width - 1), y = std::min(j * stride, height - 1);
        lattice[size_t(j * nx + i)] = storedOf(held[size_t((y - w.y0) * w.width() + x - w.x0)], r, compressed);
      }
    });
  });
  DemRows coarse;
  coarse.heights = lattice.data();
  coarse.rows = ny;
  coarse.cols = nx;
  coarse.width = width;
  coarse.height = height;
  coarse.spacing = manifest.spacing;
  coarse.stride = stride;
  coarse.wrapColumns = wrap;
  return arena.execute([&] { return writer.finish(coarse); });
}

}  // namespace

PreparedTerrainWindows prepareTerrainWindows(const DemSource& source, const fs::path& scratchFile,
                                             const WindowedTerrainOptions& options, AtlasManifest& manifest) {
  validateTerrainAtlasOptions(options.atlas);
  PreparedTerrainWindows prepared;
  WindowedTerrainResult& r = prepared.result;
  r.dem = source.info();
  DemRaster& dem = r.dem;
  const fs::path input = manifest.source.empty() ? fs::path("DEM") : fs::path(manifest.source);
  const uint64_t width = dem.width, height = dem.height;
  const uint64_t budget = std::max<uint64_t>(options.memoryBytes, uint64_t{16} << 20);

  // 1. Read: a row of scratch tiles at a time (heights, and a validity byte per sample). The
  // tile side is the largest power of two up to 256 whose row of tiles takes a quarter of the
  // budget; coding a band runs while the next one is read.
  uint32_t tile = 256;
  while (tile > 8 && uint64_t(tile) * width * 5 * 2 > budget / 4) tile /= 2;
  prepared.scratch = std::make_unique<ScratchRaster>(scratchFile, input, width, height, tile);
  ScratchRaster& scratch = *prepared.scratch;
  uint64_t voids = 0;
  float lo = std::numeric_limits<float>::infinity(), hi = -lo;
  // The range of the heights a compressed atlas stores, for the step chosen when the DEM is not
  // all whole metres (a whole-metre DEM stores its heights as they are).
  const double fallbackPrecision =
      options.heightPrecision > 0 ? options.heightPrecision : options.defaultHeightPrecision;
  float slo = lo, shi = hi;
  dem.integerHeights = true;
  {
    const uint64_t rowsPerBand = std::min<uint64_t>(tile, height);
    std::array<std::vector<float>, 2> h;
    std::array<std::vector<uint8_t>, 2> v;
    for (int i = 0; i < 2; ++i) h[i].resize(rowsPerBand * width), v[i].resize(rowsPerBand * width);
    const progress::ProgressStage stage("read DEM", height);
    tbb::task_group coding;
    // A failed read waits for the band being coded before the scratch goes.
    struct Join {
      tbb::task_group& g;
      ~Join() {
        try {
          g.wait();
        } catch (...) {}
      }
    } join{coding};
    int at = 0;
    for (uint64_t y0 = 0; y0 < height; y0 += rowsPerBand, at ^= 1) {
      const uint64_t rows = std::min(rowsPerBand, height - y0);
      const size_t n = size_t(rows * width);
      source.readRows(uint32_t(y0), uint32_t(rows), h[at].data(), v[at].data());
      float* hb = h[at].data();
      const uint8_t* vb = v[at].data();
      for (size_t i = 0; i < n; ++i) {
        if (!vb[i]) {
          ++voids;
          hb[i] = 0.f;
          continue;
        }
        lo = std::min(lo, hb[i]);
        hi = std::max(hi, hb[i]);
        const float stored = storedHeight(hb[i], fallbackPrecision);
        slo = std::min(slo, stored);
        shi = std::max(shi, stored);
        dem.integerHeights = dem.integerHeights && hb[i] == std::nearbyint(hb[i]);
      }
      coding.wait();
      coding.run([&scratch, hb, vb, y0, rows, width] {
        scratch.write(CellWindow{0, int64_t(y0), int64_t(width), int64_t(y0 + rows)}, hb, vb);
      });
      progress::advance(rows);
    }
    coding.wait();
  }
  if (voids == width * height)
    throw InputError(input.string() + ": every sample is nodata (" + std::to_string(voids) + " samples)");

  // 2. The step a compressed atlas quantizes heights to, and the range of what it stores.
  const bool compressed = options.atlas.coding.compressed;
  if (compressed)
    r.heightPrecision = terrainHeightPrecision(input, options.heightPrecision, dem.integerHeights,
                                               options.defaultHeightPrecision, lo, hi);
  auto stored = [&](float x) { return compressed ? storedHeight(x, r.heightPrecision) : x; };
  if (!compressed || r.heightPrecision != fallbackPrecision) slo = stored(lo), shi = stored(hi);

  // 3. Voids, window by window; the range takes in what they are filled with.
  dem.voidsFilled = voids;
  dem.voidFillMethod = kVoidFillMethod;
  if (voids > 0) {
    WindowedFill io;
    io.read = [&](const CellWindow& w, float* h, uint8_t* ok) { scratch.read(w, h, ok); };
    io.write = [&](const CellWindow& w, const float* h) {
      for (size_t i = 0; i < w.cells(); ++i) slo = std::min(slo, stored(h[i])), shi = std::max(shi, stored(h[i]));
      scratch.write(w, h, nullptr);
    };
    io.hasVoids = [&](const CellWindow& w) { return scratch.hasVoids(w); };
    // A window's levels, copies and flags take about 16 bytes per level-0 sample.
    fillVoidsWindowed(dem.width, dem.height, lo, hi, io, std::max<uint64_t>(budget / 4 / 16, 1u << 18));
  }
  dem.minHeight = slo;
  dem.maxHeight = shi;
  r.scratchBytes = scratch.peakBytes();
  r.scratchTile = scratch.tileSide();

  // 4. The manifest's chart fields.
  TerrainAtlasOptions atlas = options.atlas;
  atlas.coding.heightPrecision = r.heightPrecision;
  fillTerrainManifest(dem, atlas, manifest);
  manifest.compression = CompressionInfo{};
  if (compressed) {
    manifest.compression.present = true;
    manifest.compression.heightPrecision = r.heightPrecision;
  }
  return prepared;
}

uint32_t windowChartTile(uint32_t chartSize, uint32_t blockIntervals, uint64_t budget) {
  return windowTiling(chartSize, blockIntervals, std::max<uint64_t>(budget, uint64_t{16} << 20)).tile;
}

WindowedTerrainResult writeTerrainChartsWindowed(const DemSource& source, const fs::path& dir,
                                                 const WindowedTerrainOptions& options, AtlasManifest& manifest) {
  const auto start = std::chrono::steady_clock::now();
  PreparedTerrainWindows prepared = prepareTerrainWindows(source, dir / ".dem.scratch", options, manifest);
  WindowedTerrainResult& r = prepared.result;
  writeTerrainChartWindows(*prepared.scratch, dir, options, manifest, {}, r);
  r.charts.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return std::move(r);
}

void writeTerrainChartWindows(const ScratchRaster& scratch, const fs::path& dir, const WindowedTerrainOptions& options,
                              const AtlasManifest& manifest, const std::vector<uint32_t>& charts,
                              WindowedTerrainResult& r) {
  const auto start = std::chrono::steady_clock::now();
  const uint64_t width = manifest.samplesX, height = manifest.samplesY;
  const uint64_t budget = std::max<uint64_t>(options.memoryBytes, uint64_t{16} << 20);
  const bool compressed = options.atlas.coding.compressed;
  TerrainAtlasOptions atlas = options.atlas;
  atlas.coding.heightPrecision = r.heightPrecision;
  const fs::path input = manifest.source.empty() ? fs::path("DEM") : fs::path(manifest.source);
  std::vector<uint8_t> selected(manifest.charts.size(), charts.empty() ? 1 : 0);
  for (uint32_t c : charts) selected.at(c) = 1;
  const uint32_t count = charts.empty() ? uint32_t(manifest.charts.size()) : uint32_t(charts.size());
  fs::create_directories(dir / "charts");
  const uint32_t cs = atlas.chartSize;
  const uint64_t m = cs - 1, spanRows = 3 * m + 1;
  const int64_t wrap = manifest.planet.wrapColumns;
  const ChartTiling tiling =
      options.chartTile ? chartTiling(cs, atlas.blockIntervals, std::max(options.chartTile, 2 * atlas.blockIntervals))
                        : windowTiling(cs, atlas.blockIntervals, budget);
  if (tiling.tiled()) {
    r.charts.bytesOnDisk = writeTiledChartsWindowed(scratch, dir, manifest, selected, {atlas, tiling, budget}, r);
    r.charts.charts = count;
    r.charts.samples = width * height;
    for (uint32_t k = 0; k <= manifest.intervalsLog2(); ++k) r.charts.storedSamples += ((m >> k) + 1) * ((m >> k) + 1);
    r.charts.storedSamples *= r.charts.charts;
    r.charts.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return;
  }
  // A window of g chart columns holds spanRows x ((g + 2) m + 1) heights; the charts in flight
  // take the other half of the budget.
  if (spanRows * spanRows * 4 > budget / 4)
    throw InputError(input.string() + ": a chart and its neighbours' margins (" + std::to_string(spanRows) +
                     "^2 samples) need " + std::to_string((spanRows * spanRows * 4) >> 20) +
                     " MiB, over a quarter of the " + std::to_string(budget >> 20) +
                     " MiB the windows may use; give a smaller " + optionRef("chartSize") + " or a larger " +
                     optionRef("maxMemory"));
  const uint64_t groupColumns =
      std::clamp<uint64_t>((budget / 4 / (spanRows * 4) - 1) / m, 3, manifest.chartsX + 2) - 2;
  uint64_t perChart = 0;
  for (uint32_t k = 0; k <= manifest.intervalsLog2(); ++k) {
    const uint64_t s = ((cs - 1) >> k) + 1;
    perChart += s * s;
  }
  // A chart in flight holds its pyramid with ring heights and its file image: about 20 bytes per
  // stored sample.
  const int concurrency = int(std::clamp<uint64_t>((budget / 2) / std::max<uint64_t>(perChart * 20, 1), 1,
                                                   uint64_t(tbb::this_task_arena::max_concurrency())));
  tbb::task_arena arena(concurrency);
  std::vector<float> window;
  std::atomic<uint64_t> bytes{0};
  const progress::ProgressStage stage("charts", count);
  for (uint32_t gy = 0; gy < manifest.chartsY; ++gy) {
    const auto rowSpan = chartRowSpan(gy, cs, int64_t(height));
    for (const auto& run : selectedRuns(selected, manifest.chartsX, gy, groupColumns)) {
      const uint32_t g0 = run[0], g1 = run[1];  // (named: clang before 16 cannot capture a structured binding)
      // Round a planet, the charts at the antimeridian read a chart past it.
      const int64_t x0 = wrap && g0 == 0 ? -int64_t(m) : chartRowSpan(g0, cs, int64_t(width))[0];
      const int64_t x1 =
          wrap && g1 == manifest.chartsX ? int64_t(width + m) : chartRowSpan(g1 - 1, cs, int64_t(width))[1];
      const CellWindow w{x0, rowSpan[0], x1, rowSpan[1]};
      r.bandRows = std::max<uint64_t>(r.bandRows, uint64_t(w.height()));
      r.bandColumns = std::max<uint64_t>(r.bandColumns, uint64_t(w.width()));
      window.resize(w.cells());
      arena.execute([&] { readWindow(scratch, w, wrap, window.data()); });
      for (float& x : window) x = storedOf(x, r, compressed);
      const DemRows view = heldRows(window, w, int64_t(width), int64_t(height), manifest.spacing, wrap);
      arena.execute([&] {
        tbb::parallel_for(g0, g1, [&](uint32_t gx) {
          const ChartInfo& c = manifest.charts[size_t(gy) * manifest.chartsX + gx];
          const ChartPyramid p = buildChartPyramid(view, c.gridX, c.gridY, cs, compressed);
          bytes += writeChartFile(dir / c.file, p, cs, atlas.blockIntervals, atlas.coding);
          progress::advance();
        });
      });
    }
  }
  r.charts.charts = count;
  r.charts.samples = width * height;
  r.charts.storedSamples = perChart * r.charts.charts;
  r.charts.bytesOnDisk = bytes.load();
  r.charts.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace gimlod
