#include "runtime/atlas_view.h"

#include <limits>

namespace gimlod {

AtlasView openAtlas(const std::filesystem::path& dir, uint32_t maxRoots) {
  AtlasView a;
  a.dir = dir;
  a.manifest = readManifest(dir);
  const auto hpath = dir / a.manifest.hierarchyFile;
  a.hierarchy = readHierarchy(hpath);
  const HierarchyParams p = hierarchyParams(a.manifest);
  const HierarchyParams& q = a.hierarchy.params;
  if (p.intervalsLog2 != q.intervalsLog2 || p.depth != q.depth || p.maxNodeResLog2 != q.maxNodeResLog2 ||
      p.minNodeResLog2 != q.minNodeResLog2 || a.hierarchy.chartCount() != a.manifest.charts.size())
    throw InputError(hpath.string() + ": does not match " + (dir / kManifestName).string());
  try {
    a.hierarchy.finestLevels = finestLevels(a.manifest, hierarchyParams(a.manifest));
  } catch (const InputError& e) {
    throw InputError((dir / kManifestName).string() + ": " + e.what());
  }
  a.hierarchy.groups = buildRootGroups(a.hierarchy, maxRoots);
  if (a.manifest.kind == AtlasKind::Geometry || a.manifest.planet.present) {
    // A mesh or planet atlas: the union of the chart roots' boxes.
    a.lo = glm::dvec3(std::numeric_limits<double>::infinity());
    a.hi = -a.lo;
    for (uint32_t c = 0; c < a.hierarchy.chartCount(); ++c) {
      const auto& b = a.hierarchy.bounds({c, 0, 0, 0});
      a.lo = glm::min(a.lo, glm::dvec3(b[0], b[1], b[2]));
      a.hi = glm::max(a.hi, glm::dvec3(b[3], b[4], b[5]));
    }
    return a;
  }
  a.lo = {0.0, 0.0, a.manifest.heightRange[0]};
  a.hi = {double(a.manifest.samplesX - 1) * a.manifest.spacing[0],
          double(a.manifest.samplesY - 1) * a.manifest.spacing[1], a.manifest.heightRange[1]};
  return a;
}

}  // namespace gimlod
