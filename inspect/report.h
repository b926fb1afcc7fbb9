// `gimlod inspect`: a static report on an atlas that opens from disk in any browser: index.html,
// report.json (every figure the page shows) and PNG images. It summarizes the build (stats.json),
// validates the seams (inspect/seams.h), lists every chart's figures worst first, and shows the
// worst charts' geometry images (normals, positions, stretch with backward texels marked).
// Views rendered elsewhere (the app draws them through the real renderer) are included as given.
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "inspect/source_report.h"

namespace gimlod {

// An image made outside the report (e.g. a rendered view), copied into it with its caption.
struct ReportImage {
  std::filesystem::path png;
  std::string caption;
  // Figures of the view, shown in the crack table when they hold "boundary_edges",
  // "open_border_edges" and "other_boundary_edges" (runtime/cut_mesh.h: the drawn cut, welded).
  nlohmann::json figures = nlohmann::json::object();
};

struct InspectOptions {
  std::filesystem::path atlas;   // the atlas directory
  std::filesystem::path output;  // the report directory; an earlier report there is replaced
  uint32_t worstCharts = 24;     // charts shown with images (the worst first); figures for all
  uint32_t thumbnailSize = 129;  // at most this many samples a side in chart images (2^k + 1)
  std::vector<ReportImage> views;
  // The mesh the atlas was built from: compared sample by sample (inspect/source_report.h); empty:
  // no comparison.
  std::filesystem::path source;
  // Renders more views once the source comparison is done (the app draws them through the real
  // renderer): given every sample's distance to the source, or null without a source.
  std::function<std::vector<ReportImage>(const SourceDistances*)> renderViews;
};

struct InspectResult {
  nlohmann::json figures;  // = report.json
  uint64_t bytes = 0;      // the report's size on disk
  uint32_t images = 0;     // PNG files written
  double seconds = 0.0;
};

// Writes the report (atomically: built in a sibling directory, renamed into place). Throws
// InputError naming the atlas or a chart file that is missing or corrupt, or the output directory
// when it cannot be written or holds something other than an earlier report.
InspectResult writeInspectReport(const InspectOptions& options);

}  // namespace gimlod
