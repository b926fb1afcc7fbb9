// Terrain imagery: any RGB(A) raster GDAL reads, reprojected by GDAL onto the DEM's sample lattice
// refined by 2^scaleLog2, then cut into per-chart attribute pyramids that sit beside the height
// charts (core/atlas_format.h ImageryInfo). The imagery's resolution is its own: the scale is
// chosen from the two rasters' sample spacings, so a Blue Marble image over ETOPO5 or an
// orthophoto over a 90 m DEM each keep the detail they have.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "atlas/terrain/dem.h"
#include "atlas/terrain/terrain_atlas.h"
#include "core/atlas_format.h"

namespace gimlod {

inline constexpr int kAutoImageryScale = -1;

struct ImageryOptions {
  std::filesystem::path path;
  // log2 of imagery samples per DEM sample interval, 0..kMaxImageryScaleLog2; kAutoImageryScale:
  // the power of two nearest the DEM spacing / imagery pixel size, clamped to that range (imagery
  // coarser than the DEM is resampled onto the DEM's own lattice).
  int scaleLog2 = kAutoImageryScale;
  // West, south, east, north edges in the DEM's reference system, for imagery without a
  // georeference (a plain JPEG of the whole Earth: -180,-90,180,90). Ignored when the imagery has
  // a geotransform.
  std::optional<std::array<double, 4>> extent;
};

// The imagery on the refined lattice: sample (ix, iy) lies at DEM sample (ix, iy) / 2^scaleLog2;
// row 0 is south, like DemRaster. Alpha: 255 where the imagery covers the sample, 0 where it does
// not (partial at the imagery's edges).
struct ImageryRaster {
  uint32_t scaleLog2 = 0;
  uint32_t width = 0, height = 0;  // (dem.width - 1) * 2^scaleLog2 + 1, likewise for height
  std::vector<PackedColour> rgba;  // row-major, row 0 south
  double coverage = 0.0;           // fraction of samples with alpha > 0
  std::string resampling;          // GDAL's method: "bilinear" or "average"
  std::vector<std::string> warnings;
};

// Throws InputError (naming the option with optionRef) for a scale outside 0..kMaxImageryScaleLog2
// or an empty or inverted extent.
void validateImageryOptions(const ImageryOptions& options);

// The imagery opened and placed on a DEM's lattice refined by 2^scaleLog2, reprojected by GDAL in
// fixed tiles of kImageryTile^2 lattice samples (aligned on the lattice, in GDAL's row order), so
// that a sample's colour is the same whichever window asks for it: the whole lattice at once
// (loadImagery) or window by window (writeImageryChartsWindowed). `demPath` names the DEM in
// messages. Geographic imagery that spans the whole globe wraps around the antimeridian (a
// -180..180 image over a 0..360 DEM). Throws InputError naming the file for: unreadable data, no
// georeference (and no extent), a band layout that is not grey, grey + alpha, RGB or RGBA bytes,
// a DEM without a georeference.
inline constexpr uint32_t kImageryTile = 1024;

class ImagerySource {
 public:
  // dem: its size and georeference (heights unused).
  ImagerySource(const DemRaster& dem, const std::filesystem::path& demPath, const ImageryOptions& options);
  ~ImagerySource();
  ImagerySource(const ImagerySource&) = delete;
  ImagerySource& operator=(const ImagerySource&) = delete;

  uint32_t scaleLog2() const;
  uint32_t width() const;  // (dem.width - 1) * 2^scaleLog2 + 1
  uint32_t height() const;
  const std::string& resampling() const;  // GDAL's method: "bilinear" or "average"
  // GDAL's warnings so far.
  std::vector<std::string> warnings() const;
  // Keeps up to `bytes` of reprojected tiles for later windows (least recently used go first);
  // 0 (the default): one.
  void keepTiles(uint64_t bytes);
  // Lattice samples [x0, x0 + w) x [y0, y0 + h) (row 0 south), row-major; alpha as ImageryRaster.
  // Throws InputError naming the imagery when GDAL fails. Not thread-safe.
  std::vector<PackedColour> window(uint32_t x0, uint32_t y0, uint32_t w, uint32_t h) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

// Reads and reprojects the imagery onto `dem`'s whole lattice (ImagerySource). Throws InputError
// as ImagerySource does, and for imagery that does not overlap the DEM.
ImageryRaster loadImagery(const DemRaster& dem, const std::filesystem::path& demPath, const ImageryOptions& options);

// Relative path of chart `id`'s imagery file: "imagery/chart_0007.bin".
std::string imageryFileName(uint32_t id);

// The imagery's pyramid over a whole chart grid: level k is the refined lattice at 2^k times its
// spacing, each coarser level a [1 2 1]^2 / 16 filter of the finer one centred on its even
// samples (integer, rounded), edge-clamped. Charts cut their levels out of these global images, so
// two charts hold bit-identical colours on every shared border sample.
// A chart grid's imagery: chartsX x chartsY charts of chartSize samples (the geometry's), on a
// lattice refined by 2^scaleLog2.
struct ImageryGrid {
  uint32_t chartsX = 0, chartsY = 0;
  uint32_t chartSize = 0;
  uint32_t scaleLog2 = 0;
};

// A window of a chart grid's level-0 imagery samples: [x0, x0 + w) x [y0, y0 + h).
struct ImageryWindow {
  uint32_t x0 = 0, y0 = 0;
  uint32_t w = 0, h = 0;
};

class ImageryPyramid {
 public:
  // chartsX x chartsY charts of chartSize samples (the geometry's); `levels` pyramid levels.
  ImageryPyramid(const ImageryRaster& raster, uint32_t chartsX, uint32_t chartsY, uint32_t chartSize, uint32_t levels);
  // The same pyramid of `grid` over `window` of its whole base (the lattice edge-clamped to
  // chartsX * intervals + 1 samples a side), whose samples are given in `rgba` (w * h, row 0
  // south), with x0 and y0 multiples of 2^(levels - 1). Its charts are the whole pyramid's, bit for
  // bit, for charts at least 2^(levels - 1) level-0 samples inside the window on every side that is
  // not the grid's edge (each coarser level's filter reads one sample past the window, which the
  // window clamps: one wrong sample at its edge on every level).
  ImageryPyramid(std::vector<PackedColour> rgba, const ImageryWindow& window, const ImageryGrid& grid, uint32_t levels);
  // Chart (gridX, gridY)'s attribute pyramid (colours only): level k has
  // (((chartSize - 1) << scaleLog2) >> k) + 1 samples per side.
  ChartPyramid chart(int32_t gridX, int32_t gridY) const;
  // Level k's sample (x, y), in the whole level's samples (inside the window), and the level's
  // row stride: what a chart file's blocks are coded from.
  const PackedColour* at(uint32_t k, uint64_t x, uint64_t y) const;
  size_t stride(uint32_t k) const { return levels_.at(k).width; }
  uint32_t levels() const { return uint32_t(levels_.size()); }

 private:
  struct Level {
    uint32_t x0 = 0, y0 = 0;  // the window's origin at this level, in the whole level's samples
    uint32_t width = 0, height = 0;
    std::vector<PackedColour> rgba;
  };
  void buildLevels(uint32_t levels, uint32_t gridWidth, uint32_t gridHeight);
  uint32_t chartIntervals_ = 0;  // (chartSize - 1) << scaleLog2
  std::vector<Level> levels_;
};

struct ImageryWriteStats {
  uint64_t bytesOnDisk = 0;
  uint64_t storedSamples = 0;
  uint64_t coveredSamples = 0;  // lattice samples with alpha > 0 that the written charts own
  double seconds = 0.0;
};

// Writes every chart's imagery file into dir/imagery and fills manifest.imagery and each chart's
// imageryFile. The manifest's chart grid must already be filled (fillTerrainManifest).
ImageryWriteStats writeImageryCharts(const ImageryRaster& raster, const std::string& source,
                                     const std::filesystem::path& dir, AtlasManifest& manifest);

struct ImageryWindowStats {
  uint64_t windows = 0;        // windows of charts reprojected
  uint64_t windowSamples = 0;  // the most level-0 samples one window held
};

// How writeImageryChartsWindowed cuts the imagery into windows: within memoryBytes, and, for charts
// the geometry builds in tiles of maxTile intervals (ChartTiling), in those tiles.
struct ImageryWindowing {
  uint64_t memoryBytes = 0;
  uint32_t maxTile = kMaxChartTile;
};

// The same files as writeImageryCharts of the whole raster, byte for byte, window by window: each
// window a block of charts with a margin of 2^(levels - 1) level-0 samples round it, reprojected
// from `imagery` and filtered into its pyramid, within windowing.memoryBytes (at least one chart and
// its margin), a quarter of it keeping reprojected tiles for the next windows. Throws InputError
// naming the imagery when it does not overlap the DEM.
// Charts the geometry builds in tiles (chartTiling(chartSize, blockIntervals, maxTile).tiled():
// over maxTile + 1 samples) take their imagery in the same tiles, scaled by 2^scaleLog2: each
// tile, with a margin of 2^coarseLevel level-0 samples, gives its levels below coarseLevel exactly
// (the whole pyramid's samples); the tiles' level coarseLevel, gathered over the whole grid
// (1/4^coarseLevel of the samples), gives the levels above. A chart's colours are those of the
// whole pyramid, so shared borders stay bit-identical; its file holds its tiles' blocks in the
// tiles' order, then the coarse levels, whatever memoryBytes is.
ImageryWriteStats writeImageryChartsWindowed(ImagerySource& imagery, const std::string& source,
                                             const std::filesystem::path& dir, AtlasManifest& manifest,
                                             const ImageryWindowing& windowing,
                                             ImageryWindowStats* windowStats = nullptr);

// The imagery of a build in shards, in two steps whose files are writeImageryChartsWindowed's, byte
// for byte. Each chart is split at a coarse level (shardImageryTiling): the levels below it come
// from the chart's tiles of the geometry (a chart's own tile where the geometry has none), each
// reprojected with a margin of 2^coarseLevel level-0 samples; the levels from it up come from the
// whole grid's coarse level (1/4^coarseLevel of the samples), gathered from every chart.
inline constexpr uint32_t kShardImageryCoarseLevel = 4;
ChartTiling shardImageryTiling(const AtlasManifest& manifest, uint32_t maxTile = kMaxChartTile);

struct ImageryPart {
  uint32_t coarseLevel = 0;
  // Each chart's coarse level, ((((chartSize - 1) << scaleLog2) >> coarseLevel) + 1)^2 samples
  // row-major, chart after chart in the order of the charts given.
  std::vector<PackedColour> coarse;
  ImageryWriteStats stats;  // coveredSamples: the lattice samples with alpha > 0 the charts' tiles own
  ImageryWindowStats windows;
};
// Step 1, a shard's: the imagery files of `charts` (indices into the manifest's) in dir/imagery, partial chart files
// (ChartFileWriter::commitPartial) holding the levels below the coarse level, and those charts'
// chart fields and the manifest's imagery fields (its coverage 0). A row of charts whose east chart
// is written at the antimeridian also reprojects the first column's west tiles for its border.
// Summed over a partition of the charts, stats.coveredSamples is the whole build's coverage times
// the lattice's samples.
ImageryPart writeImageryChartsPart(ImagerySource& imagery, const std::string& source, const std::filesystem::path& dir,
                                   AtlasManifest& manifest, const ImageryWindowing& windowing,
                                   const std::vector<uint32_t>& charts);
// Step 2, the merge's: every chart's file in dir/imagery, carried on from its partial file
// (`partials`, by chart) with the levels from coarseLevel up, filtered from the whole grid's coarse
// level assembled from `coarse` (every chart's, in the manifest's order, as writeImageryChartsPart
// gives them); fills the charts' imagery files. The manifest's imagery fields must be filled.
ImageryWriteStats finishImageryCharts(const std::filesystem::path& dir, AtlasManifest& manifest,
                                      const std::vector<std::filesystem::path>& partials,
                                      std::vector<PackedColour> coarse, uint32_t coarseLevel);

}  // namespace gimlod
