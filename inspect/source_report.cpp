#include "inspect/source_report.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <numeric>
#include <unordered_map>
#include <vector>

#include <glm/common.hpp>
#include <glm/geometric.hpp>
#include <tbb/parallel_for.h>

#include "atlas/fidelity/fidelity.h"
#include "atlas/mesh/mesh_io.h"
#include "atlas/terrain/dem.h"
#include "inspect/png.h"

namespace gimlod {

using nlohmann::json;

namespace {

// The largest `count` of values, as indices, largest first.
std::vector<uint32_t> largest(const std::vector<float>& values, uint32_t count) {
  std::vector<uint32_t> idx(values.size());
  std::iota(idx.begin(), idx.end(), 0u);
  const size_t k = std::min<size_t>(count, idx.size());
  std::partial_sort(idx.begin(), idx.begin() + k, idx.end(),
                    [&](uint32_t a, uint32_t b) { return values[a] > values[b]; });
  idx.resize(k);
  return idx;
}

// Maps of the per-sample distances (n^2 per chart, chart-major) of the `count` charts with the
// largest; log scale over 4 decades below `top`.
json distanceMaps(const std::vector<float>& distances, uint32_t n, uint32_t charts, uint32_t count, double top,
                  const std::filesystem::path& dir) {
  std::vector<float> chartMax(charts, 0.f);
  for (size_t i = 0; i < distances.size(); ++i)
    chartMax[i / (size_t(n) * n)] = std::max(chartMax[i / (size_t(n) * n)], distances[i]);
  json maps = json::array();
  top = std::max(top, 1e-30);
  for (uint32_t c : largest(chartMax, count)) {
    std::vector<uint8_t> rgb(size_t(n) * n * 3);
    for (uint32_t v = 0; v < n; ++v)
      for (uint32_t u = 0; u < n; ++u) {
        const double d = distances[size_t(c) * n * n + size_t(v) * n + u];
        const double t = d > 0.0 ? std::clamp(1.0 + std::log10(d / top) / 4.0, 0.0, 1.0) : 0.0;
        const auto col = heatColour(t);
        const size_t o = (size_t(n - 1 - v) * n + u) * 3;
        rgb[o] = col[0], rgb[o + 1] = col[1], rgb[o + 2] = col[2];
      }
    const std::string name = "source_distance_chart_" + std::to_string(c) + ".png";
    writePngRgb(dir / name, n, n, rgb);
    maps.push_back({{"chart", c}, {"max_distance", chartMax[c]}, {"file", name}});
  }
  return maps;
}

// A height-field atlas against its DEM: every level-0 sample inside the DEM against the DEM's
// height there (after void filling and z-scale, as the build read it): vertical distances.
json demComparison(const AtlasManifest& m, const std::filesystem::path& atlasDir, const std::filesystem::path& source,
                   const SourceReportOptions& report, SourceDistances* out) {
  const std::filesystem::path& dir = report.dir;
  const uint32_t mapCharts = report.mapCharts, worstSamples = report.worstSamples;
  const auto t0 = std::chrono::steady_clock::now();
  DemOptions o;
  o.zScale = m.zScale;
  const DemRaster dem = loadDem(source, o);
  if (dem.width != m.samplesX || dem.height != m.samplesY)
    throw InputError(source.string() + ": " + std::to_string(dem.width) + " x " + std::to_string(dem.height) +
                     " samples, but the atlas was built from " + std::to_string(m.samplesX) + " x " +
                     std::to_string(m.samplesY));
  const uint32_t n = m.chartSize, step = n - 1;
  std::vector<float> distances(size_t(m.charts.size()) * n * n, 0.f);
  double sum = 0.0, mx = 0.0;
  uint64_t compared = 0;
  for (uint32_t c = 0; c < m.charts.size(); ++c) {
    const ChartFileReader r(atlasDir / m.charts[c].file);
    const std::vector<float> h = r.readLevelHeights(0);
    for (uint32_t v = 0; v < n; ++v)
      for (uint32_t u = 0; u < n; ++u) {
        const int64_t gx = int64_t(m.charts[c].gridX) * step + u, gy = int64_t(m.charts[c].gridY) * step + v;
        if (gx >= dem.width || gy >= dem.height) continue;  // padding past the DEM: never drawn
        const double d = std::abs(double(h[size_t(v) * n + u]) - dem.heights[size_t(gy) * dem.width + size_t(gx)]);
        distances[size_t(c) * n * n + size_t(v) * n + u] = float(d);
        sum += d;
        mx = std::max(mx, d);
        ++compared;
      }
  }
  if (out) *out = {n, distances, mx};
  const double range = std::max(double(dem.maxHeight) - dem.minHeight, 1e-30);
  json worst = json::array();
  for (uint32_t i : largest(distances, worstSamples)) {
    const uint32_t c = i / (n * n), k = i % (n * n);
    worst.push_back({{"chart", c},
                     {"u", k % n},
                     {"v", k / n},
                     {"gx", int64_t(m.charts[c].gridX) * step + k % n},
                     {"gy", int64_t(m.charts[c].gridY) * step + k / n},
                     {"distance", distances[i]}});
  }
  return {{"source", source.string()},
          {"kind", "dem"},
          {"max_vertical_distance", mx},
          {"mean_vertical_distance", compared ? sum / double(compared) : 0.0},
          {"hausdorff", mx},
          {"hausdorff_percent_of_diagonal", mx / range * 100.0},  // of the height range, for a DEM
          {"mean_percent_of_diagonal", compared ? sum / double(compared) / range * 100.0 : 0.0},
          {"height_range", range},
          {"samples_compared", compared},
          {"voids_filled_in_source", dem.voidsFilled},
          {"worst_atlas_samples", worst},
          {"worst_input_samples", json::array()},
          {"distance_maps", distanceMaps(distances, n, uint32_t(m.charts.size()), mapCharts, mx, dir)},
          {"seconds", std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count()}};
}

// A chart's finest samples (side `side`) on the lattice of n samples a side: each point of the finer
// lattice on the triangle the renderer draws there (cells split along their (0,0)-(1,1) diagonal),
// so a coarser chart is compared as drawn, sample for sample with the others.
std::vector<glm::vec3> onFullLattice(const std::vector<glm::vec3>& P, uint32_t side, uint32_t n) {
  if (side == n) return P;
  const uint32_t step = (n - 1) / (side - 1);
  const float inv = 1.0f / float(step);
  std::vector<glm::vec3> out(size_t(n) * n);
  for (uint32_t v = 0; v < n; ++v)
    for (uint32_t u = 0; u < n; ++u) {
      const uint32_t cx = std::min(u / step, side - 2), cy = std::min(v / step, side - 2);
      const float fx = float(u - cx * step) * inv, fy = float(v - cy * step) * inv;
      const glm::vec3 p00 = P[size_t(cy) * side + cx], p10 = P[size_t(cy) * side + cx + 1];
      const glm::vec3 p01 = P[size_t(cy + 1) * side + cx], p11 = P[size_t(cy + 1) * side + cx + 1];
      out[size_t(v) * n + u] =
          fx >= fy ? p00 + fx * (p10 - p00) + fy * (p11 - p10) : p00 + fy * (p01 - p00) + fx * (p11 - p01);
    }
  return out;
}

}  // namespace

json sourceComparison(const AtlasManifest& m, const std::filesystem::path& atlasDir,
                      const std::filesystem::path& source, const SourceReportOptions& report,
                      SourceDistances* distances) {
  if (m.kind == AtlasKind::Heightfield) return demComparison(m, atlasDir, source, report, distances);
  const std::filesystem::path& dir = report.dir;
  const uint32_t mapCharts = report.mapCharts, worstSamples = report.worstSamples;
  const IndexedMesh mesh = readMesh(source);
  // The atlas surface unwelded, chart by chart: sample k of chart c is position c * n^2 + k, so a
  // distance is found back on its chart; triangles as the renderer draws the grid.
  // A chart with a coarser finest level (ChartInfo::finestLevel) is put on the full lattice as drawn.
  const uint32_t n = m.chartSize;
  std::vector<glm::vec3> positions;
  positions.reserve(size_t(m.charts.size()) * n * n);
  std::vector<std::array<uint32_t, 3>> triangles;
  triangles.reserve(size_t(m.charts.size()) * (n - 1) * (n - 1) * 2);
  for (uint32_t c = 0; c < m.charts.size(); ++c) {
    const ChartFileReader r(atlasDir / m.charts[c].file);
    const std::vector<glm::vec3> p = onFullLattice(r.readLevelPositions(0), m.chartFileSize(c), n);
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
  // The chart sample nearest each input sample's closest atlas point: a hash grid of the samples
  // (cells of about a sample spacing), searched ring by ring until a ring holds one no farther
  // than the ring's inner radius.
  std::vector<uint32_t> nearestSample(detail.meshClosest.size(), 0);
  {
    glm::vec3 lo(std::numeric_limits<float>::infinity()), hi(-std::numeric_limits<float>::infinity());
    for (const glm::vec3& p : positions) lo = glm::min(lo, p), hi = glm::max(hi, p);
    const double cell =
        std::max(double(glm::length(hi - lo)) / std::max(1.0, std::cbrt(double(positions.size()))), 1e-12);
    const auto key = [&](int64_t x, int64_t y, int64_t z) {
      return (uint64_t(x) * 73856093u) ^ (uint64_t(y) * 19349663u) ^ (uint64_t(z) * 83492791u);
    };
    const auto cellOf = [&](const glm::vec3& p, int k) { return int64_t(std::floor((double(p[k]) - lo[k]) / cell)); };
    std::unordered_map<uint64_t, std::vector<uint32_t>> grid;
    grid.reserve(positions.size() / 4 + 1);
    for (uint32_t i = 0; i < positions.size(); ++i)
      grid[key(cellOf(positions[i], 0), cellOf(positions[i], 1), cellOf(positions[i], 2))].push_back(i);
    tbb::parallel_for(size_t(0), detail.meshClosest.size(), [&](size_t j) {
      const glm::vec3& q = detail.meshClosest[j];
      const int64_t cx = cellOf(q, 0), cy = cellOf(q, 1), cz = cellOf(q, 2);
      float best = std::numeric_limits<float>::infinity();
      uint32_t bestIndex = 0;
      for (int64_t r = 0; r < 64; ++r) {
        for (int64_t x = cx - r; x <= cx + r; ++x)
          for (int64_t y = cy - r; y <= cy + r; ++y)
            for (int64_t z = cz - r; z <= cz + r; ++z) {
              if (std::max({std::abs(x - cx), std::abs(y - cy), std::abs(z - cz)}) != r) continue;  // the ring only
              const auto it = grid.find(key(x, y, z));
              if (it == grid.end()) continue;
              for (uint32_t i : it->second) {
                const glm::vec3 d = positions[i] - q;
                const float d2 = glm::dot(d, d);
                if (d2 < best) best = d2, bestIndex = i;
              }
            }
        if (best <= float(r * cell) * float(r * cell)) break;  // nothing nearer beyond this ring
      }
      nearestSample[j] = bestIndex;
    });
  }
  if (distances) {
    distances->chartSize = n;
    distances->perSample = detail.atlasDistances;
    for (size_t j = 0; j < nearestSample.size(); ++j)
      distances->perSample[nearestSample[j]] =
          std::max(distances->perSample[nearestSample[j]], detail.meshDistances[j]);
    distances->largest = st.hausdorff;
  }
  json atlasWorst = json::array(), meshWorst = json::array();
  for (uint32_t i : largest(detail.atlasDistances, worstSamples)) {
    const glm::vec3& p = positions[i];
    const uint32_t c = i / (n * n), k = i % (n * n);
    atlasWorst.push_back({{"chart", c},
                          {"u", k % n},
                          {"v", k / n},
                          {"position", {p.x, p.y, p.z}},
                          {"distance", detail.atlasDistances[i]}});
  }
  for (uint32_t i : largest(detail.meshDistances, worstSamples)) {
    const glm::vec3& p = detail.meshSamples[i];
    // Where on the atlas: the chart sample nearest the closest point of the atlas surface.
    const size_t nearest = nearestSample[i];
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
  // Maps of the farthest charts.
  out["distance_maps"] =
      distanceMaps(detail.atlasDistances, n, uint32_t(m.charts.size()), mapCharts, st.maxAtlasToMesh, dir);
  out["kind"] = "mesh";
  return out;
}

}  // namespace gimlod
