// DEM input through GDAL: any single-band raster GDAL reads (GeoTIFF, SRTM .hgt, USGS ASCII DEM,
// netCDF, ESRI ASCII grid, ...). Voids (nodata, NaN, inf) are filled and counted.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "atlas/terrain/void_fill.h"
#include "core/planet.h"
#include "core/atlas_format.h"

namespace gimlod {

struct DemOptions {
  double zScale = 1.0;     // multiplies heights; must be finite and non-zero
  std::string subdataset;  // netCDF variable (empty: the first 2D one GDAL offers)
  // GDAL's block cache for the read, bytes (it holds copies of the blocks read, by default 5% of
  // the machine's memory); 0: GDAL's default. Process-wide: set before the read.
  uint64_t gdalCacheBytes = 0;
  // The memory the whole build may use, bytes, and what it needs per sample: a raster over it is
  // refused (InputError naming optionRef "maxMemory") once opened, before its data is read.
  // 0: no cap.
  uint64_t maxMemory = 0;
  double buildBytesPerSample = 0.0;
  // The band holding the heights, from 1; 0: band 1 of a single-band raster, and of a raster of
  // several bands with a warning, except an image of 3 or 4 byte bands (RGB, RGBA), which is refused.
  uint32_t band = 0;
  // Metres between samples in x (east) and y (north), replacing what the georeference gives; 0:
  // from the georeference (a raster without one is taken as 1 m, with a warning).
  std::array<double, 2> spacing{0.0, 0.0};
  // A planet build (atlas/terrain/planet_grid.h; > 0: the sphere's radius in metres): the raster
  // read is the planet lattice laid from the DEM's rows, its antimeridian on a multiple of
  // planetChartIntervals columns, whichever build reads it. The DEM must be geographic.
  double planetRadius = 0.0;
  double planetFlattening = 0.0;  // > 0: an ellipsoid of equatorial radius planetRadius
  uint32_t planetChartIntervals = 1;
};

// Heights in metres after z-scale, row-major with row 0 at the SOUTH edge (gy grows north).
struct DemRaster {
  uint32_t width = 0, height = 0;
  std::vector<float> heights;
  std::array<double, 2> spacing{1.0, 1.0};  // metres between samples in x (east) and y (north)
  Georeference georef;
  uint64_t voidsFilled = 0;
  std::string voidFillMethod;
  float minHeight = 0.f, maxHeight = 0.f;
  bool integerHeights = false;        // every sample the source gave (voids aside) is a whole number
  std::vector<std::string> warnings;  // non-fatal issues (extra bands, no georeference, ...)
  PlanetInfo planet;                  // read as a planet lattice (DemOptions::planetRadius)
};

// Human-readable name of the void-fill method (stored in DemRaster::voidFillMethod).
extern const char* const kVoidFillMethod;

// Converts one degree of latitude / longitude to metres at latitude phiDeg (WGS84 series).
double metresPerDegreeLatitude(double phiDeg);
double metresPerDegreeLongitude(double phiDeg);  // |phi| clamped to 89 degrees

// Loads and repairs a DEM. Throws InputError naming the file on: unreadable or truncated data,
// not a raster, zero-size, all samples void, bad options.
DemRaster loadDem(const std::filesystem::path& path, const DemOptions& options = {});

// GDAL is asked for a DEM's rows in chunks of this many (from the raster's first row), whatever
// rows a caller reads.
inline constexpr int64_t kDemChunkRows = 32;

// A DEM opened for reading in rows, for builds larger than memory: the raster's size, spacing,
// georeference and warnings (info(); its heights empty) once opened, and any rows on demand.
class DemSource {
 public:
  // Opens the raster and reads its metadata; throws InputError naming the file.
  DemSource(const std::filesystem::path& path, const DemOptions& options = {});
  ~DemSource();
  DemSource(const DemSource&) = delete;
  DemSource& operator=(const DemSource&) = delete;
  const DemRaster& info() const { return info_; }
  // Rows [y0, y0 + rows), row 0 at the south edge, every column: heights in metres after z-scale
  // and valid (0 at nodata, NaN, inf and masked samples, whose heights are undefined). Throws
  // InputError naming the file. Not thread-safe. showProgress: a "read DEM" progress stage.
  void readRows(uint32_t y0, uint32_t rows, float* heights, uint8_t* valid, bool showProgress = false) const;

 private:
  // A planet build (DemOptions::planetRadius): the lattice the rows are laid on, and info_'s.
  void layPlanetGrid(const DemOptions& options);
  // The raster's own rows (readRows without the planet lattice).
  void readSourceRows(uint32_t y0, uint32_t rows, float* heights, uint8_t* valid, bool showProgress) const;
  struct Impl;
  std::unique_ptr<Impl> impl_;
  DemRaster info_;
};

// fillVoids (atlas/terrain/void_fill.h) fills the voids loadDem finds.

}  // namespace gimlod
