// The height block codec (core/block_codec.h) on the shipped SRTM tile: integer metres round-trip
// exactly in every 65^2 block, float heights within half the precision, and every truncated block
// and (but for frame-header hints zstd ignores) every corrupted one is detected (CodecError), never
// decoded to wrong heights or a crash. Then the settling of positions and normals within their
// tolerances, on a curved sheet, and whole byte strings.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <random>
#include <set>
#include <string>

#include <glm/geometric.hpp>

#include <gdal_priv.h>
#include <zstd.h>

#include "atlas/terrain/dem.h"
#include "core/atlas_format.h"
#include "core/block_codec.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

constexpr uint32_t kSide = 65;

// The tile's raw int16 metres (voids included: -32768 is an integer too) as floats.
std::vector<float> rawTile(uint32_t* width, uint32_t* height) {
  GDALAllRegister();
  GDALDataset* ds =
      GDALDataset::FromHandle(GDALOpen((test::repoData() / "terrain/mt_rainier_90m.tif").c_str(), GA_ReadOnly));
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
    } catch (const CodecError&) {}
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

// A smooth curved sheet, side^2 positions, samples `spacing` apart; rows from `squeezeRow` on
// are squeezed to a hundredth of that, so grid neighbours there lie far closer than a tolerance.
std::vector<float> sheet(uint32_t side, double spacing, uint32_t squeezeRow = ~0u) {
  std::vector<float> xyz(3 * size_t(side) * side);
  for (uint32_t v = 0; v < side; ++v)
    for (uint32_t u = 0; u < side; ++u) {
      const double x = u * spacing + 0.3;
      const double y = v < squeezeRow ? v * spacing : (squeezeRow + (v - squeezeRow) * 0.01) * spacing;
      float* p = xyz.data() + 3 * (size_t(v) * side + u);
      p[0] = float(x);
      p[1] = float(y);
      p[2] = float(0.2 * std::sin(3 * x) * std::cos(2 * y) + 0.05 * x * y);
    }
  return xyz;
}

double distance3(const float* a, const float* b) {
  return std::sqrt(double(a[0] - b[0]) * (a[0] - b[0]) + double(a[1] - b[1]) * (a[1] - b[1]) +
                   double(a[2] - b[2]) * (a[2] - b[2]));
}

// Settled positions: the border at its nearest lattice point, every other sample on the lattice
// within min(tolerance, d / 4) of its input (d: the distance to the nearest other sample of its
// 5x5 grid window), no two samples of such a window merged, decoded exactly, and coded in fewer bytes than the nearest
// points.
TEST(PositionSettling, WithinTheToleranceOnTheLatticeAndCheaper) {
  const double step = std::exp2(-18.0), tolerance = 2e-4;
  for (const uint32_t squeeze : {~0u, 40u}) {
    const std::vector<float> in = sheet(kSide, 1.0 / 64, squeeze);
    const std::vector<float> nearest = settlePositions(in, kSide, step, 0.0);
    const std::vector<float> settled = settlePositions(in, kSide, step, tolerance);
    size_t moved = 0;
    for (uint32_t v = 0; v < kSide; ++v)
      for (uint32_t u = 0; u < kSide; ++u) {
        const size_t i = size_t(v) * kSide + u;
        const bool border = u == 0 || v == 0 || u + 1 == kSide || v + 1 == kSide;
        for (int c = 0; c < 3; ++c) {
          ASSERT_EQ(nearest[3 * i + c], quantizeToStep(in[3 * i + c], step));
          ASSERT_EQ(std::nearbyint(double(settled[3 * i + c]) / step) * step, double(settled[3 * i + c]));
          if (border) {
            ASSERT_EQ(settled[3 * i + c], nearest[3 * i + c]) << u << "," << v;
          }
        }
        if (border) continue;
        double d = 1e300;
        for (uint32_t y = v >= 2 ? v - 2 : 0; y <= std::min(v + 2, kSide - 1); ++y)
          for (uint32_t x = u >= 2 ? u - 2 : 0; x <= std::min(u + 2, kSide - 1); ++x) {
            const size_t j = size_t(y) * kSide + x;
            if (j == i) continue;
            d = std::min(d, distance3(&in[3 * i], &in[3 * j]));
            ASSERT_GT(distance3(&settled[3 * i], &settled[3 * j]), 0.0) << "samples merged at " << u << "," << v;
          }
        const double allowed = std::max(std::min(tolerance, d / 4), std::sqrt(3.0) * step / 2);
        ASSERT_LE(distance3(&settled[3 * i], &in[3 * i]), allowed * (1 + 1e-6) + 1e-9) << u << "," << v;
        moved += distance3(&settled[3 * i], &nearest[3 * i]) > 0;
      }
    EXPECT_GT(moved, size_t(kSide) * kSide / 4);
    const std::vector<uint8_t> a = encodePositions(nearest, kSide, step), b = encodePositions(settled, kSide, step);
    std::vector<float> back(settled.size());
    decodePositions(b, kSide, back);
    EXPECT_EQ(back, settled);
    std::printf("  %s sheet: %zu bytes at the nearest lattice points, %zu settled within %g\n",
                squeeze == ~0u ? "smooth" : "squeezed", a.size(), b.size(), tolerance);
    EXPECT_LT(double(b.size()), 0.8 * double(a.size()));
  }
  EXPECT_THROW(settlePositions(sheet(kSide, 0.01), kSide, step, -1.0), std::invalid_argument);
  EXPECT_THROW(settlePositions(sheet(kSide, 0.01), kSide - 1, step, 0.0), std::invalid_argument);
}

// Positions round-trip exactly to their lattice points whatever the residuals' width: random walks
// whose residuals take 1, 2, 3 and 4 byte planes, at every block side the atlases use, and a
// block whose coordinates reach the lattice's bound of 2^23 steps either way.
TEST(PositionCodec, RoundTripsExactlyAtEveryResidualWidth) {
  const double step = std::exp2(-18.0);
  std::mt19937 rng(7);
  for (const uint32_t side : {2u, 3u, 9u, 65u}) {
    for (const int32_t spread : {3, 100, 30000, 3000000, 1 << 23}) {
      std::uniform_int_distribution<int32_t> d(-spread, spread);
      std::vector<float> in(size_t(3) * side * side);
      for (float& v : in) v = float(double(d(rng)) * step);
      const std::vector<uint8_t> coded = encodePositions(in, side, step);
      std::vector<float> back(in.size(), -1.0f);
      decodePositions(coded, side, back);
      ASSERT_EQ(back, in) << "side " << side << ", residuals up to " << spread << " steps";
    }
  }
  // The bound itself, both ways, alternating (the largest residuals a block can hold).
  std::vector<float> in(size_t(3) * kSide * kSide);
  for (size_t i = 0; i < in.size(); ++i) in[i] = float(double((i & 1) ? (1 << 23) : -(1 << 23)) * step);
  std::vector<float> back(in.size());
  decodePositions(encodePositions(in, kSide, step), kSide, back);
  EXPECT_EQ(back, in);
}

// The raw body of a coded block (its zstd frame after the magic), or empty when it does not decode.
std::vector<uint8_t> blockBody(const std::vector<uint8_t>& block) {
  const unsigned long long size = ZSTD_getFrameContentSize(block.data() + 4, block.size() - 4);
  if (size == ZSTD_CONTENTSIZE_ERROR || size == ZSTD_CONTENTSIZE_UNKNOWN) return {};
  std::vector<uint8_t> raw(size);
  const size_t got = ZSTD_decompress(raw.data(), raw.size(), block.data() + 4, block.size() - 4);
  if (ZSTD_isError(got) || got != size) return {};
  return raw;
}

// A position block of `raw` (the magic and a checksummed zstd frame), as a writer frames it.
std::vector<uint8_t> positionBlock(const std::vector<uint8_t>& raw) {
  std::vector<uint8_t> block = {'G', 'P', 'B', '1'};
  block.resize(4 + ZSTD_compressBound(raw.size()));
  ZSTD_CCtx* cctx = ZSTD_createCCtx();
  ZSTD_CCtx_setParameter(cctx, ZSTD_c_checksumFlag, 1);
  const size_t written = ZSTD_compress2(cctx, block.data() + 4, block.size() - 4, raw.data(), raw.size());
  ZSTD_freeCCtx(cctx);
  block.resize(ZSTD_isError(written) ? 4 : 4 + written);
  return block;
}

// Blocks written before the first sample moved to the block's header (flags 0: every sample a
// Lorenzo residual, the first from 0) still decode, built here byte by byte as that writer did.
TEST(PositionCodec, BlocksWithoutTheFirstSampleInTheHeaderStillDecode) {
  const double step = 0.25;
  constexpr uint32_t side = 3;
  std::vector<int32_t> q(3 * side * side);
  for (size_t i = 0; i < q.size(); ++i) q[i] = int32_t(i * i) - 20 + (i % 3 == 2 ? 70000 : 0);
  std::vector<uint32_t> z(q.size());
  for (uint32_t y = 0; y < side; ++y)
    for (uint32_t x = 0; x < side; ++x)
      for (uint32_t c = 0; c < 3; ++c) {
        auto at = [&](uint32_t u, uint32_t v) { return int64_t(q[(size_t(v) * side + u) * 3 + c]); };
        const int64_t pred = x > 0 && y > 0 ? at(x - 1, y) + at(x, y - 1) - at(x - 1, y - 1)
                             : x > 0        ? at(x - 1, y)
                             : y > 0        ? at(x, y - 1)
                                            : 0;
        const int32_t r = int32_t(at(x, y) - pred);
        z[(size_t(y) * side + x) * 3 + c] = (uint32_t(r) << 1) ^ uint32_t(r >> 31);
      }
  constexpr uint8_t planes = 3;  // the first z coordinate's 140,000-odd needs three
  std::vector<uint8_t> raw(16 + size_t(planes) * z.size(), 0);
  raw[0] = 1;  // quantized to a step
  raw[1] = planes;
  raw[2] = 3;  // channels; raw[3]: flags 0
  std::memcpy(raw.data() + 4, &side, 4);
  std::memcpy(raw.data() + 8, &step, 8);
  const size_t n = size_t(side) * side;
  for (uint32_t c = 0; c < 3; ++c)
    for (uint32_t p = 0; p < planes; ++p)
      for (size_t i = 0; i < n; ++i) raw[16 + (c * planes + p) * n + i] = uint8_t(z[i * 3 + c] >> (8 * p));
  const std::vector<uint8_t> block = positionBlock(raw);
  ASSERT_GT(block.size(), 4u);
  std::vector<float> back(q.size());
  decodePositions(block, side, back);
  for (size_t i = 0; i < q.size(); ++i) EXPECT_EQ(back[i], float(q[i] * step)) << i;
  // The same samples coded now (the first sample in the header) round-trip too, in another code.
  std::vector<float> in(q.size());
  for (size_t i = 0; i < q.size(); ++i) in[i] = float(q[i] * step);
  const std::vector<uint8_t> now = encodePositions(in, side, step);
  decodePositions(now, side, back);
  EXPECT_EQ(back, in);
  EXPECT_NE(now, block);
}

// A settled sheet is coded in the interpolation order (flag 4), decodes exactly, and takes fewer
// bytes than the same samples' other codes would (a smooth sheet's settled samples are their
// coarser neighbours' means); damage, another side, an interpolated body on a side that is not
// 2^k + 1, with planar squares, or with values past the lattice's bound are CodecError.
TEST(PositionCodec, InterpolatedBlocksRoundTripAndDetectDamage) {
  const double step = std::exp2(-18.0);
  const std::vector<float> in = settlePositions(sheet(kSide, 1.0 / 64), kSide, step, 2e-4);
  const std::vector<uint8_t> code = encodePositions(in, kSide, step, 0);
  std::vector<uint8_t> raw = blockBody(code);
  ASSERT_GT(raw.size(), 16u);
  EXPECT_EQ(raw[3], 1 | 4);  // the first sample in the header, the interpolation order
  std::vector<float> back(in.size());
  decodePositions(code, kSide, back);
  EXPECT_EQ(back, in);
  std::printf("  settled sheet: %zu bytes\n", code.size());
  std::vector<uint8_t> bad = code;
  bad[bad.size() - 1] ^= 0x10;
  EXPECT_THROW(decodePositions(bad, kSide, back), CodecError);
  EXPECT_THROW(decodePositions({code.data(), code.size() - 3}, kSide, back), CodecError);
  std::vector<float> smaller(3 * 33 * 33);
  EXPECT_THROW(decodePositions(code, 33, smaller), CodecError);
  // The same body, re-framed, decodes; changed as a crafted block would be, it is refused.
  EXPECT_NO_THROW(decodePositions(positionBlock(raw), kSide, back));
  EXPECT_EQ(back, in);
  std::vector<uint8_t> planar = raw;
  planar[3] |= 2;
  EXPECT_THROW(decodePositions(positionBlock(planar), kSide, back), CodecError);
  std::vector<uint8_t> noFirst = raw;
  noFirst[3] = 4;
  EXPECT_THROW(decodePositions(positionBlock(noFirst), kSide, back), CodecError);
  // Side 11 (not 2^k + 1): the header's side and the body's size made to agree.
  constexpr uint32_t odd = 11;
  std::vector<uint8_t> oddBody(16 + 12 + size_t(raw[1]) * 3 * odd * odd, 0);
  std::copy(raw.begin(), raw.begin() + 28, oddBody.begin());
  std::memcpy(oddBody.data() + 4, &odd, 4);
  std::vector<float> oddOut(3 * odd * odd);
  EXPECT_THROW(decodePositions(positionBlock(oddBody), odd, oddOut), CodecError);
  // Every residual at the largest value its planes hold: the values leave the lattice's bound.
  std::vector<uint8_t> far(raw.begin(), raw.begin() + 28);
  far[1] = 4;  // four byte planes
  far.resize(28 + 4 * 3 * size_t(kSide) * kSide, uint8_t(0xFE));
  EXPECT_THROW(decodePositions(positionBlock(far), kSide, back), CodecError);
}

// Blocks whose squares a writer placed on their corners' triangles, largest first, nested at
// every size and against every set of chart-border edges (whose samples stay put), with
// coordinates near 0 and across the whole lattice: each decodes to exactly its samples, codes in
// fewer bytes than with every sample coded, and a block with no planar square codes exactly as
// without them.
TEST(PositionCodec, PlanarSquaresRoundTripExactlyAndCodeFewerBytes) {
  const double step = 1.0 / 1024;
  std::mt19937 rng(5);
  size_t planarBlocks = 0;
  for (const int range : {1000, 1 << 23})
    for (const uint32_t side : {3u, 5u, 9u, 17u, 33u, 65u})
      for (const uint8_t border : {uint8_t(0), uint8_t(15), uint8_t(kChartBorderBottom | kChartBorderTop),
                                   uint8_t(kChartBorderLeft | kChartBorderRight)})
        for (const double share : {0.0, 0.3, 0.7}) {
          SCOPED_TRACE(::testing::Message()
                       << "side " << side << ", border " << int(border) << ", share " << share << ", range " << range);
          std::uniform_int_distribution<int> value(-range, range);
          const uint32_t M = side - 1;
          std::vector<int64_t> q(size_t(side) * side * 3);
          for (int64_t& v : q) v = value(rng);
          std::vector<uint8_t> placed(size_t(side) * side, 0);
          std::bernoulli_distribution take(share);
          std::vector<uint8_t> parent;  // the previous size's squares: 1 planar or inside one
          for (uint32_t s = M; s >= 2; s /= 2) {
            const uint32_t n = M / s;
            std::vector<uint8_t> here(size_t(n) * n, 0);
            for (uint32_t sy = 0; sy < n; ++sy)
              for (uint32_t sx = 0; sx < n; ++sx) {
                if (!parent.empty() && parent[size_t(sy / 2) * (n / 2) + sx / 2]) {
                  here[size_t(sy) * n + sx] = 1;
                  continue;
                }
                if (!take(rng)) continue;
                here[size_t(sy) * n + sx] = 1;
                const uint32_t x0 = sx * s, y0 = sy * s;
                for (uint32_t dy = 0; dy <= s; ++dy)
                  for (uint32_t dx = 0; dx <= s; ++dx) {
                    const uint32_t x = x0 + dx, y = y0 + dy;
                    const size_t i = size_t(y) * side + x;
                    const bool onBorder =
                        ((border & kChartBorderBottom) && y == 0) || ((border & kChartBorderRight) && x == M) ||
                        ((border & kChartBorderTop) && y == M) || ((border & kChartBorderLeft) && x == 0);
                    if (placed[i] || (dx % s == 0 && dy % s == 0) || onBorder) continue;
                    for (int c = 0; c < 3; ++c) {
                      auto at = [&](uint32_t a, uint32_t b) { return q[(size_t(b) * side + a) * 3 + c]; };
                      q[i * 3 + c] =
                          planarSquareSample(at(x0, y0), at(x0 + s, y0), at(x0, y0 + s), at(x0 + s, y0 + s), s, dx, dy);
                    }
                    placed[i] = 1;
                  }
              }
            parent = here;
          }
          std::vector<float> in(q.size());
          for (size_t i = 0; i < q.size(); ++i) in[i] = float(double(q[i]) * step);
          // (Row order alone against row order or planar squares: the interpolated code apart.)
          const std::vector<uint8_t> all = encodePositions(in, side, step, -1, false),
                                     planar = encodePositions(in, side, step, border, false);
          std::vector<float> back(in.size(), -1.0f);
          decodePositions(planar, side, back);
          ASSERT_EQ(back, in);
          if (share == 0.0) {
            EXPECT_EQ(planar, all);  // no planar square: coded as before
          } else if (std::count(placed.begin(), placed.end(), 1) > 4) {
            EXPECT_LT(planar.size(), all.size());
            ++planarBlocks;
          }
          // Damage is detected, never decoded to other samples.
          for (size_t at = 4; at < planar.size(); at += 7) {
            std::vector<uint8_t> bad = planar;
            bad[at] ^= 0x24;
            try {
              decodePositions(bad, side, back);
              EXPECT_EQ(back, in) << "byte " << at;
            } catch (const CodecError&) {}
          }
          EXPECT_THROW(decodePositions(std::span(planar).first(planar.size() - 3), side, back), CodecError);
        }
  EXPECT_GT(planarBlocks, 10u);
  // Where the squares put a sample: on the two triangles, rounded half up, and the half-size square
  // of a subsampling puts it at the same place.
  EXPECT_EQ(planarSquareSample(0, 8, 0, 8, 8, 3, 1), 3);
  EXPECT_EQ(planarSquareSample(0, 0, 8, 8, 8, 1, 3), 3);
  EXPECT_EQ(planarSquareSample(0, 3, 0, 3, 2, 1, 0), 2);     // 1.5 rounds up
  EXPECT_EQ(planarSquareSample(0, -3, 0, -3, 2, 1, 0), -1);  // -1.5 rounds up
  for (uint32_t d = 0; d <= 4; ++d)
    EXPECT_EQ(planarSquareSample(5, -17, 40, 9, 8, 2 * d, 2 * (d / 2)), planarSquareSample(5, -17, 40, 9, 4, d, d / 2));
}

// A planar block's body damaged behind a valid frame (as a checksum cannot see: a writer's bug, a
// crafted file): every damage decodes to some samples or is a CodecError, never reads or writes
// out of bounds (the sanitizers' builds run this too).
TEST(PositionCodec, DamagedPlanarBodiesDecodeOrThrow) {
  const double step = 1.0 / 1024;
  std::mt19937 rng(11);
  size_t thrown = 0, decoded = 0;
  for (const uint32_t side : {9u, 17u, 65u}) {
    // Random corners every 4 intervals, the squares between them planar but where a random
    // sample lies off them.
    std::vector<float> in(size_t(side) * side * 3);
    std::uniform_int_distribution<int> corner(-5000, 5000), off(0, 60), bump(-9, 9);
    std::vector<int64_t> grid(size_t(side) * side * 3);
    for (uint32_t y = 0; y < side; y += 4)
      for (uint32_t x = 0; x < side; x += 4)
        for (uint32_t c = 0; c < 3; ++c) grid[(size_t(y) * side + x) * 3 + c] = corner(rng);
    for (uint32_t y = 0; y < side; ++y)
      for (uint32_t x = 0; x < side; ++x)
        for (uint32_t c = 0; c < 3; ++c) {
          const uint32_t x0 = std::min(x / 4 * 4, side - 5), y0 = std::min(y / 4 * 4, side - 5);
          auto at = [&](uint32_t u, uint32_t v) { return grid[(size_t(v) * side + u) * 3 + c]; };
          const int64_t v =
              planarSquareSample(at(x0, y0), at(x0 + 4, y0), at(x0, y0 + 4), at(x0 + 4, y0 + 4), 4, x - x0, y - y0);
          in[(size_t(y) * side + x) * 3 + c] = float(double(v + (off(rng) ? 0 : bump(rng))) * step);
        }
    const std::vector<uint8_t> block = encodePositions(in, side, step, kChartBorderLeft, false);
    std::vector<uint8_t> raw(ZSTD_getFrameContentSize(block.data() + 4, block.size() - 4));
    ASSERT_EQ(ZSTD_decompress(raw.data(), raw.size(), block.data() + 4, block.size() - 4), raw.size());
    ASSERT_EQ(raw[3], 1 | 2) << "a block with planar squares";
    ZSTD_CCtx* cctx = ZSTD_createCCtx();
    ZSTD_CCtx_setParameter(cctx, ZSTD_c_checksumFlag, 1);
    std::vector<float> back(in.size());
    for (int trial = 0; trial < 400; ++trial) {
      std::vector<uint8_t> bad = raw;
      std::uniform_int_distribution<size_t> at(16, bad.size() - 1);
      if (trial % 4 == 3) {
        bad.resize(at(rng));  // cut short
      } else {
        for (int k = 0; k <= trial % 3; ++k) bad[at(rng)] ^= uint8_t(1u << (rng() % 8));
      }
      std::vector<uint8_t> framed = {'G', 'P', 'B', '1'};
      framed.resize(4 + ZSTD_compressBound(bad.size()));
      const size_t written = ZSTD_compress2(cctx, framed.data() + 4, framed.size() - 4, bad.data(), bad.size());
      ASSERT_FALSE(ZSTD_isError(written));
      framed.resize(4 + written);
      try {
        decodePositions(framed, side, back);
        ++decoded;
      } catch (const CodecError&) {
        ++thrown;
      }
    }
    ZSTD_freeCCtx(cctx);
  }
  EXPECT_GT(thrown, 100u);   // cut short or miscounted: the sizes no longer agree
  EXPECT_GT(decoded, 100u);  // a residual changed: other samples, as a checksum would have caught
}

// A sample beside the border that rounds to its border neighbour's lattice point (a chart sampled
// more densely than the lattice, as a thin limb's charts are) is kept apart from it, whatever the
// tolerance: the border is fixed, and a merged pair would weld the chart's inside to its seam.
TEST(PositionSettling, SamplesBesideTheBorderNeverMeetIt) {
  const double step = std::exp2(-18.0);
  constexpr uint32_t side = 9;
  std::vector<float> in(size_t(3) * side * side);
  for (uint32_t v = 0; v < side; ++v)
    for (uint32_t u = 0; u < side; ++u) {
      // Columns a step apart, but the last inner one 0.3 steps from the last (border) column.
      const double x = u + 1 < side - 1 ? double(u) : double(side - 1) - 0.3;
      float* p = &in[3 * (size_t(v) * side + u)];
      p[0] = float(x * step);
      p[1] = float(double(v) * step);
      p[2] = float(0.25 * step);
    }
  for (const double tolerance : {0.0, 4 * step}) {
    const std::vector<float> out = settlePositions(in, side, step, tolerance);
    for (uint32_t v = 1; v + 1 < side; ++v) {
      const size_t inner = size_t(v) * side + side - 2, border = inner + 1;
      EXPECT_FALSE(out[3 * inner] == out[3 * border] && out[3 * inner + 1] == out[3 * border + 1] &&
                   out[3 * inner + 2] == out[3 * border + 2])
          << "row " << v << ", tolerance " << tolerance;
      EXPECT_EQ(out[3 * border], quantizeToStep(in[3 * border], step));
    }
  }
}

// The normals of a sphere's cap seen from above, side^2 samples: smooth, as resampled normals are.
std::vector<PackedNormal> capNormals(uint32_t side) {
  std::vector<PackedNormal> n(size_t(side) * side);
  for (uint32_t v = 0; v < side; ++v)
    for (uint32_t u = 0; u < side; ++u) {
      const float x = (float(u) / float(side - 1) - 0.5f) * 1.2f, y = (float(v) / float(side - 1) - 0.4f) * 1.2f;
      const glm::vec3 d = glm::normalize(glm::vec3(x, y, std::sqrt(std::max(0.05f, 1.0f - x * x - y * y))));
      n[size_t(v) * side + u] = packNormal(d.x, d.y, d.z);
    }
  return n;
}

// Settled normals: block borders unchanged, every byte within the tolerance, decoded exactly,
// coded in fewer bytes, by interpolation; tolerance 0 changes nothing.
TEST(NormalSettling, WithinTheToleranceAndCheaper) {
  const std::vector<float> xyz = sheet(kSide, 1.0 / 64);
  std::vector<PackedNormal> sheetNormals(size_t(kSide) * kSide);
  for (uint32_t v = 0; v < kSide; ++v)
    for (uint32_t u = 0; u < kSide; ++u) {
      const size_t i = size_t(v) * kSide + u;
      const size_t r = u + 1 < kSide ? i + 1 : i - 1;
      const size_t up = v + 1 < kSide ? i + kSide : i - kSide;
      const glm::vec3 p(xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]);
      const glm::vec3 du = glm::vec3(xyz[3 * r], xyz[3 * r + 1], xyz[3 * r + 2]) - p;
      const glm::vec3 dv = glm::vec3(xyz[3 * up], xyz[3 * up + 1], xyz[3 * up + 2]) - p;
      glm::vec3 n = glm::normalize(glm::cross(du, dv));
      if (n.z < 0) n = -n;
      sheetNormals[i] = packNormal(n.x, n.y, n.z);
    }
  for (const std::vector<PackedNormal>& in : {sheetNormals, capNormals(kSide)}) {
    std::vector<PackedNormal> same = in;
    settleNormals(same, kSide, 0, 16);
    EXPECT_EQ(same, in);
    for (const uint32_t tolerance : {1u, 2u})
      for (const uint32_t blockIntervals : {16u, 64u}) {
        std::vector<PackedNormal> settled = in;
        settleNormals(settled, kSide, tolerance, blockIntervals);
        size_t moved = 0;
        for (uint32_t v = 0; v < kSide; ++v)
          for (uint32_t u = 0; u < kSide; ++u) {
            const size_t i = size_t(v) * kSide + u;
            const bool border = u % blockIntervals == 0 || v % blockIntervals == 0;
            for (int c = 0; c < 4; ++c) {
              const int d = std::abs(int(settled[i][c]) - int(in[i][c]));
              ASSERT_LE(d, border || c == 3 ? 0 : int(tolerance)) << u << "," << v << " byte " << c;
              moved += d > 0;
            }
          }
        EXPECT_GT(moved, 0u);
        const std::vector<uint8_t> a = encodeNormals(in, kSide), b = encodeNormals(settled, kSide);
        std::vector<PackedNormal> back(settled.size());
        decodeNormals(b, kSide, back);
        EXPECT_EQ(back, settled);
        std::printf("  normals: %zu bytes as sampled, %zu settled within %u packed steps in blocks of %u\n", a.size(),
                    b.size(), tolerance, blockIntervals);
        EXPECT_LT(b.size(), a.size());
        if (blockIntervals == 64) {
          EXPECT_EQ(std::string(b.begin(), b.begin() + 4), "GNI1");  // the interpolated code
        }
      }
  }
  std::vector<PackedNormal> same = sheetNormals;
  EXPECT_THROW(settleNormals(same, kSide, 128, 64), std::invalid_argument);
  EXPECT_THROW(settleNormals(same, kSide, 1, 48), std::invalid_argument);
  std::vector<PackedNormal> odd(11 * 11, PackedNormal{128, 128, 255, 255});
  EXPECT_THROW(settleNormals(odd, 11, 1, 8), std::invalid_argument);
}

// Normal blocks of every side, smooth or noise: back exactly, whichever prediction codes them;
// damage and a wrong side detected.
TEST(NormalCodec, RoundTripsWithEitherPredictionAndDetectsDamage) {
  std::mt19937 rng(7);
  std::set<std::string> magics;
  for (const uint32_t side : {2u, 3u, 11u, 17u, kSide}) {
    std::vector<PackedNormal> noise(size_t(side) * side);
    for (auto& n : noise) n = {uint8_t(rng()), uint8_t(rng()), uint8_t(rng()), 255};
    std::vector<PackedNormal> settledCap = capNormals(side);
    if (side == kSide) settleNormals(settledCap, side, 2, 64);
    for (const std::vector<PackedNormal>& in : {noise, capNormals(side), settledCap}) {
      const std::vector<uint8_t> code = encodeNormals(in, side);
      magics.insert(std::string(code.begin(), code.begin() + 4));
      std::vector<PackedNormal> out(in.size(), PackedNormal{1, 2, 3, 4});
      decodeNormals(code, side, out);
      EXPECT_EQ(out, in) << side;
      std::vector<PackedNormal> larger(size_t(side + 1) * (side + 1));
      EXPECT_THROW(decodeNormals(code, side + 1, larger), CodecError);
      std::vector<uint8_t> bad = code;
      bad[bad.size() - 1] ^= 0x10;
      EXPECT_THROW(decodeNormals(bad, side, out), CodecError);
      EXPECT_THROW(decodeNormals({code.data(), code.size() - 3}, side, out), CodecError);
      EXPECT_THROW(decodeColours(code, side, out), CodecError);  // another kind of block
    }
  }
  EXPECT_EQ(magics, (std::set<std::string>{"GNB1", "GNI1"}));  // both predictions were kept somewhere
  std::vector<PackedNormal> bad(9, PackedNormal{128, 128, 255, 7});
  EXPECT_THROW((void)encodeNormals(bad, 3), std::invalid_argument);
}

// Whole byte strings: back exactly; corrupt or truncated frames, and frames that claim more
// than the reader allows, are CodecError.
TEST(ByteCodec, RoundTripsAndDetectsDamage) {
  std::vector<uint8_t> raw(100000);
  std::mt19937 rng(3);
  for (size_t i = 0; i < raw.size(); ++i) raw[i] = uint8_t(i % 7 == 0 ? rng() : i / 1000);
  const std::vector<uint8_t> coded = compressBytes(raw);
  EXPECT_LT(coded.size(), raw.size() / 2);
  EXPECT_EQ(decompressBytes(coded, raw.size()), raw);
  EXPECT_THROW(decompressBytes(coded, raw.size() - 1), CodecError);
  EXPECT_THROW(decompressBytes({coded.data(), coded.size() / 2}, raw.size()), CodecError);
  std::vector<uint8_t> bad = coded;
  bad[bad.size() / 2] ^= 0x40;
  EXPECT_THROW(decompressBytes(bad, raw.size()), CodecError);
}

// The frame made piece by piece decodes like the one made at once; the stated size is held to.
TEST(ByteCodec, PieceByPieceFramesDecodeAsAWhole) {
  std::vector<uint8_t> raw(3'000'000);
  std::mt19937 rng(5);
  for (size_t i = 0; i < raw.size(); ++i) raw[i] = uint8_t(i % 5 == 0 ? rng() : i / 4096);
  std::vector<uint8_t> coded;
  size_t sinks = 0;
  {
    BytesCompressor c(raw.size(), [&](const uint8_t* p, size_t n) {
      coded.insert(coded.end(), p, p + n);
      ++sinks;
    });
    for (size_t at = 0; at < raw.size();) {
      const size_t n = std::min<size_t>(raw.size() - at, 1 + rng() % 200000);
      c.add({raw.data() + at, n});
      at += n;
    }
    c.finish();
    EXPECT_THROW(c.finish(), std::logic_error);
  }
  EXPECT_GT(sinks, 2u);  // handed on as it was made
  EXPECT_LT(coded.size(), raw.size() / 2);
  EXPECT_EQ(decompressBytes(coded, raw.size()), raw);
  std::vector<uint8_t> bad = coded;
  bad[bad.size() / 3] ^= 0x10;
  EXPECT_THROW(decompressBytes(bad, raw.size()), CodecError);
  // More or fewer bytes than stated.
  BytesCompressor over(10, [](const uint8_t*, size_t) {});
  EXPECT_THROW(over.add({raw.data(), 11}), std::logic_error);
  BytesCompressor under(10, [](const uint8_t*, size_t) {});
  under.add({raw.data(), 9});
  EXPECT_THROW(under.finish(), std::logic_error);
}

// Border normals: the border back exactly, the rest untouched; damage detected.
TEST(BorderNormals, RoundTripTheBorderAndDetectDamage) {
  std::mt19937 rng(7);
  for (const uint32_t side : {2u, 3u, kSide}) {
    std::vector<PackedNormal> in(size_t(side) * side);
    for (auto& n : in) n = {uint8_t(rng()), uint8_t(rng()), uint8_t(rng()), 255};
    const std::vector<uint8_t> code = encodeBorderNormals(in, side);
    std::vector<PackedNormal> out(in.size(), PackedNormal{1, 2, 3, 4});
    decodeBorderNormals(code, side, out);
    for (uint32_t v = 0; v < side; ++v)
      for (uint32_t u = 0; u < side; ++u) {
        const size_t i = size_t(v) * side + u;
        if (u == 0 || v == 0 || u + 1 == side || v + 1 == side) {
          EXPECT_EQ(out[i], in[i]) << side << ": " << u << "," << v;
        } else {
          EXPECT_EQ(out[i], (PackedNormal{1, 2, 3, 4}));
        }
      }
    std::vector<PackedNormal> larger(size_t(side + 1) * (side + 1));
    EXPECT_THROW(decodeBorderNormals(code, side + 1, larger), CodecError);  // another side
    std::vector<uint8_t> bad = code;
    bad[bad.size() - 1] ^= 0x10;
    EXPECT_THROW(decodeBorderNormals(bad, side, out), CodecError);
    EXPECT_THROW(decodeBorderNormals({code.data(), code.size() - 3}, side, out), CodecError);
    EXPECT_THROW(decodeNormals(code, side, out), CodecError);  // another kind of block
  }
}

}  // namespace
}  // namespace gimlod
