// `gimlod view` as a person uses it: a real GLFW window on a virtual X display (Xvfb, Mesa's
// GLX), driven with xdotool: keys and mouse drags change what is drawn as they should (read back
// from the window's screenshots and the per-frame stats), a scripted run draws what `render`
// draws for the same cameras, and a path recorded in the window replays through `render`.
#include <gtest/gtest.h>

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <fstream>
#include <functional>
#include <sstream>

#include <OpenImageIO/imageio.h>
#include <nlohmann/json.hpp>

#include "runtime/atlas_view.h"
#include "runtime/camera.h"
#include "tests/small_atlases.h"
#include "tests/test_util.h"

namespace gimlod {
namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

using test::quoted;

// An Xvfb server on a free display number (Xvfb picks it: -displayfd), stopped at the end.
class VirtualDisplay {
 public:
  VirtualDisplay() {
    int fds[2];
    if (::pipe(fds) != 0) return;
    pid_ = ::fork();
    if (pid_ == 0) {
      ::close(fds[0]);
      const std::string fd = std::to_string(fds[1]);
      const int devnull = ::open("/dev/null", O_WRONLY);
      ::dup2(devnull, 2);
      ::execlp("Xvfb", "Xvfb", "-displayfd", fd.c_str(), "-screen", "0", "1280x1024x24", "-nolisten", "tcp",
               static_cast<char*>(nullptr));
      ::_exit(127);
    }
    ::close(fds[1]);
    std::string number;
    pollfd p{fds[0], POLLIN, 0};
    char ch = 0;
    while (::poll(&p, 1, 20000) > 0 && ::read(fds[0], &ch, 1) == 1 && ch != '\n') number += ch;
    ::close(fds[0]);
    if (!number.empty()) display_ = ":" + number;
  }
  ~VirtualDisplay() {
    if (pid_ > 0) {
      ::kill(pid_, SIGTERM);
      ::waitpid(pid_, nullptr, 0);
    }
  }
  // ":N", or empty when Xvfb could not start.
  const std::string& display() const { return display_; }

 private:
  pid_t pid_ = -1;
  std::string display_;
};

struct Image {
  int width = 0, height = 0;
  std::vector<uint8_t> rgb;  // 3 per pixel
  const uint8_t* at(int x, int y) const { return &rgb[(size_t(y) * width + x) * 3]; }
};

Image readImage(const fs::path& p) {
  Image im;
  auto in = OIIO::ImageInput::open(p.string());
  if (!in) return im;
  const OIIO::ImageSpec& spec = in->spec();
  im.width = spec.width;
  im.height = spec.height;
  std::vector<uint8_t> all(size_t(spec.width) * spec.height * spec.nchannels);
  in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::UINT8, all.data());
  im.rgb.resize(size_t(spec.width) * spec.height * 3);
  for (size_t i = 0; i < size_t(spec.width) * spec.height; ++i)
    for (int c = 0; c < 3; ++c) im.rgb[i * 3 + c] = all[i * spec.nchannels + std::min(c, spec.nchannels - 1)];
  return im;
}

// The fraction of pixels whose channels differ by more than `slack`.
double differentFraction(const Image& a, const Image& b, int slack = 2) {
  if (a.width != b.width || a.height != b.height || a.rgb.empty()) return 1.0;
  size_t diff = 0;
  for (size_t i = 0; i < a.rgb.size(); i += 3) {
    bool d = false;
    for (int c = 0; c < 3; ++c) d |= std::abs(int(a.rgb[i + c]) - int(b.rgb[i + c])) > slack;
    diff += d;
  }
  return double(diff) / double(a.rgb.size() / 3);
}

// Pixels that are not the background colour, and their centroid (in [0, 1]^2).
struct Coverage {
  double fraction = 0.0, cx = 0.0, cy = 0.0;
};
Coverage coverage(const Image& im, std::array<int, 3> background) {
  Coverage c;
  size_t n = 0;
  for (int y = 0; y < im.height; ++y)
    for (int x = 0; x < im.width; ++x) {
      const uint8_t* p = im.at(x, y);
      if (std::abs(p[0] - background[0]) + std::abs(p[1] - background[1]) + std::abs(p[2] - background[2]) <= 6)
        continue;
      ++n;
      c.cx += (x + 0.5) / im.width;
      c.cy += (y + 0.5) / im.height;
    }
  if (n > 0) c.fraction = double(n) / (double(im.width) * im.height), c.cx /= double(n), c.cy /= double(n);
  return c;
}

// Of the pixels `a` covers (not background), the fraction that are background in `b`.
double uncoveredFraction(const Image& a, const Image& b, std::array<int, 3> background) {
  auto isBackground = [&](const uint8_t* p) {
    return std::abs(p[0] - background[0]) + std::abs(p[1] - background[1]) + std::abs(p[2] - background[2]) <= 6;
  };
  size_t covered = 0, opened = 0;
  for (int y = 0; y < a.height && y < b.height; ++y)
    for (int x = 0; x < a.width && x < b.width; ++x) {
      if (isBackground(a.at(x, y))) continue;
      ++covered;
      opened += isBackground(b.at(x, y));
    }
  return covered ? double(opened) / double(covered) : 0.0;
}

std::vector<std::map<std::string, std::string>> readStats(const fs::path& p) {
  std::ifstream f(p);
  std::vector<std::map<std::string, std::string>> rows;
  std::string line;
  std::vector<std::string> head;
  while (std::getline(f, line)) {
    std::vector<std::string> cells;
    std::stringstream ss(line);
    std::string cell;
    while (std::getline(ss, cell, ',')) cells.push_back(cell);
    if (!line.empty() && line.back() == ',') cells.emplace_back();  // an empty last cell
    if (head.empty()) {
      head = cells;
      continue;
    }
    if (cells.size() != head.size()) continue;  // a row being written
    std::map<std::string, std::string> row;
    for (size_t i = 0; i < head.size(); ++i) row[head[i]] = cells[i];
    rows.push_back(row);
  }
  return rows;
}

// Two cameras looking at the atlas's box from the front (from +z for a y-up scan, from -y for a
// z-up terrain) and from a quarter turn round it.
fs::path writeTwoCameras(const fs::path& file, const fs::path& atlasDir, bool yUp) {
  const AtlasView atlas = openAtlas(atlasDir);
  const glm::dvec3 centre = (atlas.lo + atlas.hi) * 0.5;
  const double d = glm::length(atlas.hi - atlas.lo) * 0.9;
  const glm::dvec3 up = yUp ? glm::dvec3(0, 1, 0) : glm::dvec3(0, 0, 1);
  const glm::dvec3 front = yUp ? glm::dvec3(0, 0.4, 1) : glm::dvec3(0, -1, 0.6);
  const glm::dvec3 side = yUp ? glm::dvec3(1, 0.4, 0) : glm::dvec3(1, 0, 0.6);
  nlohmann::json frames = nlohmann::json::array();
  for (const glm::dvec3& dir : {front, side}) {
    const glm::dvec3 eye = centre + d * glm::normalize(dir);
    frames.push_back({{"eye", {eye.x, eye.y, eye.z}},
                      {"target", {centre.x, centre.y, centre.z}},
                      {"up", {up.x, up.y, up.z}},
                      {"fov_deg", 45.0}});
  }
  std::ofstream(file) << nlohmann::json{{"frames", frames}}.dump(1);
  return file;
}

class ViewWindow : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new test::TempDir("gimlod-view");
    test::buildSmallScanAtlas(dir_->path() / "bunny.atlas", false);
    test::buildSmallDemAtlas(dir_->path() / "rainier.atlas");
  }
  static void TearDownTestSuite() {
    delete dir_;
    dir_ = nullptr;
  }
  void SetUp() override {
    ASSERT_EQ(test::runCommand("command -v Xvfb xdotool"), 0) << "needs Xvfb and xdotool (scripts/install-deps.sh)";
    display_ = std::make_unique<VirtualDisplay>();
    ASSERT_FALSE(display_->display().empty()) << "Xvfb did not start";
  }
  std::string env() const { return "DISPLAY=" + display_->display() + " "; }
  static const fs::path& dir() { return dir_->path(); }

  static test::TempDir* dir_;
  std::unique_ptr<VirtualDisplay> display_;
};
test::TempDir* ViewWindow::dir_ = nullptr;

constexpr std::array<int, 3> kBackground{20, 30, 40};
const std::string kBackgroundArg = " --background 20,30,40";

// A scripted run (--path, --frames, --hide-ui, --screenshot) draws, pixel for pixel within
// rounding, what `render` draws from the same camera, on the shipped bunny and the shipped DEM
// (multisampled, --msaa 4), and the model covers the middle of the window.
TEST_F(ViewWindow, ScriptedRunDrawsWhatRenderDraws) {
  const std::string app = test::appPath().string();
  for (const char* name : {"bunny", "rainier"}) {
    SCOPED_TRACE(name);
    const fs::path atlas = dir() / (std::string(name) + ".atlas");
    const fs::path path = writeTwoCameras(dir() / (std::string(name) + "_path.json"), atlas, name[0] == 'b');
    const fs::path shot = dir() / (std::string(name) + "_view.png"), frames = dir() / (std::string(name) + "_render");
    const std::string msaa = name[0] == 'r' ? " --msaa 4" : "";
    std::string out;
    ASSERT_EQ(test::runCommand(env() + app + " view '" + atlas.string() + "' --path '" + path.string() +
                                   "' --frames 4 --size 320x240 --hide-ui --screenshot '" + shot.string() + "'" +
                                   kBackgroundArg + msaa,
                               &out),
              0)
        << out;
    ASSERT_EQ(test::runCommand(app + " render '" + atlas.string() + "' --path '" + path.string() +
                                   "' --size 320x240 -o '" + frames.string() + "'" + kBackgroundArg + msaa,
                               &out),
              0)
        << out;
    const Image view = readImage(shot), render = readImage(frames / "frame_0001.png");
    ASSERT_EQ(view.width, 320);
    ASSERT_EQ(view.height, 240);
    const double diff = differentFraction(view, render);
    std::printf("  %s: %.4f%% of the pixels differ from render's\n", name, 100.0 * diff);
    EXPECT_LT(diff, 0.005);
    // The path's last camera holds: the other camera's picture is a different one.
    EXPECT_GT(differentFraction(view, readImage(frames / "frame_0000.png")), 0.05);
    const Coverage cov = coverage(view, kBackground);
    EXPECT_GT(cov.fraction, 0.08);
    EXPECT_NEAR(cov.cx, 0.5, 0.15);
    EXPECT_NEAR(cov.cy, 0.5, 0.2);
  }
}

// The interactive window, driven like a person: keys toggle the wireframe and the colourings
// (chart, resolution, error), a lower tolerance draws more triangles, a frozen cut stays while a
// drag turns the camera, a resized window draws at its new size, and T hands the budgets to the
// frame-time controller.
class Session {
 public:
  Session(const std::string& env, const std::string& options, const fs::path& cwd) : env_(env), cwd_(cwd) {
    stats_ = cwd / "stats.csv";
    rc_ = cwd / "rc";
    fs::remove(stats_);
    fs::remove(rc_);
    // The exit status is written whole and then renamed into place, so `finished()` never sees
    // the file before its number is in it.
    const std::string cmd = "cd '" + cwd.string() + "' && (" + env + test::appPath().string() + " view " + options +
                            " --stats '" + stats_.string() + "' --exit-after 100000 > view.log 2>&1; echo $? > '" +
                            rc_.string() + ".part' && mv '" + rc_.string() + ".part' '" + rc_.string() +
                            "') > /dev/null 2>&1 &";
    ok_ = test::runCommand(cmd) == 0;
    std::string id;
    ok_ = ok_ && test::runCommand(env + "timeout 30 xdotool search --sync --name 'gimlod view'", &id) == 0;
    window_ = id.substr(0, id.find('\n'));
    ok_ = ok_ && waitFor([](const auto& r) { return !r.empty(); });
  }
  ~Session() {
    if (!finished()) {
      key("Escape");
      test::waitForFiles(
          cwd_, [&] { return finished(); }, 10s);
    }
  }
  bool ok() const { return ok_; }
  bool finished() const { return fs::exists(rc_); }
  int exitCode() const {
    std::ifstream f(rc_);
    int rc = -1;
    f >> rc;
    return rc;
  }
  void key(const std::string& k) { test::runCommand(env_ + "xdotool key --window " + window_ + " " + k); }
  void resize(int w, int h) {
    test::runCommand(env_ + "xdotool windowsize " + window_ + " " + std::to_string(w) + " " + std::to_string(h));
  }
  // A left-button drag across the window from (x0, y0) to (x1, y1), in steps, each seen by a frame
  // of its own.
  void drag(int x0, int y0, int x1, int y1) {
    const std::string move = env_ + "xdotool mousemove --window " + window_ + " ";
    test::runCommand(move + std::to_string(x0) + " " + std::to_string(y0) + " mousedown 1");
    for (int s = 1; s <= 8; ++s) {
      test::runCommand(move + std::to_string(x0 + (x1 - x0) * s / 8) + " " + std::to_string(y0 + (y1 - y0) * s / 8));
      settle(1);
    }
    test::runCommand(env_ + "xdotool mouseup 1");
  }
  // Waits (up to 60 s: llvmpipe under a sanitizer is slow) until the stats rows so far satisfy
  // `done`, rechecking at each row the window writes (one a frame); false on time-out, or when
  // the program ended without satisfying it.
  bool waitFor(const std::function<bool(const std::vector<std::map<std::string, std::string>>&)>& done) const {
    test::waitForFiles(
        cwd_, [&] { return finished() || done(readStats(stats_)); }, 60s);
    return done(readStats(stats_));
  }
  // The row of the latest frame drawn after `after` more frames than now.
  std::map<std::string, std::string> settle(size_t after = 3) const {
    const size_t n = readStats(stats_).size();
    waitFor([&](const auto& r) { return r.size() >= n + after; });
    const auto rows = readStats(stats_);
    return rows.empty() ? std::map<std::string, std::string>{} : rows.back();
  }
  // P: a screenshot (gimlod-view-NNN.png in the working directory), read back.
  Image screenshot() {
    const fs::path file = cwd_ / fmt(shots_++);
    key("p");
    test::waitForFiles(
        cwd_, [&] { return fs::exists(file); }, 60s);
    return readImage(file);
  }

 private:
  static std::string fmt(int k) {
    char name[32];
    std::snprintf(name, sizeof name, "gimlod-view-%03d.png", k);
    return name;
  }
  std::string env_;
  fs::path cwd_, stats_, rc_;
  std::string window_;
  int shots_ = 0;
  bool ok_ = false;
};

TEST_F(ViewWindow, KeysAndDragsChangeWhatIsDrawn) {
  const fs::path cwd = dir() / "keys";
  fs::create_directories(cwd);
  Session s(env(), quoted(dir() / "bunny.atlas") + " --size 480x360 --hide-ui --tolerance 4" + kBackgroundArg, cwd);
  ASSERT_TRUE(s.ok()) << "the window did not come up";
  auto plainRow = s.settle();
  const Image plain = s.screenshot();
  const Coverage plainCov = coverage(plain, kBackground);
  EXPECT_GT(plainCov.fraction, 0.05);

  // X: wireframe on (the background shows between the edges), and off again.
  s.key("x");
  ASSERT_TRUE(s.waitFor([](const auto& r) { return !r.empty() && r.back().at("wireframe") == "1"; }));
  s.settle();
  const Image wire = s.screenshot();
  const double opened = uncoveredFraction(plain, wire, kBackground);
  std::printf("  wireframe: %.1f%% of the model's pixels show the background\n", 100.0 * opened);
  EXPECT_GT(opened, 0.1);
  s.key("x");
  ASSERT_TRUE(s.waitFor([](const auto& r) { return !r.empty() && r.back().at("wireframe") == "0"; }));
  s.settle();
  EXPECT_LT(differentFraction(s.screenshot(), plain), 0.005);

  // C: chart colouring, then (two more) resolution colouring; both repaint the model.
  s.key("c");
  ASSERT_TRUE(s.waitFor([](const auto& r) { return !r.empty() && r.back().at("overlay") == "chart"; }));
  s.settle();
  const Image charts = s.screenshot();
  EXPECT_GT(differentFraction(charts, plain, 8), 0.5 * plainCov.fraction);
  s.key("c");
  s.key("c");
  ASSERT_TRUE(s.waitFor([](const auto& r) { return !r.empty() && r.back().at("overlay") == "res"; }));
  s.settle();
  const Image res = s.screenshot();
  EXPECT_GT(differentFraction(res, plain, 8), 0.5 * plainCov.fraction);
  EXPECT_GT(differentFraction(res, charts, 8), 0.1 * plainCov.fraction);
  // One more: the screen-space error as a heat map; then back to plain shading.
  s.key("c");
  ASSERT_TRUE(s.waitFor([](const auto& r) { return !r.empty() && r.back().at("overlay") == "error"; }));
  s.settle();
  EXPECT_GT(differentFraction(s.screenshot(), res, 8), 0.1 * plainCov.fraction);
  s.key("c");
  ASSERT_TRUE(s.waitFor([](const auto& r) { return !r.empty() && r.back().at("overlay") == "none"; }));

  // B, N, K: node borders, normals as colours, the stitching's snapped vertices (there are some:
  // the cut mixes levels); each changes the picture, and off again it is the plain one.
  for (const char* k : {"b", "n", "k"}) {
    SCOPED_TRACE(k);
    const std::string column = k[0] == 'b' ? "node_borders" : k[0] == 'n' ? "normals" : "snapped";
    s.key(k);
    ASSERT_TRUE(s.waitFor([&](const auto& r) { return !r.empty() && r.back().at(column) == "1"; }));
    s.settle();
    EXPECT_GT(differentFraction(s.screenshot(), plain, 8), 0.02 * plainCov.fraction);
    s.key(k);
    ASSERT_TRUE(s.waitFor([&](const auto& r) { return !r.empty() && r.back().at(column) == "0"; }));
  }
  s.settle();
  EXPECT_LT(differentFraction(s.screenshot(), plain), 0.005);

  // [ twice: the tolerance halves (4 to 2 px), and more triangles are drawn.
  const uint64_t before = std::stoull(plainRow.at("triangles"));
  s.key("bracketleft");
  s.key("bracketleft");
  ASSERT_TRUE(s.waitFor([](const auto& r) { return !r.empty() && std::stod(r.back().at("tolerance_px")) < 2.01; }));
  const auto fine = s.settle();
  EXPECT_GT(std::stoull(fine.at("triangles")), before);

  // F: the cut freezes; a drag turns the camera (the picture changes) but not the cut.
  s.key("f");
  ASSERT_TRUE(s.waitFor([](const auto& r) { return !r.empty() && r.back().at("frozen") == "1"; }));
  const auto frozen = s.settle();
  const Image beforeDrag = s.screenshot();
  s.drag(240, 180, 330, 200);
  const auto turned = s.settle();
  const Image afterDrag = s.screenshot();
  EXPECT_GT(differentFraction(afterDrag, beforeDrag), 0.05);
  EXPECT_EQ(turned.at("nodes"), frozen.at("nodes"));
  EXPECT_EQ(turned.at("triangles"), frozen.at("triangles"));
  // Unfrozen, the cut follows the new view.
  s.key("f");
  ASSERT_TRUE(s.waitFor([](const auto& r) { return !r.empty() && r.back().at("frozen") == "0"; }));
  s.settle();

  // A larger window: the picture follows its size, and the same tolerance takes more triangles.
  const auto small = s.settle();
  s.resize(720, 540);
  ASSERT_TRUE(s.waitFor([&](const auto& r) {
    return !r.empty() && std::stoull(r.back().at("triangles")) > std::stoull(small.at("triangles"));
  }));
  s.settle();
  const Image large = s.screenshot();
  EXPECT_EQ(large.width, 720);
  EXPECT_EQ(large.height, 540);
  EXPECT_GT(coverage(large, kBackground).fraction, 0.05);

  // T: the frame-time controller takes the budgets (budget mode) and moves them from where they
  // were.
  s.key("t");
  ASSERT_TRUE(s.waitFor([](const auto& r) { return !r.empty() && !r.back().at("target_ms").empty(); }));
  const auto held = s.settle(1);
  EXPECT_EQ(held.at("mode"), "budget");
  EXPECT_TRUE(
      s.waitFor([&](const auto& r) { return !r.empty() && r.back().at("max_triangles") != held.at("max_triangles"); }));

  s.key("Escape");
  ASSERT_TRUE(s.waitFor([&](const auto&) { return s.finished(); }));
  EXPECT_EQ(s.exitCode(), 0);
}

// R, a drag, R: the path recorded in the window replays through `render` to the same cameras (its
// last frame is the window's picture after the drag).
TEST_F(ViewWindow, RecordedPathReplaysThroughRender) {
  const fs::path cwd = dir() / "record";
  fs::create_directories(cwd);
  const fs::path atlas = dir() / "rainier.atlas", path = cwd / "recorded.json";
  {
    Session s(env(), quoted(atlas) + " --size 320x240 --hide-ui --record " + quoted(path) + kBackgroundArg, cwd);
    ASSERT_TRUE(s.ok()) << "the window did not come up";
    s.settle();
    s.key("r");
    s.settle();
    s.drag(160, 120, 230, 150);
    s.settle();
    s.key("r");
    test::waitForFiles(
        cwd, [&] { return fs::exists(path); }, 60s);
    ASSERT_TRUE(fs::exists(path));
    s.settle();
    const Image window = s.screenshot();
    std::string out;
    ASSERT_EQ(test::runCommand(test::appPath().string() + " render '" + atlas.string() + "' --path '" + path.string() +
                                   "' --size 320x240 -o '" + (cwd / "frames").string() + "'" + kBackgroundArg,
                               &out),
              0)
        << out;
    const std::vector<Camera> cams = readCameraPath(path);
    ASSERT_GE(cams.size(), 2u);
    EXPECT_GT(glm::length(cams.front().eye - cams.back().eye), 0.0) << "the drag did not turn the camera";
    char last[32];
    std::snprintf(last, sizeof last, "frame_%04zu.png", cams.size() - 1);
    const double diff = differentFraction(window, readImage(cwd / "frames" / last));
    std::printf("  %zu cameras recorded; the last one through render: %.4f%% of the pixels differ\n", cams.size(),
                100.0 * diff);
    EXPECT_LT(diff, 0.005);
  }
}

}  // namespace
}  // namespace gimlod
