#include "inspect/hierarchy_report.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "inspect/png.h"
#include "runtime/adapt.h"
#include "runtime/camera.h"

namespace gimlod {

using nlohmann::json;

json hierarchyFigures(const AtlasView& atlas, const std::filesystem::path& dir, uint32_t maxImageSide) {
  const Hierarchy& h = atlas.hierarchy;
  const HierarchyParams& p = h.params;
  const uint32_t charts = h.chartCount();
  json levels = json::array(), maps = json::array();
  double largest = 0.0;
  for (uint32_t c = 0; c < charts; ++c)
    for (float e : h.charts[c].errors)
      if (std::isfinite(e)) largest = std::max(largest, double(e));
  // Chart placement: a DEM's grid, else a near-square tiling.
  const bool grid = atlas.manifest.kind == AtlasKind::Heightfield && atlas.manifest.chartsX > 0;
  const uint32_t cols = grid ? atlas.manifest.chartsX : uint32_t(std::ceil(std::sqrt(double(std::max(charts, 1u)))));
  const uint32_t rows = grid ? atlas.manifest.chartsY : (charts + cols - 1) / std::max(cols, 1u);
  for (uint32_t level = 0; level < p.depth; ++level) {
    const uint32_t side = 1u << level;
    json row = {{"level", level}, {"nodes", uint64_t(charts) * side * side}};
    json byRes = json::array();
    for (uint32_t res = p.minNodeResLog2; res <= p.maxResLog2(level); ++res) {
      double mx = 0.0, sum = 0.0;
      uint64_t n = 0;
      for (uint32_t c = 0; c < charts; ++c)
        for (uint32_t y = 0; y < side; ++y)
          for (uint32_t x = 0; x < side; ++x) {
            const float e = h.error({c, level, x, y}, res);
            if (!std::isfinite(e)) continue;
            mx = std::max(mx, double(e));
            sum += e;
            ++n;
          }
      byRes.push_back({{"res", res}, {"max_error", mx}, {"mean_error", n ? sum / double(n) : 0.0}});
    }
    row["errors"] = byRes;
    // The heat maps, one per resolution: each node a cell of `scale` pixels, at least 256 pixels a
    // side where possible.
    const uint32_t cellsX = cols * side, cellsY = rows * side;
    const uint32_t scale = std::max(1u, 256u / std::max(1u, std::max(cellsX, cellsY)));
    const uint32_t w = cellsX * scale, ht = cellsY * scale;
    json rowMaps = json::array();
    for (uint32_t res = p.minNodeResLog2; res <= p.maxResLog2(level); ++res) {
      if (w == 0 || ht == 0 || w > maxImageSide || ht > maxImageSide) break;
      std::vector<uint8_t> rgb(size_t(w) * ht * 3, 40);
      for (uint32_t c = 0; c < charts; ++c) {
        const uint32_t cx = grid ? uint32_t(atlas.manifest.charts[c].gridX) : c % cols;
        const uint32_t cy = grid ? uint32_t(atlas.manifest.charts[c].gridY) : c / cols;
        for (uint32_t y = 0; y < side; ++y)
          for (uint32_t x = 0; x < side; ++x) {
            const float e = h.error({c, level, x, y}, res);
            // log scale over 4 decades below the largest error
            const double t = std::isfinite(e) && e > 0.0 && largest > 0.0
                                 ? std::clamp(1.0 + std::log10(double(e) / largest) / 4.0, 0.0, 1.0)
                                 : 0.0;
            const std::array<uint8_t, 3> colour = heatColour(t);
            // v up: row 0 of the image is the chart's top
            const uint32_t px = (cx * side + x) * scale, py = ((rows - 1 - cy) * side + (side - 1 - y)) * scale;
            for (uint32_t dy = 0; dy < scale; ++dy)
              for (uint32_t dx = 0; dx < scale; ++dx) {
                const size_t o = (size_t(py + dy) * w + px + dx) * 3;
                rgb[o] = colour[0], rgb[o + 1] = colour[1], rgb[o + 2] = colour[2];
              }
          }
      }
      const std::string name = "errors_level_" + std::to_string(level) + "_res_" + std::to_string(res) + ".png";
      writePngRgb(dir / name, w, ht, rgb);
      rowMaps.push_back({{"res", res}, {"file", name}});
      maps.push_back(name);
    }
    row["heat_maps"] = rowMaps;
    levels.push_back(row);
  }
  return {{"levels", levels},
          {"heat_maps", maps},
          {"largest_error", largest},
          {"layout_columns", cols},
          {"layout_rows", rows}};
}

json streamingFigures(const AtlasView& atlas, uint32_t width, uint32_t height) {
  const AtlasManifest& m = atlas.manifest;
  const HierarchyParams& p = atlas.hierarchy.params;
  const bool geometry = m.kind == AtlasKind::Geometry;
  // Bytes a sample holds on disk and in a page: heights or positions, normals, colours.
  uint64_t perSample = (geometry ? 12 : 4) + 4;
  if (geometry && !m.charts.empty()) {
    const ChartFileReader r(atlas.dir / m.charts[0].file);
    if (r.hasChannel(kChannelColours)) perSample += 4;
  }
  json levels = json::array();
  for (uint32_t l = 0; l < m.pyramidLevels(); ++l) {
    const uint64_t n = ((m.chartSize - 1) >> l) + 1;
    // The charts whose finest samples are no coarser than the level hold it.
    const uint64_t holding = uint64_t(
        std::count_if(m.charts.begin(), m.charts.end(), [&](const ChartInfo& c) { return c.finestLevel <= l; }));
    levels.push_back(
        {{"pyramid_level", l}, {"samples_per_side", n}, {"charts", holding}, {"bytes", holding * n * n * perSample}});
  }
  json pages = json::array();
  for (uint32_t l = 0; l < p.depth; ++l) {
    const uint64_t s = (uint64_t(1) << p.maxResLog2(l)) + 1;
    pages.push_back({{"level", l}, {"page_samples_per_side", s}, {"page_bytes", s * s * perSample}});
  }
  std::vector<std::string> names;
  const std::vector<Camera> cams = axisViews(atlas.lo, atlas.hi, 40.0, &names);
  json views = json::array();
  double nodesSum = 0.0, bytesSum = 0.0;
  uint64_t nodesMax = 0, bytesMax = 0;
  for (size_t i = 0; i < cams.size(); ++i) {
    const ViewParams v = makeViewParams(cams[i], width, height);
    AdaptOptions o;
    o.tolerancePx = 1.0;
    o.maxNodes = 0;
    AdaptStats st;
    const Cut cut = adaptErrorThreshold(atlas.hierarchy, v, o, &st);
    uint64_t bytes = 0;
    for (const CutNode& n : cut.nodes) bytes += pages[n.id.level]["page_bytes"].get<uint64_t>();
    // The nodes drawn finer than their error needs: with no node budget, the stitching
    // constraint raised them (to give a finer neighbour's corners a vertex).
    json raised = json::array();
    uint32_t raisedCount = 0;
    for (const CutNode& n : cut.nodes) {
      const uint32_t needed = std::max(neededResolution(atlas.hierarchy, n.id, v, o.tolerancePx), p.minNodeResLog2);
      if (n.resLog2 <= needed) continue;
      ++raisedCount;
      if (raised.size() < 32)
        raised.push_back({{"chart", n.id.chart},
                          {"level", n.id.level},
                          {"x", n.id.x},
                          {"y", n.id.y},
                          {"needed_res", needed},
                          {"drawn_res", n.resLog2}});
    }
    views.push_back({{"view", names[i]},
                     {"nodes", cut.nodes.size()},
                     {"triangles", cut.triangles()},
                     {"page_bytes", bytes},
                     {"constraint_raises", st.constraintRaises},
                     {"constraint_splits", st.constraintSplits},
                     {"max_error_px", st.maxErrorPx},
                     {"nodes_raised", raisedCount},
                     {"raised", raised}});
    nodesSum += double(cut.nodes.size());
    bytesSum += double(bytes);
    nodesMax = std::max<uint64_t>(nodesMax, cut.nodes.size());
    bytesMax = std::max(bytesMax, bytes);
  }
  return {{"bytes_per_sample", perSample},
          {"pyramid_levels", levels},
          {"pages", pages},
          {"views", views},
          {"view_size", std::to_string(width) + "x" + std::to_string(height)},
          {"view_nodes_mean", nodesSum / double(cams.size())},
          {"view_nodes_max", nodesMax},
          {"view_page_bytes_mean", bytesSum / double(cams.size())},
          {"view_page_bytes_max", bytesMax}};
}

}  // namespace gimlod
