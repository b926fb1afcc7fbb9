#include "apps/build_command.h"

#include <charconv>
#include <cmath>
#include <iostream>
#include <map>

#include "apps/streaming_args.h"
#include "core/atlas_format.h"
#include "core/planet.h"
#include "pipeline/build.h"
#include "pipeline/build_report.h"
#include "pipeline/input_kind.h"

namespace gimlod {
namespace {

// A whole number in [0, 2^32 - 2] ("auto" is told apart before); throws InputError naming the option.
uint32_t parseCount(const std::string& option, const std::string& text) {
  uint64_t v = 0;
  const char* end = text.data() + text.size();
  const auto [ptr, ec] = std::from_chars(text.data(), end, v);
  if (text.empty() || ec != std::errc() || ptr != end || v >= 0xFFFFFFFFull)
    throw InputError(option + " '" + text + "' must be a whole number (or auto)");
  return uint32_t(v);
}

// The charting and parameterization options, which only meshes take.
void addMeshChartOptions(CLI::App* b, BuildArgs& a) {
  b->add_option(
       "--charts", a.chartsArg,
       "Meshes: target patches (each becomes 1-5 quad charts, see --quads, and the chart repair may cut more); auto: "
       "24 up to 4M triangles, above that about sqrt(triangles) / 80, at least 48; 0: --chart-error")
      ->capture_default_str();
  b->add_option("--quads", a.quadsArg,
                "Meshes: how a patch becomes quad charts: sides (each chart edge a whole patch side, about n/2 "
                "charts an n-sided patch, one for 4 sides), kites (each side halved, n charts), or auto (sides, "
                "and kites too if sides leave flipped texels, two-chart corners or a sampling error over the bound; "
                "from the density's chart size up, doubled only while neither layout meets the bound; keeping "
                "the first that leaves nothing to repair, else whichever leaves fewer flipped texels)")
      ->check(CLI::IsMember({"auto", "sides", "kites"}))
      ->capture_default_str();
  b->add_option("--normals", a.normalsArg,
                "Meshes: stored (every sample's normal is stored), derived (only block borders' normals are "
                "stored; readers derive the others from the positions), or auto (derived when the charts keep at "
                "most 16 samples per input triangle)")
      ->check(CLI::IsMember({"auto", "stored", "derived"}))
      ->capture_default_str();
  b->add_option("--sizing", a.sizingArg,
                "Meshes: patch (each patch's charts at their own size: from the density's, doubled while they "
                "fold or sample the surface more coarsely than --sample-error; one quad layout, sides unless "
                "--quads kites, no patch cut) or layout (every chart at one size, the chart repair cutting the "
                "patches whose charts fold or sample too coarsely, and with --quads auto both layouts tried); "
                "--chart-size asks for one size")
      ->check(CLI::IsMember({"patch", "layout"}))
      ->capture_default_str();
  b->add_option("--quad-map", a.quadMapArg,
                "Meshes: how a quad chart's square maps into its patch's parameterization: bilinear (of the "
                "quad's corners), stretch (least stretch over the chart itself; the border samples are the same), or "
                "folding (stretch for the charts that fold under bilinear, where they fold less)")
      ->check(CLI::IsMember({"bilinear", "stretch", "folding"}))
      ->capture_default_str();
  b->add_flag(
      "--full-charts", [&](int64_t) { a.mesh.coarsenCharts = false; },
      "Meshes: every chart keeps its finest samples, each where it was resampled (by default a chart "
      "keeps only the levels from the coarsest whose surface stays within --sample-error of the input "
      "vertices, and the squares of that level that the two triangles of their corners follow within it "
      "move onto them, their corners alone stored)");
  b->add_flag(
      "--no-unfold", [&](int64_t) { a.mesh.unfold = false; },
      "Meshes: keep every inner sample where the quad map puts it (no sliding of the samples round "
      "flipped texels over the surface to unfold them)");
  b->add_option("--chart-metric", a.chartMetricArg,
                "Meshes: what the patch clustering keeps patches: planar (plane fit and normal spread), "
                "developable (cone fit: planes, cylinders and cones, so fewer, larger patches flatten with "
                "little stretch), or auto (developable up to 4M triangles, planar above)")
      ->check(CLI::IsMember({"auto", "planar", "developable"}))
      ->capture_default_str();
  b->add_option("--chart-error", a.mesh.maxPatchError,
                "Meshes with --charts 0: largest RMS plane distance of a patch / bounding-box diagonal")
      ->capture_default_str();
  b->add_flag("--no-fidelity", a.noFidelity, "Meshes: skip the Hausdorff distance between the input and the atlas");
  b->add_option("--fidelity", a.fidelityArg,
                "Meshes: how the Hausdorff distance is measured: fast (the atlas read a chart at a time: every "
                "input vertex and triangle centroid measured exactly, the atlas side on about a million samples "
                "with the confidence stated) or full (the whole atlas surface welded and every sample measured; "
                "memory grows with the atlas)")
      ->check(CLI::IsMember({"fast", "full"}))
      ->capture_default_str();
  b->add_option("--repair-rounds,--flip-repair-rounds", a.mesh.repairRounds,
                "Meshes: rounds of each chart repair (cutting patches whose charts have flipped texels or a "
                "sampling error over --sample-error); 0: none")
      ->capture_default_str();
  b->add_option("--repair-budget,--flip-repair-budget", a.mesh.repairBudget,
                "Meshes: the chart repair stops once it has parameterized this many times the surface's triangles "
                "again, counting at most 2^20 of them (its time is about this many resamplings up to a million "
                "triangles); with --quads auto, each of its repairs (up to two layouts at each size it tries) "
                "takes a quarter")
      ->capture_default_str();
  b->add_option("--sample-error", a.sampleErrorPercent,
                "Meshes: the largest distance, in % of the bounding-box diagonal, from an input vertex to its "
                "chart's surface; patches whose charts exceed it are cut; 0: flips only (default: 0.08 when the "
                "chart size is chosen by density, else 0)");
}

// The memory cap, the quadtree and the DEM options.
void addCommonAndTerrainOptions(CLI::App* b, BuildArgs& a) {
  b->add_option("--max-memory", a.maxMemory,
                "Memory cap (e.g. 2G, 512M). Meshes: larger ones go through cell files. DEMs: one whose "
                "in-memory build would exceed it is built window by window within it (default for DEMs: 3/4 of "
                "the machine's memory)")
      ->capture_default_str();
  b->add_option("--depth", a.common.depth,
                "Quadtree levels per chart, 1 to 12 (default: as many as leave the finest nodes 32 intervals wide; "
                "DEMs at least 5, meshes at most 5)");
  b->add_option("--node-res", a.common.nodeRes, "Maximum node resolution R in intervals (power of two)")
      ->capture_default_str();
  b->add_option("--min-node-res", a.common.minNodeRes, "Minimum node resolution in intervals")->capture_default_str();
  b->add_option("--z-scale", a.terrain.zScale, "Height multiplier")->capture_default_str();
  b->add_option("--subdataset", a.terrain.subdataset, "netCDF variable / GDAL subdataset to read");
  b->add_option("--band", a.terrain.band,
                "DEMs: the band holding the heights, from 1 (default: band 1; a 3- or 4-band byte image is "
                "refused as colour)");
  b->add_option("--spacing", a.spacingArg,
                "DEMs: metres between samples, X[,Y] (east, north; Y defaults to X), in place of the georeference's "
                "(a raster without one is otherwise taken as 1 m)")
      ->delimiter(',')
      ->expected(1, 2);
  b->add_option("--threads", a.common.threads, "Worker threads (0: all cores)")->capture_default_str();
  b->add_option("--imagery", a.terrain.imagery,
                "DEMs: colour raster (RGB/RGBA/grey, any format GDAL reads) draped over the terrain, reprojected "
                "with GDAL onto the DEM's grid at its own resolution");
  b->add_option("--imagery-scale", a.imageryScale,
                "DEMs with --imagery: imagery samples per DEM sample interval, 1, 2 or 4 (default: the power of "
                "two nearest the two rasters' resolutions)");
  b->add_option("--imagery-extent", a.imageryExtent,
                "DEMs with --imagery: WEST,SOUTH,EAST,NORTH of imagery without a georeference, in the DEM's "
                "reference system (a whole-Earth image: -180,-90,180,90)")
      ->delimiter(',')
      ->expected(4);

  b->add_option("--height-precision", a.terrain.heightPrecision,
                "DEMs: heights that are not whole metres are stored to this step, in metres; whole metres are "
                "stored exactly (default: 1 for a source of whole metres like SRTM, whose filled voids are "
                "rounded like it, else 0.01)");
  b->add_flag("--out-of-core", a.terrain.outOfCore,
              "DEMs: build window by window within --max-memory even when the DEM would fit in memory "
              "(a DEM that would not is built so anyway)");
  b->add_flag("--planet", a.terrain.planet,
              "DEMs in longitude and latitude: draw the terrain on a sphere (a DEM circling the planet wraps at "
              "the antimeridian and closes at the poles)");
  b->add_option("--radius", a.terrain.planetRadius, "DEMs with --planet: the sphere's radius, metres")
      ->capture_default_str();
  b->add_option("--ellipsoid", a.ellipsoid,
                "DEMs with --planet: draw on a reference ellipsoid instead of a sphere, heights along its "
                "normal (WGS84 or GRS80)");
  b->add_flag("--uncompressed", a.uncompressed,
              "Write raw chart files (atlas format version 1: float32 heights or positions, 4-byte normals) "
              "instead of compressed ones");
}

// How meshes' samples are stored.
void addMeshStorageOptions(CLI::App* b, BuildArgs& a) {
  b->add_option("--position-bits", a.mesh.positionBits,
                "Meshes: positions are stored on a lattice of 2^B steps across the bounding-box diagonal")
      ->capture_default_str();
  b->add_option("--position-tolerance", a.positionTolerancePercent,
                "Meshes: positions inside a chart may move this far, in % of the bounding-box diagonal, to the "
                "lattice point their neighbours predict, so they code in fewer bytes; the Hausdorff distance "
                "grows by at most this much; 0: every position at its nearest lattice point")
      ->capture_default_str();
  b->add_option("--normal-tolerance", a.mesh.normalTolerance,
                "Meshes: normals inside a chart may move this many packed steps (1/127.5) per component to "
                "the value their neighbours predict; 0: normals stored as sampled")
      ->capture_default_str();
}

// Builds across processes (apps/shard_command.h).
void addShardOptions(CLI::App* b, BuildArgs& a) {
  b->add_flag("--prepare", a.shardArgs.prepare,
              "DEMs, a build across processes: the step that reads the whole DEM, once, into the shard area "
              "beside the atlas (ATLAS.shards, on a file system every node sees); then --shard, then merge");
  b->add_option("--shard", a.shardArgs.shard,
                "DEMs, a build across processes: build shard I of N (I from 0) after --prepare; each shard can be "
                "run again alone")
      ->excludes("--prepare");
  b->add_flag("--mpi", a.shardArgs.mpi,
              "DEMs: under mpirun, rank 0 prepares and merges and every rank takes shards from a work list")
      ->excludes("--prepare")
      ->excludes("--shard");
  b->add_option("--shards", a.shardArgs.shards,
                "With --mpi or --emit-slurm: the number of shards (default: four a "
                "rank, at most one a chart; or 8)");
  b->add_option("--emit-slurm", a.shardArgs.slurmDir,
                "DEMs: write Slurm batch scripts for this build into DIR (prepare, a job array of shards, the "
                "merge, and submit.sh chaining them with --dependency=afterok) instead of building")
      ->excludes("--prepare")
      ->excludes("--shard")
      ->excludes("--mpi");
}

// The options of a mesh build; throws InputError for options that only DEMs take.
MeshBuildOptions meshOptions(const BuildArgs& a, const CommonBuildOptions& common, uint64_t maxMemory) {
  if (a.shardArgs.any())
    throw InputError(common.input.string() +
                     ": builds across processes (--prepare, --shard, --mpi, "
                     "--emit-slurm) take DEMs; a mesh is built in one process");
  if (!a.terrain.imagery.empty())
    throw InputError(common.input.string() +
                     ": --imagery drapes a raster over a DEM; a mesh carries its own "
                     "vertex colours");
  if (a.terrain.planet)
    throw InputError(common.input.string() +
                     ": --planet draws a longitude/latitude DEM on a sphere; a mesh "
                     "is drawn as it is");
  MeshBuildOptions mesh = a.mesh;
  static_cast<CommonBuildOptions&>(mesh) = common;
  if (a.chartSizeOption->count() > 0) mesh.chartSize = a.terrain.chartSize;
  mesh.patches = a.chartsArg == "auto" ? kAutoPatches : parseCount("--charts", a.chartsArg);
  mesh.chartMetric = a.chartMetricArg == "developable" ? MeshChartMetric::kDevelopable
                     : a.chartMetricArg == "planar"    ? MeshChartMetric::kPlanar
                                                       : MeshChartMetric::kAuto;
  mesh.quadMap = a.quadMapArg == "stretch"   ? MeshQuadMap::kStretch
                 : a.quadMapArg == "folding" ? MeshQuadMap::kFolding
                                             : MeshQuadMap::kBilinear;
  mesh.normals = a.normalsArg == "stored"    ? MeshNormals::kStored
                 : a.normalsArg == "derived" ? MeshNormals::kDerived
                                             : MeshNormals::kAuto;
  mesh.sizing = a.sizingArg == "layout" ? MeshSizing::kLayout : MeshSizing::kPatch;
  mesh.quads = a.quadsArg == "sides" ? MeshQuads::kSides : a.quadsArg == "kites" ? MeshQuads::kKites : MeshQuads::kAuto;
  mesh.maxSampleError = a.sampleErrorPercent < 0.0 && a.command->get_option("--sample-error")->count() == 0
                            ? kAutoSampleError
                            : a.sampleErrorPercent / 100.0;
  mesh.maxMemory = maxMemory;
  mesh.positionTolerance = a.positionTolerancePercent / 100.0;
  mesh.measureFidelity = !a.noFidelity;
  mesh.fidelity = a.fidelityArg == "full" ? MeshFidelity::kFull : MeshFidelity::kFast;
  return mesh;
}

// The options of a DEM build; throws InputError for a bad value or a missing companion option.
TerrainBuildOptions terrainOptions(const BuildArgs& a, const CommonBuildOptions& common, uint64_t maxMemory) {
  TerrainBuildOptions terrain = a.terrain;
  static_cast<CommonBuildOptions&>(terrain) = common;
  if (a.command->get_option("--max-memory")->count() > 0) terrain.maxMemory = maxMemory;
  if (a.command->get_option("--imagery-scale")->count() > 0) {
    if (a.imageryScale != 1 && a.imageryScale != 2 && a.imageryScale != 4)
      throw InputError("--imagery-scale " + std::to_string(a.imageryScale) + " must be 1, 2 or 4");
    terrain.imageryScaleLog2 = int(log2u(a.imageryScale));
  }
  if (!a.spacingArg.empty()) {
    for (double v : a.spacingArg)
      if (!(v > 0.0) || !std::isfinite(v))
        throw InputError("--spacing " + std::to_string(v) + " must be a positive number of metres");
    terrain.spacing = {a.spacingArg[0], a.spacingArg.back()};
  }
  if (!a.imageryExtent.empty())
    terrain.imageryExtent =
        std::array<double, 4>{a.imageryExtent[0], a.imageryExtent[1], a.imageryExtent[2], a.imageryExtent[3]};
  if (terrain.imagery.empty() && (terrain.imageryExtent || terrain.imageryScaleLog2 >= 0))
    throw InputError("--imagery-scale and --imagery-extent need --imagery");
  if (a.command->get_option("--radius")->count() > 0 && !terrain.planet) throw InputError("--radius needs --planet");
  if (!a.ellipsoid.empty()) {
    if (!terrain.planet) throw InputError("--ellipsoid needs --planet");
    if (a.command->get_option("--radius")->count() > 0)
      throw InputError("--ellipsoid and --radius: give one (an ellipsoid has its own radii)");
    const Ellipsoid* e = findEllipsoid(a.ellipsoid);
    if (!e) throw InputError("--ellipsoid " + a.ellipsoid + ": unknown; give WGS84 or GRS80");
    terrain.planetRadius = e->radius;
    terrain.planetFlattening = e->flattening;
  }
  if (!(terrain.planetRadius >= 1.0 && terrain.planetRadius <= 1e9))
    throw InputError("--radius " + std::to_string(terrain.planetRadius) + " must be between 1 and 1e9 metres");
  return terrain;
}

}  // namespace

std::string flagFor(std::string_view name) {
  static const std::map<std::string_view, std::string_view> kFlags = {{"chartSize", "--chart-size"},
                                                                      {"blockIntervals", "--node-res"},
                                                                      {"depth", "--depth"},
                                                                      {"nodeRes", "--node-res"},
                                                                      {"minNodeRes", "--min-node-res"},
                                                                      {"zScale", "--z-scale"},
                                                                      {"subdataset", "--subdataset"},
                                                                      {"threads", "--threads"},
                                                                      {"band", "--band"},
                                                                      {"spacing", "--spacing"},
                                                                      {"imagery", "--imagery"},
                                                                      {"patches", "--charts"},
                                                                      {"maxPatchError", "--chart-error"},
                                                                      {"repairRounds", "--repair-rounds"},
                                                                      {"repairBudget", "--repair-budget"},
                                                                      {"maxSampleError", "--sample-error"},
                                                                      {"maxMemory", "--max-memory"},
                                                                      {"measureFidelity", "--no-fidelity"},
                                                                      {"output", "--output"},
                                                                      {"worstCharts", "--worst"},
                                                                      {"thumbnailSize", "--image-size"},
                                                                      {"imageryScale", "--imagery-scale"},
                                                                      {"imageryExtent", "--imagery-extent"},
                                                                      {"heightPrecision", "--height-precision"},
                                                                      {"compress", "--uncompressed"},
                                                                      {"positionBits", "--position-bits"},
                                                                      {"positionTolerance", "--position-tolerance"},
                                                                      {"normalTolerance", "--normal-tolerance"},
                                                                      {"normals", "--normals"},
                                                                      {"imagery", "--imagery"},
                                                                      {"quads", "--quads"},
                                                                      {"quadMap", "--quad-map"},
                                                                      {"sizing", "--sizing"},
                                                                      {"outOfCore", "--out-of-core"},
                                                                      {"planet", "--planet"},
                                                                      {"planetFlattening", "--ellipsoid"},
                                                                      {"planetRadius", "--radius"},
                                                                      {"shard", "--shard"},
                                                                      {"shards", "--shards"}};
  const auto it = kFlags.find(name);
  return std::string(it == kFlags.end() ? name : it->second);
}

CLI::App* addBuildCommand(CLI::App& app, BuildArgs& a) {
  a.command = app.add_subcommand("build", "Build an atlas (charts, pyramids, hierarchy) from a DEM or a mesh");
  CLI::App* b = a.command;
  b->add_option("input", a.common.input,
                "DEM (GeoTIFF, SRTM .hgt, USGS .dem, netCDF, ESRI ASCII, ...) or mesh (PLY, OBJ, OFF, STL)")
      ->required();
  b->add_option("-o,--output", a.common.output, "Atlas directory to create")->required();
  a.chartSizeOption = b->add_option(
      "--chart-size", a.terrain.chartSize,
      "Chart side in samples, 2^m+1 (DEMs: by default the smallest from 513 that gives at most 64 charts, "
      "up to 32769, 2049 with imagery; meshes: from the input's density, 65 to 1025)");
  addMeshChartOptions(b, a);
  addCommonAndTerrainOptions(b, a);
  addMeshStorageOptions(b, a);
  addShardOptions(b, a);
  return b;
}

int runBuildCommand(const BuildArgs& a, int argc, char** argv) {
  CommonBuildOptions common = a.common;
  const uint64_t maxMemory = parseBytes("--max-memory", a.maxMemory);
  // (0 is how the options say "not given".)
  if (a.command->get_option("--depth")->count() > 0 && (common.depth < 1 || common.depth > 12))
    throw InputError("--depth " + std::to_string(common.depth) + " must be in [1, 12]");
  common.spellOption = flagFor;
  common.compress = !a.uncompressed;
  if (isMesh(detectInputKind(common.input))) {
    std::cout << buildSummary(common.output, buildMeshAtlas(meshOptions(a, common, maxMemory)));
    return 0;
  }
  const TerrainBuildOptions terrain = terrainOptions(a, common, maxMemory);
  if (a.shardArgs.any()) return runShardedBuild(terrain, a.shardArgs, argc, argv);
  std::cout << buildSummary(terrain.output, buildTerrainAtlas(terrain));
  return 0;
}

}  // namespace gimlod
