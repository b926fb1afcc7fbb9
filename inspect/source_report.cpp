#include "inspect/source_report.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <vector>

#include "atlas/fidelity/fidelity.h"
#include "atlas/mesh/mesh_io.h"
#include "inspect/png.h"

namespace gimlod {

using nlohmann::json;

json sourceComparison(const AtlasManifest& m, const std::filesystem::path& atlasDir,
                      const std::filesystem::path& source, const std::filesystem::path& dir, uint32_t mapCharts,
                      uint32_t worstSamples) {
  if (m.kind != AtlasKind::Geometry)
    throw InputError(source.string() + ": --source compares a mesh atlas with its mesh; this atlas is a height field");
  const IndexedMesh mesh = readMesh(source);
  // The atlas surface unwelded, chart by chart: sample k of chart c is position c * n^2 + k, so a
  // distance is found back on its chart; triangles as the renderer draws the grid.
  const uint32_t n = m.chartSize;
  std::vector<glm::vec3> positions;
  positions.reserve(size_t(m.charts.size()) * n * n);
  std::vector<std::array<uint32_t, 3>> triangles;
  triangles.reserve(size_t(m.charts.size()) * (n - 1) * (n - 1) * 2);
  for (uint32_t c = 0; c < m.charts.size(); ++c) {
    const ChartFileReader r(atlasDir / m.charts[c].file);
    const std::vector<glm::vec3> p = r.readLevelPositions(0);
    const uint32_t base = uint32_t(positions.size());
    positions.insert(positions.end(), p.begin(), p.end());
    for (uint32_t v = 0; v + 1 < n; ++v)
      for (uint32_t u = 0; u + 1 < n; ++u) {
        const uint32_t a = base + v * n + u, b = a + 1, d = a + n, e = d + 1;
        triangles.push_back({a, b, e});
        triangles.push_back({a, e, d});
      }
  }
  FidelityDetail detail;
  const FidelityStats st = measureFidelity(mesh.positions, mesh.triangles, positions, triangles, &detail);
  json out = {{"source", source.string()},
              {"diagonal", st.diagonal},
              {"hausdorff", st.hausdorff},
              {"hausdorff_percent_of_diagonal", st.hausdorffPercent},
              {"mean_percent_of_diagonal", st.meanPercent},
              {"max_atlas_to_mesh", st.maxAtlasToMesh},
              {"max_mesh_to_atlas", st.maxMeshToAtlas},
              {"atlas_samples", st.atlasSamples},
              {"mesh_samples", st.meshSamples},
              {"seconds", st.seconds}};
  // The largest distances, each way.
  const auto worst = [&](const std::vector<float>& d) {
    std::vector<uint32_t> idx(d.size());
    std::iota(idx.begin(), idx.end(), 0u);
    const size_t k = std::min<size_t>(worstSamples, idx.size());
    std::partial_sort(idx.begin(), idx.begin() + k, idx.end(), [&](uint32_t a, uint32_t b) { return d[a] > d[b]; });
    idx.resize(k);
    return idx;
  };
  json atlasWorst = json::array(), meshWorst = json::array();
  for (uint32_t i : worst(detail.atlasDistances)) {
    const glm::vec3& p = positions[i];
    const uint32_t c = i / (n * n), k = i % (n * n);
    atlasWorst.push_back({{"chart", c}, {"u", k % n}, {"v", k / n}, {"position", {p.x, p.y, p.z}},
                          {"distance", detail.atlasDistances[i]}});
  }
  for (uint32_t i : worst(detail.meshDistances)) {
    const glm::vec3& p = detail.meshSamples[i];
    // Where on the atlas: the chart sample nearest the closest point of the atlas surface.
    const glm::vec3& q = detail.meshClosest[i];
    size_t nearest = 0;
    float best = std::numeric_limits<float>::infinity();
    for (size_t k = 0; k < positions.size(); ++k) {
      const glm::vec3 d = positions[k] - q;
      const float d2 = d.x * d.x + d.y * d.y + d.z * d.z;
      if (d2 < best) best = d2, nearest = k;
    }
    const uint32_t c = uint32_t(nearest / (size_t(n) * n)), k = uint32_t(nearest % (size_t(n) * n));
    meshWorst.push_back({{"sample", i},
                         {"position", {p.x, p.y, p.z}},
                         {"distance", detail.meshDistances[i]},
                         {"chart", c},
                         {"u", k % n},
                         {"v", k / n}});
  }
  out["worst_atlas_samples"] = atlasWorst;
  out["worst_input_samples"] = meshWorst;
  // Per chart: the largest distance of its samples; maps of the farthest.
  std::vector<double> chartMax(m.charts.size(), 0.0);
  for (size_t i = 0; i < detail.atlasDistances.size(); ++i)
    chartMax[i / (n * n)] = std::max(chartMax[i / (n * n)], double(detail.atlasDistances[i]));
  std::vector<uint32_t> order(m.charts.size());
  std::iota(order.begin(), order.end(), 0u);
  std::stable_sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) { return chartMax[a] > chartMax[b]; });
  json maps = json::array();
  const double top = std::max(st.maxAtlasToMesh, 1e-30);
  for (size_t j = 0; j < order.size() && j < mapCharts; ++j) {
    const uint32_t c = order[j];
    std::vector<uint8_t> rgb(size_t(n) * n * 3);
    for (uint32_t v = 0; v < n; ++v)
      for (uint32_t u = 0; u < n; ++u) {
        const double d = detail.atlasDistances[size_t(c) * n * n + size_t(v) * n + u];
        // log scale over 4 decades below the atlas's largest distance
        const double t = d > 0.0 ? std::clamp(1.0 + std::log10(d / top) / 4.0, 0.0, 1.0) : 0.0;
        const auto col = heatColour(t);
        const size_t o = (size_t(n - 1 - v) * n + u) * 3;
        rgb[o] = col[0], rgb[o + 1] = col[1], rgb[o + 2] = col[2];
      }
    const std::string name = "source_distance_chart_" + std::to_string(c) + ".png";
    writePngRgb(dir / name, n, n, rgb);
    maps.push_back({{"chart", c}, {"max_distance", chartMax[c]}, {"file", name}});
  }
  out["distance_maps"] = maps;
  return out;
}

}  // namespace gimlod
