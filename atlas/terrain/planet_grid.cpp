#include "atlas/terrain/planet_grid.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include <fmt/format.h>

namespace gimlod {
namespace {

// The mean of row y's heights (over its distinct columns), as the DEM would store it.
float rowMean(const DemRaster& dem, uint32_t y, uint32_t columns) {
  double sum = 0.0;
  for (uint32_t x = 0; x < columns; ++x) sum += dem.heights[size_t(y) * dem.width + x];
  const double mean = sum / double(columns);
  return dem.integerHeights ? float(std::nearbyint(mean)) : float(mean);
}

// Each row's `columns` distinct samples round the circle resampled linearly to `to` (W' = to).
void resampleTurn(DemRaster& dem, uint32_t columns, uint32_t to) {
  std::vector<float> out(size_t(to) * dem.height);
  const double step = double(columns) / double(to);
  for (uint32_t y = 0; y < dem.height; ++y) {
    const float* row = &dem.heights[size_t(y) * dem.width];
    float* o = &out[size_t(y) * to];
    for (uint32_t x = 0; x < to; ++x) {
      const double at = double(x) * step;
      const uint32_t i = uint32_t(at), j = (i + 1) % columns;
      const double f = at - double(i);
      const double h = double(row[i]) + f * (double(row[j]) - double(row[i]));
      o[x] = dem.integerHeights ? float(std::nearbyint(h)) : float(h);
    }
  }
  dem.heights.swap(out);
  dem.width = to;
}

// The DEM with `south` rows before its first and `north` after its last (zero), and `east` columns
// after its last (copies of column 0).
void growDem(DemRaster& dem, uint32_t south, uint32_t north, uint32_t east) {
  const uint32_t w = dem.width + east, h = dem.height + south + north;
  std::vector<float> out(size_t(w) * h, 0.0f);
  for (uint32_t y = 0; y < dem.height; ++y) {
    const float* row = &dem.heights[size_t(y) * dem.width];
    float* to = &out[size_t(y + south) * w];
    std::copy_n(row, dem.width, to);
    for (uint32_t x = 0; x < east; ++x) to[dem.width + x] = row[x % dem.width];
  }
  dem.heights.swap(out);
  dem.width = w;
  dem.height = h;
}

}  // namespace

PlanetInfo preparePlanetGrid(DemRaster& dem, const std::filesystem::path& input, double radius,
                             uint32_t chartIntervals) {
  const auto& gt = dem.georef.geotransform;
  if (!dem.georef.geographic)
    throw InputError(input.string() + ": --planet needs a DEM in longitude and latitude (a geographic reference "
                     "system, or an extent in degrees); this one is projected or has no georeference");
  if (!(gt[1] > 0.0) || gt[2] != 0.0 || gt[4] != 0.0 || gt[5] == 0.0)
    throw InputError(input.string() + ": --planet needs a north-up, unrotated longitude/latitude grid");
  const double dx = gt[1], dy = std::fabs(gt[5]);
  const uint32_t W = dem.width, H = dem.height;
  PlanetInfo p;
  p.present = true;
  p.radius = radius;
  p.lon0Deg = gt[0] + 0.5 * dx;
  // Row 0 of the DEM is its southern row.
  double south = gt[5] < 0 ? gt[3] + (double(H) - 0.5) * gt[5] : gt[3] + 0.5 * gt[5];
  p.dlonDeg = dx;
  p.dlatDeg = dy;
  // Longitude: a whole turn of W columns, or of W - 1 (the last one repeats the first); made a
  // whole number of charts, plus the wrap column.
  uint32_t turn = 0;
  if (std::fabs(double(W) * dx - 360.0) < 0.5 * dx)
    turn = W;
  else if (W > 2 && std::fabs(double(W - 1) * dx - 360.0) < 0.5 * dx)
    turn = W - 1;
  uint32_t east = 0;
  if (turn) {
    const uint64_t m = std::max<uint32_t>(chartIntervals, 1);
    const uint64_t to = (turn + m - 1) / m * m;
    if (to > uint64_t(INT32_MAX))
      throw InputError(input.string() + ": --planet: too many columns a turn");
    if (to != turn || W != turn) {
      if (W != turn) {
        // Drop the repeated antimeridian column before resampling.
        DemRaster cut = dem;
        cut.width = turn;
        cut.heights.resize(size_t(turn) * H);
        for (uint32_t y = 0; y < H; ++y)
          std::copy_n(&dem.heights[size_t(y) * W], turn, &cut.heights[size_t(y) * turn]);
        dem.heights.swap(cut.heights);
        dem.width = turn;
      }
      if (to != turn) resampleTurn(dem, turn, uint32_t(to));
    }
    p.dlonDeg = 360.0 / double(to);
    p.wrapColumns = uint32_t(to);
    east = 1;
  }
  // Latitude: snapped to a whole half turn where the rows span one.
  if (std::fabs(double(H - 1) * dy - 180.0) < 0.5 * dy) {
    p.dlatDeg = 180.0 / double(H - 1);
    south = -90.0;
  } else if (std::fabs(double(H) * dy - 180.0) < 0.5 * dy) {
    p.dlatDeg = 180.0 / double(H);
    south = -90.0 + 0.5 * p.dlatDeg;
  }
  const double north = south + double(H - 1) * p.dlatDeg;
  if (south < -90.0 - 0.5 * p.dlatDeg || north > 90.0 + 0.5 * p.dlatDeg || std::fabs(p.lon0Deg) > 540.0)
    throw InputError(input.string() + fmt::format(": --planet: latitudes {:.4f} to {:.4f} or longitude {:.4f} lie "
                                                  "off the sphere; is the grid in degrees?",
                                                  south, north, p.lon0Deg));
  const uint32_t columns = p.wrapColumns ? p.wrapColumns : W;
  const uint32_t rows = dem.height;
  const double tol = 0.01 * p.dlatDeg;
  const bool southOn = std::fabs(south + 90.0) < tol, northOn = std::fabs(north - 90.0) < tol;
  const bool southNear = !southOn && south < -90.0 + p.dlatDeg - tol;
  const bool northNear = !northOn && north > 90.0 - p.dlatDeg + tol;
  const float southMean = rowMean(dem, 0, columns), northMean = rowMean(dem, rows - 1, columns);
  growDem(dem, southNear ? 1 : 0, northNear ? 1 : 0, east);
  p.lat0Deg = southOn ? -90.0 : southNear ? south - p.dlatDeg : south;
  if (southOn || southNear) std::fill_n(dem.heights.begin(), dem.width, southMean);
  if (northOn || northNear) std::fill_n(dem.heights.end() - dem.width, dem.width, northMean);
  const double deg = std::numbers::pi / 180.0;
  dem.spacing = {radius * p.dlonDeg * deg, radius * p.dlatDeg * deg};
  dem.georef.geotransform = {p.lon0Deg - 0.5 * p.dlonDeg, p.dlonDeg, 0.0,
                             p.lat0Deg + (double(dem.height) - 0.5) * p.dlatDeg, 0.0, -p.dlatDeg};
  dem.minHeight = std::min({dem.minHeight, southMean, northMean});
  dem.maxHeight = std::max({dem.maxHeight, southMean, northMean});
  return p;
}

void linkPlanetSeam(AtlasManifest& m) {
  if (!m.planet.present || !m.planet.wrapColumns || m.chartsX == 0) return;
  if (uint64_t(m.chartsX) * (m.chartSize - 1) != m.planet.wrapColumns) return;
  for (uint32_t y = 0; y < m.chartsY; ++y) {
    const uint32_t first = y * m.chartsX, last = first + m.chartsX - 1;
    m.charts[last].neighbours[kEdgeRight] = RootNeighbour{int32_t(first), uint8_t(kEdgeLeft), true};
    m.charts[first].neighbours[kEdgeLeft] = RootNeighbour{int32_t(last), uint8_t(kEdgeRight), true};
  }
}

}  // namespace gimlod
