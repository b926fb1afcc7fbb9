#include "pipeline/terrain_build.h"

#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <limits>
#include <list>
#include <memory>
#include <mutex>
#include <vector>

#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#include "atlas/terrain/imagery.h"
#include "atlas/terrain/terrain_windowed.h"
#include "core/atlas_format.h"
#include "core/block_codec.h"
#include "core/stage_meter.h"
#include "pipeline/build.h"
#include "pipeline/build_report.h"

namespace fs = std::filesystem;

namespace gimlod {
namespace {

bool isPowerOfTwo(uint32_t v) { return std::has_single_bit(v); }

// A message that may name options (optionRef), each spelled as the options spell it.
std::string spelledMessage(const CommonBuildOptions& opts, const std::string& marked) {
  const InputError e(marked);
  return opts.spellOption ? e.message(opts.spellOption) : std::string(e.what());
}

// The imagery options of a build.
// The in-memory build's memory cap: --max-memory, or 3/4 of the machine's memory.
uint64_t memoryCap(const TerrainBuildOptions& o) { return o.maxMemory ? o.maxMemory : physicalMemoryBytes() / 4 * 3; }

}  // namespace

ImageryOptions imageryOptions(const TerrainBuildOptions& o) {
  ImageryOptions io;
  io.path = o.imagery;
  io.scaleLog2 = o.imageryScaleLog2;
  io.extent = o.imageryExtent;
  return io;
}

DemOptions terrainDemOptions(const TerrainBuildOptions& o) {
  DemOptions d;
  d.zScale = o.zScale;
  d.subdataset = o.subdataset;
  d.band = o.band;
  d.spacing = o.spacing;
  d.gdalCacheBytes = std::clamp<uint64_t>(memoryCap(o) / 32, uint64_t{8} << 20, uint64_t{64} << 20);
  if (o.planet) {
    if (o.chartSize == kAutoChartSize) throw std::logic_error("demOptions: a planet's chart size is planned first");
    d.planetRadius = o.planetRadius;
    d.planetFlattening = o.planetFlattening;
    d.planetChartIntervals = o.chartSize - 1;
  }
  return d;
}

namespace {

// The in-memory build's peak per DEM sample, with the imagery's.
double inMemoryBytesPerSample(const TerrainBuildOptions& o) {
  double b = kTerrainBytesPerSample;
  if (!o.imagery.empty()) {
    const int s = o.imageryScaleLog2 >= 0 ? o.imageryScaleLog2 : int(kMaxImageryScaleLog2);
    b += 4.0 * double(1u << (2 * s)) * 4.0 / 3.0;  // the refined imagery and its pyramid
  }
  return b;
}

// Compressed atlases: heights that are not integers are quantized to the precision before anything
// is built from them, so the pyramids, normals and the hierarchy's errors are those of the decoded
// surface (the codec gives quantized heights back exactly).
// Returns the precision used.
double quantizeHeights(DemRaster& dem, const TerrainBuildOptions& o) {
  const double p = terrainHeightPrecision(o.input, o.heightPrecision, dem.integerHeights, kDefaultHeightPrecision,
                                          dem.minHeight, dem.maxHeight);
  float lo = std::numeric_limits<float>::infinity(), hi = -lo;
  for (float& h : dem.heights) {
    h = storedHeight(h, p);
    lo = std::min(lo, h);
    hi = std::max(hi, h);
  }
  dem.minHeight = lo;
  dem.maxHeight = hi;
  return p;
}

}  // namespace

TerrainPlan planTerrain(const fs::path& input, uint64_t width, uint64_t height, const TerrainBuildOptions& o) {
  if (width < 2 || height < 2)
    throw InputError(fmt::format("{}: {} x {} samples; a DEM needs at least 2 x 2", input.string(), width, height));
  TerrainPlan plan;
  plan.autoChartSize = o.chartSize == kAutoChartSize;
  plan.autoDepth = o.depth == kAutoDepth;
  auto along = [](uint64_t samples, uint64_t m) { return std::max<uint64_t>(1, (samples - 1 + m - 1) / m); };
  uint32_t cs = o.chartSize;
  if (plan.autoChartSize) {
    cs = kMinPlannedChartSize;
    while (cs < kMaxTerrainChartSize && along(width, cs - 1) * along(height, cs - 1) > kTargetTerrainCharts)
      cs = 2 * cs - 1;
  }
  plan.chartSize = cs;
  plan.samplesX = width;
  plan.samplesY = height;
  plan.chartsX = uint32_t(along(width, cs - 1));
  plan.chartsY = uint32_t(along(height, cs - 1));
  // The finest nodes 32 intervals wide, as 513-sample charts have at kDefaultDepth.
  const uint32_t L = log2u(cs - 1);
  plan.depth = plan.autoDepth ? std::clamp<uint32_t>(L > 5 ? L - 4 : 1, kDefaultDepth, 12) : o.depth;
  if (plan.autoDepth) plan.depth = std::min(plan.depth, L - log2u(o.minNodeRes ? o.minNodeRes : 1) + 1);
  const uint32_t resCount = log2u(std::max(o.nodeRes, 1u)) - log2u(std::max(o.minNodeRes, 1u)) + 1;
  while (plan.autoDepth && plan.depth > kDefaultDepth &&
         terrainHierarchyBytes(uint64_t(plan.chartsX) * plan.chartsY, plan.depth, resCount) > memoryCap(o) / 4)
    --plan.depth;
  return plan;
}

uint64_t terrainHierarchyBytes(uint64_t charts, uint32_t depth, uint32_t resCount) {
  const uint64_t perNode = sizeof(std::array<float, 6>) + sizeof(uint8_t) + sizeof(float) * resCount;
  return charts * ((uint64_t(1) << (2 * depth)) - 1) / 3 * perNode;
}

TerrainBuildOptions plannedOptions(const TerrainBuildOptions& options, const TerrainPlan& plan) {
  TerrainBuildOptions o = options;
  o.chartSize = plan.chartSize;
  o.depth = plan.depth;
  return o;
}

void validateTerrainBuildOptions(const TerrainBuildOptions& options) {
  if (options.chartSize == kAutoChartSize) {
    // What holds for some chart size (planTerrain's, checked again once it is chosen).
    TerrainBuildOptions o = options;
    o.chartSize = kMaxTerrainChartSize;
    validateTerrainBuildOptions(o);
    return;
  }
  const TerrainBuildOptions& o = options;
  if (!(o.chartSize >= 9 && o.chartSize <= kMaxTerrainChartSize && isPowerOfTwo(o.chartSize - 1)))
    throw InputError(fmt::format("{} {} must be 2^m+1 between 9 and {} (e.g. 257, 513, 1025)", optionRef("chartSize"),
                                 o.chartSize, kMaxTerrainChartSize));
  if (!isPowerOfTwo(o.nodeRes) || o.nodeRes < 4 || o.nodeRes > 1024 || o.nodeRes > o.chartSize - 1)
    throw InputError(fmt::format("{} {} must be a power of two in [4, min(1024, {} - 1)]", optionRef("nodeRes"),
                                 o.nodeRes, optionRef("chartSize")));
  if (!isPowerOfTwo(o.minNodeRes) || o.minNodeRes > o.nodeRes)
    throw InputError(fmt::format("{} {} must be a power of two in [1, {}]", optionRef("minNodeRes"), o.minNodeRes,
                                 optionRef("nodeRes")));
  if (!std::isfinite(o.zScale) || o.zScale == 0.0)
    throw InputError(optionRef("zScale") + " must be finite and non-zero");
  if (o.threads > 1024) throw InputError(optionRef("threads") + " must be at most 1024");
  if (!(o.planetFlattening >= 0.0 && o.planetFlattening <= kMaxPlanetFlattening))
    throw InputError(fmt::format("{} {} must be between 0 (a sphere) and {}", optionRef("planetFlattening"),
                                 o.planetFlattening, kMaxPlanetFlattening));
  if (o.compress && o.heightPrecision != kAutoHeightPrecision &&
      !(o.heightPrecision >= 1e-6 && o.heightPrecision <= 1000.0))
    throw InputError(
        fmt::format("{} {} must be between 1e-6 and 1000 metres", optionRef("heightPrecision"), o.heightPrecision));
  validateImageryOptions(imageryOptions(o));
  HierarchyParams p;
  p.intervalsLog2 = log2u(o.chartSize - 1);
  p.depth = terrainDepth(o.depth);
  p.maxNodeResLog2 = log2u(o.nodeRes);
  p.minNodeResLog2 = log2u(o.minNodeRes);
  p.validate();
}

namespace {

// ", N voids filled (P% of the samples)", or nothing; the fill itself is described in the docs.
std::string voidsFilledText(uint64_t voids, uint64_t samples) {
  if (voids == 0) return {};
  return fmt::format(", {} voids filled ({:.3g}% of the samples)", voids, 100.0 * double(voids) / double(samples));
}

void logPlan(const TerrainBuildOptions& o, const TerrainPlan& plan) {
  spdlog::info("{}: {} x {} charts of {} samples{}, {} quadtree levels{}", o.input.string(), plan.chartsX, plan.chartsY,
               plan.chartSize,
               plan.autoChartSize
                   ? fmt::format(" (the smallest from 513 giving at most {} charts)", kTargetTerrainCharts)
                   : std::string(),
               plan.depth, fmt::format(" (finest nodes {} intervals wide)", (plan.chartSize - 1) >> (plan.depth - 1)));
}

}  // namespace

void logTerrainSource(const TerrainBuildOptions& o, const DemRaster& dem) {
  for (const std::string& warning : dem.warnings) spdlog::warn("{}: {}", o.input.string(), spelledMessage(o, warning));
  const PlanetInfo& p = dem.planet;
  if (!p.present) return;
  const std::string surface = p.flattening > 0.0 ? fmt::format(
                                                       "an ellipsoid of equatorial radius {:.1f} m and "
                                                       "flattening 1/{:.12g}",
                                                       p.radius, 1.0 / p.flattening)
                                                 : fmt::format("a sphere of radius {:.1f} m", p.radius);
  spdlog::info("{}: on {}, {}x{} samples{}", o.input.string(), surface, dem.width, dem.height,
               p.wrapColumns ? fmt::format(", {} columns round the planet", p.wrapColumns) : std::string(", regional"));
}

DemRaster readTerrain(const TerrainBuildOptions& o, TerrainReadStats* stats) {
  const auto t0 = std::chrono::steady_clock::now();
  // buildTerrainAtlas has chosen this build because its estimate fits the cap.
  DemRaster dem = loadDem(o.input, terrainDemOptions(o));
  logTerrainSource(o, dem);
  stats->seconds = secondsSince(t0);
  stats->width = dem.width;
  stats->height = dem.height;
  stats->spacing = dem.spacing;
  stats->heightRange = {dem.minHeight, dem.maxHeight};
  stats->voidsFilled = dem.voidsFilled;
  stats->voidFillMethod = dem.voidFillMethod;
  spdlog::info("{}: {}x{} samples, spacing {:.3f} x {:.3f} m, heights {:.1f}..{:.1f} m{}", o.input.string(), dem.width,
               dem.height, dem.spacing[0], dem.spacing[1], dem.minHeight, dem.maxHeight,
               voidsFilledText(dem.voidsFilled, uint64_t{dem.width} * dem.height));
  return dem;
}

AtlasManifest terrainManifest(const TerrainBuildOptions& o) {
  AtlasManifest m;
  m.chartSize = o.chartSize;
  m.blockIntervals = o.nodeRes;
  m.depth = terrainDepth(o.depth);
  m.maxNodeResLog2 = log2u(o.nodeRes);
  m.minNodeResLog2 = log2u(o.minNodeRes);
  m.zScale = o.zScale;
  m.source = fs::absolute(o.input).string();
  return m;
}

TerrainAtlasOptions terrainAtlasOptions(const TerrainBuildOptions& o) {
  TerrainAtlasOptions topt;
  topt.chartSize = o.chartSize;
  topt.blockIntervals = o.nodeRes;
  topt.coding.compressed = o.compress;
  return topt;
}

namespace {

// The chart files the hierarchy reads, the last few kept open: it reads a chart's tiles one after
// another (each open parses the file's directory), and an atlas may hold more charts than a
// process may have files open.
class OpenCharts {
 public:
  OpenCharts(const AtlasManifest& m, const fs::path& dir, size_t keep) : m_(m), dir_(dir), keep_(keep) {}
  std::shared_ptr<const ChartFileReader> get(uint32_t chart) {
    {
      const std::lock_guard<std::mutex> lock(mutex_);
      for (auto it = open_.begin(); it != open_.end(); ++it)
        if (it->first == chart) {
          open_.splice(open_.begin(), open_, it);
          return it->second;
        }
    }
    auto reader = std::make_shared<const ChartFileReader>(dir_ / m_.charts[chart].file);
    const std::lock_guard<std::mutex> lock(mutex_);
    open_.emplace_front(chart, reader);
    if (open_.size() > keep_) open_.pop_back();
    return reader;
  }

 private:
  const AtlasManifest& m_;
  fs::path dir_;
  size_t keep_;
  std::mutex mutex_;
  std::list<std::pair<uint32_t, std::shared_ptr<const ChartFileReader>>> open_;
};

}  // namespace

Hierarchy measureTerrainHierarchy(const AtlasManifest& m, const fs::path& dir, HierarchyStats* stats) {
  OpenCharts charts(m, dir, 2 * size_t(tbb::this_task_arena::max_concurrency()) + 2);
  const ChartWindowSource source = [&](uint32_t c, uint32_t level, uint32_t u0, uint32_t v0, uint32_t n) {
    return charts.get(c)->readHeightsWindow(level, u0, v0, n);
  };
  return m.planet.present ? buildPlanetHierarchy(m, source, stats) : buildTerrainHierarchy(m, source, stats);
}

namespace {

// The hierarchy (from level 0 of every chart file, as a restarted stage would read it) and the
// manifest, once the chart files are written.
void finishTerrainAtlas(AtlasManifest& m, const fs::path& dir, TerrainWriteStats& w) {
  const Hierarchy h = measureTerrainHierarchy(m, dir, &w.hierarchy);
  writeHierarchy(dir / m.hierarchyFile, h, m.compression.present);
  writeManifest(dir, m);
  w.chartsX = m.chartsX;
  w.chartsY = m.chartsY;
  w.chartSize = m.chartSize;
  w.depth = m.depth;
}

// The imagery's write figures into its stats, and the log line.
void finishImagery(const TerrainBuildOptions& o, const ImageryWriteStats& ws, TerrainImageryStats& im) {
  im.storedSamples = ws.storedSamples;
  im.bytesOnDisk = ws.bytesOnDisk;
  im.writeSeconds = ws.seconds;
  spdlog::info("{}: {}x{} imagery samples ({} per DEM interval, {} resampling{}), {:.1f}% of the terrain covered",
               o.imagery.string(), im.width, im.height, 1u << im.scaleLog2, im.resampling,
               im.windows ? fmt::format(", {} windows", im.windows) : std::string(), 100.0 * im.coverage);
}

// Imagery reprojected and filtered window by window (or tile by tile, for tiled charts) in
// memoryBytes.
void writeImageryWindowed(const TerrainBuildOptions& o, const DemRaster& dem, const fs::path& dir, AtlasManifest& m,
                          uint64_t memoryBytes, TerrainWriteStats& w) {
  const auto t0 = std::chrono::steady_clock::now();
  ImagerySource imagery(dem, o.input, imageryOptions(o));
  TerrainImageryStats& im = w.imagery.emplace();
  im.readSeconds = secondsSince(t0);
  im.source = fs::absolute(o.imagery).string();
  im.scaleLog2 = imagery.scaleLog2();
  im.width = imagery.width();
  im.height = imagery.height();
  im.resampling = imagery.resampling();
  ImageryWindowStats ws;
  const ImageryWriteStats st = writeImageryChartsWindowed(imagery, im.source, dir, m, {memoryBytes}, &ws);
  for (const std::string& warning : imagery.warnings()) spdlog::warn("{}: {}", o.imagery.string(), warning);
  im.coverage = m.imagery.coverage;
  im.windows = ws.windows;
  im.windowSamples = ws.windowSamples;
  finishImagery(o, st, im);
}

}  // namespace

TerrainWriteStats writeTerrainAtlas(DemRaster&& dem, const TerrainBuildOptions& options, const fs::path& dir) {
  const TerrainBuildOptions o = plannedOptions(options, planTerrain(options.input, dem.width, dem.height, options));
  validateTerrainBuildOptions(o);
  AtlasManifest m = terrainManifest(o);
  TerrainAtlasOptions topt = terrainAtlasOptions(o);
  if (o.compress) topt.coding.heightPrecision = quantizeHeights(dem, o);
  TerrainWriteStats w;
  w.charts = writeTerrainCharts(dem, topt, dir, m);
  if (!o.imagery.empty() && chartTiling(m.chartSize, m.blockIntervals).tiled()) {
    // Charts too large to hold whole take their imagery in tiles, as their geometry.
    writeImageryWindowed(o, dem, dir, m, memoryCap(o) / 2, w);
  } else if (!o.imagery.empty()) {
    // Imagery: reprojected onto the DEM's lattice, then cut like the heights.
    const auto t0 = std::chrono::steady_clock::now();
    ImageryRaster raster = loadImagery(dem, o.input, imageryOptions(o));
    for (const std::string& warning : raster.warnings) spdlog::warn("{}: {}", o.imagery.string(), warning);
    TerrainImageryStats& im = w.imagery.emplace();
    im.readSeconds = secondsSince(t0);
    im.source = fs::absolute(o.imagery).string();
    im.scaleLog2 = raster.scaleLog2;
    im.width = raster.width;
    im.height = raster.height;
    im.coverage = raster.coverage;
    im.resampling = raster.resampling;
    finishImagery(o, writeImageryCharts(raster, im.source, dir, m), im);
  }
  dem = DemRaster{};
  finishTerrainAtlas(m, dir, w);
  return w;
}

WindowedTerrainOptions windowedTerrainOptions(const TerrainBuildOptions& o) {
  WindowedTerrainOptions wo;
  wo.atlas = terrainAtlasOptions(o);
  wo.heightPrecision = o.heightPrecision;
  wo.defaultHeightPrecision = kDefaultHeightPrecision;
  // What the process holds already (libraries, GDAL's block cache to come) stays out of the windows.
  const uint64_t cap = memoryCap(o), held = residentBytes() + terrainDemOptions(o).gdalCacheBytes;
  wo.memoryBytes = cap > held ? (cap - held) / 5 * 4 : 0;
  return wo;
}

TerrainWriteStats writeTerrainAtlasWindowed(const TerrainBuildOptions& o, const fs::path& dir, TerrainReadStats* read) {
  const auto t0 = std::chrono::steady_clock::now();
  const uint64_t cap = memoryCap(o);
  const DemOptions dopt = terrainDemOptions(o);
  const DemSource source(o.input, dopt);
  logTerrainSource(o, source.info());
  AtlasManifest m = terrainManifest(o);
  const WindowedTerrainOptions wo = windowedTerrainOptions(o);
  spdlog::info("{}: {}x{} samples, built window by window in {} MiB of windows (memory cap {} MiB)", o.input.string(),
               source.info().width, source.info().height, wo.memoryBytes >> 20, cap >> 20);
  TerrainWriteStats w;
  const WindowedTerrainResult r = writeTerrainChartsWindowed(source, dir, wo, m);
  w.charts = r.charts;
  w.windowed.emplace();
  w.windowed->memoryBytes = wo.memoryBytes;
  w.windowed->scratchBytes = r.scratchBytes;
  w.windowed->scratchTile = r.scratchTile;
  w.windowed->bandRows = r.bandRows;
  w.windowed->bandColumns = r.bandColumns;
  read->seconds = secondsSince(t0);
  read->width = r.dem.width;
  read->height = r.dem.height;
  read->spacing = r.dem.spacing;
  read->heightRange = {r.dem.minHeight, r.dem.maxHeight};
  read->voidsFilled = r.dem.voidsFilled;
  read->voidFillMethod = r.dem.voidFillMethod;
  if (!o.imagery.empty()) writeImageryWindowed(o, r.dem, dir, m, wo.memoryBytes, w);
  finishTerrainAtlas(m, dir, w);
  return w;
}

namespace {

// A planet's chart size: the plan's, or a half or a quarter of it where that adds fewer columns.
// The lattice resamples each row of a DEM that circles the planet to whole charts round the turn
// (atlas/terrain/planet_grid.h), so the columns past the DEM's own are stored samples, unlike a
// flat grid's empty padding. The largest size whose turn is within 1/16 of the DEM's columns, else
// the one that adds the fewest (ETOPO5 at 5.5G samples: 104,832 columns make 114,688 in charts of
// 16,385, 106,496 in charts of 8,193). Never below kMinPlannedChartSize, where the plan's depth
// stops following the chart's size and smaller charts would have more nodes an area. A regional
// DEM keeps the plan's.
uint32_t planetChartSize(const TerrainBuildOptions& options, uint32_t planned, uint64_t width) {
  uint32_t best = planned;
  uint64_t fewest = UINT64_MAX;
  for (uint32_t size = planned, i = 0; i < 3 && size >= kMinPlannedChartSize; ++i, size = (size - 1) / 2 + 1) {
    TerrainBuildOptions o = options;
    o.chartSize = size;
    const uint64_t turn = DemSource(options.input, terrainDemOptions(o)).info().planet.wrapColumns;
    if (turn == 0) return planned;
    if (turn * 16 <= width * 17) return size;
    if (turn < fewest) best = size, fewest = turn;
  }
  return best;
}

}  // namespace

TerrainBuildOptions plannedTerrainBuild(const TerrainBuildOptions& options, TerrainPlan* planOut) {
  std::error_code ec;
  validateTerrainBuildOptions(options);
  if (!fs::exists(options.input, ec)) throw InputError(options.input.string() + ": no such file");
  if (!options.imagery.empty() && !fs::exists(options.imagery, ec))
    throw InputError(options.imagery.string() + ": no such file");
  TerrainPlan plan;
  TerrainBuildOptions po = options;
  {
    TerrainBuildOptions raw = options;
    raw.planet = false;  // the DEM's own size first
    raw.chartSize = kMaxTerrainChartSize;
    const DemSource source(options.input, terrainDemOptions(raw));
    const uint64_t w = source.info().width, h = source.info().height;
    // A planet's antimeridian is laid on a chart border: the chart size first, then the lattice.
    if (options.planet && options.chartSize == kAutoChartSize)
      po.chartSize = planetChartSize(options, planTerrain(options.input, w, h, options).chartSize, w);
    plan = planTerrain(options.input, w, h, po);
  }
  const TerrainBuildOptions o = plannedOptions(po, plan);
  validateTerrainBuildOptions(o);
  logPlan(o, plan);
  if (planOut) *planOut = plan;
  return o;
}

TerrainBuildStats buildTerrainAtlas(const TerrainBuildOptions& options) {
  TerrainPlan plan;
  const TerrainBuildOptions o = plannedTerrainBuild(options, &plan);
  const double samples = double(plan.samplesX) * double(plan.samplesY);
  std::unique_ptr<tbb::global_control> threads;
  if (o.threads)
    threads = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, o.threads);

  const auto t0 = std::chrono::steady_clock::now();
  TerrainBuildStats stats;
  // In memory when the estimate fits the cap, else window by window. A cap
  // below what the process holds, with room for windows, cannot be kept.
  const uint64_t held = residentBytes();
  if (memoryCap(o) < held + (uint64_t{32} << 20))
    throw InputError(
        fmt::format("{} {} MiB is below the {} MiB this program holds before reading the DEM, plus 32 MiB "
                    "for the windows",
                    optionRef("maxMemory"), memoryCap(o) >> 20, held >> 20));
  bool windowed = o.outOfCore;
  if (!windowed) windowed = samples * inMemoryBytesPerSample(o) + double(residentBytes()) > double(memoryCap(o));
  StagedDirectory stage(o.output, kManifestName, "atlas");
  if (windowed) {
    stats.write = writeTerrainAtlasWindowed(o, stage.path(), &stats.read);
  } else {
    DemRaster dem = readTerrain(o, &stats.read);
    stats.write = writeTerrainAtlas(std::move(dem), o, stage.path());
  }
  stats.input = fs::absolute(o.input).string();
  stats.bytesOnDisk = directoryBytes(stage.path());
  stats.totalSeconds = secondsSince(t0);
  stats.peakRssBytes = peakResidentBytes();
  writeStatsFile(stage.path(), statsJson(stats));
  stage.commit();
  return stats;
}

}  // namespace gimlod
