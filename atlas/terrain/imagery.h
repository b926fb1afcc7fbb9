// Terrain imagery: any RGB(A) raster GDAL reads, reprojected by GDAL onto the DEM's sample lattice
// refined by 2^scaleLog2, then cut into per-chart attribute pyramids that sit beside the height
// charts (core/atlas_format.h ImageryInfo). The imagery's resolution is its own: the scale is
// chosen from the two rasters' sample spacings, so a Blue Marble image over ETOPO5 or an
// orthophoto over a 90 m DEM each keep the detail they have.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "atlas/terrain/dem.h"
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

// Reads and reprojects the imagery onto `dem`'s lattice. `demPath` names the DEM in messages.
// Geographic imagery that spans the whole globe wraps around the antimeridian (a -180..180 image
// over a 0..360 DEM). Throws InputError naming the file for: unreadable data, no georeference
// (and no extent), a band layout that is not grey, grey + alpha, RGB or RGBA bytes, a DEM without
// a georeference, imagery that does not overlap the DEM.
ImageryRaster loadImagery(const DemRaster& dem, const std::filesystem::path& demPath,
                          const ImageryOptions& options);

// Relative path of chart `id`'s imagery file: "imagery/chart_0007.bin".
std::string imageryFileName(uint32_t id);

// The imagery's pyramid over a whole chart grid: level k is the refined lattice at 2^k times its
// spacing, each coarser level a [1 2 1]^2 / 16 filter of the finer one centred on its even
// samples (integer, rounded), edge-clamped. Charts cut their levels out of these global images, so
// two charts hold bit-identical colours on every shared border sample.
class ImageryPyramid {
 public:
  // chartsX x chartsY charts of chartSize samples (the geometry's); `levels` pyramid levels.
  ImageryPyramid(const ImageryRaster& raster, uint32_t chartsX, uint32_t chartsY, uint32_t chartSize,
                 uint32_t levels);
  // Chart (gridX, gridY)'s attribute pyramid (colours only): level k has
  // (((chartSize - 1) << scaleLog2) >> k) + 1 samples per side.
  ChartPyramid chart(int32_t gridX, int32_t gridY) const;

 private:
  struct Level {
    uint32_t width = 0, height = 0;
    std::vector<PackedColour> rgba;
  };
  uint32_t chartIntervals_ = 0;  // (chartSize - 1) << scaleLog2
  std::vector<Level> levels_;
};

struct ImageryWriteStats {
  uint64_t bytesOnDisk = 0;
  uint64_t storedSamples = 0;
  double seconds = 0.0;
};

// Writes every chart's imagery file into dir/imagery and fills manifest.imagery and each chart's
// imageryFile. The manifest's chart grid must already be filled (fillTerrainManifest).
ImageryWriteStats writeImageryCharts(const ImageryRaster& raster, const std::string& source,
                                     const std::filesystem::path& dir, AtlasManifest& manifest);

}  // namespace gimlod
