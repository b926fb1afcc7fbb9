#include "pipeline/mesh_build.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <string>
#include <vector>

#include <fmt/format.h>
#include <fmt/ranges.h>
#include <glm/geometric.hpp>
#include <spdlog/spdlog.h>
#include <tbb/global_control.h>

#include "atlas/mesh/charting.h"
#include "atlas/fidelity/fidelity.h"
#include "atlas/mesh/gridify.h"
#include "atlas/mesh/mesh_atlas.h"
#include "core/atlas_format.h"
#include "pipeline/build.h"
#include "pipeline/build_report.h"

namespace fs = std::filesystem;

namespace gimlod {

uint32_t meshPatchTarget(uint64_t triangles) {
  if (triangles <= kFewPatchesTriangles) return 24;
  return uint32_t(std::clamp<double>(std::round(std::sqrt(double(triangles)) / 80.0), 48.0, 4096.0));
}

MeshChartMetric meshChartMetric(uint64_t triangles) {
  return triangles <= kFewPatchesTriangles ? MeshChartMetric::kDevelopable : MeshChartMetric::kPlanar;
}

HierarchyParams meshHierarchyParams(const MeshBuildOptions& o) {
  if (o.chartSize == 0) {  // chosen after the charting: check the rest with the smallest it can be
    MeshBuildOptions probe = o;
    probe.chartSize = 65;
    meshHierarchyParams(probe);
    return {};
  }
  if (!isChartSizeValid(o.chartSize) || o.chartSize < 9)
    throw InputError(optionRef("chartSize") + " " + std::to_string(o.chartSize) +
                     " must be 2^m + 1 with m >= 3 for meshes");
  if (o.maxMemory < (64ull << 20)) throw InputError(optionRef("maxMemory") + " must be at least 64 MiB");
  if (o.threads > 1024) throw InputError(optionRef("threads") + " must be at most 1024");
  if (o.positionBits < 8 || o.positionBits > 22)
    throw InputError(optionRef("positionBits") + " " + std::to_string(o.positionBits) + " must be between 8 and 22");
  if (!(o.positionTolerance >= 0.0 && o.positionTolerance <= 0.01))
    throw InputError(optionRef("positionTolerance") + " must be between 0 and 1% of the bounding-box diagonal");
  if (o.normalTolerance > 16) throw InputError(optionRef("normalTolerance") + " must be between 0 and 16 packed steps");
  if (o.nodeRes < 4 || (o.nodeRes & (o.nodeRes - 1)) || o.minNodeRes < 2 || (o.minNodeRes & (o.minNodeRes - 1)) ||
      o.minNodeRes > o.nodeRes)
    throw InputError(optionRef("nodeRes") + " and " + optionRef("minNodeRes") +
                     " must be powers of two with 2 <= min <= node-res");
  if (o.depth > 12) throw InputError(optionRef("depth") + " must be in [1, 12]");
  if (o.repairRounds > 16) throw InputError(optionRef("repairRounds") + " must be in [0, 16]");
  if (!(o.repairBudget >= 0.0 && o.repairBudget <= 100.0))
    throw InputError(optionRef("repairBudget") + " must be in [0, 100] (times the surface's triangles)");
  if (o.maxSampleError != kAutoSampleError && !(o.maxSampleError >= 0.0 && o.maxSampleError <= 0.1))
    throw InputError(optionRef("maxSampleError") + " must be between 0 and 10% of the bounding-box diagonal");
  if (o.chartSize > 8193)
    throw InputError(optionRef("chartSize") + " " + std::to_string(o.chartSize) +
                     " is above 8193, the largest mesh chart size");
  if (o.patches == 0 && !(o.maxPatchError > 0.0 && std::isfinite(o.maxPatchError)))
    throw InputError(optionRef("maxPatchError") +
                     " must be a positive fraction of the bounding-box diagonal (it is the target when " +
                     optionRef("patches") + " is 0)");
  HierarchyParams p;
  p.intervalsLog2 = log2u(o.chartSize - 1);
  p.maxNodeResLog2 = std::min(log2u(o.nodeRes), p.intervalsLog2);
  p.minNodeResLog2 = std::min(log2u(o.minNodeRes), p.maxNodeResLog2);
  p.depth = std::min(meshDepth(o.depth, p.intervalsLog2), p.intervalsLog2 - p.minNodeResLog2 + 1);
  p.validate();
  return p;
}

ChartedMesh chartMesh(const MeshBuildOptions& o, const MeshInfo& info, const fs::path& dir, StageMeter& meter) {
  ChartingOptions copt;
  copt.targetPatches = o.patches == kAutoPatches ? meshPatchTarget(info.triangleEstimate) : o.patches;
  copt.maxError = o.maxPatchError;
  const MeshChartMetric metric =
      o.chartMetric == MeshChartMetric::kAuto ? meshChartMetric(info.triangleEstimate) : o.chartMetric;
  copt.metric = metric == MeshChartMetric::kDevelopable ? ChartMetric::kDevelopable : ChartMetric::kPlanar;
  copt.threads = o.threads;
  ChartedMesh c;
  MeshChartStats& st = c.stats;
  st.developable = copt.metric == ChartMetric::kDevelopable;
  st.outOfCore = info.triangleEstimate * 256 > o.maxMemory / 4;
  if (st.outOfCore) {
    GridifyOptions g;
    g.maxMemoryBytes = o.maxMemory;
    const fs::path grid = dir / "grid.tmp";
    GridifyResult gr = gridify(o.input, grid, g);
    finishStage(meter, "gridify");
    c.layout = buildPatchLayoutFromCells(grid, copt, &st.charting);
    if (o.measureFidelity) {
      c.cells = grid;  // the input for the fidelity figure, removed after it
    } else {
      std::error_code ec;
      fs::remove_all(grid, ec);
    }
    st.read = gr.read;
    gr.manifest = GridManifest{};
    st.gridify = std::move(gr);
  } else {
    c.mesh = readMesh(o.input);
    st.read = c.mesh.stats;
    for (const std::string& w : st.read.warnings) spdlog::warn("{}: {}", o.input.string(), w);
    finishStage(meter, "read");
    c.layout = buildPatchLayout(c.mesh, copt, &st.charting);
  }
  finishStage(meter, "charting");
  return c;
}

double meshPositionStep(const MeshBounds& b, uint32_t positionBits) {
  if (b.empty()) return 1.0;
  const double diagonal = glm::length(glm::dvec3(b.max) - glm::dvec3(b.min));
  double largest = 0.0;  // the largest coordinate's magnitude
  for (int a = 0; a < 3; ++a) largest = std::max({largest, std::abs(double(b.min[a])), std::abs(double(b.max[a]))});
  // A power of two, so lattice points are exact floats, and no finer than 2^-22 of the largest
  // coordinate, so every coordinate is within 2^23 steps (float holds nothing finer there).
  // The exponents are read off the doubles (ilogb: floor of log2, exactly), not computed by libm.
  const int wanted = std::ilogb(std::max(diagonal, 1e-30)) - int(positionBits);
  const int floorExp = std::ilogb(std::max(largest, 1e-30)) - 22;
  return std::ldexp(1.0, std::max(wanted, floorExp));
}

QuadChartOptions quadChartOptions(const MeshBuildOptions& o) {
  QuadChartOptions q;
  q.input = o.input;
  q.spellOption = o.spellOption;
  q.chartSize = o.chartSize;
  q.threads = o.threads;
  q.maxMemory = o.maxMemory;
  q.straightenRounds = o.straightenRounds;
  q.repairRounds = o.repairRounds;
  q.repairBudget = o.repairBudget;
  q.maxSampleError = o.maxSampleError;
  q.quads = o.quads;
  q.quadMap = o.quadMap;
  q.unfold = o.unfold;
  q.sizing = o.sizing;
  if (o.compress) q.positionStep = [bits = o.positionBits](const MeshBounds& b) { return meshPositionStep(b, bits); };
  q.coarsestLevel = [o](uint32_t chartSize) {
    MeshBuildOptions at = o;
    at.chartSize = chartSize;
    return meshHierarchyParams(at).maxFinestLevel();
  };
  return q;
}

MeshWriteStats writeMeshAtlas(ResampledMesh&& r, const HierarchyParams& p, const MeshBuildOptions& o,
                              const fs::path& dir, StageMeter& meter) {
  AtlasManifest m;
  m.depth = p.depth;
  m.maxNodeResLog2 = p.maxNodeResLog2;
  m.minNodeResLog2 = p.minNodeResLog2;
  m.source = fs::absolute(o.input).string();
  MeshWriteStats w;
  ChartCoding coding;
  coding.compressed = o.compress;
  coding.positionStep = meshPositionStep(r.bounds, o.positionBits);
  const double diagonal = r.bounds.empty() ? 0.0 : glm::length(glm::dvec3(r.bounds.max) - glm::dvec3(r.bounds.min));
  coding.positionTolerance = o.positionTolerance * diagonal;
  coding.normalTolerance = o.normalTolerance;
  const uint64_t triangles = std::max<uint64_t>(r.triangles, 1);
  // Each chart's finest level first: the normals go by the samples the charts keep.
  std::vector<uint32_t> finest;
  if (o.coarsenCharts) {
    ChartCoarsening coarsen;
    coarsen.bound = r.stats.maxSampleError;
    coarsen.maxFinestLevel = p.maxFinestLevel();
    finest = chartFinestLevels(r.set, r.spill.get(), coarsen);
  }
  uint64_t kept = 0;
  for (const GeometryImage& g : r.set.charts)
    w.resampledSamples += uint64_t(g.side(r.set.chartSize)) * g.side(r.set.chartSize);
  for (size_t i = 0; i < r.set.charts.size(); ++i) {
    const uint64_t side = ((r.set.chartSize - 1) >> (finest.empty() ? r.set.charts[i].level : finest[i])) + 1;
    kept += side * side;
  }
  w.samplesPerTriangle = double(kept) / double(triangles);
  coding.deriveGeometryNormals =
      o.compress && (o.normals == MeshNormals::kDerived ||
                     (o.normals == MeshNormals::kAuto && w.samplesPerTriangle <= kDerivedNormalsSamplesPerTriangle));
  if (o.compress)
    spdlog::info(
        "positions on a lattice of {:.4g} ({:.4g}% of the diagonal), settled within {:.4g}% of it; normals "
        "within {} packed steps",
        coding.positionStep, 100.0 * coding.positionStep / std::max(diagonal, 1e-300), 100.0 * o.positionTolerance,
        o.normalTolerance);
  {
    const GeometryChartsWritten written =
        writeGeometryCharts(r.set, dir, 1u << p.maxNodeResLog2, m, r.spill.get(), coding, finest,
                            o.coarsenCharts ? r.stats.maxSampleError : 0.0);
    w.bounds = written.bounds;
    w.chartsByFinestLevel = written.chartsByFinestLevel;
    w.finestSamples = written.finestSamples;
    w.planarSamples = written.planarSamples;
    if (written.chartsByFinestLevel.size() > 1)
      spdlog::info(
          "charts by their finest level (0 = {}^2 samples): {}; {} samples ({:.1f} per input triangle, "
          "{:.2f} of the resampled charts')",
          r.set.chartSize, fmt::join(written.chartsByFinestLevel, ", "), written.finestSamples,
          double(written.finestSamples) / double(triangles),
          double(written.finestSamples) / double(std::max<uint64_t>(w.resampledSamples, 1)));
    if (written.planarSamples > 0)
      spdlog::info("{} of the charts' finest samples ({:.2f}) moved onto planar squares, whose corners alone are coded",
                   written.planarSamples,
                   double(written.planarSamples) / double(std::max<uint64_t>(written.finestSamples, 1)));
    w.normalsDerived = coding.deriveGeometryNormals;
    w.normalAngles = written.normalAngles;
  }
  if (w.normalsDerived)
    spdlog::info(
        "normals derived from the positions ({:.1f} samples per input triangle): {:.2f} degrees from the "
        "resampled ones at the median, {:.2f} at the 99th percentile, {:.1f} at most",
        w.samplesPerTriangle, w.normalAngles.median, w.normalAngles.p99, w.normalAngles.max);
  w.spilledBytes = r.spill->bytes();
  r.spill.reset();  // the file goes before the staging directory becomes the atlas
  r.set = GeometryImageSet{};
  releaseFreedMemory();
  {
    std::vector<std::array<RootNeighbour, 4>> roots;
    for (const ChartInfo& c : m.charts) roots.push_back(c.neighbours);
    // Each chart file is opened only while it is read (more charts than open files may exist).
    std::vector<uint8_t> finest;
    for (const ChartInfo& c : m.charts) finest.push_back(uint8_t(c.finestLevel));
    const Hierarchy h = buildGeometryHierarchy(
        p, roots, [&](uint32_t c) { return ChartFileReader(dir / m.charts[c].file).readLevelPositions(0); },
        &w.hierarchy, finest);
    // Quantized: the boxes and errors a compressed mesh atlas's hierarchy holds take about 0.4 of
    // their exact bytes (a quarter of the bunny's atlas was its hierarchy).
    writeHierarchy(dir / m.hierarchyFile, h, o.compress ? HierarchyCoding::kQuantized : HierarchyCoding::kRaw);
  }
  writeManifest(dir, m);
  finishStage(meter, "write");
  w.charts = uint32_t(m.charts.size());
  w.chartsX = m.chartsX;
  w.chartsY = m.chartsY;
  w.chartSize = m.chartSize;
  w.depth = m.depth;
  return w;
}

FidelityStats measureMeshFidelity(ChartedMesh& c, const MeshBuildOptions& o, const fs::path& dir, StageMeter& meter) {
  const bool outOfCore = c.stats.outOfCore;
  FidelityStats f;
  releaseFreedMemory();  // what the write freed, before the blocks take their share
  if (outOfCore) {
    // Block by block, from the cell files and the charts just written, in half of maxMemory.
    OutOfCoreFidelityOptions fo;
    fo.memoryBytes = o.maxMemory / 2;
    f = measureFidelityOutOfCore(c.cells, dir, fo);
    std::error_code ec;
    fs::remove_all(c.cells, ec);
  } else {
    if (o.fidelity == MeshFidelity::kFast) {
      f = measureFidelityByCharts(c.mesh.positions, c.mesh.triangles, dir);
    } else {
      const AtlasSurface surface = readAtlasSurface(dir, 0);
      f = measureFidelity(c.mesh.positions, c.mesh.triangles, surface.positions, surface.triangles);
    }
  }
  spdlog::info("atlas fidelity: Hausdorff {:.4f}% of the diagonal (mean {:.5f}%), {} atlas and {} mesh samples{}{}",
               f.hausdorffPercent, f.meanPercent, f.atlasSamples, f.meshSamples,
               outOfCore ? fmt::format(", {} blocks", f.blocks) : std::string(),
               f.atlasFractionAbove > 0.0
                   ? fmt::format(" (atlas samples: {} of {}; with 99% confidence at most {:.4f}% of them lie farther)",
                                 f.atlasSamples, f.atlasSamplesTotal, 100.0 * f.atlasFractionAbove)
                   : std::string());
  if (!f.exact)
    spdlog::warn(
        "{}: too many samples lie far from the other surface to resolve them all within {}; the "
        "Hausdorff figure is a lower bound",
        o.input.string(), spelledOption(o, "maxMemory"));
  finishStage(meter, "fidelity");
  return f;
}

MeshBuildStats buildMeshAtlas(const MeshBuildOptions& o) {
  std::error_code ec;
  if (!fs::exists(o.input, ec)) throw InputError(o.input.string() + ": no such file");
  meshHierarchyParams(o);  // checks the options before anything is read
  std::unique_ptr<tbb::global_control> threads;
  if (o.threads)
    threads = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, o.threads);
  const auto t0 = std::chrono::steady_clock::now();
  MeshBuildStats stats;
  stats.input = fs::absolute(o.input).string();
  StageMeter meter;
  meter.start();

  const MeshInfo info = probeMesh(o.input);
  StagedDirectory stage(o.output, kManifestName, "atlas");
  ChartedMesh charted = chartMesh(o, info, stage.path(), meter);
  stats.chart = charted.stats;
  stats.chart.seconds = secondsSince(t0);
  ResampledMesh resampled = makeQuadCharts(std::move(charted.layout), quadChartOptions(o), stage.path(), meter);
  stats.resample = std::move(resampled.stats);
  MeshBuildOptions chosen = o;
  chosen.chartSize = stats.resample.chartSize;
  stats.write = writeMeshAtlas(std::move(resampled), meshHierarchyParams(chosen), o, stage.path(), meter);
  stats.fidelityMode = o.fidelity;
  if (o.measureFidelity) stats.fidelity = measureMeshFidelity(charted, o, stage.path(), meter);
  charted = ChartedMesh{};
  stats.stages = meter.stages();
  stats.bytesOnDisk = directoryBytes(stage.path());
  stats.totalSeconds = secondsSince(t0);
  stats.peakRssBytes = meter.peak();
  writeStatsFile(stage.path(), statsJson(stats));
  stage.commit();
  return stats;
}

}  // namespace gimlod
