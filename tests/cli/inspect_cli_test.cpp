// `gimlod inspect` through the command-line tool, with its six views rendered by the real renderer
// through headless EGL in the chart overlay, and `gimlod render --overlay`.
#include <gtest/gtest.h>

#include <fstream>
#include <set>
#include <sstream>

#include <OpenImageIO/imageio.h>
#include <nlohmann/json.hpp>

#include "tests/test_util.h"

namespace gimlod {
namespace {

namespace fs = std::filesystem;

std::vector<uint8_t> readRgb(const fs::path& png, int* w = nullptr, int* h = nullptr) {
  auto in = OIIO::ImageInput::open(png.string());
  EXPECT_TRUE(in) << png;
  if (!in) return {};
  const OIIO::ImageSpec& spec = in->spec();
  std::vector<uint8_t> px(size_t(spec.width) * spec.height * 3);
  EXPECT_TRUE(in->read_image(0, 0, 0, 3, OIIO::TypeDesc::UINT8, px.data()));
  if (w) *w = spec.width;
  if (h) *h = spec.height;
  return px;
}

size_t distinctColours(const std::vector<uint8_t>& rgb) {
  std::set<uint32_t> c;
  for (size_t i = 0; i + 2 < rgb.size(); i += 3)
    c.insert(uint32_t(rgb[i]) << 16 | uint32_t(rgb[i + 1]) << 8 | rgb[i + 2]);
  return c.size();
}

class InspectCli : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new test::TempDir("gimlod-inspect-cli");
    std::string out;
    ASSERT_EQ(
        test::runCommand(test::appPath().string() + " build '" + (test::repoData() / "meshes/bun_zipper.ply").string() +
                             "' -o '" + (dir_->path() / "bunny.atlas").string() +
                             "' --charts 24 --chart-size 17 --depth 3 --node-res 8 --min-node-res 2 --no-fidelity",
                         &out),
        0)
        << out;
  }
  static void TearDownTestSuite() { delete dir_; }
  static test::TempDir* dir_;
};
test::TempDir* InspectCli::dir_ = nullptr;

TEST_F(InspectCli, ReportHoldsSixRenderedViewsOfTheCharts) {
  const fs::path report = dir_->path() / "report";
  std::string out;
  ASSERT_EQ(test::runCommand(test::appPath().string() + " inspect '" + (dir_->path() / "bunny.atlas").string() +
                                 "' -o '" + report.string() + "' --view-size 160x120 --worst 3 2>&1",
                             &out),
            0)
      << out;
  EXPECT_NE(out.find("seams bit-identical"), std::string::npos) << out;
  std::ifstream in(report / "report.json");
  const nlohmann::json r = nlohmann::json::parse(in);
  ASSERT_EQ(r["views"].size(), 6u);
  std::set<std::string> axes;
  for (const nlohmann::json& v : r["views"]) {
    const fs::path png = report / v["file"].get<std::string>();
    int w = 0, h = 0;
    const std::vector<uint8_t> rgb = readRgb(png, &w, &h);
    EXPECT_EQ(w, 160);
    EXPECT_EQ(h, 120);
    // The chart overlay: many charts in their own colours, not a blank or clay picture.
    EXPECT_GT(distinctColours(rgb), 40u) << png;
    const std::string caption = v["caption"];
    axes.insert(caption.substr(caption.find("from ") + 5, 2));
  }
  EXPECT_EQ(axes, (std::set<std::string>{"+x", "-x", "+y", "-y", "+z", "-z"}));
  // The crack table: every view's drawn cut is closed but for the bunny's holes.
  for (const nlohmann::json& v : r["views"]) {
    EXPECT_EQ(v["other_boundary_edges"], 0u) << v["view"];
    EXPECT_GT(v["open_border_edges"].get<uint64_t>(), 0u) << v["view"];
  }
  EXPECT_EQ(r["summary"]["crack_edges_in_views"], 0u);
  EXPECT_EQ(r["chart_images"].size(), 3u);
}

// With the source mesh, six more views colour every node by its distance to the source: the
// largest distances (red) are where the source comparison says they are.
TEST_F(InspectCli, SourceDistancesAreDrawnOnTheModel) {
  const fs::path report = dir_->path() / "source_report";
  std::string out;
  ASSERT_EQ(test::runCommand(test::appPath().string() + " inspect '" + (dir_->path() / "bunny.atlas").string() +
                                 "' -o '" + report.string() + "' --view-size 160x120 --worst 1 --source '" +
                                 (test::repoData() / "meshes/bun_zipper.ply").string() + "' 2>&1",
                             &out),
            0)
      << out;
  std::ifstream in(report / "report.json");
  const nlohmann::json r = nlohmann::json::parse(in);
  ASSERT_EQ(r["views"].size(), 12u);
  size_t reddish = 0;
  for (size_t i = 6; i < 12; ++i) {
    const nlohmann::json& v = r["views"][i];
    EXPECT_NE(v["caption"].get<std::string>().find("distance to the source"), std::string::npos);
    const std::vector<uint8_t> rgb = readRgb(report / v["file"].get<std::string>());
    EXPECT_NE(rgb, readRgb(report / r["views"][i - 6]["file"].get<std::string>())) << "same picture as the charts";
    for (size_t k = 0; k + 2 < rgb.size(); k += 3) reddish += rgb[k] > 150 && rgb[k + 1] < 90 && rgb[k + 2] < 90;
  }
  EXPECT_GT(reddish, 0u) << "the largest distances are drawn red somewhere";
  EXPECT_GT(r["source"]["hausdorff"].get<double>(), 0.0);
}

TEST_F(InspectCli, ChartOverlayChangesThePictureAndBadNamesAreRefused) {
  const std::string app = test::appPath().string(), atlas = (dir_->path() / "bunny.atlas").string();
  std::string out;
  for (const char* mode : {"none", "chart", "level", "res"}) {
    ASSERT_EQ(test::runCommand(app + " render '" + atlas + "' -o '" + (dir_->path() / mode).string() +
                                   "' --orbit 1 --size 96x72 --overlay " + mode + " 2>&1",
                               &out),
              0)
        << out;
  }
  const auto plain = readRgb(dir_->path() / "none/frame_0000.png");
  const auto charts = readRgb(dir_->path() / "chart/frame_0000.png");
  const auto levels = readRgb(dir_->path() / "level/frame_0000.png");
  ASSERT_EQ(plain.size(), charts.size());
  EXPECT_NE(plain, charts);
  EXPECT_NE(charts, levels);
  // Clay is one hue; the chart overlay has many.
  std::set<uint32_t> hues;
  for (size_t i = 0; i + 2 < charts.size(); i += 3) {
    const int r = charts[i], g = charts[i + 1], b = charts[i + 2];
    if (std::max({r, g, b}) - std::min({r, g, b}) > 30)
      hues.insert(uint32_t(r / 32) << 6 | uint32_t(g / 32) << 3 | uint32_t(b / 32));
  }
  EXPECT_GT(hues.size(), 8u);
  EXPECT_EQ(test::runCommand(app + " render '" + atlas + "' -o '" + (dir_->path() / "bad").string() +
                                 "' --orbit 1 --size 32x24 --overlay charts 2>&1",
                             &out),
            2);
  EXPECT_NE(out.find("--overlay"), std::string::npos) << out;
}

}  // namespace
}  // namespace gimlod
