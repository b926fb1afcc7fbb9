// What each build stage reports: plain structs, turned into stats.json and the printed summary
// by pipeline/build_report.h.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "atlas/mesh/charting.h"
#include "atlas/fidelity/fidelity.h"
#include "atlas/mesh/gridify.h"
#include "atlas/mesh/layout_refine.h"
#include "atlas/mesh/mesh_atlas.h"
#include "atlas/mesh/mesh_io.h"
#include "atlas/mesh/quad_charts.h"
#include "atlas/mesh/resample.h"
#include "atlas/terrain/terrain_atlas.h"
#include "core/stage_meter.h"
#include "hierarchy/hierarchy.h"

namespace gimlod {

// ---- terrain --------------------------------------------------------------------------------

// Read and fill: the DEM as loaded, its voids filled.
struct TerrainReadStats {
  uint32_t width = 0, height = 0;              // samples
  std::array<double, 2> spacing{1.0, 1.0};     // metres between samples (x east, y north)
  std::array<float, 2> heightRange{0.f, 0.f};  // metres, after z-scale
  uint64_t voidsFilled = 0;
  std::string voidFillMethod;
  double seconds = 0.0;
};

// Chart and write: the chart files, and the hierarchy and manifest written after them.
// The imagery draped over it (absent without --imagery).
struct TerrainImageryStats {
  std::string source;
  uint32_t scaleLog2 = 0;          // imagery samples per DEM interval: 2^scaleLog2
  uint32_t width = 0, height = 0;  // the reprojected imagery
  double coverage = 0.0;           // fraction of the terrain covered
  std::string resampling;
  uint64_t storedSamples = 0;
  uint64_t bytesOnDisk = 0;
  double readSeconds = 0.0;    // read and reproject (window by window: 0, counted in writeSeconds)
  double writeSeconds = 0.0;   // pyramid and chart files
  uint64_t windows = 0;        // window by window: the windows of charts reprojected
  uint64_t windowSamples = 0;  // and the most imagery samples one held
};

// The window-by-window build (atlas/terrain/terrain_windowed.h), when it ran.
struct TerrainWindowedStats {
  uint64_t memoryBytes = 0;   // what its windows could use
  uint64_t scratchBytes = 0;  // the most the compressed scratch raster took on disk
  uint32_t scratchTile = 0;   // its tiles' side
  uint64_t bandRows = 0;      // the most DEM rows a window of charts held
  uint64_t bandColumns = 0;   // and the most columns
};

struct TerrainWriteStats {
  TerrainAtlasStats charts;  // chart files (atlas/terrain_atlas.h)
  std::optional<TerrainWindowedStats> windowed;
  std::optional<TerrainImageryStats> imagery;
  uint32_t chartsX = 0, chartsY = 0;  // the chart grid
  uint32_t chartSize = 0;             // samples per chart side
  uint32_t depth = 0;                 // quadtree levels per chart
  HierarchyStats hierarchy;
};

// A whole terrain build (stats.json).
struct TerrainBuildStats {
  std::string input;  // absolute path of the DEM
  TerrainReadStats read;
  TerrainWriteStats write;
  uint64_t bytesOnDisk = 0;  // the atlas directory (stats.json aside)
  double totalSeconds = 0.0;
  uint64_t peakRssBytes = 0;  // the process's peak resident set (VmHWM) when the build ended
};

// ---- meshes ---------------------------------------------------------------------------------

// Read and chart: what the reader read and repaired, and the patch layout.
struct MeshChartStats {
  bool outOfCore = false;                // the mesh went through cell files
  bool developable = false;              // the patches were clustered by ChartMetric::kDevelopable
  std::optional<GridifyResult> gridify;  // the cell files (out-of-core path; manifest left empty)
  MeshReadStats read;
  ChartingStats charting;
  double seconds = 0.0;  // wall, from the build's start to the end of the charting
};

// Write: the chart files, the hierarchy and the manifest.
struct MeshWriteStats {
  uint32_t charts = 0;
  uint32_t chartsX = 0, chartsY = 0;
  uint32_t chartSize = 0;
  uint32_t depth = 0;             // quadtree levels per chart
  std::array<float, 6> bounds{};  // min x, y, z, max x, y, z over every sample
  uint64_t spilledBytes = 0;      // of the chart spill (atlas/resample.h ChartSpill)
  // The samples the charts were resampled with, each at its own size (GeometryImage::level).
  uint64_t resampledSamples = 0;
  HierarchyStats hierarchy;
  // Normals: stored, or derived from the positions on reading (block borders stored), with the
  // angles between the derived normals and the resampled ones over the derived samples.
  bool normalsDerived = false;
  double samplesPerTriangle = 0.0;  // what the automatic choice went by
  NormalAngles normalAngles;
  // The charts' finest levels (ChartInfo::finestLevel): charts by level, and their samples summed.
  std::vector<uint32_t> chartsByFinestLevel;
  uint64_t finestSamples = 0;
  uint64_t planarSamples = 0;  // of those, moved onto planar squares (geometryPyramid)
};

// A whole mesh build (stats.json).
struct MeshBuildStats {
  std::string input;  // absolute path of the mesh
  MeshChartStats chart;
  MeshResampleStats resample;
  MeshWriteStats write;
  std::optional<FidelityStats> fidelity;  // none: not measured
  MeshFidelity fidelityMode = MeshFidelity::kFast;
  std::vector<StageTiming> stages;
  uint64_t peakRssBytes = 0;
  uint64_t bytesOnDisk = 0;  // the atlas directory (stats.json aside)
  double totalSeconds = 0.0;
};

}  // namespace gimlod
