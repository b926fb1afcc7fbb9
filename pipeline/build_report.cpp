#include "pipeline/build_report.h"

#include <fmt/format.h>

#include "core/atlas_format.h"

namespace gimlod {
namespace {

// What the mesh reader read, repaired and warned about (docs/mesh_stage.md, "Mesh input").
nlohmann::json readJson(const MeshReadStats& rs) {
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

nlohmann::json gridifyJson(const GridifyResult& gr) {
  return {{"cells", gr.cells},
          {"triangles", gr.triangles},
          {"max_cell_triangles", gr.maxCellTriangles},
          {"peak_buffered_bytes", gr.peakBufferedBytes},
          {"peak_tracked_bytes", gr.peakTrackedBytes},
          {"bytes_written", gr.bytesWritten},
          {"seconds", gr.seconds}};
}

nlohmann::json chartingJson(const ChartingStats& cst, bool outOfCore) {
  return {{"triangles", cst.outputTriangles},
          {"patches", cst.charts},
          {"dropped_degenerate", cst.droppedDegenerate},
          {"dropped_duplicate", cst.droppedDuplicate},
          {"vertices_welded", cst.verticesWelded},
          {"non_manifold_edges", cst.nonManifoldEdges},
          {"non_manifold_vertices", cst.nonManifoldVertices},
          {"vertices_split", cst.verticesSplit},
          {"boundary_edges", cst.boundaryEdges},
          {"corners_inserted", cst.cornersInserted},
          {"patches_split", cst.patchesSplit},
          {"max_planarity_error", cst.maxPlanarityError},
          {"sides_histogram", cst.sidesHistogram},
          {"out_of_core", outOfCore},
          {"cells", cst.cells},
          {"cell_clusters", cst.cellClusters},
          {"cell_clusters_dissolved", cst.cellClustersDissolved},
          {"charts_before_fixing", cst.chartsBeforeFixing},
          {"merges_refused_not_disk", cst.mergesRefusedNotDisk},
          {"patches_unfixed", cst.patchesUnfixed},
          {"weld_seconds", cst.weldSeconds},
          {"cluster_seconds", cst.clusterSeconds},
          {"cell_seconds", cst.cellSeconds},
          {"sides_seconds", cst.sidesSeconds},
          {"peak_bytes_estimate", cst.peakBytesEstimate},
          {"seconds", cst.seconds}};
}

nlohmann::json resampleJson(const MeshResampleStats& rs, uint64_t spilledBytes) {
  const ChartRepairStats& flips = rs.repair;
  nlohmann::json j = {{"charts", rs.charts},
                      {"param_stretch_l2", rs.param.stretchL2},
                      {"param_stretch_linf", rs.param.stretchLinf},
                      {"param_flipped", rs.param.flippedTriangles},
                      {"param_degenerate", rs.param.degenerateTriangles},
                      {"image_stretch_l2", rs.image.stretchL2},
                      {"image_stretch_linf", rs.image.stretchLinf},
                      {"flipped_texels", rs.image.flippedTexels},
                      {"texels_against_vertex_normals", rs.image.texelsAgainstNormals},
                      {"sample_error", rs.image.sampleError},
                      {"max_sample_error", rs.maxSampleError},
                      {"sample_error_before_splits", flips.sampleErrorFirst},
                      {"patches_over_sample_error_before_splits", flips.patchesOverErrorFirst},
                      {"chart_size_by_density", rs.chartSizeByDensity},
                      {"chart_size_for_density", rs.densityChartSize},
                      {"chart_size_doublings_after_repair", rs.repairDoublings},
                      {"sides_lengthened", rs.sidesLengthened},
                      {"sides_straightened", rs.sidesStraightened},
                      {"side_ears_mended", rs.sideEarsMended},
                      {"quads", rs.sideQuads ? "sides" : "kites"},
                      {"quad_map", rs.quadMap},
                      {"unfold", rs.unfold},
                      {"texels_unfolded", rs.image.texelsUnfolded},
                      {"samples_unfolded_past_quad", rs.image.samplesPastQuad},
                      {"even_side_corners", rs.evenSideCorners},
                      {"side_edges_split", rs.sideEdgesSplit},
                      {"other_quads_flipped_texels", rs.alternativeFlippedTexels},
                      {"two_quad_corners", rs.twoQuadCorners},
                      {"flipped_texels_before_splits", flips.flippedTexelsFirst},
                      {"patches_split_by_repair", flips.patchesSplit},
                      {"patches_unsplittable", flips.patchesUnsplit},
                      {"split_rounds", flips.rounds},
                      {"repair_stopped_for_memory", flips.stoppedForMemory},
                      {"repair_stopped_for_work", flips.stoppedForWork},
                      {"repair_work", rs.repairWork},
                      {"repair_triangles_whole_rounds", flips.trianglesWholeRounds},
                      {"repair_triangles_trials", flips.trianglesTrials},
                      {"patches", rs.patches},
                      {"degenerate_texels", rs.image.degenerateTexels},
                      {"sizing", rs.perPatchSize ? "patch" : "layout"},
                      {"sizing_rounds", rs.sizeRounds},
                      {"patches_doubled", rs.patchesDoubled},
                      {"patches_by_size", rs.patchesBySize},
                      {"patches_below_density_size", rs.patchesBelowDensitySize},
                      {"patches_over_bound_at_largest_size", rs.patchesAtLargestSize},
                      {"patches_over_bound_at_sample_cap", rs.patchesAtSampleCap},
                      {"patches_over_bound_at_lattice", rs.patchesAtLattice},
                      {"patches_over_bound_flat", rs.patchesAtFlatError},
                      {"patches_over_bound_at_memory", rs.patchesAtMemory}};
  // Per chart: its patch and quad, its side in samples, stretch of the sampled image, flipped and
  // degenerate texels.
  nlohmann::json perChart = nlohmann::json::array();
  for (const ChartQuality& c : rs.perChart) {
    perChart.push_back({{"patch", c.patch},
                        {"quad", c.quad},
                        {"side", c.side},
                        {"stretch_l2", c.quality.stretchL2},
                        {"stretch_linf", c.quality.stretchLinf},
                        {"flipped_texels", c.quality.flippedTexels},
                        {"texels_against_vertex_normals", c.quality.texelsAgainstNormals},
                        {"degenerate_texels", c.quality.degenerateTexels},
                        {"sample_error", c.quality.sampleError}});
  }
  j["per_chart"] = std::move(perChart);
  j["spilled_bytes"] = spilledBytes;
  return j;
}

nlohmann::json fidelityJson(const FidelityStats& f, bool outOfCore, MeshFidelity mode) {
  nlohmann::json j = {{"hausdorff_percent_of_diagonal", f.hausdorffPercent},
                      {"mean_percent_of_diagonal", f.meanPercent},
                      {"max_atlas_to_mesh", f.maxAtlasToMesh},
                      {"max_mesh_to_atlas", f.maxMeshToAtlas},
                      {"diagonal", f.diagonal},
                      {"atlas_samples", f.atlasSamples},
                      {"mesh_samples", f.meshSamples},
                      {"out_of_core", outOfCore},
                      {"seconds", f.seconds}};
  j["mode"] = outOfCore ? "blocks" : mode == MeshFidelity::kFast ? "fast" : "full";
  if (!outOfCore && mode == MeshFidelity::kFast) {
    j["atlas_samples_total"] = f.atlasSamplesTotal;
    j["atlas_fraction_above"] = f.atlasFractionAbove;
    j["samples_beyond_margin"] = f.samplesBeyondMargin;
  }
  if (outOfCore) {
    j["blocks"] = f.blocks;
    j["samples_beyond_margin"] = f.samplesBeyondMargin;
    j["exact"] = f.exact;
  }
  return j;
}

nlohmann::json stagesJson(const std::vector<StageTiming>& stages) {
  nlohmann::json j = nlohmann::json::array();
  for (const StageTiming& s : stages)
    j.push_back({{"stage", s.stage},
                 {"seconds", s.seconds},
                 {"cpu_seconds", s.cpuSeconds},
                 {"peak_rss_bytes", s.peakRssBytes}});
  return j;
}

// What every build's summary prints: its charts (chartsX x chartsY of chartSize samples a side),
// samples, voids filled, hierarchy, bytes on disk and time.
struct SummaryFigures {
  uint32_t charts = 0, chartsX = 0, chartsY = 0, chartSize = 0;
  uint64_t samples = 0, voidsFilled = 0;
  const HierarchyStats& hierarchy;
  uint64_t bytesOnDisk = 0;
  double totalSeconds = 0.0;
};

// The lines every build prints.
std::string summaryLines(const std::filesystem::path& output, const SummaryFigures& f) {
  const HierarchyStats& hs = f.hierarchy;
  return fmt::format(
      "built {}\n  charts            {} ({}x{}, {} samples each side)\n  samples           {}\n"
      "  voids filled      {}\n  hierarchy         {:.2f} M samples/s ({} threads, {:.3f} s)\n"
      "  bytes on disk     {}\n  total             {:.2f} s\n",
      output.string(), f.charts, f.chartsX, f.chartsY, f.chartSize, f.samples, f.voidsFilled,
      hs.samplesPerSecond * 1e-6, hs.threads, hs.seconds, f.bytesOnDisk, f.totalSeconds);
}

uint64_t meshSamples(const MeshWriteStats& w) { return w.resampledSamples; }

}  // namespace

nlohmann::json statsJson(const TerrainBuildStats& s) {
  const TerrainWriteStats& w = s.write;
  const TerrainAtlasStats& cs = w.charts;
  nlohmann::json stats = {
      {"input", s.input},
      {"charts", cs.charts},
      {"charts_grid", {w.chartsX, w.chartsY}},
      {"chart_size", w.chartSize},
      {"samples", cs.samples},
      {"stored_samples", cs.storedSamples},
      {"voids_filled", s.read.voidsFilled},
      {"void_fill_method", s.read.voidFillMethod},
      {"spacing_m", s.read.spacing},
      {"height_range_m", s.read.heightRange},
      {"hierarchy_depth", w.depth},
      {"hierarchy_nodes", uint64_t(nodesPerChart(w.depth)) * cs.charts},
      {"hierarchy_samples", w.hierarchy.samples},
      {"hierarchy_seconds", w.hierarchy.seconds},
      {"hierarchy_samples_per_second", w.hierarchy.samplesPerSecond},
      {"hierarchy_threads", w.hierarchy.threads},
      {"load_seconds", s.read.seconds},
      {"chart_seconds", cs.seconds},
  };
  if (w.imagery) {
    const TerrainImageryStats& im = *w.imagery;
    stats["imagery"] = {{"source", im.source},
                        {"scale_log2", im.scaleLog2},
                        {"size", {im.width, im.height}},
                        {"coverage", im.coverage},
                        {"resampling", im.resampling},
                        {"stored_samples", im.storedSamples},
                        {"bytes_on_disk", im.bytesOnDisk},
                        {"read_seconds", im.readSeconds},
                        {"write_seconds", im.writeSeconds}};
    if (im.windows > 0) {
      stats["imagery"]["windows"] = im.windows;
      stats["imagery"]["window_samples"] = im.windowSamples;
    }
  }
  if (w.windowed)
    stats["windowed"] = {{"memory_bytes", w.windowed->memoryBytes},
                         {"scratch_bytes", w.windowed->scratchBytes},
                         {"scratch_tile", w.windowed->scratchTile},
                         {"band_rows", w.windowed->bandRows},
                         {"band_columns", w.windowed->bandColumns}};
  stats["bytes_on_disk"] = s.bytesOnDisk;
  stats["bytes_per_sample"] = cs.samples ? double(s.bytesOnDisk) / double(cs.samples) : 0.0;
  stats["samples_per_second"] = s.totalSeconds > 0 ? double(cs.samples) / s.totalSeconds : 0.0;
  stats["total_seconds"] = s.totalSeconds;
  stats["peak_rss_bytes"] = s.peakRssBytes;
  return stats;
}

nlohmann::json statsJson(const MeshBuildStats& s) {
  const MeshChartStats& ch = s.chart;
  const MeshWriteStats& w = s.write;
  nlohmann::json stats = {{"input", s.input}, {"kind", atlasKindName(AtlasKind::Geometry)}};
  if (ch.gridify) stats["gridify"] = gridifyJson(*ch.gridify);
  stats["read"] = readJson(ch.read);
  stats["charting"] = chartingJson(ch.charting, ch.outOfCore);
  stats["charting"]["metric"] = ch.developable ? "developable" : "planar";
  stats["resample"] = resampleJson(s.resample, w.spilledBytes);
  if (s.fidelity)
    stats["fidelity"] = fidelityJson(*s.fidelity, ch.outOfCore, s.fidelityMode);
  else
    stats["fidelity"] = "not measured (--no-fidelity)";  // note: a stats.json value, read as such
  stats["charts"] = w.charts;
  stats["chart_size"] = w.chartSize;
  stats["samples"] = meshSamples(w);
  stats["bounds"] = w.bounds;
  stats["hierarchy_depth"] = w.depth;
  stats["charts_by_finest_level"] = w.chartsByFinestLevel;
  stats["finest_samples"] = w.finestSamples;
  stats["planar_samples"] = w.planarSamples;
  stats["hierarchy_samples_per_second"] = w.hierarchy.samplesPerSecond;
  stats["hierarchy_seconds"] = w.hierarchy.seconds;
  stats["hierarchy_threads"] = w.hierarchy.threads;
  stats["normals"] = {{"derived", w.normalsDerived}, {"samples_per_triangle", w.samplesPerTriangle}};
  if (w.normalsDerived)
    stats["normals"]["degrees_from_resampled"] = {{"samples", w.normalAngles.samples},
                                                  {"mean", w.normalAngles.mean},
                                                  {"median", w.normalAngles.median},
                                                  {"p99", w.normalAngles.p99},
                                                  {"max", w.normalAngles.max}};
  stats["voids_filled"] = 0;
  stats["charting_seconds"] = ch.seconds;
  stats["bytes_on_disk"] = s.bytesOnDisk;
  stats["total_seconds"] = s.totalSeconds;
  stats["charts_grid"] = {w.chartsX, w.chartsY};
  stats["stages"] = stagesJson(s.stages);
  stats["peak_rss_bytes"] = s.peakRssBytes;
  return stats;
}

std::string buildSummary(const std::filesystem::path& output, const TerrainBuildStats& s) {
  const TerrainWriteStats& w = s.write;
  std::string lines = summaryLines(output, {w.charts.charts, w.chartsX, w.chartsY, w.chartSize, w.charts.samples,
                                            s.read.voidsFilled, w.hierarchy, s.bytesOnDisk, s.totalSeconds});
  if (w.imagery)
    lines += fmt::format("  imagery           {} x {} samples ({} per DEM interval, {}), {:.1f}% covered, {} bytes\n",
                         w.imagery->width, w.imagery->height, 1u << w.imagery->scaleLog2, w.imagery->resampling,
                         100.0 * w.imagery->coverage, w.imagery->bytesOnDisk);
  return lines;
}

std::string buildSummary(const std::filesystem::path& output, const MeshBuildStats& s) {
  const MeshWriteStats& w = s.write;
  const MeshReadStats& rd = s.chart.read;
  const ChartingStats& ch = s.chart.charting;
  // Mesh input: what was repaired (docs/mesh_stage.md, "Mesh input").
  return summaryLines(output, {w.charts, w.chartsX, w.chartsY, w.chartSize, meshSamples(w), 0, w.hierarchy,
                               s.bytesOnDisk, s.totalSeconds}) +
         fmt::format(
             "  input             {} triangles read, {} kept; dropped: {} non-finite, {} degenerate, {} duplicate\n"
             "  repaired          {} non-manifold edges, {} non-manifold vertices ({} vertex copies), "
             "{} more triangles dropped after welding\n",
             rd.trianglesRead, rd.trianglesOut, rd.droppedNonFinite, rd.droppedDegenerate, rd.droppedDuplicate,
             ch.nonManifoldEdges, ch.nonManifoldVertices, ch.verticesSplit, ch.droppedDegenerate + ch.droppedDuplicate);
}

uint64_t directoryBytes(const std::filesystem::path& dir) {
  uint64_t total = 0;
  for (const auto& e : std::filesystem::recursive_directory_iterator(dir))
    if (e.is_regular_file()) total += e.file_size();
  return total;
}

void writeStatsFile(const std::filesystem::path& dir, const nlohmann::json& json) {
  const std::string text = json.dump(2) + "\n";
  atomicWriteFile(dir / "stats.json", text.data(), text.size());
}

}  // namespace gimlod
