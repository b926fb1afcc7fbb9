#include "inspect/seams.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <memory>
#include <numeric>

#include <glm/geometric.hpp>
#include <glm/vec3.hpp>
#include <tbb/parallel_for.h>

#include "core/atlas_format.h"
#include "core/union_find.h"

namespace gimlod {
namespace {

bool bitEqual(const glm::vec3& a, const glm::vec3& b) { return std::memcmp(&a, &b, sizeof a) == 0; }

// The samples of the 4 edges of one chart at one level, edge e at [e * n, e * n + n), each in the
// edge's counter-clockwise direction. Height fields hold their heights in z.
std::vector<glm::vec3> readBorders(const ChartFileReader& r, bool geometry, uint32_t level, uint32_t n) {
  std::vector<glm::vec3> all;
  if (geometry) {
    all = r.readLevelPositions(level);
  } else {
    const std::vector<float> h = r.readLevelHeights(level);
    all.resize(h.size());
    for (size_t i = 0; i < h.size(); ++i) all[i] = glm::vec3(0.f, 0.f, h[i]);
  }
  std::vector<glm::vec3> borders(size_t(4) * n);
  for (uint32_t e = 0; e < 4; ++e)
    for (uint32_t k = 0; k < n; ++k) borders[size_t(e) * n + k] = all[edgeSampleIndex(n, e, k)];
  return borders;
}

void keepOffender(std::vector<SeamOffender>& out, const SeamOffender& o, uint32_t most) {
  if (most == 0) return;
  const auto larger = [](const SeamOffender& a, const SeamOffender& b) { return a.difference > b.difference; };
  if (out.size() < most) {
    out.push_back(o);
    std::push_heap(out.begin(), out.end(), larger);
  } else if (o.difference > out.front().difference) {
    std::pop_heap(out.begin(), out.end(), larger);
    out.back() = o;
    std::push_heap(out.begin(), out.end(), larger);
  }
}

}  // namespace

uint64_t SeamReport::mismatches() const {
  uint64_t n = 0;
  for (const SeamLevel& l : levels) n += l.edgeMismatches + l.cornerMismatches;
  return n;
}

double SeamReport::maxDifference() const {
  double d = 0.0;
  for (const SeamLevel& l : levels) d = std::max({d, l.maxEdgeDifference, l.maxCornerDifference});
  return d;
}

SeamReport validateSeams(const std::filesystem::path& atlasDir, uint32_t maxOffenders) {
  const auto t0 = std::chrono::steady_clock::now();
  const AtlasManifest m = readManifest(atlasDir);
  const bool geometry = m.kind == AtlasKind::Geometry;
  SeamReport report;
  const uint32_t charts = uint32_t(m.charts.size());
  report.charts = charts;
  std::vector<std::unique_ptr<ChartFileReader>> readers(charts);
  for (uint32_t c = 0; c < charts; ++c) {
    readers[c] = std::make_unique<ChartFileReader>(atlasDir / m.charts[c].file);
    if (readers[c]->chartSize() != m.chartFileSize(c) ||
        readers[c]->levels() != m.pyramidLevels() - m.charts[c].finestLevel)
      throw InputError((atlasDir / m.charts[c].file).string() + ": chart size or levels differ from the manifest's");
  }
  // Corner groups: corner i of chart c is where its edge i starts; across edge e to (d, f), the
  // start of e meets the end of f when reversed (else its start), and likewise the end.
  UnionFind corners(size_t(charts) * 4);
  for (uint32_t c = 0; c < charts; ++c)
    for (uint32_t e = 0; e < 4; ++e) {
      const RootNeighbour& r = m.charts[c].neighbours[e];
      if (r.chart < 0) {
        ++report.openEdges;
        continue;
      }
      ++report.sharedEdges;
      const uint32_t d = uint32_t(r.chart), f = r.edge;
      corners.unite(c * 4 + e, r.reversed ? d * 4 + (f + 1) % 4 : d * 4 + f);
      corners.unite(c * 4 + (e + 1) % 4, r.reversed ? d * 4 + f : d * 4 + (f + 1) % 4);
    }
  report.sharedEdges /= 2;
  std::map<uint32_t, uint32_t> groupSize;
  for (uint32_t i = 0; i < charts * 4; ++i) ++groupSize[corners.find(i)];
  for (const auto& [g, n] : groupSize) ++report.cornerValence[n];

  const auto difference = [&](const glm::vec3& a, const glm::vec3& b) {
    return double(glm::length(glm::dvec3(a) - glm::dvec3(b)));
  };
  // Each level is compared between the charts that hold it (ChartInfo::finestLevel); a chart whose
  // finest level is coarser meets its neighbours from there on.
  const auto holds = [&](uint32_t c, uint32_t level) { return m.charts[c].finestLevel <= level; };
  for (uint32_t level = 0; level < m.pyramidLevels(); ++level) {
    const uint32_t n = ((m.chartSize - 1) >> level) + 1;
    std::vector<std::vector<glm::vec3>> borders(charts);
    tbb::parallel_for(uint32_t(0), charts, [&](uint32_t c) {
      if (holds(c, level)) borders[c] = readBorders(*readers[c], geometry, level - m.charts[c].finestLevel, n);
    });
    SeamLevel sl;
    sl.level = level;
    for (uint32_t c = 0; c < charts; ++c)
      for (uint32_t e = 0; e < 4; ++e) {
        const RootNeighbour& r = m.charts[c].neighbours[e];
        if (r.chart < 0 || std::make_pair(uint32_t(r.chart), uint32_t(r.edge)) < std::make_pair(c, e)) continue;
        if (!holds(c, level) || !holds(uint32_t(r.chart), level)) continue;
        for (uint32_t k = 0; k < n; ++k) {
          const uint32_t k2 = r.reversed ? n - 1 - k : k;
          const glm::vec3& a = borders[c][size_t(e) * n + k];
          const glm::vec3& b = borders[r.chart][size_t(r.edge) * n + k2];
          ++sl.edgeSamples;
          if (bitEqual(a, b)) continue;
          ++sl.edgeMismatches;
          const double d = difference(a, b);
          sl.maxEdgeDifference = std::max(sl.maxEdgeDifference, d);
          keepOffender(report.offenders, {level, c, e, k, uint32_t(r.chart), r.edge, k2, false, d}, maxOffenders);
        }
      }
    std::map<uint32_t, uint32_t> first;  // corner group -> its first corner
    for (uint32_t i = 0; i < charts * 4; ++i) {
      const uint32_t g = corners.find(i);
      if (groupSize[g] < 2 || !holds(i / 4, level)) continue;
      ++sl.cornerSamples;
      const auto [it, fresh] = first.emplace(g, i);
      if (fresh) continue;
      const glm::vec3& a = borders[i / 4][size_t(i % 4) * n];
      const glm::vec3& b = borders[it->second / 4][size_t(it->second % 4) * n];
      if (bitEqual(a, b)) continue;
      ++sl.cornerMismatches;
      const double d = difference(a, b);
      sl.maxCornerDifference = std::max(sl.maxCornerDifference, d);
      keepOffender(report.offenders, {level, i / 4, i % 4, 0, it->second / 4, it->second % 4, 0, true, d},
                   maxOffenders);
    }
    report.levels.push_back(sl);
  }
  std::sort(report.offenders.begin(), report.offenders.end(),
            [](const SeamOffender& a, const SeamOffender& b) { return a.difference > b.difference; });
  report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return report;
}

}  // namespace gimlod
