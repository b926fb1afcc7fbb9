// The windowed void fill gives, bit for bit, what the whole-raster fill gives: on the shipped
// SRTM tile with its own voids, and with large voids punched in it (a lake wider than any window,
// which needs the coarse levels filled whole), for windows far smaller than the raster.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>

#include <gdal_priv.h>

#include "atlas/terrain/void_fill.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

struct Raster {
  uint32_t width = 0, height = 0;
  std::vector<float> heights;
  std::vector<bool> voids;
};

// The tile's raw samples, its -32768 voids marked.
Raster rawTile() {
  GDALAllRegister();
  GDALDataset* ds =
      GDALDataset::FromHandle(GDALOpen((test::repoData() / "terrain/mt_rainier_90m.tif").c_str(), GA_ReadOnly));
  Raster r;
  r.width = uint32_t(ds->GetRasterXSize());
  r.height = uint32_t(ds->GetRasterYSize());
  r.heights.resize(size_t(r.width) * r.height);
  EXPECT_EQ(ds->GetRasterBand(1)->RasterIO(GF_Read, 0, 0, int(r.width), int(r.height), r.heights.data(), int(r.width),
                                           int(r.height), GDT_Float32, 0, 0),
            CE_None);
  GDALClose(ds);
  r.voids.resize(r.heights.size());
  for (size_t i = 0; i < r.heights.size(); ++i) r.voids[i] = r.heights[i] <= -32000.f;
  return r;
}

// Fills r in memory and window by window (windows of about windowSamples); expects the same bits.
void expectWindowedFillMatches(const Raster& r, uint64_t windowSamples, size_t* coresWritten) {
  std::vector<float> whole = r.heights;
  const uint64_t filled = fillVoids(whole, r.voids, r.width, r.height);
  ASSERT_GT(filled, 0u);
  float lo = std::numeric_limits<float>::infinity(), hi = -lo;
  for (size_t i = 0; i < r.heights.size(); ++i)
    if (!r.voids[i]) lo = std::min(lo, r.heights[i]), hi = std::max(hi, r.heights[i]);
  std::vector<float> windowed = r.heights;
  uint64_t largestRead = 0;
  *coresWritten = 0;
  WindowedFill io;
  io.read = [&](const CellWindow& w, float* h, uint8_t* valid) {
    largestRead = std::max<uint64_t>(largestRead, w.cells());
    for (int64_t y = w.y0; y < w.y1; ++y)
      for (int64_t x = w.x0; x < w.x1; ++x) {
        const size_t k = size_t(y) * r.width + size_t(x), o = size_t(y - w.y0) * size_t(w.width()) + size_t(x - w.x0);
        h[o] = r.heights[k];  // the source, never what was written: fills must not feed fills
        valid[o] = r.voids[k] ? 0 : 1;
      }
  };
  io.write = [&](const CellWindow& w, const float* h) {
    ++*coresWritten;
    for (int64_t y = w.y0; y < w.y1; ++y)
      std::memcpy(windowed.data() + size_t(y) * r.width + size_t(w.x0), h + size_t(y - w.y0) * size_t(w.width()),
                  size_t(w.width()) * sizeof(float));
  };
  io.hasVoids = [&](const CellWindow& w) {
    for (int64_t y = w.y0; y < w.y1; ++y)
      for (int64_t x = w.x0; x < w.x1; ++x)
        if (r.voids[size_t(y) * r.width + size_t(x)]) return true;
    return false;
  };
  fillVoidsWindowed(r.width, r.height, lo, hi, io, windowSamples);
  size_t differ = 0;
  for (size_t i = 0; i < whole.size(); ++i) differ += std::memcmp(&whole[i], &windowed[i], sizeof(float)) != 0;
  EXPECT_EQ(differ, 0u) << "of " << filled << " filled samples";
  // The windows stay near the size asked for: the raster is several times larger.
  EXPECT_LT(largestRead, r.heights.size() / 3);
}

TEST(WindowedVoidFill, TheTilesOwnVoidsFillAsInMemory) {
  const Raster r = rawTile();
  size_t cores = 0;
  expectWindowedFillMatches(r, 400 * 400, &cores);
  EXPECT_GT(cores, 2u);
}

TEST(WindowedVoidFill, ALakeWiderThanAnyWindowFillsAsInMemory) {
  Raster r = rawTile();
  // A 700 x 260 lake, a thin channel and scattered single voids: voids survive past the windowed
  // levels, so the coarse levels are filled whole.
  for (uint32_t y = 300; y < 560; ++y)
    for (uint32_t x = 200; x < 900; ++x) r.voids[size_t(y) * r.width + x] = true;
  for (uint32_t x = 0; x < r.width; ++x) r.voids[size_t(900) * r.width + x] = true;
  for (size_t i = 0; i < r.voids.size(); i += 997) r.voids[i] = true;
  size_t cores = 0;
  expectWindowedFillMatches(r, 300 * 300, &cores);
  EXPECT_GT(cores, 4u);
}

}  // namespace
}  // namespace gimlod
