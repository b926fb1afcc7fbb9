// Seam validation of an atlas on disk: every shared chart edge and every corner where charts meet
// must hold the same samples in every chart, at every pyramid level, or the renderer's stitching
// cannot close the surface. Reads the chart files' borders only, level by level.
#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <vector>

namespace gimlod {

// One place where the samples of two charts that should agree do not.
struct SeamOffender {
  uint32_t level = 0;
  uint32_t chart = 0, edge = 0, sample = 0;  // sample k along the edge (corners: edge = corner)
  uint32_t otherChart = 0, otherEdge = 0, otherSample = 0;
  bool corner = false;      // a corner group, not an edge
  double difference = 0.0;  // distance (geometry) or |height difference|
};

struct SeamLevel {
  uint32_t level = 0;
  uint64_t edgeSamples = 0;     // samples compared along shared edges (each pair once)
  uint64_t edgeMismatches = 0;  // of those, not bit-identical
  double maxEdgeDifference = 0.0;
  uint64_t cornerSamples = 0;     // chart corners in a group of 2 or more
  uint64_t cornerMismatches = 0;  // corners not bit-identical with their group's first
  double maxCornerDifference = 0.0;
};

struct SeamReport {
  uint32_t charts = 0;
  uint64_t sharedEdges = 0;                    // chart edge pairs
  uint64_t openEdges = 0;                      // chart edges without a neighbour (the input's own borders)
  std::map<uint32_t, uint32_t> cornerValence;  // charts meeting at a corner -> corners
  std::vector<SeamLevel> levels;
  std::vector<SeamOffender> offenders;  // the largest differences first, at most maxOffenders
  double seconds = 0.0;

  uint64_t mismatches() const;
  double maxDifference() const;
  bool seamless() const { return mismatches() == 0; }
};

// Validates the seams of the atlas in atlasDir (either kind: geometry charts compare positions,
// height fields their heights). Throws InputError naming the manifest or a chart file that is
// missing or corrupt.
SeamReport validateSeams(const std::filesystem::path& atlasDir, uint32_t maxOffenders = 64);

}  // namespace gimlod
