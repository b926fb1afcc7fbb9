// The shipped Rainier tile upsampled by a GDAL VRT: a larger DEM of the same terrain, made without
// writing its samples (the terrain tests' stand-in for a large DEM).
#pragma once

#include <filesystem>
#include <stdexcept>

#include <gdal_priv.h>
#include <gdal_utils.h>

#include "tests/test_util.h"

namespace gimlod::test {

// The shipped tile upsampled by a GDAL VRT (bilinear, whole metres; its voids come through as
// nodata).
inline std::filesystem::path upsampledTile(const std::filesystem::path& dir, const char* scale) {
  const std::filesystem::path tile = test::repoData() / "terrain/mt_rainier_90m.tif";
  const std::filesystem::path vrt = dir / "upsampled.vrt";
  GDALAllRegister();
  GDALDatasetH src = GDALOpen(tile.c_str(), GA_ReadOnly);
  if (!src) throw std::runtime_error("cannot open " + tile.string());
  const char* argv[] = {"-q", "-of", "VRT", "-outsize", scale, scale, "-r", "bilinear", nullptr};
  GDALTranslateOptions* opts = GDALTranslateOptionsNew(const_cast<char**>(argv), nullptr);
  GDALDatasetH out = GDALTranslate(vrt.c_str(), src, opts, nullptr);
  GDALTranslateOptionsFree(opts);
  if (out) GDALClose(out);  // before its source, which it refers to
  GDALClose(src);
  if (!out) throw std::runtime_error("cannot write " + vrt.string());
  return vrt;
}

}  // namespace gimlod::test
