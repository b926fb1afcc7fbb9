// Baseline adaptations to compare against the multi-grained adapters (same interface).
// Based on: Niski, Purnomo, Cohen, I3D 2007, section 7.1 (the traditional one-degree-of-freedom
// LOD that ties triangles to nodes, as in chunked LOD / CDLOD, versus the simple top-down
// algorithm); section 7.4 (stitching constraint).
#pragma once

#include <cstdint>

#include "runtime/adapt.h"

namespace gimlod {

// Fixed granularity (chunked LOD / CDLOD style): every node of level l is drawn at maxRes(l), so
// detail only grows by splitting. Refines top-down, frustum culled (when frustumCull), splitting
// the node with the largest screen error above tolerance first while the drawn node count stays
// within maxNodes (0 = no limit); then enforces the stitching constraint, keeping every node at
// its level's fixed resolution. Stats as for adaptErrorThreshold.
Cut adaptFixedGranularity(const Hierarchy& h, const ViewParams& view, double tolerancePx,
                          uint32_t maxNodes, AdaptStats* stats = nullptr, bool frustumCull = true);

// The stateless top-down greedy of paper 7.1: adaptErrorThreshold with these arguments.
Cut adaptTopDownGreedy(const Hierarchy& h, const ViewParams& view, double tolerancePx,
                       uint32_t maxNodes, AdaptStats* stats = nullptr, bool frustumCull = true);

}  // namespace gimlod
