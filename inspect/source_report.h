// The source comparison of the inspection report (inspect/report.h, with --source): a mesh atlas
// against the mesh it was built from, two-sided, sample by sample (atlas/fidelity); a height-field
// atlas against its DEM, every sample's vertical distance. The Hausdorff figures, where the
// largest distances lie (atlas samples by chart and (u, v); input vertices and triangle centroids
// by position and nearest chart sample) and, for the charts farthest from the input, maps of
// every sample's distance.
#pragma once

#include <cstdint>
#include <filesystem>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/atlas_format.h"

namespace gimlod {

// What the source comparison reports beyond its figures: the distance maps of the `mapCharts`
// farthest charts, written into dir, and the `worstSamples` largest distances each way.
struct SourceReportOptions {
  std::filesystem::path dir;
  uint32_t mapCharts = 6;
  uint32_t worstSamples = 16;
};

// Compares the atlas in atlasDir with `source`: a geometry atlas (level 0, every chart's grid as the
// renderer draws it) with its mesh, a height field with its DEM (read as the build read it, with
// the atlas's z-scale; samples past the DEM, the charts' padding, are not compared; the Hausdorff
// percentage is then of the height range). Writes the distance maps `report` asks for into its
// dir. Throws InputError naming the source when it cannot be read, is not of the atlas's kind, or
// (a DEM) has another size than the atlas's.
// Every level-0 chart sample's distance to the source, for drawing on the model: a mesh atlas's
// samples take the larger of their own distance to the input and that of every input sample whose
// closest atlas point is nearest them; a DEM's samples their vertical distance.
struct SourceDistances {
  uint32_t chartSize = 0;
  std::vector<float> perSample;  // chart-major, chartSize^2 a chart, row v
  double largest = 0.0;
};

nlohmann::json sourceComparison(const AtlasManifest& m, const std::filesystem::path& atlasDir,
                                const std::filesystem::path& source, const SourceReportOptions& report,
                                SourceDistances* distances = nullptr);

}  // namespace gimlod
