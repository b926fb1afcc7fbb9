// A mosaic of tiles is one DEM: the shipped SRTM tile cut into four GeoTIFFs (sharing their edge
// rows and columns, as SRTM tiles do) and put back together with a GDAL VRT builds the same atlas,
// byte for byte, as the tile itself.
#include <gtest/gtest.h>

#include <fstream>
#include <iterator>

#include <gdal_priv.h>
#include <gdal_utils.h>
#include <ogr_spatialref.h>
#include <nlohmann/json.hpp>

#include "core/atlas_format.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

namespace fs = std::filesystem;

TEST(Mosaic, FourTilesInAVrtBuildTheSameAtlasAsTheTile) {
  test::TempDir dir("gimlod-mosaic");
  const fs::path tile = test::repoData() / "terrain/mt_rainier_90m.tif";
  GDALAllRegister();
  GDALDatasetH src = GDALOpen(tile.c_str(), GA_ReadOnly);
  ASSERT_NE(src, nullptr);
  std::vector<GDALDatasetH> parts;
  std::vector<std::string> names;
  for (int ty = 0; ty < 2; ++ty)
    for (int tx = 0; tx < 2; ++tx) {
      // 601 x 601 samples each, sharing the middle row and column.
      const std::string name = (dir.path() / ("part_" + std::to_string(tx) + std::to_string(ty) + ".tif")).string();
      const std::string x0 = std::to_string(600 * tx), y0 = std::to_string(600 * ty);
      const char* args[] = {"-q", "-srcwin", x0.c_str(), y0.c_str(), "601", "601", nullptr};
      GDALTranslateOptions* o = GDALTranslateOptionsNew(const_cast<char**>(args), nullptr);
      GDALDatasetH part = GDALTranslate(name.c_str(), src, o, nullptr);
      GDALTranslateOptionsFree(o);
      ASSERT_NE(part, nullptr) << name;
      parts.push_back(part);
      names.push_back(name);
    }
  const std::string vrt = (dir.path() / "mosaic.vrt").string();
  GDALDatasetH mosaic = GDALBuildVRT(vrt.c_str(), int(parts.size()), parts.data(), nullptr, nullptr, nullptr);
  ASSERT_NE(mosaic, nullptr);
  EXPECT_EQ(GDALGetRasterXSize(mosaic), 1201);
  EXPECT_EQ(GDALGetRasterYSize(mosaic), 1201);
  GDALClose(mosaic);
  for (GDALDatasetH p : parts) GDALClose(p);
  GDALClose(src);

  std::string out;
  const fs::path a = dir.path() / "tile.atlas", b = dir.path() / "mosaic.atlas";
  ASSERT_EQ(test::runCommand(test::appPath().string() + " build '" + tile.string() + "' -o '" + a.string() + "'", &out),
            0)
      << out;
  ASSERT_EQ(test::runCommand(test::appPath().string() + " build '" + vrt + "' -o '" + b.string() + "'", &out), 0)
      << out;
  EXPECT_NE(out.find("voids filled      9033"), std::string::npos) << out;  // the tile's voids, through the VRT
  const AtlasManifest ma = readManifest(a), mb = readManifest(b);
  ASSERT_EQ(ma.charts.size(), mb.charts.size());
  for (size_t c = 0; c < ma.charts.size(); ++c)
    EXPECT_TRUE(test::fileBytes(a / ma.charts[c].file) == test::fileBytes(b / mb.charts[c].file)) << ma.charts[c].file;
  EXPECT_TRUE(test::fileBytes(a / ma.hierarchyFile) == test::fileBytes(b / mb.hierarchyFile));
  // The manifests differ only in the source they name, and in how GDAL spells the same reference
  // system (the tiles were written by GDAL, which spells EPSG:4326 without the datum ensemble).
  nlohmann::json ja = nlohmann::json::parse(test::fileBytes(a / kManifestName));
  nlohmann::json jb = nlohmann::json::parse(test::fileBytes(b / kManifestName));
  OGRSpatialReference sa, sb;
  ASSERT_EQ(sa.importFromWkt(ja["georef"]["wkt"].get<std::string>().c_str()), OGRERR_NONE);
  ASSERT_EQ(sb.importFromWkt(jb["georef"]["wkt"].get<std::string>().c_str()), OGRERR_NONE);
  EXPECT_TRUE(sa.IsSame(&sb));
  for (nlohmann::json* j : {&ja, &jb}) {
    j->erase("source");
    (*j)["georef"].erase("wkt");
  }
  EXPECT_EQ(ja, jb);
}

}  // namespace
}  // namespace gimlod
