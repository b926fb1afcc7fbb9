// Baseline adaptations to compare against the multi-grained adapters (same interface).
// Based on: Niski, Purnomo, Cohen, I3D 2007, section 7.1 (the traditional one-degree-of-freedom
// LOD that ties triangles to nodes, as in chunked LOD / CDLOD, versus the simple top-down
// algorithm); section 7.4 (stitching constraint).
#pragma once

#include <cstdint>

#include "runtime/adapt.h"
#include "runtime/adapt_quad_queue.h"

namespace gimlod {

// Fixed granularity (chunked LOD / CDLOD style): every node is drawn at its finest resolution
// (Hierarchy::maxResLog2: maxResLog2(l) within its chart's finest level), so detail only grows by splitting. Refines
// top-down, frustum culled (when frustumCull), splitting the node with the largest screen error above tolerance first
// while the drawn node count stays within maxNodes (0 = no limit); then enforces the stitching constraint, keeping
// every node at its level's fixed resolution. Stats and node bound as for adaptErrorThreshold.
Cut adaptFixedGranularity(const Hierarchy& h, const ViewParams& view, double tolerancePx, uint32_t maxNodes,
                          AdaptStats* stats = nullptr, bool frustumCull = true);

// The stateless top-down greedy of paper 7.1: adaptErrorThreshold with these arguments.
Cut adaptTopDownGreedy(const Hierarchy& h, const ViewParams& view, double tolerancePx, uint32_t maxNodes,
                       AdaptStats* stats = nullptr, bool frustumCull = true);

// Triangle-budget fixed granularity: every node at its finest resolution (Hierarchy::maxResLog2; when
// even the visible roots do not fit maxTriangles at maxResLog2(0), the roots take the highest common
// resolution that fits, each within its chart's finest). Refines top-down, largest screen error first, splitting while
// the triangles and drawn nodes stay within maxTriangles and maxNodes; then enforces the stitching constraint, undoing
// the last splits if the constraint pushed the cut over a budget: at most max(maxNodes, rootFloor) nodes. Fills refines
// (0), splits, nodes, triangles, errors, constraint counts and the root floor.
Cut adaptFixedGranularityBudget(const Hierarchy& h, const ViewParams& view, const BudgetOptions& options,
                                BudgetStats* stats = nullptr);

// Triangle-budget simple top-down greedy: the paper's top-down error-threshold algorithm (7.1,
// adaptErrorThreshold, maxNodes as its node budget) with its tolerance searched every frame, by
// bisection in log(tolerance) over [1e-4, 1e4] px (20 adaptations), for the finest cut whose
// triangles fit maxTriangles; the way a one-knob LOD is put under a triangle budget. When not
// even the coarsest cut fits, its resolutions are lowered (fitTriangleBudget). Nodes as for
// adaptErrorThreshold. Fills rounds (the adaptations run), splits, nodes, triangles, errors, the
// constraint counts and the root floor.
Cut adaptGreedyBudget(const Hierarchy& h, const ViewParams& view, const BudgetOptions& options,
                      BudgetStats* stats = nullptr);

}  // namespace gimlod
