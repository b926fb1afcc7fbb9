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
#include "apps/view_command.h"
#include "apps/streaming_args.h"
#include "apps/view_args.h"
#include "atlas/mesh/mesh_atlas.h"
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
  double geomorph = 0.0;  // SceneOptions::geomorph
  uint32_t msaa = 1;      // SceneOptions::samples
  uint64_t triangles = 0;  // > 0: triangle-budget mode (quad queue)
  double frameMs = 0.0;    // > 0: the frame-time controller sets the budgets (budget mode)
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

// A whole number in [0, 2^32 - 2] ("auto" is told apart before); throws InputError naming the option.
uint32_t parseCount(const std::string& option, const std::string& text) {
  uint64_t v = 0;
  const char* end = text.data() + text.size();
  const auto [ptr, ec] = std::from_chars(text.data(), end, v);
  if (text.empty() || ec != std::errc() || ptr != end || v >= 0xFFFFFFFFull)
    throw InputError(option + " '" + text + "' must be a whole number (or auto)");
  return uint32_t(v);
}

// The command-line flag that sets the library parameter `name` (InputError::message); the name
// itself for one the command line does not set.
std::string flagFor(std::string_view name) {
  static const std::map<std::string_view, std::string_view> kFlags = {
      {"chartSize", "--chart-size"},          {"blockIntervals", "--node-res"},
      {"depth", "--depth"},                   {"nodeRes", "--node-res"},
      {"minNodeRes", "--min-node-res"},       {"zScale", "--z-scale"},
      {"subdataset", "--subdataset"},         {"threads", "--threads"},
      {"band", "--band"},                     {"spacing", "--spacing"},
      {"imagery", "--imagery"},
      {"charts", "--charts"},                 {"maxChartError", "--chart-error"},
      {"repairRounds", "--repair-rounds"},    {"repairBudget", "--repair-budget"},
      {"maxSampleError", "--sample-error"},
      {"maxMemory", "--max-memory"},          {"measureFidelity", "--no-fidelity"},
      {"output", "--output"},                 {"worstCharts", "--worst"},
      {"thumbnailSize", "--image-size"},      {"imageryScale", "--imagery-scale"},
      {"imageryExtent", "--imagery-extent"},  {"heightPrecision", "--height-precision"},
      {"compress", "--uncompressed"},         {"positionBits", "--position-bits"},
      {"positionTolerance", "--position-tolerance"}, {"normalTolerance", "--normal-tolerance"},
      {"normals", "--normals"},
      {"imagery", "--imagery"},              {"quads", "--quads"},
      {"quadMap", "--quad-map"},              {"sizing", "--sizing"},
      {"outOfCore", "--out-of-core"},         {"planet", "--planet"},
      {"planetFlattening", "--ellipsoid"},    {"planetRadius", "--radius"},
      {"shard", "--shard"},                   {"shards", "--shards"}};
  const auto it = kFlags.find(name);
  return std::string(it == kFlags.end() ? name : it->second);
}

int runBuild(const TerrainBuildOptions& o) {
  std::cout << buildSummary(o.output, buildTerrainAtlas(o));
  return 0;
}

int runBuild(const MeshBuildOptions& o) {
  std::cout << buildSummary(o.output, buildMeshAtlas(o));
  return 0;
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
    const double t = mx > 0.f && d.largest > 0.0 ? std::clamp(1.0 + std::log10(double(mx) / d.largest) / 4.0, 0.0, 1.0) : 0.0;
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
  so.minNodeRoom = a.maxNodes;  // the page pool holds the budget's cuts
  gl::AtlasScene scene(atlas, so);
  spdlog::info("GPU page pool: {} pages of {} bytes in {} texture array(s), room for cuts of {} nodes",
               scene.renderer().pageCapacity(), scene.pageBytes(), scene.renderer().pageArrays(), scene.nodeRoom());
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
  std::string csv = "frame,nodes,triangles,max_screen_error_px,adapt_ms,stitch_ms,upload_ms,draw_ms,"
                    "draw_calls,pages_loaded,pages_missing,pages_requested,nodes_substituted,node_budget_bound,"
                    "constraint_raises,constraint_splits,attribute_texels,attribute_above_page,root_floor,"
                    "budget_below_roots,max_nodes,max_triangles,frame_ms,gpu_ms,closed_groups,grouped_roots,"
                    "resident_gpu_bytes,gpu_budget_bytes,resident_ram_bytes,ram_budget_bytes,upload_bytes,"
                    "loads_issued,loads_done,loads_cancelled,loads_failed,prefetch_requests,pages_needed,"
                    "pages_resident,incomplete\n";
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
      spdlog::warn("--max-nodes {} is below the {} visible {} (frame {}): no cut has fewer nodes, so such frames "
                   "draw the visible roots (root_floor, budget_below_roots in stats.csv)",
                   a.maxNodes, f.adapt.rootFloor, atlas.hierarchy.groups.empty() ? "chart roots" : "top groups", i);
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
      spdlog::info("frame {}: wrote the cut as drawn to {}: {} vertices, {} triangles; {} boundary edges, {} on open "
                   "chart borders, {} elsewhere (cracks, or the edge of what the view culled)",
                   i, ex->second.string(), mesh.positions.size(), mesh.triangles.size(), mesh.boundaryEdges,
                   mesh.openBorderEdges, mesh.otherBoundaryEdges);
    }
    csv += fmt::format("{},{},{},{:.4f},{:.4f},{:.4f},{:.4f},{:.4f},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{:.4f},{:.4f},{},{}", i,
                       f.cut.nodeCount(),
                       f.draw.triangles, f.maxErrorPx, f.adaptMs, f.stitchMs, f.uploadMs, f.draw.drawMs,
                       f.draw.drawCalls, f.pagesLoaded + f.pagesUploaded, f.pagesMissing, f.pagesRequested, f.nodesSubstituted,
                       int(f.adapt.nodeBudgetBound), f.adapt.constraintRaises,
                       f.adapt.constraintSplits, f.attributes.texels, f.attributes.abovePage, f.adapt.rootFloor,
                       int(f.adapt.budgetBelowRoots), budgetMode ? bo.maxNodes : a.maxNodes,
                       budgetMode ? bo.maxTriangles : 0, frameMs, f.draw.gpuMs, f.adapt.closedGroups,
                       f.adapt.groupedRoots);
    csv += fmt::format(",{},{},{},{},{},{},{},{},{},{},{},{},{}\n", f.residentGpuBytes, f.gpuBudgetBytes,
                       f.residentRamBytes, so.asyncLoads ? so.ramCacheBytes : 0, f.uploadBytes, f.loadsIssued,
                       f.loadsDone, f.loadsCancelled, f.loadsFailed, f.prefetchRequests, f.pagesNeeded,
                       f.pagesResident, int(f.incomplete));
    drawMsTotal += f.draw.drawMs;
    triTotal += f.draw.triangles;
    spdlog::info("frame {:4d}: {:5d} nodes, {:8d} triangles, max error {:.3f} px, adapt {:.3f} ms, draw {:.2f} ms",
                 i, f.cut.nodeCount(), f.draw.triangles, f.maxErrorPx, f.adaptMs, f.draw.drawMs);
  }
  atomicWriteFile(out / "stats.csv", csv.data(), csv.size());
  std::cout << fmt::format("rendered {} frames to {} on {}: {:.2f} M triangles/s\n", cams.size(), a.output,
                           context->renderer(), drawMsTotal > 0 ? double(triTotal) / drawMsTotal * 1e-3 : 0.0);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"gimlod: multi-grained level of detail from seamless geometry-image atlases"};
  app.require_subcommand(1);
  spdlog::set_pattern("[%l] %v");
  spdlog::set_default_logger(spdlog::stderr_color_mt("gimlod"));
  spdlog::set_pattern("[%l] %v");
  // SPDLOG_LEVEL=debug (or warn, ...) sets the log level.
  spdlog::cfg::load_env_levels();

  // note: the shared options are parsed into `common`, the others into the struct of the input
  // kind they apply to (told from the input's content when the command runs).
  CommonBuildOptions common;
  TerrainBuildOptions terrain;
  MeshBuildOptions mesh;
  auto* build =
      app.add_subcommand("build", "Build an atlas (charts, pyramids, hierarchy) from a DEM or a mesh");
  build
      ->add_option("input", common.input,
                   "DEM (GeoTIFF, SRTM .hgt, USGS .dem, netCDF, ESRI ASCII, ...) or mesh (PLY, OBJ, OFF, STL)")
      ->required();
  build->add_option("-o,--output", common.output, "Atlas directory to create")->required();
  auto* chartSizeOpt =
      build->add_option("--chart-size", terrain.chartSize, "Chart side in samples, 2^m+1 (DEMs: by default the smallest from 513 that gives at most 64 charts, "
                    "up to 32769, 2049 with imagery; meshes: from the input's density, 65 to 1025)");
  std::string chartsArg = "auto";
  build
      ->add_option("--charts", chartsArg,
                   "Meshes: target patches (each becomes 1-5 quad charts, see --quads, and the chart repair may cut more); auto: "
                   "24 up to 4M triangles, above that about sqrt(triangles) / 80, at least 48; 0: --chart-error")
      ->capture_default_str();
  std::string quadsArg = "auto";
  build->add_option("--quads", quadsArg,
                    "Meshes: how a patch becomes quad charts: sides (each chart edge a whole patch side, about n/2 "
                    "charts an n-sided patch, one for 4 sides), kites (each side halved, n charts), or auto (sides, "
                    "and kites too if sides leave flipped texels, two-chart corners or a sampling error over the bound; "
                    "from the density's chart size up, doubled only while neither layout meets the bound; keeping "
                    "the first that leaves nothing to repair, else whichever leaves fewer flipped texels)")
      ->check(CLI::IsMember({"auto", "sides", "kites"}))
      ->capture_default_str();
  std::string normalsArg = "auto";
  build->add_option("--normals", normalsArg,
                    "Meshes: stored (every sample's normal is stored), derived (only block borders' normals are "
                    "stored; readers derive the others from the positions), or auto (derived when the charts keep at "
                    "most 16 samples per input triangle)")
      ->check(CLI::IsMember({"auto", "stored", "derived"}))
      ->capture_default_str();
  std::string sizingArg = "patch";
  build->add_option("--sizing", sizingArg,
                    "Meshes: patch (each patch's charts at their own size: from the density's, doubled while they "
                    "fold or sample the surface more coarsely than --sample-error; one quad layout, sides unless "
                    "--quads kites, no patch cut) or layout (every chart at one size, the chart repair cutting the "
                    "patches whose charts fold or sample too coarsely, and with --quads auto both layouts tried); "
                    "--chart-size asks for one size")
      ->check(CLI::IsMember({"patch", "layout"}))
      ->capture_default_str();
  std::string quadMapArg = "bilinear";
  build->add_option("--quad-map", quadMapArg,
                    "Meshes: how a quad chart's square maps into its patch's parameterization: bilinear (of the "
                    "quad's corners), stretch (least stretch over the chart itself; the border samples are the same), or "
                    "folding (stretch for the charts that fold under bilinear, where they fold less)")
      ->check(CLI::IsMember({"bilinear", "stretch", "folding"}))
      ->capture_default_str();
  build->add_flag("--full-charts", [&](int64_t) { mesh.coarsenCharts = false; },
                  "Meshes: every chart keeps its finest samples, each where it was resampled (by default a chart "
                  "keeps only the levels from the coarsest whose surface stays within --sample-error of the input "
                  "vertices, and the squares of that level that the two triangles of their corners follow within it "
                  "move onto them, their corners alone stored)");
  build->add_flag("--no-unfold", [&](int64_t) { mesh.unfold = false; },
                  "Meshes: keep every inner sample where the quad map puts it (no sliding of the samples round "
                  "flipped texels over the surface to unfold them)");
  std::string chartMetricArg = "auto";
  build->add_option("--chart-metric", chartMetricArg,
                    "Meshes: what the patch clustering keeps patches: planar (plane fit and normal spread), "
                    "developable (cone fit: planes, cylinders and cones, so fewer, larger patches flatten with "
                    "little stretch), or auto (developable up to 4M triangles, planar above)")
      ->check(CLI::IsMember({"auto", "planar", "developable"}))
      ->capture_default_str();
  build->add_option("--chart-error", mesh.maxChartError,
                    "Meshes with --charts 0: largest RMS plane distance of a patch / bounding-box diagonal")
      ->capture_default_str();
  std::string maxMemory = "4G";
  bool noFidelity = false;
  build->add_flag("--no-fidelity", noFidelity, "Meshes: skip the Hausdorff distance between the input and the atlas");
  std::string fidelityArg = "fast";
  build->add_option("--fidelity", fidelityArg,
                    "Meshes: how the Hausdorff distance is measured: fast (the atlas read a chart at a time: every "
                    "input vertex and triangle centroid measured exactly, the atlas side on about a million samples "
                    "with the confidence stated) or full (the whole atlas surface welded and every sample measured; "
                    "memory grows with the atlas)")
      ->check(CLI::IsMember({"fast", "full"}))
      ->capture_default_str();
  build->add_option("--repair-rounds,--flip-repair-rounds", mesh.repairRounds,
                    "Meshes: rounds of each chart repair (cutting patches whose charts have flipped texels or a "
                    "sampling error over --sample-error); 0: none")
      ->capture_default_str();
  build->add_option("--repair-budget,--flip-repair-budget", mesh.repairBudget,
                    "Meshes: the chart repair stops once it has parameterized this many times the surface's triangles "
                    "again, counting at most 2^20 of them (its time is about this many resamplings up to a million "
                    "triangles); with --quads auto, each of its repairs (up to two layouts at each size it tries) "
                    "takes a quarter")
      ->capture_default_str();
  double sampleErrorPercent = -1.0;
  build->add_option("--sample-error", sampleErrorPercent,
                    "Meshes: the largest distance, in % of the bounding-box diagonal, from an input vertex to its "
                    "chart's surface; patches whose charts exceed it are cut; 0: flips only (default: 0.05 when the "
                    "chart size is chosen by density, else 0)");
  build->add_option("--max-memory", maxMemory,
                    "Memory cap (e.g. 2G, 512M). Meshes: larger ones go through cell files. DEMs: one whose "
                    "in-memory build would exceed it is built window by window within it (default for DEMs: 3/4 of "
                    "the machine's memory)")
      ->capture_default_str();
  build
      ->add_option("--depth", common.depth,
                   "Quadtree levels per chart, 1 to 12 (default: as many as leave the finest nodes 32 intervals wide; "
                   "DEMs at least 5, meshes at most 5)");
  build->add_option("--node-res", common.nodeRes, "Maximum node resolution R in intervals (power of two)")
      ->capture_default_str();
  build->add_option("--min-node-res", common.minNodeRes, "Minimum node resolution in intervals")->capture_default_str();
  build->add_option("--z-scale", terrain.zScale, "Height multiplier")->capture_default_str();
  build->add_option("--subdataset", terrain.subdataset, "netCDF variable / GDAL subdataset to read");
  build->add_option("--band", terrain.band,
                    "DEMs: the band holding the heights, from 1 (default: band 1; a 3- or 4-band byte image is "
                    "refused as colour)");
  std::vector<double> spacingArg;
  build->add_option("--spacing", spacingArg,
                    "DEMs: metres between samples, X[,Y] (east, north; Y defaults to X), in place of the georeference's "
                    "(a raster without one is otherwise taken as 1 m)")
      ->delimiter(',')
      ->expected(1, 2);
  build->add_option("--threads", common.threads, "Worker threads (0: all cores)")->capture_default_str();
  build->add_option("--imagery", terrain.imagery,
                    "DEMs: colour raster (RGB/RGBA/grey, any format GDAL reads) draped over the terrain, reprojected "
                    "with GDAL onto the DEM's grid at its own resolution");
  uint32_t imageryScale = 0;
  build->add_option("--imagery-scale", imageryScale,
                    "DEMs with --imagery: imagery samples per DEM sample interval, 1, 2 or 4 (default: the power of "
                    "two nearest the two rasters' resolutions)");
  std::vector<double> imageryExtent;
  build->add_option("--imagery-extent", imageryExtent,
                    "DEMs with --imagery: WEST,SOUTH,EAST,NORTH of imagery without a georeference, in the DEM's "
                    "reference system (a whole-Earth image: -180,-90,180,90)")
      ->delimiter(',')
      ->expected(4);

  build->add_option("--height-precision", terrain.heightPrecision,
                    "DEMs: heights that are not whole metres are stored to this step, in metres; whole metres are "
                    "stored exactly (default: 1 for a source of whole metres like SRTM, whose filled voids are "
                    "rounded like it, else 0.01)");
  build->add_flag("--out-of-core", terrain.outOfCore,
                  "DEMs: build window by window within --max-memory even when the DEM would fit in memory "
                  "(a DEM that would not is built so anyway)");
  build->add_flag("--planet", terrain.planet,
                  "DEMs in longitude and latitude: draw the terrain on a sphere (a DEM circling the planet wraps at "
                  "the antimeridian and closes at the poles)");
  build->add_option("--radius", terrain.planetRadius, "DEMs with --planet: the sphere's radius, metres")
      ->capture_default_str();
  std::string ellipsoid;
  build->add_option("--ellipsoid", ellipsoid,
                    "DEMs with --planet: draw on a reference ellipsoid instead of a sphere, heights along its "
                    "normal (WGS84 or GRS80)");
  bool uncompressed = false;
  build->add_flag("--uncompressed", uncompressed,
                  "Write raw chart files (atlas format version 1: float32 heights or positions, 4-byte normals) "
                  "instead of compressed ones");
  build->add_option("--position-bits", mesh.positionBits,
                    "Meshes: positions are stored on a lattice of 2^B steps across the bounding-box diagonal")
      ->capture_default_str();
  double positionTolerancePercent = 100.0 * kDefaultPositionTolerance;
  build->add_option("--position-tolerance", positionTolerancePercent,
                    "Meshes: positions inside a chart may move this far, in % of the bounding-box diagonal, to the "
                    "lattice point their neighbours predict, so they code in fewer bytes; the Hausdorff distance "
                    "grows by at most this much; 0: every position at its nearest lattice point")
      ->capture_default_str();
  build->add_option("--normal-tolerance", mesh.normalTolerance,
                    "Meshes: normals inside a chart may move this many packed steps (1/127.5) per component to "
                    "the value their neighbours predict; 0: normals stored as sampled")
      ->capture_default_str();
  ShardArgs shardArgs;
  build->add_flag("--prepare", shardArgs.prepare,
                  "DEMs, a build across processes: the step that reads the whole DEM, once, into the shard area "
                  "beside the atlas (ATLAS.shards, on a file system every node sees); then --shard, then merge");
  build->add_option("--shard", shardArgs.shard,
                    "DEMs, a build across processes: build shard I of N (I from 0) after --prepare; each shard can be "
                    "run again alone")
      ->excludes("--prepare");
  build->add_flag("--mpi", shardArgs.mpi,
                  "DEMs: under mpirun, rank 0 prepares and merges and every rank takes shards from a work list")
      ->excludes("--prepare")
      ->excludes("--shard");
  build->add_option("--shards", shardArgs.shards, "With --mpi or --emit-slurm: the number of shards (default: four a "
                    "rank, at most one a chart; or 8)");
  build->add_option("--emit-slurm", shardArgs.slurmDir,
                    "DEMs: write Slurm batch scripts for this build into DIR (prepare, a job array of shards, the "
                    "merge, and submit.sh chaining them with --dependency=afterok) instead of building")
      ->excludes("--prepare")
      ->excludes("--shard")
      ->excludes("--mpi");
  fs::path mergeAtlas;
  uint32_t mergeShardCount = 0;
  auto* mergeCmd = app.add_subcommand(
      "merge", "Merge the shards of a build across processes (gimlod build --prepare, then --shard I/N) into the atlas");
  mergeCmd->add_option("atlas", mergeAtlas, "The atlas directory the shards were built for")->required();
  mergeCmd->add_option("--shards", mergeShardCount, "The N the shards were run with (default: the one N present)");

  RenderArgs r;
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
  render->add_option("--texel-ratio", r.texelRatio,
                     "Normal-map texels per pixel of a node's projected size (0: page resolution)")
      ->capture_default_str();
  addStreamingOptions(render, r.streaming);
  render->add_option("--overlay", r.overlay,
                     "Draw over the shading: chart (each chart its colour, seams dark, open borders red), level, res, "
                     "error (heat map: blue 0, red at the tolerance, or the frame's largest error with --triangles)")
      ->capture_default_str();
  render->add_option("--export-cut", r.exportCut,
                     "FRAME:FILE.ply: write the cut drawn at that frame as one welded mesh (stitched positions from "
                     "the vertex shader, per-vertex chart, level, node and resolution); repeatable");
  render->add_flag("--no-stitch", r.noStitch, "Export cuts without border stitching (a negative control: it cracks)");

  BenchArgs bn;
  auto* bench = addBenchCommand(app, bn);

  std::string exportAtlas, exportOut;
  uint32_t exportLevel = 0;
  auto* exportCmd = app.add_subcommand(
      "export", "Write a mesh atlas's surface at one pyramid level as one PLY, welded along the seams");
  exportCmd->add_option("atlas", exportAtlas, "Atlas directory (a mesh or planet atlas)")->required();
  exportCmd->add_option("-o,--output", exportOut, "Output .ply")->required();
  exportCmd->add_option("--level", exportLevel, "Pyramid level (0: full resolution)")->capture_default_str();

  InspectArgs inspect;
  auto* inspectCmd = app.add_subcommand(
      "inspect", "Write an inspection report of an atlas (index.html, report.json, images) that opens from disk");
  inspectCmd->add_option("atlas", inspect.report.atlas, "Atlas directory")->required();
  inspectCmd->add_option("-o,--output", inspect.report.output, "Report directory to create")->required();
  inspectCmd->add_option("--worst", inspect.report.worstCharts, "Charts shown with images, the worst first (figures for all)")
      ->capture_default_str();
  inspectCmd->add_option("--image-size", inspect.report.thumbnailSize, "Largest chart image side in samples")
      ->capture_default_str();
  inspectCmd->add_option("--source", inspect.report.source,
                         "The mesh or DEM the atlas was built from: compare them sample by sample (where the distances lie)");
  inspectCmd->add_option("--view-size", inspect.viewSize, "Size WxH of the six rendered views")->capture_default_str();
  inspectCmd->add_flag("--no-views", [&](int64_t) { inspect.views = false; },
                       "Skip the rendered views (no GL needed)");

  ViewArgs view;
  auto* viewCmd = addViewCommand(app, view);

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    return app.exit(e);
  }
  // Long stages show their progress: a bar with an ETA on a terminal (redrawn 5 times a second),
  // a log line every 10 s otherwise (GIMLOD_PROGRESS_SECONDS sets that interval).
  {
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
  try {
    if (*build) {
      const uint64_t maxMemoryBytes = parseBytes("--max-memory", maxMemory);
      // (0 is how the options say "not given".)
      if (build->get_option("--depth")->count() > 0 && (common.depth < 1 || common.depth > 12))
        throw InputError("--depth " + std::to_string(common.depth) + " must be in [1, 12]");
      common.spellOption = flagFor;
      common.compress = !uncompressed;
      if (isMesh(detectInputKind(common.input))) {
        if (shardArgs.any())
          throw InputError(common.input.string() + ": builds across processes (--prepare, --shard, --mpi, "
                           "--emit-slurm) take DEMs; a mesh is built in one process");
        if (!terrain.imagery.empty())
          throw InputError(common.input.string() + ": --imagery drapes a raster over a DEM; a mesh carries its own "
                           "vertex colours");
        if (terrain.planet)
          throw InputError(common.input.string() + ": --planet draws a longitude/latitude DEM on a sphere; a mesh "
                           "is drawn as it is");
        static_cast<CommonBuildOptions&>(mesh) = common;
        if (chartSizeOpt->count() > 0) mesh.chartSize = terrain.chartSize;
        mesh.charts = chartsArg == "auto" ? kAutoCharts : parseCount("--charts", chartsArg);
        mesh.chartMetric = chartMetricArg == "developable" ? MeshChartMetric::kDevelopable
                           : chartMetricArg == "planar"    ? MeshChartMetric::kPlanar
                                                           : MeshChartMetric::kAuto;
        mesh.quadMap = quadMapArg == "stretch"   ? MeshQuadMap::kStretch
                       : quadMapArg == "folding" ? MeshQuadMap::kFolding
                                                 : MeshQuadMap::kBilinear;
        mesh.normals = normalsArg == "stored"    ? MeshNormals::kStored
                       : normalsArg == "derived" ? MeshNormals::kDerived
                                                 : MeshNormals::kAuto;
        mesh.sizing = sizingArg == "layout" ? MeshSizing::kLayout : MeshSizing::kPatch;
        mesh.quads = quadsArg == "sides" ? MeshQuads::kSides : quadsArg == "kites" ? MeshQuads::kKites : MeshQuads::kAuto;
        mesh.maxSampleError = sampleErrorPercent < 0.0 && build->get_option("--sample-error")->count() == 0
                                  ? kAutoSampleError
                                  : sampleErrorPercent / 100.0;
        mesh.maxMemory = maxMemoryBytes;
        mesh.positionTolerance = positionTolerancePercent / 100.0;
        mesh.measureFidelity = !noFidelity;
        mesh.fidelity = fidelityArg == "full" ? MeshFidelity::kFull : MeshFidelity::kFast;
        return runBuild(mesh);
      }
      static_cast<CommonBuildOptions&>(terrain) = common;

      if (build->get_option("--max-memory")->count() > 0) terrain.maxMemory = maxMemoryBytes;
      if (build->get_option("--imagery-scale")->count() > 0) {
        if (imageryScale != 1 && imageryScale != 2 && imageryScale != 4)
          throw InputError("--imagery-scale " + std::to_string(imageryScale) + " must be 1, 2 or 4");
        terrain.imageryScaleLog2 = int(log2u(imageryScale));
      }
      if (!spacingArg.empty()) {
        for (double v : spacingArg)
          if (!(v > 0.0) || !std::isfinite(v))
            throw InputError("--spacing " + std::to_string(v) + " must be a positive number of metres");
        terrain.spacing = {spacingArg[0], spacingArg.back()};
      }
      if (!imageryExtent.empty())
        terrain.imageryExtent = std::array<double, 4>{imageryExtent[0], imageryExtent[1], imageryExtent[2],
                                                      imageryExtent[3]};
      if (terrain.imagery.empty() && (terrain.imageryExtent || terrain.imageryScaleLog2 >= 0))
        throw InputError("--imagery-scale and --imagery-extent need --imagery");
      if (build->get_option("--radius")->count() > 0 && !terrain.planet) throw InputError("--radius needs --planet");
      if (!ellipsoid.empty()) {
        if (!terrain.planet) throw InputError("--ellipsoid needs --planet");
        if (build->get_option("--radius")->count() > 0)
          throw InputError("--ellipsoid and --radius: give one (an ellipsoid has its own radii)");
        const Ellipsoid* e = findEllipsoid(ellipsoid);
        if (!e) throw InputError("--ellipsoid " + ellipsoid + ": unknown; give WGS84 or GRS80");
        terrain.planetRadius = e->radius;
        terrain.planetFlattening = e->flattening;
      }
      if (!(terrain.planetRadius >= 1.0 && terrain.planetRadius <= 1e9))
        throw InputError("--radius " + std::to_string(terrain.planetRadius) + " must be between 1 and 1e9 metres");
      if (shardArgs.any()) return runShardedBuild(terrain, shardArgs, argc, argv);
      return runBuild(terrain);
    }
    if (*mergeCmd) {
      std::cout << shardSummary(mergeShards(mergeAtlas, mergeShardCount), mergeAtlas);
      return 0;
    }
    if (*inspectCmd) return runInspect(inspect);
    if (*render) return runRender(r);
    if (*bench) return runBench(bn);
    if (*viewCmd) return runView(view);
    if (*exportCmd) {
      const AtlasSurface s = readAtlasSurface(exportAtlas, exportLevel);
      writePly(exportOut, s.positions, s.triangles);
      std::cout << fmt::format("wrote {}: {} vertices, {} triangles from {} chart samples at level {}; {} boundary edges\n",
                               exportOut, s.positions.size(), s.triangles.size(), s.samples, exportLevel,
                               s.boundaryEdges);
      return 0;
    }
  } catch (const InputError& e) {
    spdlog::error("{}", e.message(flagFor));
    return 2;
  } catch (const std::exception& e) {
    spdlog::error("{}", e.what());
    return 1;
  }
  return 0;
}
