// The stages of a mesh build (section 5 of the paper): read and chart (in memory, or through
// cell files for a large mesh) -> resample and repair (quads, parameterization, resampling, the
// flip repair) -> write (geometry chart pyramids, hierarchy, manifest) -> fidelity (two-sided
// Hausdorff distance between the input and the atlas). Each stage is timed by the StageMeter it
// is given.
// Based on: Niski, Purnomo, Cohen, "Multi-grained Level of Detail Using a Hierarchical Seamless
// Texture Atlas", I3D 2007, section 5.
#pragma once

#include <filesystem>
#include <memory>

#include "atlas/mesh/patch_layout.h"
#include "atlas/mesh/mesh_io.h"
#include "atlas/mesh/quad_charts.h"
#include "atlas/mesh/resample.h"
#include "core/stage_meter.h"
#include "hierarchy/hierarchy.h"
#include "pipeline/build_options.h"
#include "pipeline/build_stats.h"

namespace gimlod {

// Checks the options (throws InputError naming the parameter, optionRef) and returns the
// hierarchy of charts of options.chartSize samples: R capped at chartSize - 1, the depth at what
// the chart allows (leaves keep at least the minimum node resolution).
HierarchyParams meshHierarchyParams(const MeshBuildOptions& options);

// A mesh read and charted.
struct ChartedMesh {
  PatchLayout layout;
  IndexedMesh mesh;             // the input, kept for the fidelity figure (in-memory path)
  std::filesystem::path cells;  // the cell files, kept for the fidelity figure (out-of-core path)
  MeshChartStats stats;
};

// Read and chart: in memory, or (above a quarter of options.maxMemory by info's estimate)
// through cell files in dir, the staging directory. Stages "gridify" or "read", then
// "charting". Throws InputError naming the file. stats.seconds is left to the caller.
ChartedMesh chartMesh(const MeshBuildOptions& options, const MeshInfo& info, const std::filesystem::path& dir,
                      StageMeter& meter);

// The lattice step of a compressed mesh atlas's positions: the power of two at or below
// diagonal / 2^positionBits, but no finer than 2^-22 of the largest coordinate (so every
// coordinate is within 2^23 steps, and a lattice point is an exact float).
double meshPositionStep(const MeshBounds& bounds, uint32_t positionBits);

// The layout's quad charts, made by makeQuadCharts (atlas/mesh/quad_charts.h) with the options'
// quad layout, chart size, quad map and repair.
QuadChartOptions quadChartOptions(const MeshBuildOptions& options);

// Write: the chart files, hierarchy and manifest into dir; the samples and the spill are freed.
// Stage "write". Throws InputError when a file cannot be written.
MeshWriteStats writeMeshAtlas(ResampledMesh&& resampled, const HierarchyParams& params, const MeshBuildOptions& options,
                              const std::filesystem::path& dir, StageMeter& meter);

// Fidelity: the two-sided Hausdorff distance between charted's input (its mesh, or its cell
// files, which are removed after) and the atlas written in dir, on the cell-file path block by
// block in half of options.maxMemory. Stage "fidelity".
FidelityStats measureMeshFidelity(ChartedMesh& charted, const MeshBuildOptions& options,
                                  const std::filesystem::path& dir, StageMeter& meter);

}  // namespace gimlod
