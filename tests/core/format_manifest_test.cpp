// Tests for the atlas manifest (atlas.json): round trip and validation errors.
#include <gtest/gtest.h>

#include <fstream>
#include <functional>

#include <nlohmann/json.hpp>

#include "core/atlas_format.h"
#include "core/block_codec.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

// A consistent 2 x 1 heightfield manifest.
AtlasManifest sampleManifest() {
  AtlasManifest m;
  m.chartSize = 129;
  m.blockIntervals = 32;
  m.chartsX = 2;
  m.chartsY = 1;
  m.samplesX = 250;
  m.samplesY = 100;
  m.spacing = {63.9731, 92.6343};
  m.zScale = 1.5;
  m.heightRange = {-12.5f, 4392.25f};
  m.voidsFilled = 9033;
  m.voidFillMethod = "pull-push";
  m.source = "mt_rainier_90m.tif";
  m.georef.wkt = "GEOGCRS[\"WGS 84\"]";
  m.georef.geotransform = {-122.0004166, 0.000833333, 0, 47.0004166, 0, -0.000833333};
  m.georef.geographic = true;
  m.georef.centreLatitudeDeg = 46.5;
  m.compression.present = true;
  m.compression.heightPrecision = 0.25;
  m.depth = 3;
  m.maxNodeResLog2 = 5;
  m.minNodeResLog2 = 2;
  for (uint32_t i = 0; i < 2; ++i) {
    ChartInfo c;
    c.id = i;
    c.gridX = int32_t(i);
    c.file = i == 0 ? "charts/chart_0000.bin" : "charts/chart_0001.bin";
    m.charts.push_back(c);
  }
  m.charts[0].neighbours[kEdgeRight] = {1, kEdgeLeft, true};
  m.charts[1].neighbours[kEdgeLeft] = {0, kEdgeRight, true};
  return m;
}

TEST(FormatManifest, RoundTrip) {
  test::TempDir tmp("gimlod-manifest");
  const AtlasManifest a = sampleManifest();
  writeManifest(tmp.path(), a);
  const AtlasManifest b = readManifest(tmp.path());
  EXPECT_EQ(b.version, 2u);  // its charts inline (kInlineChartsMax)
  EXPECT_EQ(b.kind, a.kind);
  EXPECT_EQ(b.chartSize, a.chartSize);
  EXPECT_EQ(b.blockIntervals, a.blockIntervals);
  EXPECT_EQ(b.chartsX, a.chartsX);
  EXPECT_EQ(b.chartsY, a.chartsY);
  EXPECT_EQ(b.samplesX, a.samplesX);
  EXPECT_EQ(b.samplesY, a.samplesY);
  EXPECT_EQ(b.spacing, a.spacing);  // exact: doubles round-trip through JSON
  EXPECT_EQ(b.zScale, a.zScale);
  EXPECT_EQ(b.heightRange, a.heightRange);
  EXPECT_EQ(b.voidsFilled, a.voidsFilled);
  EXPECT_EQ(b.voidFillMethod, a.voidFillMethod);
  EXPECT_EQ(b.source, a.source);
  EXPECT_EQ(b.georef.wkt, a.georef.wkt);
  EXPECT_EQ(b.georef.geotransform, a.georef.geotransform);
  EXPECT_EQ(b.georef.geographic, a.georef.geographic);
  EXPECT_EQ(b.georef.centreLatitudeDeg, a.georef.centreLatitudeDeg);
  EXPECT_TRUE(b.compression.present);
  EXPECT_EQ(b.compression.heightPrecision, 0.25);
  EXPECT_EQ(b.hierarchyFile, a.hierarchyFile);
  EXPECT_EQ(b.depth, a.depth);
  EXPECT_EQ(b.maxNodeResLog2, a.maxNodeResLog2);
  EXPECT_EQ(b.minNodeResLog2, a.minNodeResLog2);
  ASSERT_EQ(b.charts.size(), 2u);
  for (size_t i = 0; i < 2; ++i) {
    EXPECT_EQ(b.charts[i].id, a.charts[i].id);
    EXPECT_EQ(b.charts[i].gridX, a.charts[i].gridX);
    EXPECT_EQ(b.charts[i].gridY, a.charts[i].gridY);
    EXPECT_EQ(b.charts[i].file, a.charts[i].file);
    for (int e = 0; e < 4; ++e) {
      EXPECT_EQ(b.charts[i].neighbours[e].chart, a.charts[i].neighbours[e].chart);
      EXPECT_EQ(b.charts[i].neighbours[e].edge, a.charts[i].neighbours[e].edge);
      EXPECT_EQ(b.charts[i].neighbours[e].reversed, a.charts[i].neighbours[e].reversed);
    }
  }
  std::ifstream in(tmp.path() / kManifestName);
  const json j = json::parse(in);
  EXPECT_EQ(j["format"], "gimlod-atlas");
  EXPECT_EQ(j["version"], 2u);
  EXPECT_FALSE(fs::exists(tmp.path() / kChartListName));
  // Without compression the manifest is version 1, which earlier builds read.
  AtlasManifest plain = sampleManifest();
  plain.compression = CompressionInfo{};
  writeManifest(tmp.path(), plain);
  EXPECT_EQ(readManifest(tmp.path()).version, 1u);
  EXPECT_FALSE(readManifest(tmp.path()).compression.present);
}

// A neighbour's "reversed" is written only where it is false (true is the default and what every
// build writes); one written as true, as earlier builds did, reads back the same.
TEST(FormatManifest, ReversedIsWrittenOnlyWhereItIsNotTheDefault) {
  test::TempDir tmp("gimlod-manifest");
  AtlasManifest a = sampleManifest();
  writeManifest(tmp.path(), a);
  json j = json::parse(std::ifstream(tmp.path() / kManifestName));
  EXPECT_FALSE(j["charts"][0]["neighbours"][kEdgeRight].contains("reversed"));
  EXPECT_EQ(j["charts"][0]["neighbours"][kEdgeRight]["chart"], 1);
  EXPECT_TRUE(readManifest(tmp.path()).charts[0].neighbours[kEdgeRight].reversed);
  a.charts[0].neighbours[kEdgeRight].reversed = false;
  a.charts[1].neighbours[kEdgeLeft].reversed = false;
  writeManifest(tmp.path(), a);
  j = json::parse(std::ifstream(tmp.path() / kManifestName));
  EXPECT_EQ(j["charts"][1]["neighbours"][kEdgeLeft]["reversed"], false);
  const AtlasManifest b = readManifest(tmp.path());
  EXPECT_FALSE(b.charts[0].neighbours[kEdgeRight].reversed);
  EXPECT_FALSE(b.charts[1].neighbours[kEdgeLeft].reversed);
  EXPECT_TRUE(b.charts[0].neighbours[kEdgeLeft].reversed);  // an open border's, by default
  // As earlier builds wrote it.
  writeManifest(tmp.path(), sampleManifest());
  j = json::parse(std::ifstream(tmp.path() / kManifestName));
  for (auto& c : j["charts"])
    for (auto& n : c["neighbours"]) n["reversed"] = true;
  std::ofstream(tmp.path() / kManifestName) << j.dump();
  EXPECT_TRUE(readManifest(tmp.path()).charts[1].neighbours[kEdgeLeft].reversed);
}

// Writes the sample manifest, edits its JSON, and expects readManifest to fail naming the
// manifest and mentioning `what`.
void expectBad(const std::function<void(json&)>& edit, const std::string& what) {
  test::TempDir tmp("gimlod-manifest");
  writeManifest(tmp.path(), sampleManifest());
  const fs::path file = tmp.path() / kManifestName;
  json j;
  {
    std::ifstream in(file);
    j = json::parse(in);
  }
  edit(j);
  std::ofstream(file) << j.dump();
  try {
    readManifest(tmp.path());
    FAIL() << "expected InputError mentioning '" << what << "'";
  } catch (const InputError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find(file.string() + ": "), std::string::npos) << msg;
    EXPECT_NE(msg.find(what), std::string::npos) << msg;
  }
}

TEST(FormatManifest, ValidationErrors) {
  expectBad([](json& j) { j["format"] = "something-else"; }, "not a gimlod atlas manifest");
  expectBad([](json& j) { j.erase("format"); }, "not a gimlod atlas manifest");
  expectBad([](json& j) { j["version"] = 99; }, "unsupported atlas format version 99");
  expectBad([](json& j) { j.erase("compression"); }, "format version 2 needs the field 'compression'");
  expectBad([](json& j) { j["version"] = 1; }, "field 'compression' needs format version 2");
  expectBad([](json& j) { j["compression"]["codec"] = "lzma"; }, "unknown compression codec 'lzma'");
  expectBad([](json& j) { j["compression"]["heightPrecision"] = -1; }, "compression steps and tolerances must be >= 0");
  expectBad([](json& j) { j["compression"]["positionTolerance"] = -0.5; },
            "compression steps and tolerances must be >= 0");
  expectBad([](json& j) { j["compression"]["normalTolerance"] = 1.5; }, "normalTolerance must be a whole number");
  expectBad([](json& j) { j["compression"]["normalTolerance"] = 300; }, "normalTolerance must be a whole number");
  expectBad([](json& j) { j["chartSize"] = 500; }, "chartSize 500 is not 2^m+1");
  expectBad([](json& j) { j["chartSize"] = -129; }, "chartSize");
  expectBad([](json& j) { j["blockIntervals"] = 256; }, "blockIntervals 256");
  expectBad([](json& j) { j.erase("spacing"); }, "missing field 'spacing'");
  expectBad([](json& j) { j["spacing"] = {1.0, -2.0}; }, "spacing must be positive");
  expectBad([](json& j) { j["kind"] = "voxels"; }, "unknown atlas kind");
  expectBad([](json& j) { j["chartsX"] = 3; }, "inconsistent chart list");
  expectBad([](json& j) { j["charts"][1]["id"] = 5; }, "inconsistent chart list");
  expectBad([](json& j) { j["charts"][1]["gridX"] = 0; }, "inconsistent chart list");
  expectBad([](json& j) { j["charts"][0]["neighbours"][1]["chart"] = -1; }, "inconsistent chart list");
  expectBad([](json& j) { j["charts"][0]["neighbours"][1]["edge"] = 2; }, "inconsistent chart list");
  expectBad([](json& j) { j["charts"][0]["neighbours"][1]["chart"] = 7; }, "out of range");
  expectBad([](json& j) { j["charts"][0]["file"] = "../../etc/passwd"; }, "relative path");
  expectBad([](json& j) { j["charts"][0].erase("neighbours"); }, "charts[0].neighbours");
  expectBad([](json& j) { j["hierarchy"]["maxNodeResLog2"] = 6; }, "log2(blockIntervals)");
  expectBad([](json& j) { j["hierarchy"]["depth"] = 0; }, "hierarchy.depth");
  expectBad([](json& j) { j["zScale"] = "big"; }, "zScale");
  expectBad([](json& j) { j = json::array(); }, "not a JSON object");
  // A chart's finest level: geometry atlases only, and within the pyramid.
  expectBad([](json& j) { j["charts"][1]["finest_level"] = 1; }, "finest_level' is for geometry atlases only");
  expectBad(
      [](json& j) {
        j["kind"] = "geometry";
        j["charts"][1]["finest_level"] = 8;
      },
      "charts[1].finest_level");
}

// A geometry atlas's charts keep their pyramids from their own finest levels: written only where
// not 0, read back as written, and the chart file's size follows.
TEST(FormatManifest, FinestLevelsRoundTrip) {
  test::TempDir tmp("gimlod-manifest");
  AtlasManifest a = sampleManifest();
  a.kind = AtlasKind::Geometry;
  a.charts[1].finestLevel = 3;
  writeManifest(tmp.path(), a);
  std::ifstream in(tmp.path() / kManifestName);
  const json j = json::parse(in);
  EXPECT_FALSE(j["charts"][0].contains("finest_level"));
  EXPECT_EQ(j["charts"][1]["finest_level"], 3);
  const AtlasManifest b = readManifest(tmp.path());
  EXPECT_EQ(b.charts[0].finestLevel, 0u);
  EXPECT_EQ(b.charts[1].finestLevel, 3u);
  EXPECT_EQ(b.chartFileSize(0), 129u);
  EXPECT_EQ(b.chartFileSize(1), 17u);
}

// A geometry manifest of `n` charts in a ring (each chart's right edge joined to the next one's
// left), chart c at finest level c % 4.
AtlasManifest ringManifest(uint32_t n) {
  AtlasManifest m = sampleManifest();
  m.kind = AtlasKind::Geometry;
  m.chartsX = n;
  m.chartsY = 1;
  m.samplesX = m.samplesY = 0;
  m.charts.clear();
  for (uint32_t i = 0; i < n; ++i) {
    ChartInfo c;
    c.id = i;
    c.gridX = int32_t(i);
    c.file = "charts/chart_" + std::to_string(i) + ".bin";
    c.finestLevel = i % 4;
    c.neighbours[kEdgeRight] = {int32_t((i + 1) % n), kEdgeLeft, true};
    c.neighbours[kEdgeLeft] = {int32_t((i + n - 1) % n), kEdgeRight, true};
    m.charts.push_back(c);
  }
  return m;
}

void expectSameCharts(const AtlasManifest& a, const AtlasManifest& b) {
  ASSERT_EQ(a.charts.size(), b.charts.size());
  for (size_t i = 0; i < a.charts.size(); ++i) {
    EXPECT_EQ(b.charts[i].file, a.charts[i].file);
    EXPECT_EQ(b.charts[i].gridX, a.charts[i].gridX);
    EXPECT_EQ(b.charts[i].finestLevel, a.charts[i].finestLevel);
    for (int e = 0; e < 4; ++e) {
      EXPECT_EQ(b.charts[i].neighbours[e].chart, a.charts[i].neighbours[e].chart) << i << " " << e;
      EXPECT_EQ(b.charts[i].neighbours[e].edge, a.charts[i].neighbours[e].edge) << i << " " << e;
    }
  }
}

// Past kInlineChartsMax charts a compressed atlas's chart list is a file of its own, one zstd
// frame of the same JSON (version 3); up to it, and uncompressed, the list stays inline (version
// 2 or 1) and a list file left from before is removed. A list file that is missing, corrupt, not
// JSON, or named outside the atlas is refused naming the file.
TEST(FormatManifest, ManyChartsGoToAChartListFile) {
  test::TempDir tmp("gimlod-manifest");
  const AtlasManifest many = ringManifest(uint32_t(kInlineChartsMax) + 1);
  writeManifest(tmp.path(), many);
  const fs::path list = tmp.path() / kChartListName;
  ASSERT_TRUE(fs::exists(list));
  json j = json::parse(std::ifstream(tmp.path() / kManifestName));
  EXPECT_EQ(j["version"], 3);
  EXPECT_EQ(j["chartList"], kChartListName);
  EXPECT_FALSE(j.contains("charts"));
  AtlasManifest b = readManifest(tmp.path());
  EXPECT_EQ(b.version, 3u);
  expectSameCharts(many, b);
  // The list is the JSON an inline list would be, and codes to a small part of it.
  const std::string codedText = test::fileBytes(list);
  const std::vector<uint8_t> coded(codedText.begin(), codedText.end());
  const std::vector<uint8_t> text = decompressFrame(coded, size_t(1) << 26);
  const json charts = json::parse(text.begin(), text.end());
  ASSERT_EQ(charts.size(), many.charts.size());
  EXPECT_EQ(charts[5]["finest_level"], 1);
  EXPECT_EQ(charts[5]["neighbours"][kEdgeRight]["chart"], 6);
  EXPECT_LT(coded.size() * 4, text.size());

  auto expectRefused = [&](const std::string& file, const std::string& what) {
    try {
      readManifest(tmp.path());
      ADD_FAILURE() << "expected an InputError naming " << file;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(file), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
    }
  };
  std::vector<uint8_t> cut(coded.begin(), coded.begin() + coded.size() / 2);
  std::ofstream(list, std::ios::binary).write(reinterpret_cast<const char*>(cut.data()), std::streamsize(cut.size()));
  expectRefused(kChartListName, "zstd");
  std::vector<uint8_t> flipped = coded;
  flipped[flipped.size() / 2] ^= 0x40;
  std::ofstream(list, std::ios::binary)
      .write(reinterpret_cast<const char*>(flipped.data()), std::streamsize(flipped.size()));
  expectRefused(kChartListName, "zstd");
  const std::string notJson = "[{\"id\": 0,";
  const std::vector<uint8_t> frame =
      compressFrame({reinterpret_cast<const uint8_t*>(notJson.data()), notJson.size()}, 3);
  std::ofstream(list, std::ios::binary)
      .write(reinterpret_cast<const char*>(frame.data()), std::streamsize(frame.size()));
  expectRefused(kChartListName, "invalid JSON");
  // A list whose neighbours do not name each other back is refused like an inline one.
  json broken = charts;
  broken[3]["neighbours"][kEdgeRight]["chart"] = 9;
  const std::string brokenText = broken.dump();
  const std::vector<uint8_t> brokenFrame =
      compressFrame({reinterpret_cast<const uint8_t*>(brokenText.data()), brokenText.size()}, 3);
  std::ofstream(list, std::ios::binary)
      .write(reinterpret_cast<const char*>(brokenFrame.data()), std::streamsize(brokenFrame.size()));
  expectRefused(kChartListName, "does not name it back");
  fs::remove(list);
  expectRefused(kChartListName, "");
  j["chartList"] = "../elsewhere.json.zst";
  std::ofstream(tmp.path() / kManifestName) << j.dump();
  expectRefused(kManifestName, "relative path inside the atlas");
  j["chartList"] = kChartListName;
  j["charts"] = json::array();
  std::ofstream(tmp.path() / kManifestName) << j.dump();
  expectRefused(kManifestName, "not both");

  // At most kInlineChartsMax charts, or uncompressed: inline, and the old list file goes.
  writeManifest(tmp.path(), many);
  const AtlasManifest few = ringManifest(uint32_t(kInlineChartsMax));
  writeManifest(tmp.path(), few);
  EXPECT_FALSE(fs::exists(list));
  b = readManifest(tmp.path());
  EXPECT_EQ(b.version, 2u);
  expectSameCharts(few, b);
  AtlasManifest plain = many;
  plain.compression = CompressionInfo{};
  writeManifest(tmp.path(), plain);
  EXPECT_FALSE(fs::exists(list));
  EXPECT_EQ(json::parse(std::ifstream(tmp.path() / kManifestName))["charts"].size(), many.charts.size());
  expectSameCharts(many, readManifest(tmp.path()));
}

TEST(FormatManifest, MissingAndMalformedFiles) {
  test::TempDir tmp("gimlod-manifest");
  try {
    readManifest(tmp.path());
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(kManifestName), std::string::npos) << e.what();
  }
  std::ofstream(tmp.path() / kManifestName) << "{ \"format\": \"gimlod-atlas\", ";
  try {
    readManifest(tmp.path());
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("invalid JSON"), std::string::npos) << e.what();
  }
  EXPECT_THROW(readManifest(tmp.path() / "nope"), InputError);
}

}  // namespace
}  // namespace gimlod
