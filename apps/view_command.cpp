#include "apps/view_command.h"

#include <epoxy/gl.h>
// epoxy first: GLFW must not include the system GL header.
#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>
#include <imgui.h>
#include <backends/imgui_impl_glfw.h>
#include <backends/imgui_impl_opengl3.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cfloat>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include "apps/view_args.h"
#include "core/atlas_format.h"
#include "inspect/png.h"
#include "runtime/atlas_view.h"
#include "runtime/camera.h"
#include "runtime/camera_control.h"
#include "runtime/frame_controller.h"
#include "runtime/overlay.h"
#include "runtime/gl/atlas_scene.h"

namespace fs = std::filesystem;

namespace gimlod {
namespace {

using Clock = std::chrono::steady_clock;

double msSince(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

// The last few seconds of one figure, for a live graph: a ring of the latest kLength values.
struct Series {
  static constexpr size_t kLength = 240;
  std::array<float, kLength> values{};
  size_t count = 0, next = 0;  // values held; where the next one goes (the oldest once full)
  void add(double v) {
    values[next] = float(v);
    next = (next + 1) % kLength;
    count = std::min(count + 1, kLength);
  }
  size_t oldest() const { return count < kLength ? 0 : next; }
  float last() const { return count == 0 ? 0.f : values[(next + kLength - 1) % kLength]; }
};

// Everything the panel and the keys change.
struct Controls {
  bool budgetMode = false;
  float tolerance = 1.f;
  int maxNodes = 2048;
  int maxTrianglesK = 1000;  // thousands
  float texelRatio = 1.f;
  float geomorph = 0.f;
  bool asyncLoads = false;
  int uploadsPerFrame = 64;
  bool topDown = false;
  int overlay = 0;  // index into kOverlays
  bool wireframe = false;
  bool freeze = false;
  bool showUi = true;
  bool playing = false;
  bool loop = false;
  bool recording = false;
  bool holdFrameTime = false;                // the frame-time controller sets the budgets (budget mode)
  bool colours = true;                       // vertex colours or terrain imagery, where the atlas has them
  gl::AtlasRenderer::InspectionViews views;  // node borders, normals as colours, snapped vertices
  float targetMs = 33.3f;
};

constexpr std::array<OverlayMode, 5> kOverlays{OverlayMode::kNone, OverlayMode::kChart, OverlayMode::kLevel,
                                               OverlayMode::kResolution, OverlayMode::kError};
constexpr std::array<const char*, 5> kOverlayLabels{"none", "chart", "level", "resolution",
                                                    "error (red: the tolerance)"};

// Window state the GLFW callbacks reach through the user pointer.
struct Viewer {
  CameraControl* camera = nullptr;
  Controls* controls = nullptr;
  bool dragging[3] = {false, false, false};  // left, right, middle
  double lastX = 0.0, lastY = 0.0;
  double scroll = 0.0;
  bool screenshotRequested = false;
  bool recordToggled = false;
  bool resetCamera = false;
  bool cameraModeToggled = false;
  bool cameraTouched = false;  // the user moved the camera this frame
};

Viewer* viewerOf(GLFWwindow* w) { return static_cast<Viewer*>(glfwGetWindowUserPointer(w)); }

bool uiWantsMouse() { return ImGui::GetCurrentContext() && ImGui::GetIO().WantCaptureMouse; }
bool uiWantsKeys() { return ImGui::GetCurrentContext() && ImGui::GetIO().WantCaptureKeyboard; }

// Keys (also for xdotool in the tests): see the help text in the panel.
void onKey(GLFWwindow* w, int key, int, int action, int mods) {
  if (action != GLFW_PRESS && action != GLFW_REPEAT) return;
  if (uiWantsKeys()) return;
  Viewer& v = *viewerOf(w);
  Controls& c = *v.controls;
  const bool press = action == GLFW_PRESS;
  switch (key) {
    case GLFW_KEY_ESCAPE: glfwSetWindowShouldClose(w, GLFW_TRUE); break;
    case GLFW_KEY_X:
      if (press) c.wireframe = !c.wireframe;
      break;
    case GLFW_KEY_C:
      if (press)
        c.overlay = (c.overlay + ((mods & GLFW_MOD_SHIFT) ? int(kOverlays.size()) - 1 : 1)) % int(kOverlays.size());
      break;
    case GLFW_KEY_F:
      if (press) c.freeze = !c.freeze;
      break;
    case GLFW_KEY_M:
      if (press) c.budgetMode = !c.budgetMode;
      break;
    case GLFW_KEY_T:
      if (press) c.holdFrameTime = !c.holdFrameTime;
      break;
    case GLFW_KEY_B:
      if (press) c.views.nodeBorders = !c.views.nodeBorders;
      break;
    case GLFW_KEY_N:
      if (press) c.views.normals = !c.views.normals;
      break;
    case GLFW_KEY_K:
      if (press) c.views.snapped = !c.views.snapped;
      break;
    case GLFW_KEY_L:
      if (press) c.views.loading = !c.views.loading;
      break;
    case GLFW_KEY_G:
      if (press) c.topDown = !c.topDown;
      break;
    case GLFW_KEY_H:
      if (press) c.showUi = !c.showUi;
      break;
    case GLFW_KEY_P:
      if (press) v.screenshotRequested = true;
      break;
    case GLFW_KEY_R:
      if (press) v.recordToggled = true;
      break;
    case GLFW_KEY_SPACE:
      if (press) c.playing = !c.playing;
      break;
    case GLFW_KEY_HOME:
      if (press) v.resetCamera = true;
      break;
    case GLFW_KEY_TAB:
      if (press) v.cameraModeToggled = true;
      break;
    case GLFW_KEY_LEFT_BRACKET:  // finer: lower tolerance, or more triangles
      if (c.budgetMode)
        c.maxTrianglesK = std::min(c.maxTrianglesK * 2, 1 << 20);
      else
        c.tolerance = std::max(c.tolerance / std::sqrt(2.f), 0.01f);
      break;
    case GLFW_KEY_RIGHT_BRACKET:  // coarser
      if (c.budgetMode)
        c.maxTrianglesK = std::max(c.maxTrianglesK / 2, 1);
      else
        c.tolerance = std::min(c.tolerance * std::sqrt(2.f), 1000.f);
      break;
    case GLFW_KEY_EQUAL: c.maxNodes = std::min(c.maxNodes * 2, 1 << 20); break;
    case GLFW_KEY_MINUS: c.maxNodes = std::max(c.maxNodes / 2, 1); break;
    default: break;
  }
}

void onMouseButton(GLFWwindow* w, int button, int action, int) {
  Viewer& v = *viewerOf(w);
  if (button < 0 || button > 2) return;
  if (action == GLFW_PRESS && uiWantsMouse()) return;
  v.dragging[button] = action == GLFW_PRESS;
  glfwGetCursorPos(w, &v.lastX, &v.lastY);
}

void onCursor(GLFWwindow* w, double x, double y) {
  Viewer& v = *viewerOf(w);
  const double dx = x - v.lastX, dy = y - v.lastY;
  v.lastX = x;
  v.lastY = y;
  int width = 0, height = 0;
  glfwGetFramebufferSize(w, &width, &height);
  if (v.dragging[0]) v.camera->rotate(dx, dy, height);
  if (v.dragging[1] || v.dragging[2]) v.camera->pan(dx, dy, height);
  if (v.dragging[0] || v.dragging[1] || v.dragging[2]) v.cameraTouched = true;
}

void onScroll(GLFWwindow* w, double, double dy) {
  if (uiWantsMouse()) return;
  viewerOf(w)->scroll += dy;
}

void plot(const char* label, const Series& s, const char* unit) {
  const std::string overlay = fmt::format("{:.3g} {}", s.last(), unit);
  ImGui::PlotLines(label, s.values.data(), int(s.count), int(s.oldest()), overlay.c_str(), 0.f, FLT_MAX, ImVec2(0, 28));
}

struct FrameFigures {
  size_t nodes = 0;
  uint64_t triangles = 0;
  double maxErrorPx = 0.0, adaptMs = 0.0, drawMs = 0.0, gpuMs = 0.0, frameMs = 0.0, uploadMs = 0.0;
  uint32_t pagesLoaded = 0, pagesRequested = 0, rootFloor = 0;
  uint32_t closedGroups = 0, groupedRoots = 0;  // groups above the charts kept closed, their roots
  uint32_t standIns = 0;                        // desired nodes drawn as a resident ancestor (pages still loading)
  bool belowRoots = false;
  // Streaming: the caches' bytes after the frame, its uploads, and the pages it needed and found.
  uint64_t residentGpuBytes = 0, gpuBudgetBytes = 0, residentRamBytes = 0, uploadBytes = 0;
  uint32_t pagesNeeded = 0, pagesResident = 0, loadsIssued = 0, loadsDone = 0, loadsCancelled = 0, loadsFailed = 0;
  uint32_t prefetchRequests = 0;
  bool incomplete = false;
};

const char* kHelp =
    "mouse: left drag rotate (fly: look), right/middle drag pan, wheel zoom (fly: speed)\n"
    "Tab orbit/fly   WASD move, Q/E down/up   Home reset camera\n"
    "[ ] finer/coarser (tolerance or triangles)   - = node budget\n"
    "M error/budget mode   T hold the frame time   G top-down greedy   F freeze cut\n"
    "C colouring (chart, level, resolution, error)   X wireframe   H hide panel\n"
    "B node borders   N normals as colours   K snapped border vertices   L pages loading\n"
    "Space play/pause path   R record path   P screenshot   Esc quit";

}  // namespace

CLI::App* addViewCommand(CLI::App& app, ViewArgs& a) {
  auto* v = app.add_subcommand("view", "Fly through an atlas in a window (GLFW), with live budgets and overlays");
  v->add_option("atlas", a.atlas, "Atlas directory")->required();
  v->add_option("--size", a.size, "Window size WxH")->capture_default_str();
  v->add_option("--background", a.background, "Background colour R,G,B")->capture_default_str();
  v->add_option("--up", a.up, "Up axis: auto (z for terrain, y for meshes), x, y, z, -x, -y or -z")
      ->capture_default_str();
  v->add_option("--fov", a.fov, "Vertical field of view, degrees")->capture_default_str();
  v->add_option("--path", a.path, "Camera path JSON to play (as render and bench read)");
  v->add_flag("--loop", a.loop, "Play the path again and again");
  v->add_option("--record", a.record, "Where R writes the recorded camera path (JSON)");
  v->add_option("--screenshot", a.screenshot,
                "PNG of the last frame when the run ends (scripted runs); P writes there too");
  v->add_option("--stats", a.stats, "CSV with one row per frame (nodes, triangles, error, times)");
  v->add_option("--frames", a.frames, "Draw this many frames along --path (holding its last camera), then exit");
  v->add_option("--exit-after", a.exitAfter, "Exit after this many frames");
  v->add_flag("--hide-ui", a.hideUi, "Start without the panel (and keep it out of screenshots)");
  v->add_option("--tolerance", a.tolerance, "Screen-space error threshold in pixels")->capture_default_str();
  v->add_option("--triangles", a.triangles, "Triangle budget: start in budget mode (quad queue)");
  v->add_option("--max-nodes", a.maxNodes, "Node budget")->capture_default_str();
  addMaxRootsOption(v, a.maxRoots);
  addGeomorphOption(v, a.geomorph);
  addMsaaOption(v, a.msaa);
  v->add_option("--texel-ratio", a.texelRatio, "Normal-map texels per pixel (0: page resolution)")
      ->capture_default_str();
  addStreamingOptions(v, a.streaming);
  v->add_flag("--top-down", a.topDown, "Error mode: the stateless top-down greedy instead of the dual queue");
  v->add_option("--overlay", a.overlay, "Colouring: none, chart, level, res or error")->capture_default_str();
  v->add_flag("--wireframe", a.wireframe, "Start in wireframe");
  v->add_option("--frame-ms", a.frameMs,
                "Hold this frame time: the node and triangle budgets follow the measured costs (budget mode)");
  return v;
}

namespace {

// The panel's live graphs: the last few seconds of each figure.
struct Graphs {
  Series adaptMs, drawMs, gpuMs, frameMs, nodes, triangles, maxError, pagesLoaded;
  Series gpuMiB, ramMiB, uploadMiB, hitRate;  // streaming
  // Every graph but frameMs (measured after the panel is drawn).
  void add(const FrameFigures& f) {
    adaptMs.add(f.adaptMs);
    drawMs.add(f.drawMs);
    gpuMs.add(f.gpuMs);
    nodes.add(double(f.nodes));
    triangles.add(double(f.triangles));
    maxError.add(f.maxErrorPx);
    pagesLoaded.add(f.pagesLoaded);
    gpuMiB.add(double(f.residentGpuBytes) / (1 << 20));
    ramMiB.add(double(f.residentRamBytes) / (1 << 20));
    uploadMiB.add(double(f.uploadBytes) / (1 << 20));
    hitRate.add(f.pagesNeeded > 0 ? 100.0 * f.pagesResident / f.pagesNeeded : 100.0);
  }
};

// A frame's figures as the panel and the stats file show them; `drawn` is the cut on screen.
FrameFigures figuresOf(const gl::FrameResult& f, const Cut& drawn) {
  FrameFigures last;
  last.nodes = drawn.nodeCount();
  last.triangles = f.draw.triangles;
  last.maxErrorPx = f.maxErrorPx;
  last.adaptMs = f.adaptMs;
  last.drawMs = f.draw.drawMs;
  last.gpuMs = f.draw.gpuMs;
  last.uploadMs = f.uploadMs;
  last.pagesLoaded = f.pagesLoaded + f.pagesUploaded;
  last.pagesRequested = f.pagesRequested;
  last.standIns = f.nodesSubstituted;
  last.rootFloor = f.adapt.rootFloor;
  last.belowRoots = f.adapt.budgetBelowRoots;
  last.closedGroups = f.adapt.closedGroups;
  last.groupedRoots = f.adapt.groupedRoots;
  last.residentGpuBytes = f.residentGpuBytes;
  last.gpuBudgetBytes = f.gpuBudgetBytes;
  last.residentRamBytes = f.residentRamBytes;
  last.uploadBytes = f.uploadBytes;
  last.pagesNeeded = f.pagesNeeded;
  last.pagesResident = f.pagesResident;
  last.loadsIssued = f.loadsIssued;
  last.loadsDone = f.loadsDone;
  last.loadsCancelled = f.loadsCancelled;
  last.loadsFailed = f.loadsFailed;
  last.prefetchRequests = f.prefetchRequests;
  last.incomplete = f.incomplete;
  return last;
}

constexpr const char* kStatsHeader =
    "frame,nodes,triangles,max_screen_error_px,adapt_ms,draw_ms,frame_ms,pages_loaded,pages_requested,"
    "root_floor,budget_below_roots,mode,tolerance_px,max_nodes,max_triangles,frozen,overlay,wireframe,"
    "target_ms,node_borders,normals,snapped,pages_loading_view,nodes_waiting,gpu_ms,resident_gpu_bytes,"
    "gpu_budget_bytes,resident_ram_bytes,ram_budget_bytes,upload_bytes,loads_issued,loads_done,"
    "loads_cancelled,loads_failed,prefetch_requests,pages_needed,pages_resident,incomplete\n";

// The options checked before a window opens.
struct ViewSetup {
  uint32_t width = 0, height = 0;
  gl::SceneOptions streaming;  // the streaming options
  OverlayMode overlay = OverlayMode::kNone;
  std::array<float, 3> background{};
};

ViewSetup checkViewArgs(const ViewArgs& a) {
  ViewSetup v;
  parseFrameSize(a.size, &v.width, &v.height);
  validateViewOptions(a.tolerance, a.texelRatio, a.streaming.uploadsPerFrame, a.triangles > 0, a.topDown, a.frameMs);
  validateGeomorph(a.geomorph);
  applyStreamingArgs(a.streaming, v.streaming);
  if (!(a.fov > 1.0 && a.fov < 179.0)) throw InputError("--fov must be in (1, 179) degrees");
  if (a.frames > 0 && a.path.empty()) throw InputError("--frames needs --path");
  v.overlay = parseOverlayOption(a.overlay);
  v.background = parseBackground(a.background);
  return v;
}

// The camera's up axis: --up, or z for terrains and y for meshes.
UpAxis viewUpAxis(const ViewArgs& a, const AtlasView& atlas) {
  UpAxis up{atlas.manifest.kind == AtlasKind::Heightfield ? 2 : 1, 1.0};
  if (a.up != "auto") {
    const std::optional<UpAxis> u = parseUpAxis(a.up);
    if (!u) throw InputError("--up '" + a.up + "': expected auto, x, y, z, -x, -y or -z");
    up = *u;
  }
  return up;
}

// The panel and keys' starting values, from the command line.
Controls initialControls(const ViewArgs& a, const ViewSetup& v, bool hasPath) {
  Controls c;
  c.budgetMode = a.triangles > 0;
  c.tolerance = float(a.tolerance);
  c.maxNodes = int(std::min<uint32_t>(a.maxNodes, 1u << 20));
  c.maxTrianglesK = int(std::clamp<uint64_t>(a.triangles > 0 ? a.triangles / 1000 : 1000, 1, 1 << 20));
  c.texelRatio = float(a.texelRatio);
  c.geomorph = float(a.geomorph);
  c.asyncLoads = v.streaming.asyncLoads;
  c.uploadsPerFrame = int(a.streaming.uploadsPerFrame);
  c.topDown = a.topDown;
  c.overlay = int(std::find(kOverlays.begin(), kOverlays.end(), v.overlay) - kOverlays.begin());
  c.wireframe = a.wireframe;
  c.showUi = !a.hideUi;
  c.playing = hasPath;
  c.loop = a.loop;
  c.holdFrameTime = a.frameMs > 0.0;
  if (c.holdFrameTime) c.targetMs = float(a.frameMs);
  return c;
}

// Initializes GLFW and opens the window with an OpenGL 4.3 core context made current. The caller
// terminates GLFW.
GLFWwindow* openViewWindow(const ViewArgs& a, uint32_t width, uint32_t height) {
  glfwSetErrorCallback([](int code, const char* what) { spdlog::error("GLFW error {}: {}", code, what); });
  if (!glfwInit())
    throw std::runtime_error("gimlod view: cannot initialize GLFW (no display? set DISPLAY, or use xvfb-run)");
  glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 4);
  glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 3);
  glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
  glfwWindowHint(GLFW_OPENGL_FORWARD_COMPAT, GLFW_TRUE);
  glfwWindowHint(GLFW_SAMPLES, 0);
  const std::string title = fmt::format("gimlod view: {}", fs::path(a.atlas).filename().string());
  GLFWwindow* window = glfwCreateWindow(int(width), int(height), title.c_str(), nullptr, nullptr);
  if (!window) {
    glfwTerminate();
    throw std::runtime_error("gimlod view: cannot open an OpenGL 4.3 core window");
  }
  glfwMakeContextCurrent(window);
  glfwSwapInterval(a.frames > 0 ? 0 : 1);
  spdlog::info("OpenGL: {} ({})", reinterpret_cast<const char*>(glGetString(GL_RENDERER)),
               reinterpret_cast<const char*>(glGetString(GL_VERSION)));
  return window;
}

// A window onto an atlas, from its first frame to its last: the state runView keeps between
// frames, and each step of a frame.
class ViewSession {
 public:
  ViewSession(const ViewArgs& a, const ViewSetup& setup, const AtlasView& atlas, std::vector<Camera> path,
              GLFWwindow* window)
      : a_(a),
        setup_(setup),
        atlas_(atlas),
        path_(std::move(path)),
        window_(window),
        c_(initialControls(a, setup, !path_.empty())),
        camera_(atlas.lo, atlas.hi, viewUpAxis(a, atlas), a.fov) {
    camera_.setRadialUp(atlas.manifest.planet.present);
    if (!path_.empty()) camera_.setCamera(path_.front());
    glfwGetFramebufferSize(window_, &fbw_, &fbh_);
    scene_ = makeScene(c_.asyncLoads);
    sceneAsync_ = c_.asyncLoads;
    viewer_.camera = &camera_;
    viewer_.controls = &c_;
    glfwSetWindowUserPointer(window_, &viewer_);
    // Ours first: the ImGui backend chains to the callbacks installed before it.
    glfwSetKeyCallback(window_, onKey);
    glfwSetMouseButtonCallback(window_, onMouseButton);
    glfwSetCursorPosCallback(window_, onCursor);
    glfwSetScrollCallback(window_, onScroll);
    if (!a.stats.empty()) {
      stats_.open(a.stats);
      if (!stats_) throw InputError(a.stats + ": cannot write the stats file");
      stats_ << kStatsHeader;
    }
  }

  // Runs frames until the window closes, the scripted frames are drawn or --exit-after.
  void run();

 private:
  // The scene is made again when async loading is switched (its page loader lives with it).
  std::unique_ptr<gl::AtlasScene> makeScene(bool async) const;
  // The panel's and keys' settings, applied to the scene (made again when async loading switched).
  void applyControls();
  // The camera of this frame: the path while it plays, else the user's input.
  Camera steerCamera(double seconds);
  // R starts and stops recording the cameras; stopping writes them to --record.
  void record(const Camera& cam);
  // The frame-time controller sets the budgets (budget mode) while it holds the frame time.
  void holdFrameTime();
  // Adapts (unless frozen) and draws into the scene's framebuffer, then into the window. The cut
  // drawn is kept (moved, not copied) for a freeze.
  void drawFrame(const Camera& cam);
  void drawPanel();
  void writeStatsRow(uint64_t frame);
  void writeShot(const fs::path& file) const;

  const ViewArgs& a_;
  const ViewSetup& setup_;
  const AtlasView& atlas_;
  const std::vector<Camera> path_;
  GLFWwindow* window_;
  Controls c_;
  CameraControl camera_;
  Viewer viewer_;
  int fbw_ = 0, fbh_ = 0;
  std::unique_ptr<gl::AtlasScene> scene_;
  bool sceneAsync_ = false;
  std::optional<FrameController> controller_;
  glm::dvec3 surfaceEye_{std::numeric_limits<double>::quiet_NaN()};  // where the surface distance was measured
  Graphs graphs_;
  std::vector<Camera> recorded_;
  Cut lastCut_;  // the cut drawn last: what a freeze keeps drawing
  bool haveCut_ = false;
  size_t pathFrame_ = 0;
  std::optional<Camera> pathCamera_;  // the path's camera shown, held until the user moves on
  uint32_t screenshots_ = 0;
  bool warnedBelowRoots_ = false;
  FrameFigures last_;
  std::ofstream stats_;
};

std::unique_ptr<gl::AtlasScene> ViewSession::makeScene(bool async) const {
  gl::SceneOptions so = setup_.streaming;
  so.width = uint32_t(std::max(fbw_, 8));
  so.height = uint32_t(std::max(fbh_, 8));
  so.background = setup_.background;
  so.asyncLoads = async;
  so.maxUploadsPerFrame = uint32_t(c_.uploadsPerFrame);
  so.coherentAdaptation = !c_.topDown;
  so.texelsPerPixel = c_.texelRatio;
  so.samples = a_.msaa;
  so.minNodeRoom = uint32_t(c_.maxNodes);  // the page pool holds cuts of the budget at start
  return std::make_unique<gl::AtlasScene>(atlas_, so);
}

void ViewSession::applyControls() {
  if (uint32_t(fbw_) != scene_->width() || uint32_t(fbh_) != scene_->height())
    scene_->resize(uint32_t(fbw_), uint32_t(fbh_));
  if (c_.asyncLoads != sceneAsync_) {
    scene_ = makeScene(c_.asyncLoads);
    sceneAsync_ = c_.asyncLoads;
    haveCut_ = false;
  }
  scene_->setCoherentAdaptation(!c_.topDown);
  scene_->setTexelsPerPixel(c_.texelRatio);
  scene_->setGeomorph(c_.geomorph);
  scene_->setMaxUploadsPerFrame(uint32_t(std::max(c_.uploadsPerFrame, 1)));
  // The error colouring is against the tolerance (error mode) or the frame's largest error.
  scene_->setOverlay(kOverlays[size_t(c_.overlay)], {}, c_.budgetMode ? 0.0 : double(c_.tolerance));
  scene_->renderer().setWireframe(c_.wireframe);
  scene_->renderer().setColours(c_.colours);
  scene_->renderer().setInspectionViews(c_.views);
}

Camera ViewSession::steerCamera(double seconds) {
  if (viewer_.resetCamera) camera_.frame(), viewer_.resetCamera = false, pathCamera_.reset();
  if (viewer_.cameraModeToggled) {
    pathCamera_.reset();
    camera_.setMode(camera_.mode() == CameraControl::Mode::kOrbit ? CameraControl::Mode::kFly
                                                                  : CameraControl::Mode::kOrbit);
    viewer_.cameraModeToggled = false;
  }
  // A path's cameras are drawn as they are (render draws the same pictures), the last one held
  // once the path ends, until the user moves the camera on from it.
  if (c_.playing && !path_.empty()) {
    if (pathFrame_ >= path_.size()) {
      if (c_.loop)
        pathFrame_ = 0;
      else
        c_.playing = false;
    }
    pathCamera_ = path_[std::min(pathFrame_, path_.size() - 1)];
    camera_.setCamera(*pathCamera_);
    if (c_.playing) ++pathFrame_;
  } else if (!uiWantsKeys()) {
    glm::dvec3 move(0.0);
    if (glfwGetKey(window_, GLFW_KEY_D) == GLFW_PRESS) move.x += 1.0;
    if (glfwGetKey(window_, GLFW_KEY_A) == GLFW_PRESS) move.x -= 1.0;
    if (glfwGetKey(window_, GLFW_KEY_E) == GLFW_PRESS) move.y += 1.0;
    if (glfwGetKey(window_, GLFW_KEY_Q) == GLFW_PRESS) move.y -= 1.0;
    if (glfwGetKey(window_, GLFW_KEY_W) == GLFW_PRESS) move.z += 1.0;
    if (glfwGetKey(window_, GLFW_KEY_S) == GLFW_PRESS) move.z -= 1.0;
    if (camera_.eye() != surfaceEye_) {  // measured again only when the eye has moved
      surfaceEye_ = camera_.eye();
      camera_.setSurfaceDistance(distanceToSurface(atlas_.hierarchy, surfaceEye_));
    }
    if (move != glm::dvec3(0.0)) camera_.move(move, seconds), viewer_.cameraTouched = true;
  }
  if (viewer_.scroll != 0.0) camera_.zoom(viewer_.scroll), viewer_.scroll = 0.0, viewer_.cameraTouched = true;
  if (viewer_.cameraTouched) pathCamera_.reset(), viewer_.cameraTouched = false;
  return pathCamera_ ? *pathCamera_ : camera_.camera();
}

void ViewSession::record(const Camera& cam) {
  if (viewer_.recordToggled) {
    viewer_.recordToggled = false;
    if (c_.recording) {
      c_.recording = false;
      if (a_.record.empty()) {
        spdlog::warn("recorded {} cameras; give --record FILE.json to keep them", recorded_.size());
      } else if (!recorded_.empty()) {
        writeCameraPath(a_.record, recorded_);
        spdlog::info("wrote {} cameras to {}", recorded_.size(), a_.record);
      }
    } else {
      c_.recording = true;
      recorded_.clear();
    }
  }
  if (c_.recording) recorded_.push_back(cam);
}

void ViewSession::holdFrameTime() {
  if (!c_.holdFrameTime) {
    controller_.reset();
    return;
  }
  c_.budgetMode = true;
  if (!controller_) {
    FrameControllerOptions fo;
    fo.targetMs = c_.targetMs;
    controller_.emplace(fo, uint32_t(c_.maxNodes), uint64_t(c_.maxTrianglesK) * 1000);
  }
  controller_->setTarget(std::max(c_.targetMs, 1.f));
  c_.maxNodes = int(std::min<uint32_t>(controller_->maxNodes(), 1u << 20));
  c_.maxTrianglesK = int(std::clamp<uint64_t>(controller_->maxTriangles() / 1000, 1, 1 << 20));
}

void ViewSession::drawFrame(const Camera& cam) {
  gl::FrameResult f;
  const bool drawFrozen = c_.freeze && haveCut_;
  if (drawFrozen) {
    f.draw = scene_->drawCut(cam, lastCut_, &f);
  } else if (c_.budgetMode) {
    BudgetOptions bo;
    bo.maxTriangles = uint64_t(c_.maxTrianglesK) * 1000;
    bo.maxNodes = uint32_t(c_.maxNodes);
    f = scene_->renderFrame(cam, bo);
  } else {
    AdaptOptions ao;
    ao.tolerancePx = c_.tolerance;
    ao.maxNodes = uint32_t(c_.maxNodes);
    f = scene_->renderFrame(cam, ao);
  }
  if (f.adapt.budgetBelowRoots && !warnedBelowRoots_) {
    spdlog::warn("node budget {} is below the {} visible {}: such frames draw the visible roots", c_.maxNodes,
                 f.adapt.rootFloor, atlas_.hierarchy.groups.empty() ? "chart roots" : "top groups");
    warnedBelowRoots_ = true;
  }
  scene_->renderer().blitToDefaultFramebuffer();
  glViewport(0, 0, fbw_, fbh_);
  if (!drawFrozen) {
    lastCut_ = std::move(f.cut);
    haveCut_ = true;
  }
  last_ = figuresOf(f, lastCut_);
  graphs_.add(last_);
}

void ViewSession::drawPanel() {
  ImGui_ImplOpenGL3_NewFrame();
  ImGui_ImplGlfw_NewFrame();
  ImGui::NewFrame();
  if (c_.showUi) {
    ImGui::SetNextWindowPos(ImVec2(8, 8), ImGuiCond_FirstUseEver);
    ImGui::SetNextWindowSize(ImVec2(330, 0), ImGuiCond_FirstUseEver);
    ImGui::SetNextWindowBgAlpha(0.7f);
    ImGui::Begin("gimlod", nullptr, ImGuiWindowFlags_AlwaysAutoResize);
    ImGui::Text("%s atlas, %u charts", atlas_.manifest.kind == AtlasKind::Heightfield ? "terrain" : "mesh",
                atlas_.hierarchy.chartCount());
    int mode = c_.budgetMode ? 1 : 0;
    ImGui::RadioButton("error threshold", &mode, 0);
    ImGui::SameLine();
    ImGui::RadioButton("triangle budget", &mode, 1);
    c_.budgetMode = mode == 1;
    if (c_.budgetMode) {
      ImGui::SliderInt("triangles (k)", &c_.maxTrianglesK, 1, 20000, "%d", ImGuiSliderFlags_Logarithmic);
    } else {
      ImGui::SliderFloat("tolerance (px)", &c_.tolerance, 0.05f, 64.f, "%.2f", ImGuiSliderFlags_Logarithmic);
      ImGui::Checkbox("top-down greedy", &c_.topDown);
    }
    ImGui::SliderInt("max nodes", &c_.maxNodes, 1, 65536, "%d", ImGuiSliderFlags_Logarithmic);
    if (uint32_t(c_.maxNodes) > scene_->nodeRoom())
      ImGui::TextColored(ImVec4(1.f, 0.7f, 0.3f, 1.f), "at most %u nodes: the GPU page pool holds %u pages",
                         scene_->nodeRoom(), scene_->renderer().pageCapacity());
    ImGui::Checkbox("hold frame time", &c_.holdFrameTime);
    if (c_.holdFrameTime) {
      ImGui::SameLine();
      ImGui::SetNextItemWidth(120);
      ImGui::SliderFloat("ms", &c_.targetMs, 2.f, 200.f, "%.1f", ImGuiSliderFlags_Logarithmic);
    }
    ImGui::SliderFloat("texel ratio", &c_.texelRatio, 0.f, 8.f, "%.2f");
    ImGui::SliderFloat("geomorph range", &c_.geomorph, 0.f, 2.f, "%.2f");
    ImGui::Checkbox("async loads", &c_.asyncLoads);
    if (c_.asyncLoads) ImGui::SliderInt("uploads / frame", &c_.uploadsPerFrame, 1, 512);
    ImGui::Combo("colouring", &c_.overlay, kOverlayLabels.data(), int(kOverlayLabels.size()));
    if (scene_->hasColours()) ImGui::Checkbox("colours (vertex colours or imagery)", &c_.colours);
    ImGui::Checkbox("node borders", &c_.views.nodeBorders);
    ImGui::SameLine();
    ImGui::Checkbox("normals", &c_.views.normals);
    ImGui::SameLine();
    ImGui::Checkbox("snapped", &c_.views.snapped);
    ImGui::SameLine();
    ImGui::Checkbox("pages loading", &c_.views.loading);
    ImGui::Checkbox("wireframe", &c_.wireframe);
    ImGui::SameLine();
    ImGui::Checkbox("freeze cut", &c_.freeze);
    ImGui::Text("camera: %s%s%s", camera_.mode() == CameraControl::Mode::kOrbit ? "orbit" : "fly",
                c_.playing ? ", playing the path" : "", c_.recording ? ", recording" : "");
    ImGui::Separator();
    ImGui::Text("nodes %zu (root floor %u%s)  triangles %llu", last_.nodes, last_.rootFloor,
                last_.belowRoots ? ", above the budget" : "", static_cast<unsigned long long>(last_.triangles));
    if (last_.closedGroups > 0)
      ImGui::Text("%u closed groups drawing %u chart roots", last_.closedGroups, last_.groupedRoots);
    ImGui::Text("max error %.3f px  frame %.2f ms", last_.maxErrorPx, graphs_.frameMs.last());
    if (c_.asyncLoads)
      ImGui::Text("pages: %u requested, %u nodes waiting for theirs", last_.pagesRequested, last_.standIns);
    ImGui::Text("GPU pool %.1f of %.1f MiB", double(last_.residentGpuBytes) / (1 << 20),
                double(last_.gpuBudgetBytes) / (1 << 20));
    if (c_.asyncLoads)
      ImGui::Text("RAM %.1f of %.1f MiB  uploads %.2f of %.2f MiB  hit %.0f%%",
                  double(last_.residentRamBytes) / (1 << 20), double(setup_.streaming.ramCacheBytes) / (1 << 20),
                  double(last_.uploadBytes) / (1 << 20), double(setup_.streaming.uploadBytesPerFrame) / (1 << 20),
                  last_.pagesNeeded > 0 ? 100.0 * last_.pagesResident / last_.pagesNeeded : 100.0);
    if (ImGui::CollapsingHeader("graphs", fbh_ >= 700 ? ImGuiTreeNodeFlags_DefaultOpen : 0)) {
      plot("adapt ms", graphs_.adaptMs, "ms");
      plot("draw ms", graphs_.drawMs, "ms");
      plot("GPU ms (timer)", graphs_.gpuMs, "ms");
      plot("frame ms", graphs_.frameMs, "ms");
      plot("nodes", graphs_.nodes, "");
      plot("triangles", graphs_.triangles, "");
      plot("max error", graphs_.maxError, "px");
      plot("pages loaded", graphs_.pagesLoaded, "");
      plot("GPU pool", graphs_.gpuMiB, "MiB");
      if (c_.asyncLoads) {
        plot("loader RAM", graphs_.ramMiB, "MiB");
        plot("uploads", graphs_.uploadMiB, "MiB");
        plot("hit rate", graphs_.hitRate, "%");
      }
    }
    if (ImGui::CollapsingHeader("keys")) ImGui::TextUnformatted(kHelp);
    ImGui::End();
  }
  ImGui::Render();
  ImGui_ImplOpenGL3_RenderDrawData(ImGui::GetDrawData());
}

void ViewSession::writeStatsRow(uint64_t frame) {
  if (!stats_.is_open()) return;
  stats_ << fmt::format(
                "{},{},{},{:.4f},{:.4f},{:.4f},{:.4f},{},{},{},{},{},{:.4f},{},{},{},{},{},{},{},{},{},{},{},{:.4f}",
                frame, last_.nodes, last_.triangles, last_.maxErrorPx, last_.adaptMs, last_.drawMs, last_.frameMs,
                last_.pagesLoaded, last_.pagesRequested, last_.rootFloor, int(last_.belowRoots),
                c_.budgetMode ? "budget" : "error", c_.tolerance, c_.maxNodes, uint64_t(c_.maxTrianglesK) * 1000,
                int(c_.freeze), overlayModeName(kOverlays[size_t(c_.overlay)]), int(c_.wireframe),
                c_.holdFrameTime ? fmt::format("{:.2f}", c_.targetMs) : std::string(), int(c_.views.nodeBorders),
                int(c_.views.normals), int(c_.views.snapped), int(c_.views.loading), last_.standIns, last_.gpuMs)
         << fmt::format(",{},{},{},{},{},{},{},{},{},{},{},{},{}\n", last_.residentGpuBytes, last_.gpuBudgetBytes,
                        last_.residentRamBytes, c_.asyncLoads ? setup_.streaming.ramCacheBytes : 0, last_.uploadBytes,
                        last_.loadsIssued, last_.loadsDone, last_.loadsCancelled, last_.loadsFailed,
                        last_.prefetchRequests, last_.pagesNeeded, last_.pagesResident, int(last_.incomplete))
         << std::flush;
}

void ViewSession::writeShot(const fs::path& file) const {
  writePng(file, uint32_t(fbw_), uint32_t(fbh_), 4, gl::readWindowPixels(uint32_t(fbw_), uint32_t(fbh_)));
  spdlog::info("wrote {}", file.string());
}

void ViewSession::run() {
  const bool scripted = a_.frames > 0;
  const uint32_t lastFrame = scripted ? a_.frames : a_.exitAfter;
  auto previous = Clock::now();
  for (uint64_t frame = 0; !glfwWindowShouldClose(window_); ++frame) {
    const auto t0 = Clock::now();
    const double seconds = std::min(std::chrono::duration<double>(t0 - previous).count(), 0.25);
    previous = t0;
    glfwPollEvents();
    glfwGetFramebufferSize(window_, &fbw_, &fbh_);
    if (fbw_ < 8 || fbh_ < 8) {  // minimized
      glfwWaitEventsTimeout(0.1);
      continue;
    }
    applyControls();
    const Camera cam = steerCamera(seconds);
    record(cam);
    holdFrameTime();
    drawFrame(cam);
    drawPanel();
    last_.frameMs = msSince(t0);
    graphs_.frameMs.add(last_.frameMs);
    // Page reads and uploads are the loader's to bound (uploads per frame), not the budgets'.
    if (controller_ && !c_.freeze)
      controller_->update({uint32_t(last_.nodes), last_.triangles, last_.adaptMs, last_.drawMs,
                           std::max(last_.frameMs - last_.uploadMs, 0.0)});
    writeStatsRow(frame);
    const bool lastOne = lastFrame > 0 && frame + 1 >= lastFrame;
    if (viewer_.screenshotRequested) {
      viewer_.screenshotRequested = false;
      writeShot(a_.screenshot.empty() ? fs::path(fmt::format("gimlod-view-{:03d}.png", screenshots_++))
                                      : fs::path(a_.screenshot));
    } else if (lastOne && scripted && !a_.screenshot.empty()) {
      writeShot(a_.screenshot);
    }
    glfwSwapBuffers(window_);
    if (lastOne) break;
  }
  if (c_.recording && !a_.record.empty() && !recorded_.empty()) {
    writeCameraPath(a_.record, recorded_);
    spdlog::info("wrote {} cameras to {}", recorded_.size(), a_.record);
  }
}

// Dear ImGui on the window; shut down when it goes.
struct ImGuiPanel {
  explicit ImGuiPanel(GLFWwindow* window) {
    IMGUI_CHECKVERSION();
    ImGui::CreateContext();
    ImGui::GetIO().IniFilename = nullptr;  // no imgui.ini next to the user's files
    ImGui::StyleColorsDark();
    if (!ImGui_ImplGlfw_InitForOpenGL(window, true) || !ImGui_ImplOpenGL3_Init("#version 430 core")) {
      ImGui::DestroyContext();
      throw std::runtime_error("gimlod view: cannot set up the panel (Dear ImGui)");
    }
  }
  ~ImGuiPanel() {
    ImGui_ImplOpenGL3_Shutdown();
    ImGui_ImplGlfw_Shutdown();
    ImGui::DestroyContext();
  }
};

}  // namespace

int runView(const ViewArgs& a) {
  const ViewSetup setup = checkViewArgs(a);
  const AtlasView atlas = openAtlas(a.atlas, a.maxRoots);
  viewUpAxis(a, atlas);  // a bad --up is refused before a window opens
  std::vector<Camera> path;
  if (!a.path.empty()) {
    path = readCameraPath(a.path);
    for (Camera& c : path) fitClipPlanes(c, atlas.lo, atlas.hi);
  }
  if (!a.stats.empty() && !std::ofstream(a.stats)) throw InputError(a.stats + ": cannot write the stats file");
  GLFWwindow* window = openViewWindow(a, setup.width, setup.height);
  struct GlfwGuard {
    GLFWwindow* w;
    ~GlfwGuard() {
      glfwDestroyWindow(w);
      glfwTerminate();
    }
  } glfwGuard{window};
  ViewSession session(a, setup, atlas, std::move(path), window);
  ImGuiPanel panel(window);
  session.run();
  return 0;
}

}  // namespace gimlod
