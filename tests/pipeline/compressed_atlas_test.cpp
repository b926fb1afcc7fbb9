// Compressed atlases (chart file version 3, atlas format version 2) on the shipped SRTM tile:
// every chart's heights and normals decode to exactly the pyramid they were built from (integer
// metres losslessly, normals derived from the heights bit for bit), float heights stay within half
// the precision, a corrupt or truncated block is reported naming the file and the block, and
// version 1 atlases still open.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>
#include <iterator>
#include <memory>

#include <gdal_priv.h>
#include <nlohmann/json.hpp>
#include <glm/common.hpp>
#include <glm/geometric.hpp>

#include "atlas/terrain/dem.h"
#include "atlas/terrain/terrain_atlas.h"
#include "core/atlas_format.h"
#include "core/block_codec.h"
#include "pipeline/build.h"
#include "pipeline/mesh_build.h"
#include "runtime/atlas_view.h"
#include "runtime/page_reader.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

namespace fs = std::filesystem;

const fs::path kTile = "terrain/mt_rainier_90m.tif";

// The tile with its filled voids rounded to whole metres, as a compressed build of it stores them.
DemRaster wholeMetreTile() {
  DemRaster dem = loadDem(test::repoData() / kTile);
  EXPECT_TRUE(dem.integerHeights);
  for (float& h : dem.heights) h = quantizeToStep(h, 1.0);
  return dem;
}

// Builds options.input into dir/v1 (format version 1) and dir/v2 (compressed).
template <typename Options>
void buildBothWays(Options o, const fs::path& dir) {
  o.output = dir / "v1";
  o.compress = false;
  buildAtlas(o);
  o.output = dir / "v2";
  o.compress = true;
  buildAtlas(o);
}

void writeBytes(const fs::path& p, const std::string& bytes) {
  std::ofstream out(p, std::ios::binary | std::ios::trunc);
  out.write(bytes.data(), std::streamsize(bytes.size()));
}

TEST(CompressedAtlas, TerrainChartsDecodeToTheirPyramids) {
  const DemRaster dem = wholeMetreTile();
  test::TempDir tmp("gimlod-coded");
  constexpr uint32_t kChartSize = 257, kBlock = 32;
  ChartCoding coded;
  coded.compressed = true;
  coded.heightPrecision = 1.0;
  uint64_t rawBytes = 0, codedBytes = 0;
  for (int32_t gy = 0; gy * 256 < int32_t(dem.height) - 1; ++gy)
    for (int32_t gx = 0; gx * 256 < int32_t(dem.width) - 1; ++gx) {
      const ChartPyramid p = buildChartPyramid(dem, gx, gy, kChartSize, true);
      const ChartPyramid plain = buildChartPyramid(dem, gx, gy, kChartSize);
      // The ring does not change the heights; the normals are left to the reader to derive.
      ASSERT_EQ(plain.heights, p.heights);
      ASSERT_TRUE(p.normals.empty());
      const fs::path raw = tmp.path() / "raw.bin", code = tmp.path() / "coded.bin";
      rawBytes += writeChartFile(raw, plain, kChartSize, kBlock);
      codedBytes += writeChartFile(code, p, kChartSize, kBlock, coded);
      const ChartFileReader r(raw), c(code);
      ASSERT_FALSE(r.compressed());
      ASSERT_TRUE(c.compressed());
      ASSERT_TRUE(c.derivedNormals());
      for (uint32_t k = 0; k < c.levels(); ++k) {
        ASSERT_EQ(c.readLevelHeights(k), p.heights[k]) << "chart " << gx << "," << gy << " level " << k;
        ASSERT_EQ(c.readLevelHeights(k), r.readLevelHeights(k));
        // Derived on reading, bit for bit the normals the builder computed and version 1 stores.
        ASSERT_EQ(c.readLevelNormals(k), plain.normals[k]) << "chart " << gx << "," << gy << " level " << k;
        ASSERT_EQ(c.readLevelNormals(k), r.readLevelNormals(k));
      }
      // A window inside a block, as the page reader asks for one.
      std::vector<float> hw(9 * 9), hr(9 * 9);
      std::vector<PackedNormal> nw(9 * 9), nr(9 * 9);
      c.readHeights(0, 40, 72, 8, hw.data());
      r.readHeights(0, 40, 72, 8, hr.data());
      c.readNormals(0, 40, 72, 8, nw.data());
      r.readNormals(0, 40, 72, 8, nr.data());
      EXPECT_EQ(hw, hr);
      EXPECT_EQ(nw, nr);
    }
  std::printf("  chart files: %llu bytes raw, %llu compressed (%.1fx smaller)\n", (unsigned long long)rawBytes,
              (unsigned long long)codedBytes, double(rawBytes) / double(codedBytes));
  EXPECT_LT(codedBytes * 6, rawBytes);
}

TEST(CompressedAtlas, CorruptAndTruncatedBlocksAreNamed) {
  const DemRaster dem = wholeMetreTile();
  test::TempDir tmp("gimlod-coded-bad");
  ChartCoding coded;
  coded.compressed = true;
  const fs::path good = tmp.path() / "chart_0004.bin";
  writeChartFile(good, buildChartPyramid(dem, 1, 1, 129, true), 129, 32, coded);
  const std::string bytes = test::fileBytes(good);
  const fs::path bad = tmp.path() / "chart_bad.bin";
  auto readAll = [&] {
    const ChartFileReader r(bad);
    for (uint32_t k = 0; k < r.levels(); ++k) {
      (void)r.readLevelHeights(k);
      (void)r.readLevelNormals(k);
    }
  };
  // Every byte flipped past the header: an InputError naming the file, and for a block the level
  // and the block; or (a zstd frame's unused hint bits) the same samples.
  size_t named = 0, same = 0;
  for (size_t at = 80; at < bytes.size(); at += 7) {
    std::string b = bytes;
    b[at] = char(b[at] ^ 0x5a);
    writeBytes(bad, b);
    try {
      readAll();
      const ChartFileReader r(bad), g(good);
      for (uint32_t k = 0; k < r.levels(); ++k) ASSERT_EQ(r.readLevelHeights(k), g.readLevelHeights(k)) << at;
      ++same;
    } catch (const InputError& e) {
      const std::string msg = e.what();
      ASSERT_NE(msg.find(bad.string()), std::string::npos) << msg;
      if (msg.find(" block (") != std::string::npos) {
        ASSERT_NE(msg.find("level "), std::string::npos) << msg;
        ++named;
      }
    }
  }
  EXPECT_GT(named, (bytes.size() - 80) / 7 * 9 / 10);  // nearly every flip lands in a block's code
  std::printf("  %zu flips: %zu named the block, %zu decoded the same samples\n", (bytes.size() - 80) / 7, named, same);
  // Every truncation: an InputError naming the file.
  for (size_t len = 0; len < bytes.size(); len += 13) {
    writeBytes(bad, bytes.substr(0, len));
    try {
      readAll();
      FAIL() << "truncated to " << len << " bytes and read";
    } catch (const InputError& e) {
      ASSERT_NE(std::string(e.what()).find(bad.string()), std::string::npos) << e.what();
    }
  }
}

TEST(CompressedAtlas, FloatHeightsStayWithinHalfThePrecision) {
  // The tile in feet-like float metres: no height is whole.
  test::TempDir tmp("gimlod-coded-float");
  GDALAllRegister();
  const DemRaster src = loadDem(test::repoData() / kTile);
  const fs::path tif = tmp.path() / "float.tif";
  {
    GDALDataset* in = GDALDataset::FromHandle(GDALOpen((test::repoData() / kTile).c_str(), GA_ReadOnly));
    ASSERT_NE(in, nullptr);
    GDALDriver* gtiff = GetGDALDriverManager()->GetDriverByName("GTiff");
    GDALDataset* out = gtiff->Create(tif.c_str(), int(src.width), int(src.height), 1, GDT_Float32, nullptr);
    double gt[6];
    in->GetGeoTransform(gt);
    out->SetGeoTransform(gt);
    out->SetSpatialRef(in->GetSpatialRef());
    std::vector<float> rows(size_t(src.width) * src.height);
    // loadDem's row 0 is the south edge; the GeoTIFF's is the north.
    for (uint32_t y = 0; y < src.height; ++y)
      for (uint32_t x = 0; x < src.width; ++x)
        rows[size_t(src.height - 1 - y) * src.width + x] = src.heights[size_t(y) * src.width + x] * 0.3048f + 0.123f;
    ASSERT_EQ(out->GetRasterBand(1)->RasterIO(GF_Write, 0, 0, int(src.width), int(src.height), rows.data(),
                                              int(src.width), int(src.height), GDT_Float32, 0, 0),
              CE_None);
    GDALClose(out);
    GDALClose(in);
  }
  const DemRaster fl = loadDem(tif);
  ASSERT_FALSE(fl.integerHeights);
  TerrainBuildOptions o;
  o.input = tif;
  o.output = tmp.path() / "atlas";
  o.chartSize = 257;
  o.heightPrecision = 0.05;
  buildAtlas(o);
  const AtlasManifest m = readManifest(o.output);
  EXPECT_EQ(m.version, 2u);
  ASSERT_TRUE(m.compression.present);
  EXPECT_EQ(m.compression.heightPrecision, 0.05);
  double worst = 0.0;
  for (const ChartInfo& c : m.charts) {
    const ChartFileReader r(o.output / c.file);
    const std::vector<float> h = r.readLevelHeights(0);
    for (uint32_t v = 0; v < m.chartSize; ++v)
      for (uint32_t u = 0; u < m.chartSize; ++u) {
        const int64_t gx = std::min<int64_t>(c.gridX * 256 + u, fl.width - 1);
        const int64_t gy = std::min<int64_t>(c.gridY * 256 + v, fl.height - 1);
        worst =
            std::max(worst, std::abs(double(h[size_t(v) * m.chartSize + u]) - fl.heights[size_t(gy) * fl.width + gx]));
      }
  }
  EXPECT_GT(worst, 0.0);
  EXPECT_LE(worst, 0.025 + 1e-3);  // half the precision, plus float rounding at 1,300 m
}

TEST(CompressedAtlas, Version1AtlasesStillOpen) {
  test::TempDir tmp("gimlod-v1");
  TerrainBuildOptions o;
  o.input = test::repoData() / kTile;
  o.chartSize = 257;
  buildBothWays(o, tmp.path());
  const AtlasView v1 = openAtlas(tmp.path() / "v1"), v2 = openAtlas(tmp.path() / "v2");
  EXPECT_EQ(v1.manifest.version, 1u);
  EXPECT_FALSE(v1.manifest.compression.present);
  EXPECT_EQ(v2.manifest.version, 2u);
  ASSERT_EQ(v1.hierarchy.chartCount(), v2.hierarchy.chartCount());
  const PageReader p1(v1.dir, v1.manifest, v1.hierarchy.params), p2(v2.dir, v2.manifest, v2.hierarchy.params);
  // The same pages, but for the filled voids, which version 2 rounds to whole metres like the tile.
  size_t pages = 0;
  double worst = 0.0;
  std::vector<float> a, b;
  std::vector<PackedNormal> na, nb;
  for (uint32_t c = 0; c < v1.hierarchy.chartCount(); ++c)
    for (uint32_t level = 0; level < v1.manifest.depth; ++level)
      for (uint32_t y = 0; y < (1u << level); ++y)
        for (uint32_t x = 0; x < (1u << level); ++x) {
          p1.read(NodeId{c, level, x, y}, a, na);
          p2.read(NodeId{c, level, x, y}, b, nb);
          ASSERT_EQ(a.size(), b.size());
          for (size_t i = 0; i < a.size(); ++i) worst = std::max(worst, double(std::abs(a[i] - b[i])));
          ++pages;
        }
  EXPECT_GT(pages, 25u);
  EXPECT_LE(worst, 0.5);
  EXPECT_LT(fs::file_size(tmp.path() / "v2/charts/chart_0000.bin") * 5,
            fs::file_size(tmp.path() / "v1/charts/chart_0000.bin"));
}

// The shipped bunny, compressed and not: the same layout; on every chart border the positions
// within half a lattice step and the normals the same; inside, positions within the settling
// tolerance (and on the lattice) and normal bytes within theirs; shared chart sides bit-identical
// after decoding; the compressed atlas several times smaller, and smaller again when settled.
// Returns the compressed chart files' bytes.
uint64_t checkCodedBunny(double positionTolerance, uint32_t normalTolerance, const fs::path& dir) {
  MeshBuildOptions o;
  o.input = test::repoData() / "meshes/bun_zipper.ply";
  o.patches = 24;
  o.chartSize = 65;
  o.measureFidelity = false;
  o.positionTolerance = positionTolerance;
  o.normalTolerance = normalTolerance;
  o.normals = MeshNormals::kStored;  // compared with version 1's below; derived ones: the next test
  fs::create_directories(dir);
  buildBothWays(o, dir);
  const AtlasManifest m1 = readManifest(dir / "v1"), m2 = readManifest(dir / "v2");
  EXPECT_EQ(m1.charts.size(), m2.charts.size());
  EXPECT_EQ(m1.version, 1u);
  EXPECT_EQ(m2.version, 2u);
  const double step = m2.compression.positionStep;
  EXPECT_GT(step, 0.0);
  EXPECT_EQ(std::exp2(std::round(std::log2(step))), step);  // a power of two
  const double tolerance = m2.compression.positionTolerance;
  EXPECT_EQ(m2.compression.normalTolerance, normalTolerance);
  glm::dvec3 lo(1e300), hi(-1e300);  // the samples' box: the input's, to the sampling error
  uint64_t raw = 0, coded = 0, moved = 0, normalsMoved = 0;
  double worstInside = 0.0;
  std::vector<std::vector<glm::vec3>> level0(m2.charts.size());
  for (size_t c = 0; c < m2.charts.size() && c < m1.charts.size(); ++c) {
    const ChartFileReader a(dir / "v1" / m1.charts[c].file), b(dir / "v2" / m2.charts[c].file);
    raw += fs::file_size(a.path());
    coded += fs::file_size(b.path());
    EXPECT_TRUE(b.compressed());
    for (uint32_t k = 0; k < b.levels(); ++k) {
      const std::vector<glm::vec3> pa = a.readLevelPositions(k), pb = b.readLevelPositions(k);
      const std::vector<PackedNormal> na = a.readLevelNormals(k), nb = b.readLevelNormals(k);
      EXPECT_EQ(pa.size(), pb.size());
      const uint32_t side = ((m2.chartSize - 1) >> k) + 1;
      for (size_t i = 0; i < pa.size() && i < pb.size(); ++i) {
        const uint32_t u = uint32_t(i % side), v = uint32_t(i / side);
        const bool border = u == 0 || v == 0 || u + 1 == side || v + 1 == side;
        for (int x = 0; x < 3; ++x) {
          if (border) {
            EXPECT_LE(std::abs(double(pa[i][x]) - pb[i][x]), step / 2)
                << "chart " << c << " level " << k << " at " << u << "," << v;
          }
          EXPECT_EQ(std::nearbyint(double(pb[i][x]) / step) * step, double(pb[i][x]));  // on the lattice
          const int dn = std::abs(int(na[i][x]) - int(nb[i][x]));
          EXPECT_LE(dn, border ? 0 : int(normalTolerance)) << "chart " << c << " level " << k << " sample " << i;
          normalsMoved += dn > 0;
        }
        const double d = glm::length(glm::dvec3(pa[i]) - glm::dvec3(pb[i]));
        if (!border) worstInside = std::max(worstInside, d);
        moved += d > step;
      }
      if (k == 0) level0[c] = pb;
      for (const glm::vec3& q : pa) {
        lo = glm::min(lo, glm::dvec3(q));
        hi = glm::max(hi, glm::dvec3(q));
      }
    }
  }
  EXPECT_NEAR(tolerance, positionTolerance * glm::length(hi - lo), 0.01 * tolerance);
  // Inside: within the tolerance (or half a step of the lattice on each axis, when it is 0).
  EXPECT_LE(worstInside, std::max(tolerance, std::sqrt(3.0) * step / 2) * (1 + 1e-6));
  if (positionTolerance > 0) {
    EXPECT_GT(moved, 0u);
  } else {
    EXPECT_EQ(moved, 0u);
  }
  EXPECT_EQ(normalsMoved > 0, normalTolerance > 0);
  // Every shared side: the same samples, bit for bit, after decoding.
  const uint32_t n = m2.chartSize;
  size_t sides = 0;
  for (size_t c = 0; c < m2.charts.size(); ++c)
    for (uint32_t e = 0; e < 4; ++e) {
      const RootNeighbour& nb = m2.charts[c].neighbours[e];
      if (nb.chart < 0 || level0[c].empty()) continue;
      for (uint32_t k = 0; k < n; ++k) {
        const uint32_t j = nb.reversed ? n - 1 - k : k;
        EXPECT_EQ(level0[c][edgeSampleIndex(n, e, k)], level0[size_t(nb.chart)][edgeSampleIndex(n, nb.edge, j)])
            << "chart " << c << " edge " << e << " sample " << k;
      }
      ++sides;
    }
  EXPECT_GT(sides, m2.charts.size());
  std::printf(
      "  bunny chart files, tolerances %g of the diagonal and %u packed steps: %llu bytes raw, %llu "
      "compressed (%.1fx smaller), lattice step %.3g\n",
      positionTolerance, normalTolerance, (unsigned long long)raw, (unsigned long long)coded,
      double(raw) / double(coded), step);
  EXPECT_LT(coded * 2, raw);
  return coded;
}

TEST(CompressedAtlas, MeshPositionsLieOnTheLatticeAndSeamsStayBitIdentical) {
  test::TempDir tmp("gimlod-coded-mesh");
  const uint64_t exact = checkCodedBunny(0.0, 0, tmp.path() / "exact");
  const uint64_t settled = checkCodedBunny(kDefaultPositionTolerance, kDefaultNormalTolerance, tmp.path() / "settled");
  EXPECT_LT(double(settled), 0.9 * double(exact));
}

// The shipped bunny at 65^2 (about 6 samples per input triangle): its normals are derived by
// default, within a few degrees of the resampled ones at the median; every chart's border normals
// are stored, so charts meeting at a seam shade it alike; the atlas is smaller than with stored
// normals. At 129^2 (25 samples per triangle) they are stored.
TEST(CompressedAtlas, SparseMeshAtlasesDeriveTheirNormals) {
  test::TempDir tmp("gimlod-derived-normals");
  MeshBuildOptions o;
  o.input = test::repoData() / "meshes/bun_zipper.ply";
  o.chartSize = 65;
  o.measureFidelity = false;
  o.output = tmp.path() / "auto";
  const MeshBuildStats derived = buildMeshAtlas(o);
  o.normals = MeshNormals::kStored;
  o.output = tmp.path() / "stored";
  const MeshBuildStats stored = buildMeshAtlas(o);
  EXPECT_TRUE(derived.write.normalsDerived);
  EXPECT_FALSE(stored.write.normalsDerived);
  EXPECT_LE(derived.write.samplesPerTriangle, kDerivedNormalsSamplesPerTriangle);
  const NormalAngles& a = derived.write.normalAngles;
  std::printf(
      "  bunny at 65^2, %.1f samples per triangle: derived normals %.2f degrees from the resampled ones at "
      "the median, %.2f at the 99th percentile; atlas %llu bytes against %llu with stored normals\n",
      derived.write.samplesPerTriangle, a.median, a.p99, (unsigned long long)derived.bytesOnDisk,
      (unsigned long long)stored.bytesOnDisk);
  EXPECT_GT(a.samples, 100000u);
  EXPECT_LT(a.median, 5.0);
  EXPECT_LT(a.p99, 30.0);
  EXPECT_LT(derived.bytesOnDisk, stored.bytesOnDisk);
  const nlohmann::json st = nlohmann::json::parse(std::ifstream(tmp.path() / "auto/stats.json"));
  EXPECT_EQ(st["normals"]["derived"], true);
  EXPECT_EQ(st["normals"]["degrees_from_resampled"]["median"].get<double>(), a.median);
  // Seams: the normals on both sides of every shared chart side, bit for bit, at every level.
  const AtlasManifest m = readManifest(tmp.path() / "auto");
  std::vector<std::unique_ptr<ChartFileReader>> readers;
  for (const ChartInfo& c : m.charts)
    readers.push_back(std::make_unique<ChartFileReader>(tmp.path() / "auto" / c.file));
  ASSERT_TRUE(readers.front()->derivedNormals());
  size_t checked = 0;
  for (uint32_t k = 0; k < readers.front()->levels(); ++k) {
    std::vector<std::vector<PackedNormal>> n;
    for (const auto& r : readers) n.push_back(r->readLevelNormals(k));
    const uint32_t side = ((m.chartSize - 1) >> k) + 1;
    for (size_t c = 0; c < m.charts.size(); ++c)
      for (uint32_t e = 0; e < 4; ++e) {
        const RootNeighbour& nb = m.charts[c].neighbours[e];
        if (nb.chart < 0) continue;
        for (uint32_t i = 0; i < side; ++i, ++checked)
          ASSERT_EQ(n[c][edgeSampleIndex(side, e, i)],
                    n[size_t(nb.chart)][edgeSampleIndex(side, nb.edge, nb.reversed ? side - 1 - i : i)])
              << "level " << k << " chart " << c << " edge " << e << " sample " << i;
      }
  }
  EXPECT_GT(checked, 1000u);
  o.normals = MeshNormals::kAuto;
  o.chartSize = 129;
  o.output = tmp.path() / "dense";
  const MeshBuildStats dense = buildMeshAtlas(o);
  EXPECT_GT(dense.write.samplesPerTriangle, kDerivedNormalsSamplesPerTriangle);
  EXPECT_FALSE(dense.write.normalsDerived);
  EXPECT_FALSE(
      ChartFileReader(tmp.path() / "dense" / readManifest(tmp.path() / "dense").charts[0].file).derivedNormals());
}

TEST(CompressedAtlas, PositionLatticeIsNoFinerThanTheCoordinates) {
  MeshBounds unit;
  unit.extend(glm::vec3(0.f));
  unit.extend(glm::vec3(1.f));
  EXPECT_EQ(meshPositionStep(unit, 20), std::exp2(-20.0));  // diagonal sqrt(3): 2^0 / 2^20
  // A unit scan 1000 units from the origin: float holds 2^-14 there, so the lattice is 2^-13.
  MeshBounds far;
  far.extend(glm::vec3(1000.f, 0.f, 0.f));
  far.extend(glm::vec3(1001.f, 1.f, 1.f));
  EXPECT_EQ(meshPositionStep(far, 20), std::exp2(9.0 - 22.0));
}

}  // namespace
}  // namespace gimlod
