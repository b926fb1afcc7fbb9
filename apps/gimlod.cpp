// gimlod: build multi-grained LOD atlases, render them headless or in a window, and benchmark the
// adaptation.
#include <charconv>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <map>
#include <random>
#include <string>
#include <unordered_map>

#include <CLI/CLI.hpp>
#include <OpenImageIO/imageio.h>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <spdlog/cfg/env.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include "apps/bench_command.h"
#include "apps/build_command.h"
#include "apps/view_command.h"
#include "apps/streaming_args.h"
#include "apps/view_args.h"
#include "core/atlas_format.h"
#include "core/progress.h"
#include "inspect/png.h"
#include "inspect/report.h"
#include "pipeline/build.h"
#include "pipeline/build_report.h"
#include "pipeline/sharded_build.h"
#include "apps/shard_command.h"
#include "pipeline/input_kind.h"
#include "runtime/adapt.h"
#include "runtime/atlas_view.h"
#include "runtime/camera.h"
#include "runtime/cut_mesh.h"
#include "runtime/frame_controller.h"
#include "runtime/overlay.h"
#include "runtime/gl/egl_context.h"
#include "runtime/gl/atlas_scene.h"

namespace fs = std::filesystem;
using namespace gimlod;

namespace {

struct RenderArgs {
  std::string atlas, output, size = "640x480", background = "0.53,0.70,0.92";
  CameraArgs camera;
  uint32_t maxNodes = 2048;
  StreamingArgs streaming;
  bool topDown = false;
  double tolerance = 1.0, texelRatio = 1.0;
  double geomorph = 0.0;               // SceneOptions::geomorph
  uint32_t msaa = 1;                   // SceneOptions::samples
  uint64_t triangles = 0;              // > 0: triangle-budget mode (quad queue)
  double frameMs = 0.0;                // > 0: the frame-time controller sets the budgets (budget mode)
  std::string overlay = "none";        // runtime/overlay.h: none, chart, level, res, error
  std::vector<std::string> exportCut;  // "FRAME:FILE.ply"
  bool noStitch = false;               // exported cuts without the stitching tables (a control)
};

// "FRAME:FILE" pairs of --export-cut; throws InputError naming a bad one.
std::map<size_t, fs::path> parseCutExports(const std::vector<std::string>& specs, size_t frames) {
  std::map<size_t, fs::path> out;
  for (const std::string& s : specs) {
    const size_t colon = s.find(':');
    char* end = nullptr;
    const unsigned long frame = colon == std::string::npos ? 0 : std::strtoul(s.c_str(), &end, 10);
    if (colon == std::string::npos || colon == 0 || end != s.c_str() + colon || colon + 1 == s.size())
      throw InputError("--export-cut '" + s + "': expected FRAME:FILE.ply");
    if (frame >= frames)
      throw InputError("--export-cut '" + s + "': frame " + std::to_string(frame) + " is past the path's " +
                       std::to_string(frames) + " frames");
    out[frame] = s.substr(colon + 1);
  }
  return out;
}

struct InspectArgs {
  InspectOptions report;
  bool views = true;
  std::string viewSize = "480x360";
};

// A node's colour for the source-distance overlay: the largest distance of its samples, on the
// heat ramp over 4 decades below the largest distance (blue: that or less, red: the largest).
NodeColour sourceDistanceColour(const SourceDistances& d) {
  auto cache = std::make_shared<std::unordered_map<uint64_t, uint32_t>>();
  return [&d, cache](const NodeId& id) {
    if (const auto it = cache->find(id.key()); it != cache->end()) return it->second;
    const uint32_t n = d.chartSize, step = (n - 1) >> id.level;
    float mx = 0.f;
    for (uint32_t v = id.y * step; v <= (id.y + 1) * step; ++v)
      for (uint32_t u = id.x * step; u <= (id.x + 1) * step; ++u)
        mx = std::max(mx, d.perSample[size_t(id.chart) * n * n + size_t(v) * n + u]);
    const double t =
        mx > 0.f && d.largest > 0.0 ? std::clamp(1.0 + std::log10(double(mx) / d.largest) / 4.0, 0.0, 1.0) : 0.0;
    const std::array<uint8_t, 3> c = heatColour(t);
    const uint32_t rgba = uint32_t(c[0]) | uint32_t(c[1]) << 8 | uint32_t(c[2]) << 16 | 0xFF000000u;
    cache->emplace(id.key(), rgba);
    return rgba;
  };
}

// Renders the six axis views of the atlas with the chart overlay into `dir` (headless EGL), and,
// given the source distances, the same six with each node coloured by its distance to the source.
std::vector<ReportImage> renderInspectViews(const fs::path& atlasDir, const std::string& size, const fs::path& dir,
                                            const SourceDistances* distances) {
  uint32_t w = 0, h = 0;
  parseFrameSize(size, &w, &h);
  const AtlasView atlas = openAtlas(atlasDir);
  auto context = gl::EglContext::create();
  gl::SceneOptions so;
  so.width = w;
  so.height = h;
  so.overlay = OverlayMode::kChart;
  gl::AtlasScene scene(atlas, so);
  AdaptOptions ao;
  ao.tolerancePx = 1.0;
  ao.maxNodes = scene.nodeBudget(0);
  std::vector<std::string> names;
  const std::vector<Camera> cams = axisViews(atlas.lo, atlas.hi, 40.0, &names);
  std::vector<ReportImage> views;
  for (size_t i = 0; i < cams.size(); ++i) {
    const gl::FrameResult f = scene.renderFrame(cams[i], ao);
    const fs::path png = dir / fmt::format("view_{}.png", i);
    writePng(png, w, h, 4, scene.renderer().readPixels());
    // The cut as drawn, welded: its boundary edges off the open chart borders are cracks.
    const std::array<glm::dvec2, 2> valid{glm::dvec2(atlas.lo), glm::dvec2(atlas.hi)};
    const bool flat = atlas.manifest.kind == AtlasKind::Heightfield && !atlas.manifest.planet.present;
    const CutMesh mesh = buildCutMesh(atlas.hierarchy, f.cut, scene.capture(f.cut), flat ? &valid : nullptr);
    const nlohmann::json figures = {{"view", names[i]},
                                    {"nodes", f.cut.nodeCount()},
                                    {"triangles", f.draw.triangles},
                                    {"boundary_edges", mesh.boundaryEdges},
                                    {"open_border_edges", mesh.openBorderEdges},
                                    {"other_boundary_edges", mesh.otherBoundaryEdges}};
    views.push_back({png,
                     fmt::format("charts from {} ({} nodes, {} triangles; seams dark, open borders red), {}", names[i],
                                 f.cut.nodeCount(), f.draw.triangles, context->renderer()),
                     figures});
  }
  if (distances) {
    scene.setOverlay(OverlayMode::kCustom, sourceDistanceColour(*distances));
    for (size_t i = 0; i < cams.size(); ++i) {
      scene.renderFrame(cams[i], ao);
      const fs::path png = dir / fmt::format("source_view_{}.png", i);
      writePng(png, w, h, 4, scene.renderer().readPixels());
      views.push_back({png, fmt::format("distance to the source from {} (each node its largest: blue 1e-4 of the "
                                        "largest {:.3g} or less, red the largest)",
                                        names[i], distances->largest)});
    }
  }
  return views;
}

int runInspect(InspectArgs a) {
  // The views are rendered into a private directory and copied into the report.
  struct ScratchDir {
    fs::path path = fs::temp_directory_path() / fmt::format("gimlod-inspect-{}", ::getpid());
    ScratchDir() { fs::create_directories(path); }
    ~ScratchDir() {
      std::error_code ec;
      fs::remove_all(path, ec);
    }
  } scratch;
  if (a.views) {
    (void)readManifest(a.report.atlas);  // a bad atlas is named before a context is made
    a.report.renderViews = [&](const SourceDistances* d) {
      return renderInspectViews(a.report.atlas, a.viewSize, scratch.path, d);
    };
  }
  const InspectResult res = writeInspectReport(a.report);
  const nlohmann::json& sum = res.figures["summary"];
  std::cout << fmt::format("wrote {}: {} charts, seams {} ({} mismatches), {} images, {:.1f} MiB in {:.2f} s\n",
                           (a.report.output / "index.html").string(), sum["charts"].get<uint64_t>(),
                           sum["seams_bit_identical"].get<bool>() ? "bit-identical" : "broken",
                           sum["seam_mismatches"].get<uint64_t>(), res.images, double(res.bytes) / (1 << 20),
                           res.seconds);
  return sum["seams_bit_identical"].get<bool>() ? 0 : 3;
}

int runRender(const RenderArgs& a) {
  uint32_t w = 0, h = 0;
  parseFrameSize(a.size, &w, &h);
  validateViewOptions(a.tolerance, a.texelRatio, a.streaming.uploadsPerFrame, a.triangles > 0, a.topDown, a.frameMs);
  validateGeomorph(a.geomorph);
  validateCameraArgs(a.camera);
  const auto background = parseBackground(a.background);
  gl::SceneOptions so;
  applyStreamingArgs(a.streaming, so);

  const AtlasView atlas = openAtlas(a.atlas, a.camera.maxRoots);
  const std::vector<Camera> cams = loadCameras(a.camera, atlas);

  const std::map<size_t, fs::path> cutExports = parseCutExports(a.exportCut, cams.size());
  const fs::path out = a.output;
  std::error_code ec;
  fs::create_directories(out, ec);
  if (ec || !fs::is_directory(out)) throw InputError(a.output + ": cannot create output directory");
  if (::access(out.c_str(), W_OK) != 0) throw InputError(a.output + ": output directory is not writable");

  auto context = gl::EglContext::create();
  spdlog::info("OpenGL: {} ({})", context->renderer(), context->version());
  so.width = w;
  so.height = h;
  so.background = background;
  so.coherentAdaptation = !a.topDown;
  so.texelsPerPixel = a.texelRatio;
  so.geomorph = a.geomorph;
  so.samples = a.msaa;
  so.overlay = parseOverlayOption(a.overlay);
  so.overlayErrorPx = a.triangles > 0 ? 0.0 : a.tolerance;  // error colouring: red at the tolerance
  so.minNodeRoom = a.maxNodes;                              // the page pool holds the budget's cuts
  gl::AtlasScene scene(atlas, so);
  spdlog::info("GPU page pool: {} pages of {} bytes in {} texture array(s), room for cuts of {} nodes",
               scene.renderer().pageCapacity(), scene.pageBytes(), scene.renderer().pageArrays(), scene.nodeRoom());
  if (!scene.rootStandIns().empty())
    spdlog::info(
        "the {} chart roots do not fit the GPU cache with room to split: each has a stand-in of {}^2 samples "
        "({} bytes in all), and their pages come and go like the others",
        atlas.hierarchy.chartCount(), (1u << scene.renderer().setup().standInIntervalsLog2) + 1, scene.standInBytes());
  if (scene.nodeBudget(a.maxNodes) != a.maxNodes)
    spdlog::warn("--max-nodes {} is above what the GPU page pool holds ({} pages): using {}", a.maxNodes,
                 scene.renderer().pageCapacity(), scene.nodeRoom());

  AdaptOptions ao;
  ao.tolerancePx = a.tolerance;
  ao.maxNodes = a.maxNodes;
  BudgetOptions bo;
  bo.maxTriangles = a.triangles;
  bo.maxNodes = a.maxNodes;
  // --frame-ms: budget mode, the budgets set frame by frame from the measured costs.
  std::optional<FrameController> controller;
  const bool budgetMode = a.triangles > 0 || a.frameMs > 0.0;
  if (a.frameMs > 0.0) {
    FrameControllerOptions fo;
    fo.targetMs = a.frameMs;
    controller.emplace(fo, a.maxNodes, a.triangles > 0 ? a.triangles : 1000000);
  }
  std::string csv =
      "frame,nodes,triangles,max_screen_error_px,adapt_ms,stitch_ms,upload_ms,draw_ms,"
      "draw_calls,pages_loaded,pages_missing,pages_requested,nodes_substituted,node_budget_bound,"
      "constraint_raises,constraint_splits,attribute_texels,attribute_above_page,root_floor,"
      "budget_below_roots,max_nodes,max_triangles,frame_ms,gpu_ms,closed_groups,grouped_roots,"
      "resident_gpu_bytes,gpu_budget_bytes,resident_ram_bytes,ram_budget_bytes,upload_bytes,"
      "loads_issued,loads_done,loads_cancelled,loads_failed,prefetch_requests,pages_needed,"
      "pages_resident,incomplete,roots_on_stand_ins,charts_coarsened\n";
  double drawMsTotal = 0.0;
  uint64_t triTotal = 0;
  bool warnedBelowRoots = false;
  for (size_t i = 0; i < cams.size(); ++i) {
    if (controller) bo.maxNodes = controller->maxNodes(), bo.maxTriangles = controller->maxTriangles();
    const auto frameStart = std::chrono::steady_clock::now();
    const gl::FrameResult f = budgetMode ? scene.renderFrame(cams[i], bo) : scene.renderFrame(cams[i], ao);
    const double frameMs =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - frameStart).count();
    // Page reads and uploads are the loader's to bound (--uploads-per-frame), not the budgets'.
    if (controller)
      controller->update(
          {f.cut.nodeCount(), f.draw.triangles, f.adaptMs, f.draw.drawMs, std::max(frameMs - f.uploadMs, 0.0)});
    if (f.adapt.budgetBelowRoots && !warnedBelowRoots) {
      const uint32_t budget = scene.nodeBudget(a.maxNodes);
      spdlog::warn(
          "{} {} is below the {} visible {} (frame {}): no cut has fewer nodes, so such frames "
          "draw the visible roots (root_floor, budget_below_roots in stats.csv)",
          budget == a.maxNodes ? "--max-nodes" : "the GPU page pool's room of", budget, f.adapt.rootFloor,
          atlas.hierarchy.groups.empty() ? "chart roots" : "top groups", i);
      warnedBelowRoots = true;
    }
    writePng(out / fmt::format("frame_{:04d}.png", i), w, h, 4, scene.renderer().readPixels());
    if (const auto ex = cutExports.find(i); ex != cutExports.end()) {
      const std::array<glm::dvec2, 2> valid{glm::dvec2(atlas.lo), glm::dvec2(atlas.hi)};
      // (A planet's cut has no DEM rectangle, and its positions are written planet-centred.)
      const bool flat = atlas.manifest.kind == AtlasKind::Heightfield && !atlas.manifest.planet.present;
      CutMesh mesh = buildCutMesh(atlas.hierarchy, f.cut, scene.capture(f.cut, !a.noStitch), flat ? &valid : nullptr);
      const glm::dvec3 origin = scene.captureOrigin();
      for (glm::vec3& p : mesh.positions) p = glm::vec3(glm::dvec3(p) + origin);
      writeCutMeshPly(ex->second, mesh);
      spdlog::info(
          "frame {}: wrote the cut as drawn to {}: {} vertices, {} triangles; {} boundary edges, {} on open "
          "chart borders, {} elsewhere (cracks, or the edge of what the view culled)",
          i, ex->second.string(), mesh.positions.size(), mesh.triangles.size(), mesh.boundaryEdges,
          mesh.openBorderEdges, mesh.otherBoundaryEdges);
    }
    csv += fmt::format(
        "{},{},{},{:.4f},{:.4f},{:.4f},{:.4f},{:.4f},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{:.4f},{:.4f},{},{}", i,
        f.cut.nodeCount(), f.draw.triangles, f.maxErrorPx, f.adaptMs, f.stitchMs, f.uploadMs, f.draw.drawMs,
        f.draw.drawCalls, f.pagesLoaded + f.pagesUploaded, f.pagesMissing, f.pagesRequested, f.nodesSubstituted,
        int(f.adapt.nodeBudgetBound), f.adapt.constraintRaises, f.adapt.constraintSplits, f.attributes.texels,
        f.attributes.abovePage, f.adapt.rootFloor, int(f.adapt.budgetBelowRoots), budgetMode ? bo.maxNodes : a.maxNodes,
        budgetMode ? bo.maxTriangles : 0, frameMs, f.draw.gpuMs, f.adapt.closedGroups, f.adapt.groupedRoots);
    csv += fmt::format(",{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n", f.residentGpuBytes, f.gpuBudgetBytes,
                       f.residentRamBytes, so.asyncLoads ? so.ramCacheBytes : 0, f.uploadBytes, f.loadsIssued,
                       f.loadsDone, f.loadsCancelled, f.loadsFailed, f.prefetchRequests, f.pagesNeeded, f.pagesResident,
                       int(f.incomplete), f.rootsOnStandIns, f.chartsCoarsened);
    drawMsTotal += f.draw.drawMs;
    triTotal += f.draw.triangles;
    spdlog::info("frame {:4d}: {:5d} nodes, {:8d} triangles, max error {:.3f} px, adapt {:.3f} ms, draw {:.2f} ms", i,
                 f.cut.nodeCount(), f.draw.triangles, f.maxErrorPx, f.adaptMs, f.draw.drawMs);
  }
  atomicWriteFile(out / "stats.csv", csv.data(), csv.size());
  std::cout << fmt::format("rendered {} frames to {} on {}: {:.2f} M triangles/s\n", cams.size(), a.output,
                           context->renderer(), drawMsTotal > 0 ? double(triTotal) / drawMsTotal * 1e-3 : 0.0);
  return 0;
}

// Adds the `render` subcommand, its options parsed into `r`.
CLI::App* addRenderCommand(CLI::App& app, RenderArgs& r) {
  auto* render = app.add_subcommand("render", "Render an atlas headless (EGL) to PNG frames and stats.csv");
  render->add_option("atlas", r.atlas, "Atlas directory")->required();
  render->add_option("-o,--output", r.output, "Output directory")->required();
  addCameraOptions(render, r.camera);
  render->add_option("--size", r.size, "Frame size WxH")->capture_default_str();
  render->add_option("--background", r.background, "Background colour R,G,B")->capture_default_str();
  render->add_option("--tolerance", r.tolerance, "Screen-space error tolerance in pixels")->capture_default_str();
  render->add_option("--max-nodes", r.maxNodes, "Node budget")->capture_default_str();
  render->add_option("--triangles", r.triangles,
                     "Triangle budget: adapt with the quad queue (paper 7.1, problem 2) instead of --tolerance");
  render->add_option("--frame-ms", r.frameMs,
                     "Hold this frame time: the node and triangle budgets follow the measured costs frame by frame "
                     "(budget mode; --triangles and --max-nodes are where they start)");
  render->add_flag("--top-down", r.topDown,
                   "Error mode with the stateless top-down greedy instead of the coherent dual queue");
  addGeomorphOption(render, r.geomorph);
  addMsaaOption(render, r.msaa);
  render
      ->add_option("--texel-ratio", r.texelRatio,
                   "Normal-map texels per pixel of a node's projected size (0: page resolution)")
      ->capture_default_str();
  addStreamingOptions(render, r.streaming);
  render
      ->add_option("--overlay", r.overlay,
                   "Draw over the shading: chart (each chart its colour, seams dark, open borders red), level, res, "
                   "error (heat map: blue 0, red at the tolerance, or the frame's largest error with --triangles)")
      ->capture_default_str();
  render->add_option("--export-cut", r.exportCut,
                     "FRAME:FILE.ply: write the cut drawn at that frame as one welded mesh (stitched positions from "
                     "the vertex shader, per-vertex chart, level, node and resolution); repeatable");
  render->add_flag("--no-stitch", r.noStitch, "Export cuts without border stitching (a negative control: it cracks)");

  return render;
}

struct ExportArgs {
  std::string atlas, output;
  uint32_t level = 0;
};

CLI::App* addExportCommand(CLI::App& app, ExportArgs& e) {
  auto* exportCmd = app.add_subcommand(
      "export", "Write a mesh atlas's surface at one pyramid level as one PLY, welded along the seams");
  exportCmd->add_option("atlas", e.atlas, "Atlas directory (a mesh or planet atlas)")->required();
  exportCmd->add_option("-o,--output", e.output, "Output .ply")->required();
  exportCmd->add_option("--level", e.level, "Pyramid level (0: full resolution)")->capture_default_str();
  return exportCmd;
}

int runExport(const ExportArgs& e) {
  const SurfaceExport s = exportAtlasSurface(e.atlas, e.level, e.output);
  std::cout << fmt::format("wrote {}: {} vertices, {} triangles from {} chart samples at level {}; {} boundary edges\n",
                           e.output, s.vertices, s.triangles, s.samples, e.level, s.boundaryEdges);
  return 0;
}

CLI::App* addInspectCommand(CLI::App& app, InspectArgs& inspect) {
  auto* inspectCmd = app.add_subcommand(
      "inspect", "Write an inspection report of an atlas (index.html, report.json, images) that opens from disk");
  inspectCmd->add_option("atlas", inspect.report.atlas, "Atlas directory")->required();
  inspectCmd->add_option("-o,--output", inspect.report.output, "Report directory to create")->required();
  inspectCmd
      ->add_option("--worst", inspect.report.worstCharts, "Charts shown with images, the worst first (figures for all)")
      ->capture_default_str();
  inspectCmd->add_option("--image-size", inspect.report.thumbnailSize, "Largest chart image side in samples")
      ->capture_default_str();
  inspectCmd->add_option(
      "--source", inspect.report.source,
      "The mesh or DEM the atlas was built from: compare them sample by sample (where the distances lie)");
  inspectCmd->add_option("--view-size", inspect.viewSize, "Size WxH of the six rendered views")->capture_default_str();
  inspectCmd->add_flag(
      "--no-views", [&](int64_t) { inspect.views = false; }, "Skip the rendered views (no GL needed)");

  return inspectCmd;
}

struct MergeArgs {
  fs::path atlas;
  uint32_t shards = 0;
};

CLI::App* addMergeCommand(CLI::App& app, MergeArgs& m) {
  auto* mergeCmd = app.add_subcommand(
      "merge",
      "Merge the shards of a build across processes (gimlod build --prepare, then --shard I/N) into the atlas");
  mergeCmd->add_option("atlas", m.atlas, "The atlas directory the shards were built for")->required();
  mergeCmd->add_option("--shards", m.shards, "The N the shards were run with (default: the one N present)");

  return mergeCmd;
}

// Long stages show their progress: a bar with an ETA on a terminal (redrawn 5 times a second),
// a log line every 10 s otherwise (GIMLOD_PROGRESS_SECONDS sets that interval).
void showProgress() {
  const bool tty = ::isatty(STDERR_FILENO) == 1;
  double interval = tty ? 0.2 : 10.0;
  if (const char* env = std::getenv("GIMLOD_PROGRESS_SECONDS")) interval = std::max(std::atof(env), 0.0);
  progress::setSink(
      [tty, interval](const progress::Report& r) {
        if (tty) {
          std::fprintf(stderr, "\r%s\033[K%s", progress::format(r, 30).c_str(), r.finished ? "\n" : "");
          std::fflush(stderr);
        } else if (!r.finished || r.seconds >= interval) {
          spdlog::info("progress: {}", progress::format(r, 0));
        }
      },
      interval);
}
}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"gimlod: multi-grained level of detail from seamless geometry-image atlases"};
  app.require_subcommand(1);
  spdlog::set_default_logger(spdlog::stderr_color_mt("gimlod"));
  spdlog::set_pattern("[%l] %v");
  // SPDLOG_LEVEL=debug (or warn, ...) sets the log level.
  spdlog::cfg::load_env_levels();

  BuildArgs buildArgs;
  CLI::App* build = addBuildCommand(app, buildArgs);
  MergeArgs mergeArgs;
  CLI::App* merge = addMergeCommand(app, mergeArgs);
  RenderArgs renderArgs;
  CLI::App* render = addRenderCommand(app, renderArgs);
  BenchArgs benchArgs;
  CLI::App* bench = addBenchCommand(app, benchArgs);
  ExportArgs exportArgs;
  CLI::App* exportCmd = addExportCommand(app, exportArgs);
  InspectArgs inspectArgs;
  CLI::App* inspect = addInspectCommand(app, inspectArgs);
  ViewArgs viewArgs;
  CLI::App* view = addViewCommand(app, viewArgs);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  showProgress();
  try {
    if (*build) return runBuildCommand(buildArgs, argc, argv);
    if (*merge) {
      std::cout << shardSummary(mergeShards(mergeArgs.atlas, mergeArgs.shards), mergeArgs.atlas);
      return 0;
    }
    if (*inspect) return runInspect(inspectArgs);
    if (*render) return runRender(renderArgs);
    if (*bench) return runBench(benchArgs);
    if (*view) return runView(viewArgs);
    if (*exportCmd) return runExport(exportArgs);
  } catch (const InputError& e) {
    spdlog::error("{}", e.message(flagFor));
    return 2;
  } catch (const std::exception& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
  return 0;
}
