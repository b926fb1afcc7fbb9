// `gimlod inspect` (inspect/report.h): the report of the shipped scan's and DEM's atlases holds the
// build's figures and every image it names, opens in a real browser (headless Chromium) with no
// broken image and a non-blank page, and bad input leaves no half-written report.
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <limits>
#include <fstream>
#include <regex>
#include <set>
#include <sstream>

#include <OpenImageIO/imageio.h>
#include <nlohmann/json.hpp>

#include "core/atlas_format.h"
#include "hierarchy/root_groups.h"
#include "inspect/report.h"
#include "pipeline/build.h"
#include "tests/small_atlases.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

class InspectReportTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new test::TempDir("gimlod-inspect");
    test::buildSmallScanAtlas(dir_->path() / "bunny.atlas", true);
    test::buildSmallDemAtlas(dir_->path() / "rainier.atlas");
  }
  static void TearDownTestSuite() { delete dir_; }
  static fs::path path(const std::string& name) { return dir_->path() / name; }
  static json stats(const std::string& atlas) { return json::parse(slurp(path(atlas) / "stats.json")); }
  static test::TempDir* dir_;
};
test::TempDir* InspectReportTest::dir_ = nullptr;

// The images index.html names, and the PNG files in the report: the same set.
void expectImagesMatchFiles(const fs::path& report) {
  const std::string page = slurp(report / "index.html");
  std::set<std::string> named, files;
  const std::regex img("<img src=\"([^\"]+)\"");
  for (auto it = std::sregex_iterator(page.begin(), page.end(), img); it != std::sregex_iterator(); ++it)
    named.insert((*it)[1]);
  for (const auto& e : fs::directory_iterator(report))
    if (e.path().extension() == ".png") files.insert(e.path().filename().string());
  EXPECT_FALSE(named.empty());
  EXPECT_EQ(named, files);
}

TEST_F(InspectReportTest, ScanReportHoldsTheBuildsFiguresAndItsImages) {
  InspectOptions o;
  o.atlas = path("bunny.atlas");
  o.output = path("bunny_report");
  o.worstCharts = 5;
  const InspectResult r = writeInspectReport(o);
  const json st = stats("bunny.atlas");
  const json written = json::parse(slurp(o.output / "report.json"));
  EXPECT_EQ(written, r.figures);
  const json& sum = written["summary"];
  EXPECT_EQ(sum["kind"], "geometry");
  EXPECT_EQ(sum["charts"], st["charts"]);
  // The forest's roots: the top groups above the charts (at most 16), or every chart.
  const uint64_t charts = st["charts"].get<uint64_t>();
  EXPECT_LE(sum["roots"].get<uint64_t>(), std::min<uint64_t>(charts, kDefaultMaxRoots));
  EXPECT_GE(sum["roots"].get<uint64_t>(), 1u);
  EXPECT_EQ(sum["groups"].get<uint64_t>() > 0, charts > kDefaultMaxRoots);
  EXPECT_EQ(sum["chart_size"], 17);
  EXPECT_EQ(sum["flipped_texels"], st["resample"]["flipped_texels"]);
  EXPECT_EQ(sum["image_stretch_l2"], st["resample"]["image_stretch_l2"]);
  EXPECT_EQ(sum["hausdorff_percent_of_diagonal"], st["fidelity"]["hausdorff_percent_of_diagonal"]);
  EXPECT_EQ(sum["samples"], st["charts"].get<uint64_t>() * 17 * 17);
  // The manifest's finest levels, as the build counted them (all 0: a given chart size sets no bound).
  EXPECT_EQ(sum["charts_by_finest_level"], st["charts_by_finest_level"]);
  EXPECT_EQ(sum["charts_by_finest_level"], json::array({st["charts"]}));
  EXPECT_EQ(sum["seams_bit_identical"], true);
  EXPECT_EQ(written["charts"].size(), st["charts"].get<size_t>());
  // Worst first: by flipped texels, then degenerate texels, then stretch Linf.
  for (size_t i = 1; i < written["charts"].size(); ++i) {
    const json &a = written["charts"][i - 1], &b = written["charts"][i];
    const auto key = [](const json& c) {
      return std::make_tuple(c["flipped_texels"].get<double>(), c["degenerate_texels"].get<double>(),
                             c["stretch_linf"].get<double>());
    };
    EXPECT_GE(key(a), key(b)) << "row " << i;
  }
  ASSERT_EQ(written["chart_images"].size(), 5u);
  // Normals, positions and stretch of each, and a heat map of the errors per hierarchy level and
  // resolution: levels 0 and 1 draw at resolutions 1..3, level 2 at 1..2 (16-interval charts).
  EXPECT_EQ(written["hierarchy"]["heat_maps"].size(), 3u + 3u + 2u);
  EXPECT_EQ(r.images, 15u + 8u);
  // The hierarchy's figures: errors never grow with resolution at a level, and its node counts.
  for (const json& l : written["hierarchy"]["levels"]) {
    EXPECT_EQ(l["nodes"], st["charts"].get<uint64_t>() << (2 * l["level"].get<uint32_t>()));
    double previous = std::numeric_limits<double>::infinity();
    for (const json& e : l["errors"]) {
      EXPECT_LE(e["max_error"].get<double>(), previous) << "level " << l["level"] << " res " << e["res"];
      EXPECT_LE(e["mean_error"].get<double>(), e["max_error"].get<double>());
      previous = e["max_error"].get<double>();
    }
  }
  // Streaming: every view needs at least its visible roots, and the bytes of its pages.
  const json& streaming = written["streaming"];
  ASSERT_EQ(streaming["views"].size(), 6u);
  for (const json& v : streaming["views"]) {
    EXPECT_GT(v["nodes"].get<uint64_t>(), 0u);
    EXPECT_GE(v["page_bytes"].get<uint64_t>(),
              v["nodes"].get<uint64_t>() * streaming["pages"].back()["page_bytes"].get<uint64_t>());
    // Every node listed as raised is drawn finer than its error needs; no more are listed than counted.
    EXPECT_LE(v["raised"].size(), v["nodes_raised"].get<size_t>());
    for (const json& n : v["raised"]) EXPECT_GT(n["drawn_res"].get<uint32_t>(), n["needed_res"].get<uint32_t>());
  }
  EXPECT_EQ(streaming["pyramid_levels"][0]["bytes"].get<uint64_t>(),
            st["charts"].get<uint64_t>() * 17 * 17 * streaming["bytes_per_sample"].get<uint64_t>());
  expectImagesMatchFiles(o.output);
  EXPECT_GT(r.bytes, 0u);
}

// With the source mesh: the comparison finds the build's own Hausdorff figures, says where the
// largest distances lie, and maps the farthest charts; a DEM atlas or a missing source is refused.
TEST_F(InspectReportTest, SourceComparisonFindsTheBuildsFidelityAndWhereItLies) {
  InspectOptions o;
  o.atlas = path("bunny.atlas");
  o.output = path("bunny_source_report");
  o.worstCharts = 2;
  o.source = test::repoData() / "meshes/bun_zipper.ply";
  const InspectResult r = writeInspectReport(o);
  const json st = stats("bunny.atlas");
  const json& src = r.figures["source"];
  EXPECT_NEAR(src["hausdorff_percent_of_diagonal"].get<double>(),
              st["fidelity"]["hausdorff_percent_of_diagonal"].get<double>(),
              1e-9 * st["fidelity"]["hausdorff_percent_of_diagonal"].get<double>());
  EXPECT_NEAR(src["max_mesh_to_atlas"].get<double>(), st["fidelity"]["max_mesh_to_atlas"].get<double>(),
              1e-9 * st["fidelity"]["max_mesh_to_atlas"].get<double>());
  EXPECT_EQ(src["mesh_samples"], st["fidelity"]["mesh_samples"]);
  EXPECT_EQ(src["atlas_samples"].get<uint64_t>(), st["charts"].get<uint64_t>() * 17 * 17);  // unwelded
  ASSERT_EQ(src["worst_input_samples"].size(), 16u);
  // The worst input sample is the Hausdorff maximum (float distances), and lies on a chart.
  EXPECT_NEAR(src["worst_input_samples"][0]["distance"].get<double>(), src["max_mesh_to_atlas"].get<double>(),
              1e-6 * src["max_mesh_to_atlas"].get<double>());
  EXPECT_LT(src["worst_input_samples"][0]["chart"].get<uint32_t>(), st["charts"].get<uint32_t>());
  for (size_t i = 1; i < src["worst_input_samples"].size(); ++i)
    EXPECT_LE(src["worst_input_samples"][i]["distance"].get<double>(),
              src["worst_input_samples"][i - 1]["distance"].get<double>());
  ASSERT_EQ(src["distance_maps"].size(), 6u);
  EXPECT_EQ(r.figures["summary"]["source_hausdorff_percent_of_diagonal"], src["hausdorff_percent_of_diagonal"]);
  expectImagesMatchFiles(o.output);

  // A DEM atlas against its DEM: every sample inside the DEM is the DEM's, but for the filled voids,
  // which a compressed atlas of a whole-metre DEM rounds to whole metres; and a mesh is not its
  // source.
  o.atlas = path("rainier.atlas");
  o.output = path("rainier_source_report");
  o.source = test::repoData() / "terrain/mt_rainier_90m.tif";
  const InspectResult dem = writeInspectReport(o);
  const json& ds = dem.figures["source"];
  EXPECT_EQ(ds["kind"], "dem");
  const AtlasManifest rm = readManifest(o.atlas);
  ASSERT_TRUE(rm.compression.present);
  EXPECT_EQ(rm.compression.heightPrecision, 1.0);
  EXPECT_LE(ds["max_vertical_distance"].get<double>(), rm.compression.heightPrecision / 2);
  EXPECT_GE(ds["samples_compared"].get<uint64_t>(), uint64_t(rm.samplesX) * rm.samplesY);  // shared borders twice
  expectImagesMatchFiles(o.output);
  o.output = path("rainier_source_report_2");
  o.source = test::repoData() / "meshes/bun_zipper.ply";
  EXPECT_THROW(writeInspectReport(o), InputError);
  EXPECT_FALSE(fs::exists(o.output));
  // A DEM whose heights differ: a copy of the atlas with one sample raised by 5 m is found there.
  const fs::path raised = path("raised.atlas");
  fs::copy(path("rainier.atlas"), raised, fs::copy_options::recursive);
  {
    const fs::path file = raised / rm.charts[4].file;
    ChartPyramid p;
    const ChartFileReader r(file);
    for (uint32_t level = 0; level < r.levels(); ++level) {
      p.heights.push_back(r.readLevelHeights(level));
      p.normals.push_back(r.readLevelNormals(level));
    }
    p.heights[0][10 * rm.chartSize + 20] += 5.0f;
    writeChartFile(file, p, rm.chartSize, rm.blockIntervals);
  }
  o.atlas = raised;
  o.output = path("raised_report");
  o.source = test::repoData() / "terrain/mt_rainier_90m.tif";
  const json rs = writeInspectReport(o).figures["source"];
  EXPECT_NEAR(rs["max_vertical_distance"].get<double>(), 5.0, 1e-3);
  EXPECT_EQ(rs["worst_atlas_samples"][0]["chart"], 4);
  EXPECT_EQ(rs["worst_atlas_samples"][0]["u"], 20);
  EXPECT_EQ(rs["worst_atlas_samples"][0]["v"], 10);
  o.atlas = path("bunny.atlas");
  o.output = path("no_source_report");
  o.source = path("no_such_mesh.ply");
  try {
    writeInspectReport(o);
    ADD_FAILURE() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("no_such_mesh.ply"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(o.output));
}

TEST_F(InspectReportTest, DemReportShowsHeightsAndReplacesAnEarlierReport) {
  InspectOptions o;
  o.atlas = path("rainier.atlas");
  o.output = path("rainier_report");
  writeInspectReport(o);
  fs::remove(o.output / "chart_0_heights.png");  // an earlier report, damaged
  const InspectResult r = writeInspectReport(o);
  const json& sum = r.figures["summary"];
  EXPECT_EQ(sum["kind"], "heightfield");
  EXPECT_EQ(sum["charts"], stats("rainier.atlas")["charts"]);
  for (const json& c : r.figures["charts"]) {
    EXPECT_LE(c["height_min"].get<double>(), c["height_max"].get<double>());
  }
  // Normals and heights of the worst (here: the most relief) charts, 24 by default.
  EXPECT_EQ(r.images, 2 * std::min<size_t>(o.worstCharts, r.figures["charts"].size()) +
                          r.figures["hierarchy"]["heat_maps"].size());
  EXPECT_GT(r.figures["charts"].size(), o.worstCharts);
  expectImagesMatchFiles(o.output);
}

TEST_F(InspectReportTest, BadInputLeavesNoReport) {
  const fs::path notAtlas = path("not_an_atlas");
  fs::create_directories(notAtlas);
  InspectOptions o;
  o.atlas = notAtlas;
  o.output = path("r1");
  try {
    writeInspectReport(o);
    ADD_FAILURE() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("atlas.json"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(o.output));

  // A truncated chart file: named, and nothing written.
  const fs::path copy = path("truncated.atlas");
  fs::copy(path("bunny.atlas"), copy, fs::copy_options::recursive);
  const fs::path chart = copy / readManifest(copy).charts[2].file;
  fs::resize_file(chart, fs::file_size(chart) / 3);
  o.atlas = copy;
  o.output = path("r2");
  try {
    writeInspectReport(o);
    ADD_FAILURE() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(chart.filename().string()), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(o.output));
  for (const auto& e : fs::directory_iterator(dir_->path()))
    EXPECT_EQ(e.path().filename().string().find(".r2.partial"), std::string::npos) << e.path();

  // An output that cannot be written (its parent is a file), or holds something else.
  o.atlas = path("bunny.atlas");
  const fs::path file = path("a_file");
  std::ofstream(file) << "x";
  o.output = file / "report";
  EXPECT_THROW(writeInspectReport(o), InputError);
  const fs::path other = path("other");
  fs::create_directories(other);
  std::ofstream(other / "notes.txt") << "mine";
  o.output = other;
  EXPECT_THROW(writeInspectReport(o), InputError);
  EXPECT_TRUE(fs::exists(other / "notes.txt"));

  // A damaged stats.json: not JSON, or figures of the wrong type.
  const fs::path damaged = path("damaged.atlas");
  fs::copy(path("bunny.atlas"), damaged, fs::copy_options::recursive);
  o.atlas = damaged;
  o.output = path("r4");
  for (const std::string& text : {std::string("{\"charts\": "), std::string("[1, 2]"),
                                  std::string(R"({"resample": {"per_chart": [{"flipped_texels": "many"}]}})")}) {
    std::ofstream(damaged / "stats.json", std::ios::trunc) << text;
    try {
      writeInspectReport(o);
      ADD_FAILURE() << "expected InputError for " << text;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("stats.json"), std::string::npos) << e.what();
    }
    EXPECT_FALSE(fs::exists(o.output));
  }

  o.atlas = path("bunny.atlas");
  o.output = path("r3");
  o.thumbnailSize = 2;
  EXPECT_THROW(writeInspectReport(o), InputError);
}

// The report in a real browser: headless Chromium loads index.html from disk; the page's script
// counts its images and the broken ones; the summary's numbers are the build's; the screenshot
// is not blank.
TEST_F(InspectReportTest, OpensInHeadlessChromium) {
  std::string chromium;
  for (const char* c : {"chromium", "chromium-browser"})
    if (test::runCommand(std::string("command -v ") + c + " >/dev/null 2>&1") == 0) chromium = c;
  ASSERT_FALSE(chromium.empty()) << "chromium is not installed (scripts/install-deps.sh installs it)";
  InspectOptions o;
  o.atlas = path("bunny.atlas");
  o.output = path("browser_report");
  o.worstCharts = 4;
  writeInspectReport(o);
  const std::string url = "file://" + fs::absolute(o.output / "index.html").string();
  // The browser is not built with the sanitizers: it gets none of their preloads.
  chromium = "env -u LD_PRELOAD " + chromium;
  const std::string flags =
      " --headless --no-sandbox --disable-gpu --hide-scrollbars --virtual-time-budget=5000 "
      "--user-data-dir=" +
      (dir_->path() / "chromium-profile").string();
  std::string dom;
  ASSERT_EQ(test::runCommand(chromium + flags + " --dump-dom '" + url + "' 2>/dev/null", &dom), 0) << dom;
  std::smatch m;
  ASSERT_TRUE(std::regex_search(dom, m, std::regex("data-images=\"(\\d+)\""))) << dom.substr(0, 2000);
  EXPECT_EQ(std::stoi(m[1]), 12 + 8);  // 4 charts x 3 images, 8 (level, resolution) heat maps
  ASSERT_TRUE(std::regex_search(dom, m, std::regex("data-broken-images=\"(\\d+)\"")));
  EXPECT_EQ(std::stoi(m[1]), 0);
  const json st = stats("bunny.atlas");
  ASSERT_TRUE(std::regex_search(dom, m, std::regex("data-key=\"charts\">(\\d+)<")));
  EXPECT_EQ(std::stoul(m[1]), st["charts"].get<unsigned long>());
  ASSERT_TRUE(std::regex_search(dom, m, std::regex("data-key=\"flipped_texels\">(\\d+)<")));
  EXPECT_EQ(std::stoul(m[1]), st["resample"]["flipped_texels"].get<unsigned long>());

  const fs::path shot = dir_->path() / "shot.png";
  std::string out;
  ASSERT_EQ(
      test::runCommand(
          chromium + flags + " --window-size=1000,800 --screenshot=" + shot.string() + " '" + url + "' 2>&1", &out),
      0)
      << out;
  auto in = OIIO::ImageInput::open(shot.string());
  ASSERT_TRUE(in) << shot;
  const OIIO::ImageSpec& spec = in->spec();
  std::vector<uint8_t> px(size_t(spec.width) * spec.height * spec.nchannels);
  ASSERT_TRUE(in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::UINT8, px.data()));
  std::set<uint32_t> colours;
  for (size_t i = 0; i + 2 < px.size(); i += spec.nchannels)
    colours.insert(uint32_t(px[i]) << 16 | uint32_t(px[i + 1]) << 8 | px[i + 2]);
  EXPECT_GT(colours.size(), 50u) << "the screenshot is (nearly) blank";
}

}  // namespace
}  // namespace gimlod
