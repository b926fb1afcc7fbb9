#include "atlas/terrain/planet_grid.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include <cstdio>

namespace gimlod {

int64_t PlanetGrid::sourceRow(uint32_t y) const {
  if (southAdded && y == 0) return -1;
  if (northAdded && y + 1 == height()) return -1;
  return int64_t(y) - int64_t(southAdded);
}

PlanetGrid planPlanetGrid(const PlanetSource& dem, const std::filesystem::path& input, double radius,
                          uint32_t chartIntervals) {
  const uint32_t W = dem.width, H = dem.height;
  const auto& gt = dem.georef.geotransform;
  if (!dem.georef.geographic)
    throw InputError(input.string() +
                     ": --planet needs a DEM in longitude and latitude (a geographic reference "
                     "system, or an extent in degrees); this one is projected or has no georeference");
  if (!(gt[1] > 0.0) || gt[2] != 0.0 || gt[4] != 0.0 || gt[5] == 0.0 || W < 2 || H < 2)
    throw InputError(input.string() + ": --planet needs a north-up, unrotated longitude/latitude grid");
  const double dx = gt[1], dy = std::fabs(gt[5]);
  PlanetGrid g;
  g.sourceWidth = W;
  g.sourceHeight = H;
  g.round = dem.integerHeights;
  PlanetInfo& p = g.info;
  p.present = true;
  p.radius = radius;
  p.lon0Deg = gt[0] + 0.5 * dx;
  p.dlonDeg = dx;
  p.dlatDeg = dy;
  // Row 0 of the DEM is its southern row.
  double south = gt[5] < 0 ? gt[3] + (double(H) - 0.5) * gt[5] : gt[3] + 0.5 * gt[5];
  if (std::fabs(double(W) * dx - 360.0) < 0.5 * dx)
    g.turn = W;
  else if (W > 2 && std::fabs(double(W - 1) * dx - 360.0) < 0.5 * dx)
    g.turn = W - 1;
  if (!g.turn && std::fabs(double(W) * dx - 360.0) < 3.6) {
    char text[200];
    std::snprintf(text, sizeof text,
                  "spans %.4f degrees of longitude, not 360 within half a pixel (%.6f): drawn as a regional DEM "
                  "that does not wrap; give its extent exactly (gdal_translate -a_ullr) to wrap it",
                  double(W) * dx, 0.5 * dx);
    g.warning = text;
  }
  if (g.turn) {
    const uint64_t m = std::max<uint32_t>(chartIntervals, 1);
    const uint64_t to = (g.turn + m - 1) / m * m;
    if (to >= uint64_t(INT32_MAX)) throw InputError(input.string() + ": --planet: too many columns a turn");
    p.dlonDeg = 360.0 / double(to);
    p.wrapColumns = uint32_t(to);
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
  // How far past a pole a grid may reach: half a row, or half a degree (a global grid resampled
  // finer keeps the half cell its coarser grid passed the poles by, as DEM input allows).
  const double slack = std::max(0.5 * p.dlatDeg, 0.5);
  if (south < -90.0 - slack || north > 90.0 + slack || std::fabs(p.lon0Deg) > 540.0) {
    char text[160];
    std::snprintf(text, sizeof text,
                  ": --planet: latitudes %.4f to %.4f or longitude %.4f lie off the sphere; is the "
                  "grid in degrees?",
                  south, north, p.lon0Deg);
    throw InputError(input.string() + text);
  }
  const double tol = 0.01 * p.dlatDeg;
  g.southAdded = south > -90.0 + tol && south < -90.0 + p.dlatDeg - tol ? 1 : 0;
  g.northAdded = north < 90.0 - tol && north > 90.0 - p.dlatDeg + tol ? 1 : 0;
  p.lat0Deg = g.southAdded ? south - p.dlatDeg : south;
  // The rows on a pole, as the frame places them.
  const PlanetFrame frame(p, g.width(), g.height());
  g.southRows = uint32_t(frame.southPoleRow() + 1);
  g.northFrom = uint32_t(std::min<int64_t>(frame.northPoleRow(), g.height()));
  if (g.southRows > 0) g.southMeanRow = uint32_t(std::max<int64_t>(g.sourceRow(g.southRows - 1), 0));
  if (g.northFrom < g.height())
    g.northMeanRow = uint32_t(g.sourceRow(g.northFrom) >= 0 ? g.sourceRow(g.northFrom) : int64_t(H) - 1);
  return g;
}

float poleRowMean(const PlanetGrid& g, const float* heights, const uint8_t* valid, const std::filesystem::path& input) {
  const uint32_t columns = g.turn ? g.turn : g.sourceWidth;
  double sum = 0.0;
  uint64_t n = 0;
  for (uint32_t x = 0; x < columns; ++x)
    if (valid[x]) {
      sum += heights[x];
      ++n;
    }
  if (n == 0) throw InputError(input.string() + ": --planet: a pole row holds no valid height");
  const double mean = sum / double(n);
  return g.round ? float(std::nearbyint(mean)) : float(mean);
}

void planetGridRow(const PlanetGrid& g, uint32_t y, const float* source, const uint8_t* sourceValid, float* out,
                   uint8_t* outValid) {
  const uint32_t w = g.width();
  const bool south = y < g.southRows, north = y >= g.northFrom;
  if (south || north) {
    std::fill_n(out, w, south ? g.southMean : g.northMean);
    std::fill_n(outValid, w, uint8_t(1));
    return;
  }
  if (!g.turn) {
    std::copy_n(source, w, out);
    std::copy_n(sourceValid, w, outValid);
    return;
  }
  const uint32_t to = g.info.wrapColumns;
  if (to == g.turn) {
    std::copy_n(source, to, out);
    std::copy_n(sourceValid, to, outValid);
  } else {
    const double step = double(g.turn) / double(to);
    for (uint32_t x = 0; x < to; ++x) {
      const double at = double(x) * step;
      const uint32_t i = uint32_t(at), j = (i + 1) % g.turn;
      const double f = at - double(i);
      const double h = double(source[i]) + f * (double(source[j]) - double(source[i]));
      out[x] = g.round ? float(std::nearbyint(h)) : float(h);
      outValid[x] = sourceValid[i] && (f == 0.0 || sourceValid[j]);
    }
  }
  out[to] = out[0];
  outValid[to] = outValid[0];
}

Georeference planetGridGeoref(const PlanetGrid& g, const Georeference& source) {
  Georeference r = source;
  const PlanetInfo& p = g.info;
  r.geotransform = {
      p.lon0Deg - 0.5 * p.dlonDeg, p.dlonDeg, 0.0, p.lat0Deg + (double(g.height()) - 0.5) * p.dlatDeg, 0.0, -p.dlatDeg};
  return r;
}

std::array<double, 2> planetGridSpacing(const PlanetGrid& g) {
  const double deg = std::numbers::pi / 180.0;
  return {g.info.radius * g.info.dlonDeg * deg, g.info.radius * g.info.dlatDeg * deg};
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
