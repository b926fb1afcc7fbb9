// Nodes above the charts: chart roots gathered into groups, and groups into groups, up to a few
// top groups, so that the smallest cut of an atlas has a few nodes however many charts it has.
// A closed group is one node of a cut: it draws each of its charts' roots, and none of them
// splits. Opening it puts its children (groups, or chart roots) in the cut in its place.
// Based on: Niski, Purnomo, Cohen, I3D 2007, section 4 (a forest of quadtrees over the charts,
// whose roots bound the smallest cut); the groups are the coarse nodes above that forest.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace gimlod {

class Hierarchy;

// Top groups at most, by default: the paper's order of trees (4 to 70 per atlas). An atlas of this
// many charts or fewer gets no groups: every chart root is a root of the forest, as in the paper.
inline constexpr uint32_t kDefaultMaxRoots = 16;
// Children of a group, at most.
inline constexpr uint32_t kGroupFanout = 4;

struct RootGroups {
  struct Group {
    uint32_t begin = 0, end = 0;            // its charts: order[begin, end)
    uint32_t childBegin = 0, childEnd = 0;  // its children: groups [childBegin, childEnd), or for a
                                            // first-level group (level 0) the charts order[begin, end)
    int32_t parent = -1;                    // -1: a top group
    uint32_t level = 0;                     // 0: its children are chart roots
    std::array<float, 6> bounds{};          // the union of its charts' root boxes
    float errorMin = 0.f;                   // largest error of a member root at the minimum resolution (world units)
    float errorMax = 0.f;                   // largest error of a member root at its own maxResLog2
  };
  std::vector<uint32_t> order;      // the non-empty charts, in the groups' order (Morton order of
                                    // their roots' box centres)
  std::vector<Group> groups;        // first-level groups first, then each level above in turn
  std::vector<uint32_t> tops;       // the groups without a parent, ascending
  std::vector<int32_t> chartGroup;  // per chart: its first-level group; -1 for an empty chart
  // Per group and resolution r in [minRes, minRes + resCount): the largest error of a member root
  // drawn at r, or at its maxResLog2 where that is lower (world units).
  std::vector<float> errors;
  uint32_t minRes = 0, resCount = 0;
  float error(uint32_t g, uint32_t r) const { return errors[size_t(g) * resCount + (r - minRes)]; }

  bool empty() const { return groups.empty(); }
  bool chartsBelow(uint32_t g) const { return groups[g].level == 0; }
};

// Gathers the non-empty charts of h into groups of up to kGroupFanout consecutive charts in the
// Morton order of their root boxes' centres, then the groups likewise, level by level, until at
// most maxRoots groups remain. Empty (no groups) when there are maxRoots non-empty charts or fewer,
// when maxRoots is 0, or when some chart's root cannot take the stitching constraint's largest level
// gap (maxResLog2(root) < depth - 1): a closed group's roots never split, so each must be able to raise
// its resolution to any neighbour's level instead. Deterministic: the same hierarchy gives the same
// groups on any machine and thread count.
RootGroups buildRootGroups(const Hierarchy& h, uint32_t maxRoots = kDefaultMaxRoots);

}  // namespace gimlod
