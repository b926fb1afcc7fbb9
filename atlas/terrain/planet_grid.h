// A longitude/latitude DEM made ready to draw on a sphere (core/planet.h).
#pragma once

#include <filesystem>

#include "atlas/terrain/dem.h"
#include "core/planet.h"

namespace gimlod {

// Places a geographic DEM on a sphere of `radius` metres, repairing what a closed planet needs:
// - A DEM whose columns circle the planet (W columns of 360/W degrees, within half a column, or
//   W - 1 where the first and last both lie on the antimeridian) wraps: resampled along each row
//   (linearly, round the circle; rounded to whole metres for a DEM of whole metres) to the next
//   multiple of chartIntervals columns a turn, where W is not one, so that the antimeridian is a
//   chart border; then a column is appended that repeats column 0 (column W is column 0).
// - A DEM whose first (last) row lies within a row of the south (north) pole closes there: a row
//   on the pole is made uniform, at the mean of its heights (rounded for a DEM of whole metres),
//   or, where the row lies off the pole (cell-centred rows), a pole row of the mean of the row
//   next to it is added.
// A regional DEM is left as it is. The spacing becomes the lattice's at the equator, in metres
// (the normals' scale), and the georeference the lattice's. Throws InputError naming `input` for a
// DEM that is not in longitude and latitude.
PlanetInfo preparePlanetGrid(DemRaster& dem, const std::filesystem::path& input, double radius,
                             uint32_t chartIntervals);

// Links the charts either side of a wrapping planet's antimeridian as neighbours (the last chart
// column's right edge and the first's left), so that nodes stitch across it as across any chart
// border. No-op for a regional planet or another atlas.
void linkPlanetSeam(AtlasManifest& manifest);

}  // namespace gimlod
