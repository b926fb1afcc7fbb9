// Hand-made imagery for the imagery tests: RGB GeoTIFFs written through GDAL with colour squares
// centred on known geographic points, placed in any reference system (PROJ transforms the points,
// independently of the code under test).
#pragma once

#include <array>
#include <cmath>
#include <filesystem>
#include <functional>
#include <stdexcept>
#include <string>
#include <vector>

#include <gdal_priv.h>
#include <ogr_spatialref.h>

namespace gimlod::test {

struct GeoPoint {
  double lon = 0.0, lat = 0.0;
  std::array<uint8_t, 3> rgb{};
};

// Writes an RGB (or `bands`-band, `type`) GeoTIFF whose pixel (x, y) (y = 0 at the top) has
// colour(x, y). gt: GDAL geotransform, or empty for a raster without one; epsg 0: no SRS.
inline void writeTestRaster(const std::filesystem::path& path, int width, int height,
                            const std::function<std::array<uint8_t, 3>(int, int)>& colour,
                            const std::vector<double>& gt, int epsg, int bands = 3, GDALDataType type = GDT_Byte) {
  GDALAllRegister();
  GDALDriver* drv = GetGDALDriverManager()->GetDriverByName("GTiff");
  GDALDataset* ds = drv->Create(path.c_str(), width, height, bands, type, nullptr);
  if (!gt.empty()) ds->SetGeoTransform(const_cast<double*>(gt.data()));
  if (epsg) {
    OGRSpatialReference srs;
    srs.importFromEPSG(epsg);
    ds->SetSpatialRef(&srs);
  }
  std::vector<uint16_t> plane(size_t(width) * height);
  for (int b = 0; b < bands; ++b) {
    for (int y = 0; y < height; ++y)
      for (int x = 0; x < width; ++x) plane[size_t(y) * width + x] = colour(x, y)[size_t(std::min(b, 2))];
    if (ds->GetRasterBand(b + 1)->RasterIO(GF_Write, 0, 0, width, height, plane.data(), width, height, GDT_UInt16, 0,
                                           0) != CE_None)
      throw std::runtime_error("writeTestRaster: cannot write " + path.string());
  }
  GDALClose(ds);
}

// A UTM zone 10N (EPSG:32610) image of `pixel`-metre pixels over [x0, x1] x [y0, y1] (UTM metres):
// grey, with a square of side `side` metres in each point's colour centred on it.
inline void writeUtmImagery(const std::filesystem::path& path, const std::vector<GeoPoint>& points, double x0,
                            double y0, double x1, double y1, double pixel, double side) {
  OGRSpatialReference wgs, utm;
  wgs.importFromEPSG(4326);
  wgs.SetAxisMappingStrategy(OAMS_TRADITIONAL_GIS_ORDER);
  utm.importFromEPSG(32610);
  OGRCoordinateTransformation* ct = OGRCreateCoordinateTransformation(&wgs, &utm);
  std::vector<std::array<double, 2>> centres;
  for (const GeoPoint& p : points) {
    double x = p.lon, y = p.lat;
    ct->Transform(1, &x, &y);
    centres.push_back({x, y});
  }
  OGRCoordinateTransformation::DestroyCT(ct);
  const int w = int(std::lround((x1 - x0) / pixel)), h = int(std::lround((y1 - y0) / pixel));
  writeTestRaster(
      path, w, h,
      [&](int px, int py) {
        const double x = x0 + (px + 0.5) * pixel, y = y1 - (py + 0.5) * pixel;
        for (size_t i = 0; i < points.size(); ++i)
          if (std::abs(x - centres[i][0]) < side / 2 && std::abs(y - centres[i][1]) < side / 2) return points[i].rgb;
        return std::array<uint8_t, 3>{128, 128, 128};
      },
      {x0, pixel, 0.0, y1, 0.0, -pixel}, 32610);
}

// Three points on the shipped Rainier tile (N46W122) and their colours.
inline std::vector<GeoPoint> rainierPoints() {
  return {{-121.7603, 46.8529, {230, 30, 30}},  // the summit
          {-121.45, 46.30, {30, 200, 40}},
          {-121.90, 46.62, {40, 60, 230}}};
}

// UTM extent inside the tile's footprint.
inline constexpr double kRainierUtm[4] = {578000.0, 5096000.0, 652000.0, 5205600.0};

}  // namespace gimlod::test
