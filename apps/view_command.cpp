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
  bool holdFrameTime = false;  // the frame-time controller sets the budgets (budget mode)
  bool colours = true;         // vertex colours or terrain imagery, where the atlas has them
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
    case GLFW_KEY_X: if (press) c.wireframe = !c.wireframe; break;
    case GLFW_KEY_C:
      if (press) c.overlay = (c.overlay + ((mods & GLFW_MOD_SHIFT) ? int(kOverlays.size()) - 1 : 1)) % int(kOverlays.size());
      break;
    case GLFW_KEY_F: if (press) c.freeze = !c.freeze; break;
    case GLFW_KEY_M: if (press) c.budgetMode = !c.budgetMode; break;
    case GLFW_KEY_T: if (press) c.holdFrameTime = !c.holdFrameTime; break;
    case GLFW_KEY_B: if (press) c.views.nodeBorders = !c.views.nodeBorders; break;
    case GLFW_KEY_N: if (press) c.views.normals = !c.views.normals; break;
    case GLFW_KEY_K: if (press) c.views.snapped = !c.views.snapped; break;
    case GLFW_KEY_L: if (press) c.views.loading = !c.views.loading; break;
    case GLFW_KEY_G: if (press) c.topDown = !c.topDown; break;
    case GLFW_KEY_H: if (press) c.showUi = !c.showUi; break;
    case GLFW_KEY_P: if (press) v.screenshotRequested = true; break;
    case GLFW_KEY_R: if (press) v.recordToggled = true; break;
    case GLFW_KEY_SPACE: if (press) c.playing = !c.playing; break;
    case GLFW_KEY_HOME: if (press) v.resetCamera = true; break;
    case GLFW_KEY_TAB: if (press) v.cameraModeToggled = true; break;
    case GLFW_KEY_LEFT_BRACKET:  // finer: lower tolerance, or more triangles
      if (c.budgetMode) c.maxTrianglesK = std::min(c.maxTrianglesK * 2, 1 << 20);
      else c.tolerance = std::max(c.tolerance / std::sqrt(2.f), 0.01f);
      break;
    case GLFW_KEY_RIGHT_BRACKET:  // coarser
      if (c.budgetMode) c.maxTrianglesK = std::max(c.maxTrianglesK / 2, 1);
      else c.tolerance = std::min(c.tolerance * std::sqrt(2.f), 1000.f);
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
  ImGui::PlotLines(label, s.values.data(), int(s.count), int(s.oldest()), overlay.c_str(), 0.f, FLT_MAX,
                   ImVec2(0, 28));
}

struct FrameFigures {
  size_t nodes = 0;
  uint64_t triangles = 0;
  double maxErrorPx = 0.0, adaptMs = 0.0, drawMs = 0.0, gpuMs = 0.0, frameMs = 0.0, uploadMs = 0.0;
  uint32_t pagesLoaded = 0, pagesRequested = 0, rootFloor = 0;
  uint32_t closedGroups = 0, groupedRoots = 0;  // groups above the charts kept closed, their roots
  uint32_t standIns = 0;  // desired nodes drawn as a resident ancestor (pages still loading)
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

int runView(const ViewArgs& a) {
  uint32_t width = 0, height = 0;
  parseFrameSize(a.size, &width, &height);
  validateViewOptions(a.tolerance, a.texelRatio, a.streaming.uploadsPerFrame, a.triangles > 0, a.topDown, a.frameMs);
  validateGeomorph(a.geomorph);
  gl::SceneOptions streaming;  // the streaming options, checked before a window opens
  applyStreamingArgs(a.streaming, streaming);
  if (!(a.fov > 1.0 && a.fov < 179.0)) throw InputError("--fov must be in (1, 179) degrees");
  if (a.frames > 0 && a.path.empty()) throw InputError("--frames needs --path");
  const OverlayMode overlayMode = parseOverlayOption(a.overlay);
  const auto background = parseBackground(a.background);

  const AtlasView atlas = openAtlas(a.atlas, a.maxRoots);
  UpAxis up{atlas.manifest.kind == AtlasKind::Heightfield ? 2 : 1, 1.0};
  if (a.up != "auto") {
    const std::optional<UpAxis> u = parseUpAxis(a.up);
    if (!u) throw InputError("--up '" + a.up + "': expected auto, x, y, z, -x, -y or -z");
    up = *u;
  }
  std::vector<Camera> path;
  if (!a.path.empty()) {
    path = readCameraPath(a.path);
    for (Camera& c : path) fitClipPlanes(c, atlas.lo, atlas.hi);
  }
  std::ofstream stats;
  if (!a.stats.empty()) {
    stats.open(a.stats);
    if (!stats) throw InputError(a.stats + ": cannot write the stats file");
    stats << "frame,nodes,triangles,max_screen_error_px,adapt_ms,draw_ms,frame_ms,pages_loaded,pages_requested,"
             "root_floor,budget_below_roots,mode,tolerance_px,max_nodes,max_triangles,frozen,overlay,wireframe,"
             "target_ms,node_borders,normals,snapped,pages_loading_view,nodes_waiting,gpu_ms,resident_gpu_bytes,"
             "gpu_budget_bytes,resident_ram_bytes,ram_budget_bytes,upload_bytes,loads_issued,loads_done,"
             "loads_cancelled,loads_failed,prefetch_requests,pages_needed,pages_resident,incomplete\n";
  }

  glfwSetErrorCallback([](int code, const char* what) { spdlog::error("GLFW error {}: {}", code, what); });
  if (!glfwInit()) throw std::runtime_error("gimlod view: cannot initialize GLFW (no display? set DISPLAY, or use xvfb-run)");
  struct GlfwGuard {
    ~GlfwGuard() { glfwTerminate(); }
  } glfwGuard;
  glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 4);
  glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 3);
  glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
  glfwWindowHint(GLFW_OPENGL_FORWARD_COMPAT, GLFW_TRUE);
  glfwWindowHint(GLFW_SAMPLES, 0);
  const std::string title = fmt::format("gimlod view: {}", fs::path(a.atlas).filename().string());
  GLFWwindow* window = glfwCreateWindow(int(width), int(height), title.c_str(), nullptr, nullptr);
  if (!window) throw std::runtime_error("gimlod view: cannot open an OpenGL 4.3 core window");
  struct WindowGuard {
    GLFWwindow* w;
    ~WindowGuard() { glfwDestroyWindow(w); }
  } windowGuard{window};
  glfwMakeContextCurrent(window);
  const bool scripted = a.frames > 0;
  glfwSwapInterval(scripted ? 0 : 1);
  spdlog::info("OpenGL: {} ({})", reinterpret_cast<const char*>(glGetString(GL_RENDERER)),
               reinterpret_cast<const char*>(glGetString(GL_VERSION)));

  Controls c;
  c.budgetMode = a.triangles > 0;
  c.tolerance = float(a.tolerance);
  c.maxNodes = int(std::min<uint32_t>(a.maxNodes, 1u << 20));
  c.maxTrianglesK = int(std::clamp<uint64_t>(a.triangles > 0 ? a.triangles / 1000 : 1000, 1, 1 << 20));
  c.texelRatio = float(a.texelRatio);
  c.geomorph = float(a.geomorph);
  c.asyncLoads = streaming.asyncLoads;
  c.uploadsPerFrame = int(a.streaming.uploadsPerFrame);
  c.topDown = a.topDown;
  c.overlay = int(std::find(kOverlays.begin(), kOverlays.end(), overlayMode) - kOverlays.begin());
  c.wireframe = a.wireframe;
  c.showUi = !a.hideUi;
  c.playing = !path.empty();
  c.loop = a.loop;
  c.holdFrameTime = a.frameMs > 0.0;
  if (c.holdFrameTime) c.targetMs = float(a.frameMs);
  std::optional<FrameController> controller;

  CameraControl camera(atlas.lo, atlas.hi, up, a.fov);
  camera.setRadialUp(atlas.manifest.planet.present);
  glm::dvec3 surfaceEye(std::numeric_limits<double>::quiet_NaN());  // where the surface distance was measured
  if (!path.empty()) camera.setCamera(path.front());

  // The scene is made again when async loading is switched (its page loader lives with it).
  int fbw = 0, fbh = 0;
  glfwGetFramebufferSize(window, &fbw, &fbh);
  auto makeScene = [&](bool async) {
    gl::SceneOptions so = streaming;
    so.width = uint32_t(std::max(fbw, 8));
    so.height = uint32_t(std::max(fbh, 8));
    so.background = background;
    so.asyncLoads = async;
    so.maxUploadsPerFrame = uint32_t(c.uploadsPerFrame);
    so.coherentAdaptation = !c.topDown;
    so.texelsPerPixel = c.texelRatio;
    so.samples = a.msaa;
    so.minNodeRoom = uint32_t(c.maxNodes);  // the page pool holds cuts of the budget at start
    return std::make_unique<gl::AtlasScene>(atlas, so);
  };
  std::unique_ptr<gl::AtlasScene> scene = makeScene(c.asyncLoads);
  bool sceneAsync = c.asyncLoads;

  Viewer viewer;
  viewer.camera = &camera;
  viewer.controls = &c;
  glfwSetWindowUserPointer(window, &viewer);
  // Ours first: the ImGui backend chains to the callbacks installed before it.
  glfwSetKeyCallback(window, onKey);
  glfwSetMouseButtonCallback(window, onMouseButton);
  glfwSetCursorPosCallback(window, onCursor);
  glfwSetScrollCallback(window, onScroll);

  IMGUI_CHECKVERSION();
  ImGui::CreateContext();
  struct ImGuiGuard {
    ~ImGuiGuard() {
      ImGui_ImplOpenGL3_Shutdown();
      ImGui_ImplGlfw_Shutdown();
      ImGui::DestroyContext();
    }
  };
  ImGui::GetIO().IniFilename = nullptr;  // no imgui.ini next to the user's files
  ImGui::StyleColorsDark();
  if (!ImGui_ImplGlfw_InitForOpenGL(window, true) || !ImGui_ImplOpenGL3_Init("#version 430 core"))
    throw std::runtime_error("gimlod view: cannot set up the panel (Dear ImGui)");
  ImGuiGuard imguiGuard;

  Series adaptMs, drawMs, gpuMs, frameMs, nodes, triangles, maxError, pagesLoaded;
  Series gpuMiB, ramMiB, uploadMiB, hitRate;  // streaming
  std::vector<Camera> recorded;
  Cut lastCut;  // the cut drawn last: what a freeze keeps drawing
  bool haveCut = false;
  size_t pathFrame = 0;
  std::optional<Camera> pathCamera;  // the path's camera shown, held until the user moves on
  uint32_t screenshots = 0;
  bool warnedBelowRoots = false;
  FrameFigures last;
  auto previous = Clock::now();
  const uint32_t lastFrame = scripted ? a.frames : a.exitAfter;
  auto writeShot = [&](const fs::path& file, uint32_t w, uint32_t h) {
    writePng(file, w, h, 4, gl::readWindowPixels(w, h));
    spdlog::info("wrote {}", file.string());
  };

  for (uint64_t frame = 0; !glfwWindowShouldClose(window); ++frame) {
    const auto t0 = Clock::now();
    const double seconds = std::min(std::chrono::duration<double>(t0 - previous).count(), 0.25);
    previous = t0;
    glfwPollEvents();
    glfwGetFramebufferSize(window, &fbw, &fbh);
    if (fbw < 8 || fbh < 8) {  // minimized
      glfwWaitEventsTimeout(0.1);
      continue;
    }
    if (uint32_t(fbw) != scene->width() || uint32_t(fbh) != scene->height()) scene->resize(uint32_t(fbw), uint32_t(fbh));
    if (c.asyncLoads != sceneAsync) {
      scene = makeScene(c.asyncLoads);
      sceneAsync = c.asyncLoads;
      haveCut = false;
    }
    scene->setCoherentAdaptation(!c.topDown);
    scene->setTexelsPerPixel(c.texelRatio);
    scene->setGeomorph(c.geomorph);
    scene->setMaxUploadsPerFrame(uint32_t(std::max(c.uploadsPerFrame, 1)));
    // The error colouring is against the tolerance (error mode) or the frame's largest error.
    scene->setOverlay(kOverlays[size_t(c.overlay)], {}, c.budgetMode ? 0.0 : double(c.tolerance));
    scene->renderer().setWireframe(c.wireframe);
    scene->renderer().setColours(c.colours);
    scene->renderer().setInspectionViews(c.views);

    // Camera: the path while it plays, else the user's input.
    if (viewer.resetCamera) camera.frame(), viewer.resetCamera = false, pathCamera.reset();
    if (viewer.cameraModeToggled) {
      pathCamera.reset();
      camera.setMode(camera.mode() == CameraControl::Mode::kOrbit ? CameraControl::Mode::kFly
                                                                   : CameraControl::Mode::kOrbit);
      viewer.cameraModeToggled = false;
    }
    // A path's cameras are drawn as they are (render draws the same pictures), the last one held
    // once the path ends, until the user moves the camera on from it.
    if (c.playing && !path.empty()) {
      if (pathFrame >= path.size()) {
        if (c.loop) pathFrame = 0;
        else c.playing = false;
      }
      pathCamera = path[std::min(pathFrame, path.size() - 1)];
      camera.setCamera(*pathCamera);
      if (c.playing) ++pathFrame;
    } else if (!uiWantsKeys()) {
      glm::dvec3 move(0.0);
      if (glfwGetKey(window, GLFW_KEY_D) == GLFW_PRESS) move.x += 1.0;
      if (glfwGetKey(window, GLFW_KEY_A) == GLFW_PRESS) move.x -= 1.0;
      if (glfwGetKey(window, GLFW_KEY_E) == GLFW_PRESS) move.y += 1.0;
      if (glfwGetKey(window, GLFW_KEY_Q) == GLFW_PRESS) move.y -= 1.0;
      if (glfwGetKey(window, GLFW_KEY_W) == GLFW_PRESS) move.z += 1.0;
      if (glfwGetKey(window, GLFW_KEY_S) == GLFW_PRESS) move.z -= 1.0;
      if (camera.eye() != surfaceEye) {  // measured again only when the eye has moved
        surfaceEye = camera.eye();
        camera.setSurfaceDistance(distanceToSurface(atlas.hierarchy, surfaceEye));
      }
      if (move != glm::dvec3(0.0)) camera.move(move, seconds), viewer.cameraTouched = true;
    }
    if (viewer.scroll != 0.0) camera.zoom(viewer.scroll), viewer.scroll = 0.0, viewer.cameraTouched = true;
    if (viewer.cameraTouched) pathCamera.reset(), viewer.cameraTouched = false;
    const Camera cam = pathCamera ? *pathCamera : camera.camera();
    if (viewer.recordToggled) {
      viewer.recordToggled = false;
      if (c.recording) {
        c.recording = false;
        if (a.record.empty()) {
          spdlog::warn("recorded {} cameras; give --record FILE.json to keep them", recorded.size());
        } else if (!recorded.empty()) {
          writeCameraPath(a.record, recorded);
          spdlog::info("wrote {} cameras to {}", recorded.size(), a.record);
        }
      } else {
        c.recording = true;
        recorded.clear();
      }
    }
    if (c.recording) recorded.push_back(cam);

    // The frame-time controller sets the budgets (budget mode) while it holds the frame time.
    if (c.holdFrameTime) {
      c.budgetMode = true;
      if (!controller) {
        FrameControllerOptions fo;
        fo.targetMs = c.targetMs;
        controller.emplace(fo, uint32_t(c.maxNodes), uint64_t(c.maxTrianglesK) * 1000);
      }
      controller->setTarget(std::max(c.targetMs, 1.f));
      c.maxNodes = int(std::min<uint32_t>(controller->maxNodes(), 1u << 20));
      c.maxTrianglesK = int(std::clamp<uint64_t>(controller->maxTriangles() / 1000, 1, 1 << 20));
    } else {
      controller.reset();
    }

    // Adapt (unless frozen) and draw into the scene's framebuffer, then into the window. The cut
    // drawn is kept (moved, not copied) for a freeze.
    gl::FrameResult f;
    const bool drawFrozen = c.freeze && haveCut;
    if (drawFrozen) {
      f.draw = scene->drawCut(cam, lastCut, &f);
    } else {
      if (c.budgetMode) {
        BudgetOptions bo;
        bo.maxTriangles = uint64_t(c.maxTrianglesK) * 1000;
        bo.maxNodes = uint32_t(c.maxNodes);
        f = scene->renderFrame(cam, bo);
      } else {
        AdaptOptions ao;
        ao.tolerancePx = c.tolerance;
        ao.maxNodes = uint32_t(c.maxNodes);
        f = scene->renderFrame(cam, ao);
      }
    }
    if (f.adapt.budgetBelowRoots && !warnedBelowRoots) {
      spdlog::warn("node budget {} is below the {} visible {}: such frames draw the visible roots", c.maxNodes,
                   f.adapt.rootFloor, atlas.hierarchy.groups.empty() ? "chart roots" : "top groups");
      warnedBelowRoots = true;
    }
    scene->renderer().blitToDefaultFramebuffer();
    glViewport(0, 0, fbw, fbh);

    if (!drawFrozen) {
      lastCut = std::move(f.cut);
      haveCut = true;
    }
    last.nodes = lastCut.nodeCount();
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
    adaptMs.add(last.adaptMs);
    drawMs.add(last.drawMs);
    gpuMs.add(last.gpuMs);
    nodes.add(double(last.nodes));
    triangles.add(double(last.triangles));
    maxError.add(last.maxErrorPx);
    pagesLoaded.add(last.pagesLoaded);
    gpuMiB.add(double(last.residentGpuBytes) / (1 << 20));
    ramMiB.add(double(last.residentRamBytes) / (1 << 20));
    uploadMiB.add(double(last.uploadBytes) / (1 << 20));
    hitRate.add(last.pagesNeeded > 0 ? 100.0 * last.pagesResident / last.pagesNeeded : 100.0);

    // The panel.
    ImGui_ImplOpenGL3_NewFrame();
    ImGui_ImplGlfw_NewFrame();
    ImGui::NewFrame();
    if (c.showUi) {
      ImGui::SetNextWindowPos(ImVec2(8, 8), ImGuiCond_FirstUseEver);
      ImGui::SetNextWindowSize(ImVec2(330, 0), ImGuiCond_FirstUseEver);
      ImGui::SetNextWindowBgAlpha(0.7f);
      ImGui::Begin("gimlod", nullptr, ImGuiWindowFlags_AlwaysAutoResize);
      ImGui::Text("%s atlas, %u charts", atlas.manifest.kind == AtlasKind::Heightfield ? "terrain" : "mesh",
                  atlas.hierarchy.chartCount());
      int mode = c.budgetMode ? 1 : 0;
      ImGui::RadioButton("error threshold", &mode, 0);
      ImGui::SameLine();
      ImGui::RadioButton("triangle budget", &mode, 1);
      c.budgetMode = mode == 1;
      if (c.budgetMode) {
        ImGui::SliderInt("triangles (k)", &c.maxTrianglesK, 1, 20000, "%d", ImGuiSliderFlags_Logarithmic);
      } else {
        ImGui::SliderFloat("tolerance (px)", &c.tolerance, 0.05f, 64.f, "%.2f", ImGuiSliderFlags_Logarithmic);
        ImGui::Checkbox("top-down greedy", &c.topDown);
      }
      ImGui::SliderInt("max nodes", &c.maxNodes, 1, 65536, "%d", ImGuiSliderFlags_Logarithmic);
      if (uint32_t(c.maxNodes) > scene->nodeRoom())
        ImGui::TextColored(ImVec4(1.f, 0.7f, 0.3f, 1.f), "at most %u nodes: the GPU page pool holds %u pages",
                           scene->nodeRoom(), scene->renderer().pageCapacity());
      ImGui::Checkbox("hold frame time", &c.holdFrameTime);
      if (c.holdFrameTime) {
        ImGui::SameLine();
        ImGui::SetNextItemWidth(120);
        ImGui::SliderFloat("ms", &c.targetMs, 2.f, 200.f, "%.1f", ImGuiSliderFlags_Logarithmic);
      }
      ImGui::SliderFloat("texel ratio", &c.texelRatio, 0.f, 8.f, "%.2f");
      ImGui::SliderFloat("geomorph range", &c.geomorph, 0.f, 2.f, "%.2f");
      ImGui::Checkbox("async loads", &c.asyncLoads);
      if (c.asyncLoads) ImGui::SliderInt("uploads / frame", &c.uploadsPerFrame, 1, 512);
      ImGui::Combo("colouring", &c.overlay, kOverlayLabels.data(), int(kOverlayLabels.size()));
      if (scene->hasColours()) ImGui::Checkbox("colours (vertex colours or imagery)", &c.colours);
      ImGui::Checkbox("node borders", &c.views.nodeBorders);
      ImGui::SameLine();
      ImGui::Checkbox("normals", &c.views.normals);
      ImGui::SameLine();
      ImGui::Checkbox("snapped", &c.views.snapped);
      ImGui::SameLine();
      ImGui::Checkbox("pages loading", &c.views.loading);
      ImGui::Checkbox("wireframe", &c.wireframe);
      ImGui::SameLine();
      ImGui::Checkbox("freeze cut", &c.freeze);
      ImGui::Text("camera: %s%s%s", camera.mode() == CameraControl::Mode::kOrbit ? "orbit" : "fly",
                  c.playing ? ", playing the path" : "", c.recording ? ", recording" : "");
      ImGui::Separator();
      ImGui::Text("nodes %zu (root floor %u%s)  triangles %llu", last.nodes, last.rootFloor,
                  last.belowRoots ? ", above the budget" : "", static_cast<unsigned long long>(last.triangles));
      if (last.closedGroups > 0)
        ImGui::Text("%u closed groups drawing %u chart roots", last.closedGroups, last.groupedRoots);
      ImGui::Text("max error %.3f px  frame %.2f ms", last.maxErrorPx, frameMs.last());
      if (c.asyncLoads) ImGui::Text("pages: %u requested, %u nodes waiting for theirs", last.pagesRequested, last.standIns);
      ImGui::Text("GPU pool %.1f of %.1f MiB", double(last.residentGpuBytes) / (1 << 20),
                  double(last.gpuBudgetBytes) / (1 << 20));
      if (c.asyncLoads)
        ImGui::Text("RAM %.1f of %.1f MiB  uploads %.2f of %.2f MiB  hit %.0f%%", double(last.residentRamBytes) / (1 << 20),
                    double(streaming.ramCacheBytes) / (1 << 20), double(last.uploadBytes) / (1 << 20),
                    double(streaming.uploadBytesPerFrame) / (1 << 20),
                    last.pagesNeeded > 0 ? 100.0 * last.pagesResident / last.pagesNeeded : 100.0);
      if (ImGui::CollapsingHeader("graphs", fbh >= 700 ? ImGuiTreeNodeFlags_DefaultOpen : 0)) {
        plot("adapt ms", adaptMs, "ms");
        plot("draw ms", drawMs, "ms");
        plot("GPU ms (timer)", gpuMs, "ms");
        plot("frame ms", frameMs, "ms");
        plot("nodes", nodes, "");
        plot("triangles", triangles, "");
        plot("max error", maxError, "px");
        plot("pages loaded", pagesLoaded, "");
        plot("GPU pool", gpuMiB, "MiB");
        if (c.asyncLoads) {
          plot("loader RAM", ramMiB, "MiB");
          plot("uploads", uploadMiB, "MiB");
          plot("hit rate", hitRate, "%");
        }
      }
      if (ImGui::CollapsingHeader("keys")) ImGui::TextUnformatted(kHelp);
      ImGui::End();
    }
    ImGui::Render();
    ImGui_ImplOpenGL3_RenderDrawData(ImGui::GetDrawData());

    last.frameMs = msSince(t0);
    frameMs.add(last.frameMs);
    // Page reads and uploads are the loader's to bound (uploads per frame), not the budgets'.
    if (controller && !c.freeze)
      controller->update({uint32_t(last.nodes), last.triangles, last.adaptMs, last.drawMs,
                          std::max(last.frameMs - last.uploadMs, 0.0)});
    if (stats) {
      stats << fmt::format("{},{},{},{:.4f},{:.4f},{:.4f},{:.4f},{},{},{},{},{},{:.4f},{},{},{},{},{},{},{},{},{},{},{},{:.4f}", frame,
                           last.nodes, last.triangles, last.maxErrorPx, last.adaptMs, last.drawMs, last.frameMs,
                           last.pagesLoaded, last.pagesRequested, last.rootFloor, int(last.belowRoots),
                           c.budgetMode ? "budget" : "error", c.tolerance, c.maxNodes, uint64_t(c.maxTrianglesK) * 1000,
                           int(c.freeze), overlayModeName(kOverlays[size_t(c.overlay)]), int(c.wireframe),
                           c.holdFrameTime ? fmt::format("{:.2f}", c.targetMs) : std::string(),
                           int(c.views.nodeBorders), int(c.views.normals), int(c.views.snapped),
                           int(c.views.loading), last.standIns, last.gpuMs)
            << fmt::format(",{},{},{},{},{},{},{},{},{},{},{},{},{}\n", last.residentGpuBytes, last.gpuBudgetBytes,
                           last.residentRamBytes, c.asyncLoads ? streaming.ramCacheBytes : 0, last.uploadBytes,
                           last.loadsIssued, last.loadsDone, last.loadsCancelled, last.loadsFailed,
                           last.prefetchRequests, last.pagesNeeded, last.pagesResident, int(last.incomplete))
            << std::flush;
    }
    const bool lastOne = lastFrame > 0 && frame + 1 >= lastFrame;
    if (viewer.screenshotRequested) {
      viewer.screenshotRequested = false;
      writeShot(a.screenshot.empty() ? fs::path(fmt::format("gimlod-view-{:03d}.png", screenshots++)) : fs::path(a.screenshot),
                uint32_t(fbw), uint32_t(fbh));
    } else if (lastOne && scripted && !a.screenshot.empty()) {
      writeShot(a.screenshot, uint32_t(fbw), uint32_t(fbh));
    }
    glfwSwapBuffers(window);
    if (lastOne) break;
  }
  if (c.recording && !a.record.empty() && !recorded.empty()) {
    writeCameraPath(a.record, recorded);
    spdlog::info("wrote {} cameras to {}", recorded.size(), a.record);
  }
  return 0;
}

}  // namespace gimlod
