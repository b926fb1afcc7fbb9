// A longitude/latitude DEM laid on a sphere (core/planet.h): the lattice a planet atlas is built
// from, made row by row from the DEM's own rows, so that the in-memory and the window-by-window
// builds read the same samples (DemOptions::planet).
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>

#include "core/atlas_format.h"
#include "core/planet.h"

namespace gimlod {

// What a planet build repairs in a geographic DEM of sourceWidth x sourceHeight:
// - A DEM whose columns circle the planet (W columns of 360/W degrees, within half a column, or
//   W - 1 where the first and last both lie on the antimeridian) wraps: each row is resampled
//   linearly round the circle to the next multiple of chartIntervals columns a turn, so that the
//   antimeridian is a chart border (a resampled sample is void where either source sample is), and
//   a last column repeats column 0 (column W is column 0).
// - A DEM whose first (last) row lies within a row of the south (north) pole closes there: where
//   the row lies off the pole (cell-centred rows), a pole row is added; the rows on or past the pole
//   (a grid resampled finer may pass it by half a coarse row, up to half a degree), which all
//   meet in its point, are made uniform at the mean of the valid heights of the one nearest it.
// A regional DEM is left as it is. Heights of an integer raster stay whole metres (rounded).
struct PlanetGrid {
  PlanetInfo info;
  uint32_t sourceWidth = 0, sourceHeight = 0;
  uint32_t turn = 0;                        // distinct source columns a turn (0: no wrap)
  uint32_t southAdded = 0, northAdded = 0;  // pole rows added (0 or 1)
  // Rows [0, southRows) and [northFrom, height()) lie on a pole: uniform, at the mean of source
  // row southMeanRow (northMeanRow). southRows 0 and northFrom height(): no pole.
  uint32_t southRows = 0, northFrom = 0;
  uint32_t southMeanRow = 0, northMeanRow = 0;
  bool round = false;                        // heights rounded to whole metres
  float southMean = 0.0f, northMean = 0.0f;  // the pole rows' height
  std::string warning;                       // a DEM that nearly circles the planet but is regional
  uint32_t width() const { return info.wrapColumns ? info.wrapColumns + 1 : sourceWidth; }
  uint32_t height() const { return sourceHeight + southAdded + northAdded; }
  // The source row of row y, or -1 for an added pole row.
  int64_t sourceRow(uint32_t y) const;
};

// The DEM a planet grid is laid from: its georeference, its size, and whether its heights are
// integers.
struct PlanetSource {
  const Georeference& georef;
  uint32_t width = 0, height = 0;
  bool integerHeights = false;
};

// The plan for a DEM on a planet of `radius` in charts of chartIntervals; the pole rows' means
// (southMean, northMean) are left to the caller (poleRowMean). Throws InputError naming `input` for
// a DEM that is not in longitude and latitude.
PlanetGrid planPlanetGrid(const PlanetSource& dem, const std::filesystem::path& input, double radius,
                          uint32_t chartIntervals);
// The mean of a source row's valid heights (the distinct columns of a turn): a pole row's height.
// Throws InputError naming `input` when none is valid.
float poleRowMean(const PlanetGrid& g, const float* heights, const uint8_t* valid, const std::filesystem::path& input);
// Row y of the planet lattice (width() samples) from its source row (sourceWidth samples; ignored
// for an added pole row).
void planetGridRow(const PlanetGrid& g, uint32_t y, const float* source, const uint8_t* sourceValid, float* out,
                   uint8_t* outValid);
// The lattice's georeference (north-up, the planet's rows and columns) and spacing at the equator.
Georeference planetGridGeoref(const PlanetGrid& g, const Georeference& source);
std::array<double, 2> planetGridSpacing(const PlanetGrid& g);

// Links the charts either side of a wrapping planet's antimeridian as neighbours (the last chart
// column's right edge and the first's left), so that nodes stitch across it as across any chart
// border. No-op for a regional planet or another atlas.
void linkPlanetSeam(AtlasManifest& manifest);

}  // namespace gimlod
