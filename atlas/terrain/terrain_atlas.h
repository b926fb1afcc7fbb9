// Height-field atlas: partitions a DEM into (2^m+1)^2 charts with a one-sample overlap, builds
// each chart's subsampled pyramid and normal map, and writes them in blocks.
// Based on: Niski, Purnomo, Cohen, "Multi-grained Level of Detail Using a Hierarchical Seamless
// Texture Atlas", I3D 2007, sections 4 and 6 (height-field case).
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>

#include "atlas/terrain/dem.h"
#include "core/atlas_format.h"

namespace gimlod {

// The largest terrain chart: 2^15 + 1 samples a side. Charts over kMaxChartTile + 1 are built in
// tiles (ChartTiling), so the size does not bound the memory a build takes.
inline constexpr uint32_t kMaxTerrainChartSize = 32769;

struct TerrainAtlasOptions {
  uint32_t chartSize = 513;      // samples per chart side; must be 2^m + 1, 9..kMaxTerrainChartSize
  uint32_t blockIntervals = 64;  // block / max node resolution R; power of two, 4..1024
  ChartCoding coding;            // how chart files store blocks (compressed: format version 2)
};

struct TerrainAtlasStats {
  uint32_t charts = 0;
  uint64_t samples = 0;        // DEM samples
  uint64_t storedSamples = 0;  // samples in all pyramid levels of all charts
  uint64_t bytesOnDisk = 0;
  double seconds = 0.0;
};

// Throws InputError if chartSize is not 2^m+1 in 9..kMaxTerrainChartSize, or blockIntervals is not a power of
// two in 4..1024 and <= chartSize-1. Messages name the parameters (optionRef: "chartSize",
// "blockIntervals").
void validateTerrainAtlasOptions(const TerrainAtlasOptions& options);

// The step a compressed atlas quantizes a DEM's heights that are not whole to: `requested` if it
// is > 0, else 1 for a DEM of whole metres and `fallback` otherwise. Throws InputError naming
// `input` when heights in [lo, hi] span more than 2^23 steps of it.
double terrainHeightPrecision(const std::filesystem::path& input, double requested, bool integerHeights,
                              double fallback, float lo, float hi);
// A height as a compressed atlas stores it: whole metres exactly, others quantized to `precision`.
float storedHeight(float h, double precision);

// Relative path of chart `id`'s file inside the atlas directory: "charts/chart_0007.bin".
std::string chartFileName(uint32_t id);

// The chart's level-0 heights, (chartSize)^2 row-major (row = v = north), edge-clamped outside
// the DEM. Shared by the writer and the tests.
std::vector<float> extractChart(const DemRaster& dem, int32_t gridX, int32_t gridY, uint32_t chartSize);

// Rows [y0, y0 + rows) and columns [x0, x0 + cols) of a DEM's heights, row-major: what a group
// of charts' pyramids are built from when the DEM does not fit in memory. Access is edge-clamped
// to the whole DEM (width x height), and must fall inside the window held.
// stride > 1: a lattice of the DEM, every stride-th sample from (0, 0) and the last column and
// row clamped (lattice column i holds the height of column min(i * stride, width - 1)); rows and
// cols count lattice samples, x0 and y0 are multiples of stride, and only samples at multiples of
// stride may be asked for.
// wrapColumns W > 0: the columns circle a planet (column W is column 0; PlanetInfo::wrapColumns):
// columns are not clamped but wrap, so a chart's neighbours across the antimeridian are the ones
// at the other end. A column left of the window held is read W columns on, one right of it W
// columns back: a window of every column wraps by itself, and a narrower one holds the columns
// past either end it needs, at their unwrapped places (x0 < 0, or x0 + cols > width).
struct DemRows {
  const float* heights = nullptr;
  int64_t y0 = 0, rows = 0;
  int64_t x0 = 0, cols = 0;       // cols 0: every column (cols = width)
  int64_t width = 0, height = 0;  // the whole DEM
  std::array<double, 2> spacing{1.0, 1.0};
  int64_t stride = 1;
  int64_t wrapColumns = 0;
};
// Every row and column of a DEM in memory, its columns wrapping round a planet.
DemRows wholeRows(const DemRaster& dem);
// Lattice samples a side of a DEM of `samples` at `stride`: ceil((samples - 1) / stride) + 1.
inline int64_t latticeSamples(int64_t samples, int64_t stride) { return (samples - 1 + stride - 1) / stride + 1; }
// The rows a chart row needs (its own, and a chart's worth each side for the coarse levels'
// normals): [max(0, gridY * m - m), min(height, gridY * m + 2m + 1)), m = chartSize - 1. The
// columns a chart column needs are the same span of gridX and the width.
std::array<int64_t, 2> chartRowSpan(int64_t gridY, uint32_t chartSize, int64_t height);
ChartPyramid buildChartPyramid(const DemRows& dem, int32_t gridX, int32_t gridY, uint32_t chartSize,
                               bool keepRing = false);

// A square of a DEM: `intervals` level-0 intervals a side, its sample (0, 0) at DEM sample
// (originX, originY).
struct DemSquare {
  int64_t originX = 0, originY = 0;
  uint32_t intervals = 0;
};
// Levels [first, last] of the pyramid of `square`: level k has (intervals >> k) + 1 samples a side;
// the levels before `first` are left empty. As buildChartPyramid, of which it is the general form
// (a tile of a chart, or a chart's coarse levels from a lattice).
ChartPyramid buildPyramidLevels(const DemRows& dem, const DemSquare& square, uint32_t first, uint32_t last,
                                bool keepRing = false);

// A chart too large to build whole in memory is built in tiles of `tile` level-0 intervals a side:
// a tile holds the levels whose blocks lie inside it (levels below coarseLevel), read from the DEM
// with a margin of 2^(coarseLevel - 1) samples for their normals; the levels from coarseLevel up
// come from the DEM sampled every 2^coarseLevel samples. tile = chartSize - 1: one tile, the whole
// pyramid (coarseLevel = its level count).
struct ChartTiling {
  uint32_t tile = 0;
  uint32_t coarseLevel = 0;
  uint32_t tilesPerSide = 1;
  bool tiled() const { return tilesPerSide > 1; }
  uint32_t margin() const { return 1u << (coarseLevel - 1); }
};
inline constexpr uint32_t kMaxChartTile = 2048;
// The tiling of charts of chartSize with blocks of blockIntervals: tiles of min(chartSize - 1,
// maxTile) intervals (maxTile a power of two, at least 2 * blockIntervals).
ChartTiling chartTiling(uint32_t chartSize, uint32_t blockIntervals, uint32_t maxTile = kMaxChartTile);
// Chart (gridX, gridY) of chartSize samples a side, built in tiles.
struct TiledChart {
  int32_t gridX = 0, gridY = 0;
  uint32_t chartSize = 0;
  ChartTiling tiling;
};
// The DEM samples tile (tx, ty) of chart c reads, clamped to the DEM of width x height:
// {x0, y0, x1, y1}.
std::array<int64_t, 4> tileSpan(const TiledChart& c, uint32_t tx, uint32_t ty, int64_t width, int64_t height);
// Codes the blocks of tile (tx, ty) of chart c (levels below coarseLevel) for `file`, from `dem`
// (which must hold the tile's span), in the file's order (levels, then rows of blocks).
std::vector<ChartFileWriter::CodedBlock> codeChartTile(const DemRows& dem, const TiledChart& c, uint32_t tx,
                                                       uint32_t ty, const ChartFileWriter& file, bool ring);
// Writes the levels from coarseLevel up of chart c to `file`, from `dem` (the whole DEM, or its
// lattice at stride 2^coarseLevel).
void writeChartCoarseLevels(const DemRows& dem, const TiledChart& c, ChartFileWriter& file, bool ring);
// A tiled chart's file, opened for writing (the manifest's chart fields filled): a compressed
// height field derives its normals.
std::unique_ptr<ChartFileWriter> openTerrainChart(const std::filesystem::path& path, const AtlasManifest& manifest,
                                                  const ChartInfo& chart, const TerrainAtlasOptions& o);

// The chart files of a tiled atlas while their tiles are coded. Each chart's tiles go into its file
// in the chart's order (tile rows, then tiles), whichever thread finishes them first: a tile that
// finishes early waits for the ones before it, so the files do not depend on the order of the work.
class TiledChartWriter {
 public:
  // Opens every chart's file (the manifest's chart fields filled).
  TiledChartWriter(const std::filesystem::path& dir, const AtlasManifest& manifest, const TerrainAtlasOptions& options,
                   const ChartTiling& tiling);
  ~TiledChartWriter();
  const ChartTiling& tiling() const { return tiling_; }
  // Codes tile (tx, ty) of chart `chart` from `dem` (holding the tile's span) and writes it in its
  // turn. Thread-safe.
  void writeTile(const DemRows& dem, uint32_t chart, uint32_t tx, uint32_t ty);
  // Writes every chart's coarse levels from `coarse` (the whole DEM, or its lattice at stride
  // 2^coarseLevel) and commits the files, in parallel. Throws std::logic_error if a tile is
  // missing. Returns the files' bytes.
  uint64_t finish(const DemRows& coarse);

 private:
  struct Chart;
  const AtlasManifest& manifest_;
  TerrainAtlasOptions options_;
  ChartTiling tiling_;
  std::vector<std::unique_ptr<Chart>> charts_;
};
// Every tile of a tiled atlas from the whole DEM in memory, `concurrency` at a time, then the coarse
// levels; returns the files' bytes.
uint64_t writeTiledCharts(const DemRaster& dem, const std::filesystem::path& dir, const AtlasManifest& manifest,
                          const TerrainAtlasOptions& options, const ChartTiling& tiling, int concurrency);

// Builds the pyramid (subsampling) and normal maps of one chart. The normal at a sample comes from
// central differences of the global DEM at that level's spacing (heightFieldNormals), so shared
// borders match. keepRing: also the ring heights and frame a compressed file derives normals from.
ChartPyramid buildChartPyramid(const DemRaster& dem, int32_t gridX, int32_t gridY, uint32_t chartSize,
                               bool keepRing = false);

// Fills the manifest's chart fields for `dem` (chart grid, files, root neighbours, spacing,
// samples, height range, georeference, voids, planet, the charts either side of a planet's
// antimeridian linked) without writing anything.
void fillTerrainManifest(const DemRaster& dem, const TerrainAtlasOptions& options, AtlasManifest& manifest);

// Writes all chart files into `dir` (which must exist) and fills the manifest's chart fields
// (kind, chartSize, blockIntervals, chartsX/Y, charts, neighbours, spacing, samples, heightRange,
// georef, voids; maxNodeResLog2 is capped at log2(blockIntervals)). zScale, source and the
// hierarchy depth are left to the caller. Charts are written in parallel.
TerrainAtlasStats writeTerrainCharts(const DemRaster& dem, const TerrainAtlasOptions& options,
                                     const std::filesystem::path& dir, AtlasManifest& manifest);

}  // namespace gimlod
