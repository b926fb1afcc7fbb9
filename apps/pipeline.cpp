#include "apps/pipeline.h"

#include <unistd.h>

#include <chrono>
#include <random>

#include <fmt/format.h>
#include <spdlog/spdlog.h>
#include <tbb/global_control.h>

#include "atlas/dem.h"
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

double secondsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

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

nlohmann::json buildAtlas(const BuildOptions& o) {
  validateBuildOptions(o);
  std::error_code ec;
  if (!fs::exists(o.input, ec)) throw InputError(o.input.string() + ": no such file");
  if (isMeshFile(o.input))
    throw InputError(o.input.string() + ": mesh input is not supported yet (height fields only in this version)");
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
