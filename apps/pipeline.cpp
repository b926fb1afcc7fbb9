#include "apps/pipeline.h"

#include <unistd.h>
#if defined(__GLIBC__)
#include <malloc.h>
#endif

#include <chrono>
#include <condition_variable>
#include <mutex>
#include <thread>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <random>

#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#include "atlas/charting.h"
#include "atlas/dem.h"
#include "atlas/fidelity.h"
#include "atlas/gridify.h"
#include "atlas/mesh_atlas.h"
#include "atlas/mesh_io.h"
#include "atlas/layout_refine.h"
#include "atlas/resample.h"
#include "atlas/terrain_atlas.h"
#include "core/atlas_format.h"
#include "hierarchy/hierarchy.h"

namespace fs = std::filesystem;

namespace gimlod {
namespace {

bool isPowerOfTwo(uint32_t v) { return v && !(v & (v - 1)); }

uint32_t log2u(uint32_t v) {
  uint32_t l = 0;
  while ((1u << l) < v) ++l;
  return l;
}

bool isMeshFile(const fs::path& p) {
  std::string e = p.extension().string();
  for (char& c : e) c = char(std::tolower(static_cast<unsigned char>(c)));
  return e == ".ply" || e == ".obj" || e == ".off" || e == ".stl";
}

uint64_t directoryBytes(const fs::path& dir) {
  uint64_t total = 0;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.is_regular_file()) total += e.file_size();
  return total;
}

// What the mesh reader read, repaired and warned about (README, "Mesh input").
nlohmann::json readStatsJson(const MeshReadStats& rs) {
  return {{"format", rs.info.formatName},
          {"vertices", rs.vertices},
          {"faces", rs.faces},
          {"triangles_read", rs.trianglesRead},
          {"triangles", rs.trianglesOut},
          {"non_finite_vertices", rs.nonFiniteVertices},
          {"dropped_non_finite", rs.droppedNonFinite},
          {"dropped_degenerate", rs.droppedDegenerate},
          {"dropped_duplicate", rs.droppedDuplicate},
          {"duplicate_check_complete", rs.duplicateCheckComplete},
          {"short_faces", rs.shortFaces},
          {"polygons_fanned", rs.polygonsFanned},
          {"strips", rs.strips},
          {"colours", rs.hasColours},
          {"warnings", rs.warnings},
          {"seconds", rs.seconds}};
}

// Hands freed heap memory back to the system between stages: glibc keeps the freed pages of its
// worker arenas, which would count against --max-memory in the stages after.
void releaseFreedMemory() {
#if defined(__GLIBC__)
  malloc_trim(0);
#endif
}

double secondsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// A kB figure ("VmHWM:", "VmRSS:") of /proc/self/status, in bytes; 0 where unavailable.
uint64_t procStatusBytes(const char* key) {
  std::FILE* f = std::fopen("/proc/self/status", "r");
  if (!f) return 0;
  char line[256];
  uint64_t kb = 0;
  const size_t n = std::strlen(key);
  while (std::fgets(line, sizeof line, f))
    if (std::strncmp(line, key, n) == 0) {
      kb = std::strtoull(line + n, nullptr, 10);
      break;
    }
  std::fclose(f);
  return kb * 1024;
}

// Per-stage wall time, CPU time and peak resident memory. A sampler thread reads the resident
// size every 5 ms and keeps the largest since the stage began (the kernel's own peak, VmHWM, is
// left alone: resetting it would also reset the rusage peak that /usr/bin/time reports). A
// stage's figure is the larger of its sampled peak and VmHWM when VmHWM grew during the stage;
// the whole build's peak is the larger of VmHWM and the stages' peaks.
class StageMeter {
 public:
  explicit StageMeter(nlohmann::json& stages) : stages_(stages) {
    sampler_ = std::thread([this] {
      std::unique_lock<std::mutex> lock(mutex_);
      while (!stop_) {
        lock.unlock();
        const uint64_t rss = procStatusBytes("VmRSS:");
        lock.lock();
        stagePeak_ = std::max(stagePeak_, rss);
        wake_.wait_for(lock, std::chrono::milliseconds(5));
      }
    });
  }
  ~StageMeter() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      stop_ = true;
    }
    wake_.notify_all();
    sampler_.join();
  }
  void start() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      stagePeak_ = procStatusBytes("VmRSS:");
    }
    hwm0_ = procStatusBytes("VmHWM:");
    t0_ = std::chrono::steady_clock::now();
    cpu0_ = std::clock();
  }
  // Ends the running stage, records it under `name`, and starts the next one.
  void finish(const std::string& name) {
    const double wall = secondsSince(t0_);
    const double cpu = double(std::clock() - cpu0_) / CLOCKS_PER_SEC;
    const uint64_t hwm = procStatusBytes("VmHWM:");
    uint64_t peak = procStatusBytes("VmRSS:");
    {
      std::lock_guard<std::mutex> lock(mutex_);
      peak = std::max(peak, stagePeak_);
    }
    if (hwm > hwm0_) peak = std::max(peak, hwm);  // the process peak was reached in this stage
    stages_.push_back({{"stage", name}, {"seconds", wall}, {"cpu_seconds", cpu}, {"peak_rss_bytes", peak}});
    largestStagePeak_ = std::max(largestStagePeak_, peak);
    spdlog::info("stage {:<10} {:8.2f} s wall {:8.2f} s cpu  peak RSS {:7.1f} MiB", name, wall, cpu,
                 double(peak) / (1 << 20));
    start();
  }
  // The build's peak: VmHWM, or a stage's sampled peak where that is higher (pages handed back
  // with madvise, as malloc_trim does, leave before the kernel's high-water mark sees them).
  uint64_t peak() const { return std::max(procStatusBytes("VmHWM:"), largestStagePeak_); }

 private:
  nlohmann::json& stages_;
  std::chrono::steady_clock::time_point t0_;
  std::clock_t cpu0_ = 0;
  uint64_t hwm0_ = 0;
  std::mutex mutex_;
  std::condition_variable wake_;
  bool stop_ = false;
  uint64_t stagePeak_ = 0;
  uint64_t largestStagePeak_ = 0;
  std::thread sampler_;
};

}  // namespace

void validateBuildOptions(const BuildOptions& o) {
  if (!(o.chartSize >= 9 && o.chartSize <= 8193 && isPowerOfTwo(o.chartSize - 1)))
    throw InputError(fmt::format("--chart-size {} must be 2^m+1 between 9 and 8193 (e.g. 257, 513, 1025)",
                                 o.chartSize));
  if (!isPowerOfTwo(o.nodeRes) || o.nodeRes < 4 || o.nodeRes > 1024 || o.nodeRes > o.chartSize - 1)
    throw InputError(fmt::format("--node-res {} must be a power of two in [4, min(1024, chart-size - 1)]", o.nodeRes));
  if (!isPowerOfTwo(o.minNodeRes) || o.minNodeRes > o.nodeRes)
    throw InputError(fmt::format("--min-node-res {} must be a power of two in [1, --node-res]", o.minNodeRes));
  if (!std::isfinite(o.zScale) || o.zScale == 0.0) throw InputError("--z-scale must be finite and non-zero");
  if (o.threads > 1024) throw InputError("--threads must be at most 1024");
  HierarchyParams p;
  p.intervalsLog2 = log2u(o.chartSize - 1);
  p.depth = o.depth;
  p.maxNodeResLog2 = log2u(o.nodeRes);
  p.minNodeResLog2 = log2u(o.minNodeRes);
  p.validate();
}

// Mesh input: section 5 of the paper, then the same hierarchy as terrain over the geometry images.
nlohmann::json buildMeshAtlas(const BuildOptions& o) {
  if (!isChartSizeValid(o.meshChartSize) || o.meshChartSize < 9)
    throw InputError("--chart-size " + std::to_string(o.meshChartSize) + " must be 2^m + 1 with m >= 3 for meshes");
  if (o.maxMemory < (64ull << 20)) throw InputError("--max-memory must be at least 64 MiB");
  if (o.threads > 1024) throw InputError("--threads must be at most 1024");
  if (o.nodeRes < 4 || (o.nodeRes & (o.nodeRes - 1)) || o.minNodeRes < 2 || (o.minNodeRes & (o.minNodeRes - 1)) ||
      o.minNodeRes > o.nodeRes)
    throw InputError("--node-res and --min-node-res must be powers of two with 2 <= min <= node-res");
  if (o.depth < 1 || o.depth > 12) throw InputError("--depth must be in [1, 12]");
  if (o.flipRepairRounds > 16) throw InputError("--flip-repair-rounds must be in [0, 16]");
  if (!(o.flipRepairBudget >= 0.0 && o.flipRepairBudget <= 100.0))
    throw InputError("--flip-repair-budget must be in [0, 100] (times the surface's triangles)");
  if (o.meshChartSize > 8193)
    throw InputError("--chart-size " + std::to_string(o.meshChartSize) + " is above 8193, the largest mesh chart size");
  if (o.charts == 0 && !(o.maxChartError > 0.0 && std::isfinite(o.maxChartError)))
    throw InputError("--chart-error must be a positive fraction of the bounding-box diagonal (it is the target when "
                     "--charts is 0)");
  // note: for meshes R is capped at chart-size - 1 and the depth at what the chart allows (leaves
  // keep at least the minimum node resolution).
  HierarchyParams p;
  p.intervalsLog2 = log2u(o.meshChartSize - 1);
  p.maxNodeResLog2 = std::min(log2u(o.nodeRes), p.intervalsLog2);
  p.minNodeResLog2 = std::min(log2u(o.minNodeRes), p.maxNodeResLog2);
  p.depth = std::min(o.depth, p.intervalsLog2 - p.minNodeResLog2 + 1);
  p.validate();
  std::unique_ptr<tbb::global_control> threads;
  if (o.threads)
    threads = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, o.threads);
  const auto t0 = std::chrono::steady_clock::now();
  nlohmann::json stats = {{"input", fs::absolute(o.input).string()}, {"kind", atlasKindName(AtlasKind::Geometry)}};
  nlohmann::json stages = nlohmann::json::array();
  StageMeter meter(stages);
  meter.start();

  // Read and cluster: in memory, or through cell files when the mesh is large.
  ChartingOptions copt;
  copt.targetCharts = o.charts;
  copt.maxError = o.maxChartError;
  copt.threads = o.threads;
  ChartingStats cst;
  ChartLayout layout;
  IndexedMesh mesh;  // kept for the fidelity figure (in-memory path)
  fs::path gridDir;  // the cell files, kept for the fidelity figure (out-of-core path)
  const MeshInfo info = probeMesh(o.input);
  const bool outOfCore = info.triangleEstimate * 256 > o.maxMemory / 4;
  StagedDirectory stage(o.output, kManifestName, "atlas");
  if (outOfCore) {
    GridifyOptions g;
    g.maxMemoryBytes = o.maxMemory;
    const fs::path grid = stage.path() / "grid.tmp";
    const GridifyResult gr = gridify(o.input, grid, g);
    meter.finish("gridify");
    layout = buildChartLayoutFromCells(grid, copt, &cst);
    if (o.measureFidelity) {
      gridDir = grid;  // the input for the fidelity figure, removed after it
    } else {
      std::error_code ec;
      fs::remove_all(grid, ec);
    }
    stats["gridify"] = {{"cells", gr.cells},
                        {"triangles", gr.triangles},
                        {"max_cell_triangles", gr.maxCellTriangles},
                        {"peak_buffered_bytes", gr.peakBufferedBytes},
                        {"peak_tracked_bytes", gr.peakTrackedBytes},
                        {"bytes_written", gr.bytesWritten},
                        {"seconds", gr.seconds}};
    stats["read"] = readStatsJson(gr.read);
  } else {
    mesh = readMesh(o.input);
    const MeshReadStats& rs = mesh.stats;
    stats["read"] = readStatsJson(rs);
    for (const std::string& w : rs.warnings) spdlog::warn("{}: {}", o.input.string(), w);
    meter.finish("read");
    layout = buildChartLayout(mesh, copt, &cst);
  }
  meter.finish("charting");
  const double chartingSec = secondsSince(t0);
  stats["charting"] = {{"triangles", cst.outputTriangles},     {"patches", cst.charts},
                       {"dropped_degenerate", cst.droppedDegenerate}, {"dropped_duplicate", cst.droppedDuplicate},
                       {"vertices_welded", cst.verticesWelded}, {"non_manifold_edges", cst.nonManifoldEdges},
                       {"non_manifold_vertices", cst.nonManifoldVertices}, {"vertices_split", cst.verticesSplit},
                       {"boundary_edges", cst.boundaryEdges},   {"corners_inserted", cst.cornersInserted},
                       {"patches_split", cst.patchesSplit},     {"max_planarity_error", cst.maxPlanarityError},
                       {"sides_histogram", cst.sidesHistogram}, {"out_of_core", outOfCore},
                       {"cells", cst.cells},                    {"cell_clusters", cst.cellClusters},
                       {"cell_clusters_dissolved", cst.cellClustersDissolved},
                       {"charts_before_fixing", cst.chartsBeforeFixing},
                       {"merges_refused_not_disk", cst.mergesRefusedNotDisk},
                       {"patches_unfixed", cst.patchesUnfixed},
                       {"weld_seconds", cst.weldSeconds},       {"cluster_seconds", cst.clusterSeconds},
                       {"cell_seconds", cst.cellSeconds},
                       {"sides_seconds", cst.sidesSeconds},     {"peak_bytes_estimate", cst.peakBytesEstimate},
                       {"seconds", cst.seconds}};
  const std::vector<std::string> bad = validateChartLayout(layout);
  if (!bad.empty()) throw InputError(o.input.string() + ": the chart layout is invalid: " + bad.front());
  meter.finish("validate");
  {
    // Each chart's samples go to a spill file in the staging directory once measured, and are read
    // back one chart at a time per thread to be written: what must fit is a patch's charts (up
    // to 8 quads) and their working arrays on every thread at once in memory, and the spill
    // plus the chart files (with their pyramids) on disk. Refuse a chart size that cannot, before
    // any is made.
    uint64_t quads = 0;
    for (const Patch& pa : layout.patches) quads += pa.sides.size();
    const uint64_t samples = uint64_t(o.meshChartSize) * o.meshChartSize;
    const uint64_t perSample = layout.colours.empty() ? 16 : 20;
    const uint64_t threads = o.threads ? o.threads : uint64_t(std::max(1, tbb::this_task_arena::max_concurrency()));
    const uint64_t inFlight = threads * samples * (8 * perSample + 32);
    if (inFlight > o.maxMemory)
      throw InputError(fmt::format("{}: quad charts of {}^2 samples need {:.1f} GiB of geometry images at once "
                                   "({} threads), more than --max-memory ({:.1f} GiB): lower --chart-size or "
                                   "--threads, or raise --max-memory",
                                   o.input.string(), o.meshChartSize, double(inFlight) / double(1ull << 30), threads,
                                   double(o.maxMemory) / double(1ull << 30)));
    const uint64_t disk = quads * samples * perSample * 3;  // the spill, and chart files a third larger
    std::error_code ec;
    const fs::space_info space = fs::space(stage.path(), ec);
    if (!ec && disk > space.available)
      throw InputError(fmt::format("{}: {} quad charts of {}^2 samples need about {:.1f} GiB of disk in {}, which has "
                                   "{:.1f} GiB free: lower --chart-size or --charts",
                                   o.input.string(), quads, o.meshChartSize, double(disk) / double(1ull << 30),
                                   stage.path().parent_path().string(), double(space.available) / double(1ull << 30)));
  }

  // Quads, parameterization and resampling.
  auto spill = std::make_unique<ChartSpill>(stage.path() / "samples.tmp", o.meshChartSize, !layout.colours.empty());
  ResampleOptions ro;
  ro.chartSize = o.meshChartSize;
  ro.threads = o.threads;
  ro.spill = spill.get();
  const uint32_t straightened = o.straightenRounds ? straightenSides(layout, o.straightenRounds) : 0;
  const uint32_t ears = moveSideEars(layout);
  meter.finish("straighten");
  FlipRepairStats flips;
  GeometryImageSet first = resampleLayout(layout, ro);
  meter.finish("resample");
  // Each repair cut adds working memory: the repair stops cutting once the process holds 3/4 of
  // --max-memory, or once it has parameterized --flip-repair-budget times the triangles again.
  const uint64_t layoutTriangles = layout.triangles.size();
  GeometryImageSet set = repairFlips(
      layout, std::move(first), ro, o.flipRepairRounds, &flips,
      [&] { return procStatusBytes("VmRSS:") < o.maxMemory / 4 * 3; },
      uint64_t(std::llround(o.flipRepairBudget * double(layoutTriangles))));
  if (flips.stoppedForMemory)
    spdlog::warn("{}: the flip repair stopped at 3/4 of --max-memory ({} flipped texels left); raise --max-memory "
                 "to repair more",
                 o.input.string(), set.image.flippedTexels);
  const double repairWork =
      double(flips.trianglesWholeRounds + flips.trianglesTrials) / double(std::max<uint64_t>(layoutTriangles, 1));
  if (flips.stoppedForWork)
    spdlog::warn("{}: the flip repair stopped at its budget, {:.2f} times the surface's triangles parameterized again "
                 "({} flipped texels left); raise --flip-repair-budget to repair more",
                 o.input.string(), repairWork, set.image.flippedTexels);
  const size_t finalPatches = layout.patches.size();
  layout = ChartLayout{};
  meter.finish("flip_repair");
  stats["resample"] = {{"charts", set.charts.size()},
                       {"param_stretch_l2", set.param.stretchL2},
                       {"param_stretch_linf", set.param.stretchLinf},
                       {"param_flipped", set.param.flippedTriangles},
                       {"param_degenerate", set.param.degenerateTriangles},
                       {"image_stretch_l2", set.image.stretchL2},
                       {"image_stretch_linf", set.image.stretchLinf},
                       {"flipped_texels", set.image.flippedTexels},
                       {"texels_against_vertex_normals", set.image.texelsAgainstNormals},
                       {"sides_straightened", straightened},
                       {"side_ears_mended", ears},
                       {"flipped_texels_before_splits", flips.flippedTexelsFirst},
                       {"patches_split_for_flips", flips.patchesSplit},
                       {"patches_unsplittable", flips.patchesUnsplit},
                       {"split_rounds", flips.rounds},
                       {"flip_repair_stopped_for_memory", flips.stoppedForMemory},
                       {"flip_repair_stopped_for_work", flips.stoppedForWork},
                       {"flip_repair_work", repairWork},
                       {"flip_repair_triangles_whole_rounds", flips.trianglesWholeRounds},
                       {"flip_repair_triangles_trials", flips.trianglesTrials},
                       {"patches", finalPatches},
                       {"degenerate_texels", set.image.degenerateTexels}};
  // Per chart: its patch and quad, stretch of the sampled image, flipped and degenerate texels.
  nlohmann::json perChart = nlohmann::json::array();
  for (const GeometryImage& g : set.charts) {
    perChart.push_back({{"patch", g.patch}, {"quad", g.quad}, {"stretch_l2", g.quality.stretchL2},
                        {"stretch_linf", g.quality.stretchLinf}, {"flipped_texels", g.quality.flippedTexels},
                        {"texels_against_vertex_normals", g.quality.texelsAgainstNormals},
                        {"degenerate_texels", g.quality.degenerateTexels}});
  }
  stats["resample"]["per_chart"] = std::move(perChart);

  AtlasManifest m;
  m.depth = p.depth;
  m.maxNodeResLog2 = p.maxNodeResLog2;
  m.minNodeResLog2 = p.minNodeResLog2;
  m.source = fs::absolute(o.input).string();
  const GeometryChartsWritten w = writeGeometryCharts(set, stage.path(), 1u << p.maxNodeResLog2, m, spill.get());
  stats["resample"]["spilled_bytes"] = spill->bytes();
  spill.reset();  // the file goes before the staging directory becomes the atlas
  set = GeometryImageSet{};
  releaseFreedMemory();
  HierarchyStats hs;
  {
    std::vector<std::array<RootNeighbour, 4>> roots;
    for (const ChartInfo& c : m.charts) roots.push_back(c.neighbours);
    std::vector<std::unique_ptr<ChartFileReader>> readers;
    for (const ChartInfo& c : m.charts) readers.push_back(std::make_unique<ChartFileReader>(stage.path() / c.file));
    const Hierarchy h =
        buildGeometryHierarchy(p, roots, [&](uint32_t c) { return readers[c]->readLevelPositions(0); }, &hs);
    writeHierarchy(stage.path() / m.hierarchyFile, h);
  }
  writeManifest(stage.path(), m);
  meter.finish("write");
  if (o.measureFidelity) {
    FidelityStats f;
    if (outOfCore) {
      // Block by block, from the cell files and the charts just written, in half of --max-memory.
      OutOfCoreFidelityOptions fo;
      fo.memoryBytes = o.maxMemory / 2;
      f = measureFidelityOutOfCore(gridDir, stage.path(), fo);
      std::error_code ec;
      fs::remove_all(gridDir, ec);
    } else {
      const AtlasSurface surface = readAtlasSurface(stage.path(), 0);
      f = measureFidelity(mesh.positions, mesh.triangles, surface.positions, surface.triangles);
    }
    stats["fidelity"] = {{"hausdorff_percent_of_diagonal", f.hausdorffPercent},
                         {"mean_percent_of_diagonal", f.meanPercent},
                         {"max_atlas_to_mesh", f.maxAtlasToMesh},
                         {"max_mesh_to_atlas", f.maxMeshToAtlas},
                         {"diagonal", f.diagonal},
                         {"atlas_samples", f.atlasSamples},
                         {"mesh_samples", f.meshSamples},
                         {"out_of_core", outOfCore},
                         {"seconds", f.seconds}};
    if (outOfCore) {
      stats["fidelity"]["blocks"] = f.blocks;
      stats["fidelity"]["samples_beyond_margin"] = f.samplesBeyondMargin;
      stats["fidelity"]["exact"] = f.exact;
    }
    spdlog::info("atlas fidelity: Hausdorff {:.4f}% of the diagonal (mean {:.5f}%), {} atlas and {} mesh samples{}",
                 f.hausdorffPercent, f.meanPercent, f.atlasSamples, f.meshSamples,
                 outOfCore ? fmt::format(", {} blocks", f.blocks) : std::string());
    if (!f.exact)
      spdlog::warn("{}: too many samples lie far from the other surface to resolve them all within --max-memory; the "
                   "Hausdorff figure is a lower bound",
                   o.input.string());
    meter.finish("fidelity");
  } else {
    stats["fidelity"] = "not measured (--no-fidelity)";
  }
  mesh = IndexedMesh{};
  stats["charts"] = m.charts.size();
  stats["chart_size"] = m.chartSize;
  stats["samples"] = uint64_t(m.charts.size()) * m.chartSize * m.chartSize;
  stats["bounds"] = w.bounds;
  stats["hierarchy_depth"] = m.depth;
  stats["hierarchy_samples_per_second"] = hs.samplesPerSecond;
  stats["hierarchy_seconds"] = hs.seconds;
  stats["hierarchy_threads"] = hs.threads;
  stats["voids_filled"] = 0;
  stats["charting_seconds"] = chartingSec;
  stats["bytes_on_disk"] = directoryBytes(stage.path());
  stats["total_seconds"] = secondsSince(t0);
  stats["charts_grid"] = {m.chartsX, m.chartsY};
  stats["stages"] = stages;
  stats["peak_rss_bytes"] = meter.peak();
  const std::string text = stats.dump(2) + "\n";
  atomicWriteFile(stage.path() / "stats.json", text.data(), text.size());
  stage.commit();
  return stats;
}

nlohmann::json buildAtlas(const BuildOptions& o) {
  std::error_code ec;
  if (isMeshFile(o.input)) {
    if (!fs::exists(o.input, ec)) throw InputError(o.input.string() + ": no such file");
    return buildMeshAtlas(o);
  }
  validateBuildOptions(o);
  if (!fs::exists(o.input, ec)) throw InputError(o.input.string() + ": no such file");
  std::unique_ptr<tbb::global_control> threads;
  if (o.threads)
    threads = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, o.threads);

  const auto t0 = std::chrono::steady_clock::now();
  DemOptions dopt;
  dopt.zScale = o.zScale;
  dopt.subdataset = o.subdataset;
  DemRaster dem = loadDem(o.input, dopt);
  const double loadSec = secondsSince(t0);
  spdlog::info("{}: {}x{} samples, spacing {:.3f} x {:.3f} m, heights {:.1f}..{:.1f} m, {} voids filled ({})",
               o.input.string(), dem.width, dem.height, dem.spacing[0], dem.spacing[1], dem.minHeight,
               dem.maxHeight, dem.voidsFilled, dem.voidFillMethod);

  StagedDirectory stage(o.output, kManifestName, "atlas");
  AtlasManifest m;
  m.chartSize = o.chartSize;
  m.blockIntervals = o.nodeRes;
  m.depth = o.depth;
  m.maxNodeResLog2 = log2u(o.nodeRes);
  m.minNodeResLog2 = log2u(o.minNodeRes);
  m.zScale = o.zScale;
  m.source = fs::absolute(o.input).string();
  TerrainAtlasOptions topt;
  topt.chartSize = o.chartSize;
  topt.blockIntervals = o.nodeRes;
  const TerrainAtlasStats cs = writeTerrainCharts(dem, topt, stage.path(), m);
  dem = DemRaster{};

  // The hierarchy stage reads level 0 of every chart file, as a restarted stage would.
  std::vector<std::unique_ptr<ChartFileReader>> readers;
  for (const ChartInfo& c : m.charts) readers.push_back(std::make_unique<ChartFileReader>(stage.path() / c.file));
  HierarchyStats hs;
  const Hierarchy h =
      buildTerrainHierarchy(m, [&](uint32_t c) { return readers[c]->readLevelHeights(0); }, &hs);
  writeHierarchy(stage.path() / m.hierarchyFile, h);
  writeManifest(stage.path(), m);

  nlohmann::json stats = {
      {"input", m.source},
      {"charts", cs.charts},
      {"charts_grid", {m.chartsX, m.chartsY}},
      {"chart_size", m.chartSize},
      {"samples", cs.samples},
      {"stored_samples", cs.storedSamples},
      {"voids_filled", m.voidsFilled},
      {"void_fill_method", m.voidFillMethod},
      {"spacing_m", m.spacing},
      {"height_range_m", m.heightRange},
      {"hierarchy_depth", m.depth},
      {"hierarchy_nodes", uint64_t(nodesPerChart(m.depth)) * cs.charts},
      {"hierarchy_samples", hs.samples},
      {"hierarchy_seconds", hs.seconds},
      {"hierarchy_samples_per_second", hs.samplesPerSecond},
      {"hierarchy_threads", hs.threads},
      {"load_seconds", loadSec},
      {"chart_seconds", cs.seconds},
  };
  stats["bytes_on_disk"] = directoryBytes(stage.path());
  stats["total_seconds"] = secondsSince(t0);
  const std::string text = stats.dump(2) + "\n";
  atomicWriteFile(stage.path() / "stats.json", text.data(), text.size());
  stage.commit();
  return stats;
}

}  // namespace gimlod
