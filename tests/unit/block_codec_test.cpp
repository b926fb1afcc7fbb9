// The height block codec (core/block_codec.h) on the shipped SRTM tile: integer metres round-trip
// exactly in every 65^2 block, float heights within half the precision, and every truncated block
// and (but for frame-header hints zstd ignores) every corrupted one is detected (CodecError), never
// decoded to wrong heights or a crash.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include <gdal_priv.h>

#include "atlas/terrain/dem.h"
#include "core/block_codec.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

constexpr uint32_t kSide = 65;

// The tile's raw int16 metres (voids included: -32768 is an integer too) as floats.
std::vector<float> rawTile(uint32_t* width, uint32_t* height) {
  GDALAllRegister();
  GDALDataset* ds = GDALDataset::FromHandle(
      GDALOpen((test::repoData() / "terrain/mt_rainier_90m.tif").c_str(), GA_ReadOnly));
  *width = uint32_t(ds->GetRasterXSize());
  *height = uint32_t(ds->GetRasterYSize());
  std::vector<float> h(size_t(*width) * *height);
  const CPLErr err = ds->GetRasterBand(1)->RasterIO(GF_Read, 0, 0, int(*width), int(*height), h.data(), int(*width),
                                                    int(*height), GDT_Float32, 0, 0);
  EXPECT_EQ(err, CE_None);
  GDALClose(ds);
  return h;
}

// Block (bx, by) of kSide^2 samples sharing its last row and column with the next, as in a chart.
std::vector<float> blockOf(const std::vector<float>& h, uint32_t width, uint32_t bx, uint32_t by) {
  std::vector<float> b(size_t(kSide) * kSide);
  for (uint32_t y = 0; y < kSide; ++y)
    for (uint32_t x = 0; x < kSide; ++x) b[size_t(y) * kSide + x] = h[size_t(by * 64 + y) * width + bx * 64 + x];
  return b;
}

TEST(HeightCodec, IntegerMetresRoundTripExactly) {
  uint32_t w = 0, h = 0;
  const std::vector<float> tile = rawTile(&w, &h);
  uint64_t bytes = 0, samples = 0;
  std::vector<float> out(size_t(kSide) * kSide);
  for (uint32_t by = 0; (by + 1) * 64 < h; ++by)
    for (uint32_t bx = 0; (bx + 1) * 64 < w; ++bx) {
      const std::vector<float> block = blockOf(tile, w, bx, by);
      const std::vector<uint8_t> code = encodeHeights(block, kSide, 0.0);
      EXPECT_EQ(blockQuantization(code), HeightQuantization::kInteger);
      decodeHeights(code, kSide, out);
      ASSERT_EQ(out, block) << "block " << bx << "," << by;
      bytes += code.size();
      samples += block.size();
    }
  const double perSample = double(bytes) / double(samples);
  std::printf("  SRTM tile, 65^2 blocks: %.3f bytes per sample (int16 source: 2)\n", perSample);
  EXPECT_LT(perSample, 2.0);  // it must beat the raw int16 it came from
}

TEST(HeightCodec, FloatHeightsStayWithinHalfThePrecision) {
  const DemRaster dem = loadDem(test::repoData() / "terrain/mt_rainier_90m.tif");  // voids filled: fractions
  std::vector<float> out(size_t(kSide) * kSide);
  double worst = 0.0;
  bool quantized = false;
  for (uint32_t by = 0; by < 4; ++by)
    for (uint32_t bx = 0; bx < 18; ++bx) {
      const std::vector<float> block = blockOf(dem.heights, dem.width, bx, by * 4);
      const std::vector<uint8_t> code = encodeHeights(block, kSide, 0.01);
      quantized = quantized || blockQuantization(code) == HeightQuantization::kPrecision;
      decodeHeights(code, kSide, out);
      for (size_t i = 0; i < out.size(); ++i) worst = std::max(worst, std::abs(double(out[i]) - block[i]));
    }
  EXPECT_TRUE(quantized);
  EXPECT_LE(worst, 0.005 + 1e-3);  // half the precision, plus float rounding at 4,000 m
  EXPECT_GT(worst, 0.0);
}

TEST(HeightCodec, CorruptOrTruncatedBlocksAreDetected) {
  uint32_t w = 0, h = 0;
  const std::vector<float> tile = rawTile(&w, &h);
  const std::vector<float> block = blockOf(tile, w, 7, 9);
  const std::vector<uint8_t> code = encodeHeights(block, kSide, 0.0);
  std::vector<float> out(size_t(kSide) * kSide);
  for (size_t len = 0; len < code.size(); ++len)
    EXPECT_THROW(decodeHeights(std::span(code.data(), len), kSide, out), CodecError) << "truncated to " << len;
  std::mt19937 rng(3);
  size_t benign = 0;
  for (size_t at = 0; at < code.size(); ++at) {
    std::vector<uint8_t> bad = code;
    bad[at] ^= uint8_t(1u << (rng() % 8));
    try {
      decodeHeights(bad, kSide, out);
      // A flip zstd's format does not care about (a frame-header hint) may decode: then only to
      // the true heights.
      EXPECT_EQ(out, block) << "a flipped bit at byte " << at << " decoded to other heights";
      ++benign;
    } catch (const CodecError&) {
    }
  }
  EXPECT_LE(benign, 4u);  // nearly every flip is caught by the checksum
  EXPECT_THROW(decodeHeights(code, kSide - 2, std::span(out.data(), size_t(kSide - 2) * (kSide - 2))), CodecError);
}

TEST(HeightCodec, RefusesWhatItCannotCode) {
  std::vector<float> block(size_t(kSide) * kSide, 1.5f);
  EXPECT_THROW(encodeHeights(block, kSide, 0.0), std::invalid_argument);  // fractions need a precision
  block[5] = std::nanf("");
  EXPECT_THROW(encodeHeights(block, kSide, 0.1), std::invalid_argument);
  block.assign(block.size(), 3.0e9f);
  EXPECT_THROW(encodeHeights(block, kSide, 0.01), std::invalid_argument);
  EXPECT_THROW(encodeHeights(block, kSide + 1, 0.01), std::invalid_argument);
}

}  // namespace
}  // namespace gimlod
