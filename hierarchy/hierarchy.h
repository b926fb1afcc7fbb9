// Quadtree per chart with per-(node, resolution) geometric errors and bounds.
// Based on: Niski, Purnomo, Cohen, "Multi-grained Level of Detail Using a Hierarchical Seamless
// Texture Atlas", I3D 2007, sections 4 and 6.
#pragma once

#include <algorithm>
#include <array>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <vector>

#include <glm/vec3.hpp>

#include "core/atlas_format.h"
#include "core/level_surface.h"
#include "hierarchy/root_groups.h"

namespace gimlod {

// A node of chart `chart`'s quadtree: level 0 is the root; (x, y) in [0, 2^level)^2, y = v.
struct NodeId {
  uint32_t chart = 0;
  uint32_t level = 0;
  uint32_t x = 0, y = 0;
  bool operator==(const NodeId&) const = default;
  uint64_t key() const { return (uint64_t(chart) << 40) | (uint64_t(level) << 34) | (uint64_t(y) << 17) | uint64_t(x); }
  // Inverse of key().
  static NodeId fromKey(uint64_t k) {
    return {uint32_t(k >> 40), uint32_t((k >> 34) & 63u), uint32_t(k & 0x1FFFFu), uint32_t((k >> 17) & 0x1FFFFu)};
  }
  NodeId parent() const { return {chart, level - 1, x >> 1, y >> 1}; }
  NodeId child(uint32_t i) const { return {chart, level + 1, 2 * x + (i & 1), 2 * y + (i >> 1)}; }
};

// Index of a node in its chart's level-order array.
inline uint32_t nodeIndex(uint32_t level, uint32_t x, uint32_t y) {
  return ((1u << (2 * level)) - 1) / 3 + (y << level) + x;
}
inline uint32_t nodesPerChart(uint32_t depth) { return ((1u << (2 * depth)) - 1) / 3; }

enum NodeFlags : uint8_t {
  kNodeEmpty = 1,  // the node lies entirely outside the valid data (padding); never drawn
};

struct HierarchyParams {
  uint32_t intervalsLog2 = 9;   // log2(M): chart side in level-0 intervals
  uint32_t depth = 5;           // levels 0 .. depth-1
  uint32_t maxNodeResLog2 = 6;  // log2(R)
  uint32_t minNodeResLog2 = 2;

  // Paper eq. 1: the finest resolution (log2 intervals) a node of `level` may use.
  uint32_t maxResLog2(uint32_t level) const { return maxResLog2(level, 0); }
  // The same in a chart whose finest samples are pyramid level finestLevel (ChartInfo).
  uint32_t maxResLog2(uint32_t level, uint32_t finestLevel) const {
    return std::min(intervalsLog2 - finestLevel - level, maxNodeResLog2);
  }
  uint32_t minResLog2() const { return minNodeResLog2; }
  uint32_t resCount() const { return maxNodeResLog2 - minNodeResLog2 + 1; }
  // Pyramid level a node of `level` reads at resolution `res`.
  uint32_t pyramidLevel(uint32_t level, uint32_t res) const { return intervalsLog2 - level - res; }
  // The coarsest finest level a chart may have (ChartInfo::finestLevel): its leaves can still be
  // drawn at the minimum resolution, so every node of every chart stays usable.
  uint32_t maxFinestLevel() const { return intervalsLog2 - (depth - 1) - minNodeResLog2; }
  // Throws InputError when the combination is impossible.
  void validate() const;
};

class Hierarchy {
 public:
  HierarchyParams params;
  std::vector<std::array<RootNeighbour, 4>> roots;  // per chart, indexed by Edge
  // Per chart, per node (level order): bounds in world units, flags, and errors (world units) for
  // each res in [minNodeResLog2, maxResLog2(level)]; NaN for resolutions the node cannot use.
  struct ChartNodes {
    std::vector<std::array<float, 6>> bounds;  // minx, miny, minz, maxx, maxy, maxz
    std::vector<uint8_t> flags;
    std::vector<float> errors;  // [node * resCount + (res - minNodeResLog2)]
  };
  std::vector<ChartNodes> charts;
  // Per chart, its finest pyramid level (ChartInfo::finestLevel); empty: 0 for every chart. Not in
  // the hierarchy file: set from the manifest (loadAtlasView) or by buildGeometryHierarchy.
  std::vector<uint8_t> finestLevels;
  // The nodes above the charts (buildRootGroups); empty: every chart root is a root of the forest.
  // Not in the hierarchy file: built when an atlas is opened (openAtlas) or by the caller.
  RootGroups groups;

  uint32_t chartCount() const { return uint32_t(charts.size()); }
  uint32_t finestLevel(uint32_t chart) const { return finestLevels.empty() ? 0 : finestLevels[chart]; }
  // The finest resolution node n may use: paper eq. 1 within its chart's finest level.
  uint32_t maxResLog2(const NodeId& n) const { return params.maxResLog2(n.level, finestLevel(n.chart)); }
  const std::array<float, 6>& bounds(const NodeId& n) const {
    return charts[n.chart].bounds[nodeIndex(n.level, n.x, n.y)];
  }
  uint8_t flags(const NodeId& n) const { return charts[n.chart].flags[nodeIndex(n.level, n.x, n.y)]; }
  // Geometric error (world units) of node n drawn at resolution res.
  float error(const NodeId& n, uint32_t res) const {
    return charts[n.chart].errors[nodeIndex(n.level, n.x, n.y) * params.resCount() + (res - params.minNodeResLog2)];
  }
};

struct HierarchyStats {
  uint64_t samples = 0;  // level-0 samples processed (all charts)
  double seconds = 0.0;  // wall time, including the source reads
  double samplesPerSecond = 0.0;
  uint32_t threads = 0;
};

// Terrain input: chart id -> level-0 heights (chartSize^2, row = v). Must be thread-safe.
using ChartHeightSource = std::function<std::vector<float>(uint32_t chart)>;

// Builds the hierarchy of a height-field atlas (multithreaded over charts and pyramid levels).
// Node error at res r = max over the node's level-0 samples of |h - surface_k|, where surface_k is
// the piecewise-linear surface drawn from pyramid level k' (split along the (0,0)-(1,1) diagonal
// like the render grids), maximised over all k' <= k. So errors never decrease as resolution
// drops, a parent's error is at least its children's, and the bound holds for the drawn mesh.
Hierarchy buildTerrainHierarchy(const AtlasManifest& manifest, const ChartHeightSource& source,
                                HierarchyStats* stats = nullptr);

// Terrain input by windows: the (n+1)^2 heights of pyramid level `level` of chart `chart` from
// (u0, v0), row = v (a window of whole blocks). Must be thread-safe.
using ChartWindowSource =
    std::function<std::vector<float>(uint32_t chart, uint32_t level, uint32_t u0, uint32_t v0, uint32_t n)>;
inline constexpr uint32_t kHierarchyTile = 1024;
// The same hierarchy, a chart larger than maxTile intervals (a power of two) read in tiles of
// maxTile: each tile's level-0 heights, and the chart's pyramid level log2(maxTile) for the
// levels whose cells span several tiles. A node above the tiles takes the largest error and the
// range of its tiles. A tile past the DEM's last sample (padding of the chart grid) is not read: its
// nodes are empty (never drawn), flat at the lowest height with errors 0, and the nodes above it
// take the tiles that hold data. Memory: a few tiles' worth a thread, whatever the chart's size. A
// chart of maxTile intervals or fewer is read whole, and its nodes are those of the overload above.
Hierarchy buildTerrainHierarchy(const AtlasManifest& manifest, const ChartWindowSource& source, HierarchyStats* stats,
                                uint32_t maxTile = kHierarchyTile);

// A tile of a geometry image measured in tiles (buildTiledGeometryHierarchy), its positions
// relative to `origin`, in float: the tile's level-0 samples ((2^t + 1)^2, row = v) and the chart's
// pyramid level t (((intervals >> t) + 1)^2; empty when the tile is the whole chart).
struct GeometryTile {
  glm::dvec3 origin{0.0};
  std::vector<glm::vec3> positions;
  std::vector<glm::vec3> coarse;
};
// (chart, t, tx, ty) -> tile (tx, ty) of 2^t intervals of the chart, or nothing for a tile past the
// data (its nodes are never drawn: errors 0, empty boxes). Must be thread-safe.
using GeometryTileSource =
    std::function<std::optional<GeometryTile>(uint32_t chart, uint32_t t, uint32_t tx, uint32_t ty)>;

// The hierarchy of a geometry-image atlas whose charts are read in tiles of at most maxTile
// intervals (a power of two): the errors and boxes of buildGeometryHierarchy, each tile's samples
// measured relative to its own origin in float, so that a chart of any size keeps the precision
// of its tiles' extent. Each positive error grows by four float steps of the largest coordinate it
// was measured from (the tile's samples, and the corners of the coarser cells they lie in), each
// box by four of its tile's and rounded outwards, so both still hold for the exact positions. A
// node above the tiles takes the largest error and the union of the boxes of its tiles. Memory: a
// few tiles' worth a thread, whatever the chart's size. Flags are left clear. Throws InputError
// naming the chart and tile for arrays of the wrong size or a non-finite position.
Hierarchy buildTiledGeometryHierarchy(const HierarchyParams& params,
                                      const std::vector<std::array<RootNeighbour, 4>>& roots,
                                      const GeometryTileSource& source, HierarchyStats* stats = nullptr,
                                      uint32_t maxTile = kHierarchyTile);

// The hierarchy of a planet atlas (manifest.planet, core/planet.h): each chart's samples placed on
// the sphere (PlanetFrame::position) and measured in tiles of maxTile intervals relative to each
// tile's centre (buildTiledGeometryHierarchy), so bounds are planet-centred boxes and errors
// Euclidean distances in world units (metres on a planet), the sphere's curvature included, with
// the precision of a tile's extent whatever the chart's size. Nodes past the DEM's last samples are
// empty, as on flat terrain.
Hierarchy buildPlanetHierarchy(const AtlasManifest& manifest, const ChartWindowSource& source,
                               HierarchyStats* stats = nullptr, uint32_t maxTile = kHierarchyTile);

// Mesh-atlas input: chart id -> its finest geometry image, side ((chartSize - 1) >> finest level)
// + 1 positions (row = v). Must be thread-safe.
using ChartPositionSource = std::function<std::vector<glm::vec3>(uint32_t chart)>;

// Builds the hierarchy of a geometry-image atlas (section 5 charts; multithreaded over charts).
// roots: each chart's 4 neighbours (as in the manifest). Bounds are the 3D boxes of the node's
// samples. Node error at res r = max over the node's level-0 samples of |p(u,v) - surface_k(u,v)|
// (Euclidean), where surface_k is the level-k grid drawn as the render grids draw it (split along
// the (0,0)-(1,1) diagonal), interpolated at the sample's own (u,v), maximised over k' <= k: the
// geometry-image analogue of the terrain's vertical error, and an upper bound on the distance
// from each sample to the drawn surface. Same monotonicity as buildTerrainHierarchy.
// finestLevels: per chart (or empty: all 0), as ChartInfo::finestLevel; a chart's errors are those
// of its own samples, and a node has none at resolutions finer than its chart holds. Throws
// InputError for a wrong image size, a non-finite position or a finest level over maxFinestLevel.
Hierarchy buildGeometryHierarchy(const HierarchyParams& params, const std::vector<std::array<RootNeighbour, 4>>& roots,
                                 const ChartPositionSource& source, HierarchyStats* stats = nullptr,
                                 const std::vector<uint8_t>& finestLevels = {});

// How writeHierarchy codes the file (docs/format.md section 12).
//   raw: version 1, the arrays as they are.
//   grouped: version 2, the arrays regrouped as byte planes, then zstd with its checksum (about
//     0.4 of version 1's bytes on mesh atlases). Reads back bit for bit.
//   quantized: version 3, conservative: a node's box below its chart's root is its parent's inset
//     by a byte a side (in 255ths of the parent's extent), and holds the node's box; each error is
//     rounded up to 16 bits (at most 2^-7 above it). About 0.4 of version 2's bytes on mesh
//     atlases, where the boxes were three quarters of them. Written as version 2 where a box does
//     not lie inside its parent's (a flat terrain's empty nodes) or an error is negative.
enum class HierarchyCoding : uint8_t { kRaw, kGrouped, kQuantized };
// Atomic. All three versions are read.
void writeHierarchy(const std::filesystem::path& path, const Hierarchy& h, HierarchyCoding coding);
// compressed: grouped (version 2), else raw (version 1).
void writeHierarchy(const std::filesystem::path& path, const Hierarchy& h, bool compressed = true);
Hierarchy readHierarchy(const std::filesystem::path& path);  // throws InputError naming the file

HierarchyParams hierarchyParams(const AtlasManifest& m);

// The charts' finest levels (ChartInfo::finestLevel) as Hierarchy::finestLevels: empty when every
// one is 0. Throws InputError naming the chart when one is over p.maxFinestLevel().
std::vector<uint8_t> finestLevels(const AtlasManifest& m, const HierarchyParams& p);

}  // namespace gimlod
