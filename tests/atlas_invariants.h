// The mesh atlas invariants read back from an atlas on disk, independently of the code that wrote
// it (the shared scans' tests and the generated family's): seams bit-identical at every pyramid
// level, corners shared, no interior sample coinciding with another, and the exported surface
// welded with exactly the input's topology.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <filesystem>
#include <iostream>
#include <map>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include "atlas/mesh/mesh_atlas.h"
#include "core/atlas_format.h"
#include "tests/mesh_topology.h"

namespace gimlod::test {

inline bool bitEqual(const glm::vec3& a, const glm::vec3& b) { return std::memcmp(&a, &b, sizeof(glm::vec3)) == 0; }

// Sample k of `edge` in its counter-clockwise parameter direction on an n x n level (the chart
// edge convention of core/atlas_format.h): bottom (k, 0), right (m, k), top (m - k, m),
// left (0, m - k), m = n - 1. Written from the format's definition, not taken from atlas/.
inline uint32_t edgeSample(uint32_t n, uint32_t edge, uint32_t k) {
  const uint32_t m = n - 1;
  switch (edge) {
    case kEdgeBottom: return k;
    case kEdgeRight: return k * n + m;
    case kEdgeTop: return m * n + (m - k);
    default: return (m - k) * n;
  }
}

// Corner c of a chart is where edge c starts (counter-clockwise): (0,0), (m,0), (m,m), (0,m).
inline uint32_t cornerSample(uint32_t n, uint32_t corner) { return edgeSample(n, corner, 0); }

// Samples off their chart's border whose position is bit-identical to another sample's; `where`
// gets the first few groups as chart (u, v).
inline uint64_t coincidentInteriorSamples(const std::vector<std::vector<glm::vec3>>& pos, uint32_t n,
                                          std::string* where) {
  struct Ref {
    std::array<uint32_t, 3> key;
    uint32_t chart, index;
    bool operator<(const Ref& o) const { return key < o.key; }
  };
  std::vector<Ref> refs;
  refs.reserve(pos.size() * n * n);
  for (uint32_t c = 0; c < pos.size(); ++c)
    for (uint32_t i = 0; i < pos[c].size(); ++i) {
      Ref r{{}, c, i};
      std::memcpy(r.key.data(), &pos[c][i], sizeof(r.key));
      refs.push_back(r);
    }
  std::sort(refs.begin(), refs.end());
  auto interior = [&](uint32_t i) {
    const uint32_t u = i % n, v = i / n;
    return u > 0 && v > 0 && u + 1 < n && v + 1 < n;
  };
  uint64_t count = 0, groups = 0;
  for (size_t i = 0; i < refs.size();) {
    size_t j = i;
    bool anyInterior = false;
    while (j < refs.size() && refs[j].key == refs[i].key) anyInterior |= interior(refs[j++].index);
    if (j - i > 1 && anyInterior) {
      for (size_t k = i; k < j; ++k) count += interior(refs[k].index);
      if (groups++ < 3) {
        *where += " [";
        for (size_t k = i; k < j && k < i + 4; ++k)
          *where += " chart " + std::to_string(refs[k].chart) + " (" + std::to_string(refs[k].index % n) + ", " +
                    std::to_string(refs[k].index / n) + ")";
        *where += " ]";
      }
    }
    i = j;
  }
  return count;
}

// Seams and corners, read back from the chart files the manifest lists.
inline void checkSeams(const std::filesystem::path& dir) {
  const AtlasManifest m = readManifest(dir);  // also checks that neighbour links are symmetric
  ASSERT_EQ(m.kind, AtlasKind::Geometry);
  const uint32_t charts = uint32_t(m.charts.size());
  ASSERT_GT(charts, 0u);
  std::vector<std::unique_ptr<ChartFileReader>> readers;
  for (const ChartInfo& c : m.charts) {
    readers.push_back(std::make_unique<ChartFileReader>(dir / c.file));
    // A chart keeps the levels from its finest (ChartInfo::finestLevel).
    ASSERT_EQ(readers.back()->levels(), m.pyramidLevels() - c.finestLevel) << c.file;
    ASSERT_EQ(readers.back()->chartSize(), m.chartFileSize(c.id)) << c.file;
  }
  const auto holds = [&](uint32_t c, uint32_t level) { return m.charts[c].finestLevel <= level; };
  // Corner groups: corner i of chart c is the start of its edge i; across edge e to (d, f), the
  // start of e meets the end of f (reversed) or its start (not reversed), and likewise the end.
  UnionFind corners(size_t(charts) * 4);
  std::set<std::pair<uint32_t, uint32_t>> orientations;  // (edge, neighbour edge) pairs seen
  uint64_t sharedEdges = 0, openEdges = 0;
  for (uint32_t c = 0; c < charts; ++c)
    for (uint32_t e = 0; e < 4; ++e) {
      const RootNeighbour& r = m.charts[c].neighbours[e];
      if (r.chart < 0) {
        ++openEdges;
        continue;
      }
      ASSERT_LT(uint32_t(r.chart), charts);
      ASSERT_LT(r.edge, 4u);
      ++sharedEdges;
      orientations.insert({e, r.edge});
      const uint32_t d = uint32_t(r.chart), f = r.edge;
      const uint32_t startE = c * 4 + e, endE = c * 4 + (e + 1) % 4;
      const uint32_t startF = d * 4 + f, endF = d * 4 + (f + 1) % 4;
      corners.unite(startE, r.reversed ? endF : startF);
      corners.unite(endE, r.reversed ? startF : endF);
    }
  EXPECT_GT(sharedEdges, 0u);
  std::map<uint32_t, uint32_t> valence;  // corner group -> charts meeting there
  for (uint32_t i = 0; i < charts * 4; ++i) ++valence[corners.find(i)];
  std::map<uint32_t, uint32_t> valenceHistogram;
  for (const auto& [g, n] : valence) ++valenceHistogram[n];
  std::string hist;
  for (const auto& [n, count] : valenceHistogram) hist += " " + std::to_string(count) + "x" + std::to_string(n);
  std::cout << "  " << charts << " charts, " << sharedEdges / 2 << " shared edges, " << openEdges << " open, "
            << orientations.size() << " (edge, neighbour edge) pairs; corners (groups x charts):" << hist << "\n";
  std::string pairs;
  uint64_t rotated = 0;  // pairs other than bottom-top / left-right, as a terrain grid would join
  for (const auto& [e, f] : orientations) {
    pairs += " " + std::to_string(e) + "-" + std::to_string(f);
    rotated += f != (e + 2) % 4;
  }
  std::cout << "  edge pairs:" << pairs << "\n";
  EXPECT_GT(rotated, 0u) << "the layout should join charts at other than opposite edges";

  for (uint32_t level = 0; level < m.pyramidLevels(); ++level) {
    const uint32_t n = ((m.chartSize - 1) >> level) + 1;
    // The charts that hold the level (the others meet their neighbours from their finest level on).
    std::vector<std::vector<glm::vec3>> pos(charts);
    for (uint32_t c = 0; c < charts; ++c) {
      if (!holds(c, level)) continue;
      pos[c] = readers[c]->readLevelPositions(level - m.charts[c].finestLevel);
      ASSERT_EQ(pos[c].size(), size_t(n) * n);
    }
    uint64_t edgeMismatches = 0, checked = 0;
    std::string first;
    for (uint32_t c = 0; c < charts; ++c)
      for (uint32_t e = 0; e < 4; ++e) {
        const RootNeighbour& r = m.charts[c].neighbours[e];
        if (r.chart < 0 || !holds(c, level) || !holds(uint32_t(r.chart), level)) continue;
        for (uint32_t k = 0; k < n; ++k) {
          const glm::vec3& a = pos[c][edgeSample(n, e, k)];
          const glm::vec3& b = pos[r.chart][edgeSample(n, r.edge, r.reversed ? n - 1 - k : k)];
          ++checked;
          if (!bitEqual(a, b)) {
            if (!edgeMismatches++)
              first = "chart " + std::to_string(c) + " edge " + std::to_string(e) + " sample " + std::to_string(k) +
                      " vs chart " + std::to_string(r.chart) + " edge " + std::to_string(r.edge);
          }
        }
      }
    EXPECT_EQ(edgeMismatches, 0u) << "level " << level << ": " << edgeMismatches << " of " << checked
                                  << " shared-edge samples differ; first: " << first;
    uint64_t cornerMismatches = 0;
    std::map<uint32_t, glm::vec3> groupPosition;
    for (uint32_t i = 0; i < charts * 4; ++i) {
      if (!holds(i / 4, level)) continue;
      const glm::vec3& p = pos[i / 4][cornerSample(n, i % 4)];
      const auto [it, fresh] = groupPosition.emplace(corners.find(i), p);
      cornerMismatches += !fresh && !bitEqual(it->second, p);
    }
    EXPECT_EQ(cornerMismatches, 0u) << "level " << level << ": corner samples differ between charts meeting there";
    // The other half of welding: a sample inside a chart (off its border) must coincide with no
    // other sample of the atlas, or the welded export joins places the seams do not join.
    std::string where;
    const uint64_t coincident = coincidentInteriorSamples(pos, n, &where);
    EXPECT_EQ(coincident, 0u) << "level " << level << ": " << coincident
                              << " chart-interior samples share their position with another sample, e.g." << where;
  }
}

// The surface exported at every level (readAtlasSurface) is welded with the input's topology: as
// many samples as the charts hold there, exactly the input's open boundary loops, and (down to
// 2 intervals a chart) its non-manifold edges and Euler characteristic.
inline void checkExportedTopology(const std::filesystem::path& dir, const std::filesystem::path& input) {
  const Topology in = inputTopology(input);
  std::cout << "  input: " << in << "\n";
  const AtlasManifest m = readManifest(dir);
  for (uint32_t level = 0; level < m.pyramidLevels(); ++level) {
    const AtlasSurface s = readAtlasSurface(dir, level);
    const Topology t = topologyOf(s.positions, s.triangles);
    std::cout << "  level " << level << ": " << t << "\n";
    const uint64_t side = ((m.chartSize - 1) >> level) + 1;
    // A chart whose finest level is coarser gives its finest samples there (stitched to it).
    uint64_t samples = 0;
    for (const ChartInfo& c : m.charts) {
      const uint64_t own = ((m.chartSize - 1) >> std::max(level, c.finestLevel)) + 1;
      samples += own * own;
    }
    EXPECT_EQ(s.samples, samples) << "level " << level;
    EXPECT_EQ(s.boundaryEdges, t.boundaryEdges) << "level " << level << ": the export's own count disagrees";
    EXPECT_EQ(t.boundaryLoops, in.boundaryLoops) << "level " << level << ": open boundaries other than the scan's";
    // At the level where every chart is one quad (never drawn: nodes are drawn at minNodeRes,
    // at least 2 intervals), two layout sides that join the same two corners are one edge, so
    // the topology is checked down to 2 intervals (the horse has one such pair of sides).
    if (side < 3) continue;
    EXPECT_EQ(t.nonManifoldEdges, in.nonManifoldEdges) << "level " << level;
    EXPECT_EQ(t.euler(), in.euler()) << "level " << level << ": the welded surface changed topology";
  }
}

}  // namespace gimlod::test
