// Triangle-budget adaptation: the paper's quad-queue algorithm (refine/coarsen queues plus
// split/merge queues, undo-based termination), coherent across frames.
// Based on: Niski, Purnomo, Cohen, I3D 2007, section 7.1 (second problem statement).
#pragma once

#include <cstdint>
#include <memory>

#include "runtime/adapt.h"
#include "runtime/cut.h"

namespace gimlod {

struct BudgetOptions {
  uint64_t maxTriangles = 1000000;  // triangle budget; must be >= 2 * 4^minRes * (visible roots)
  uint32_t maxNodes = 4096;         // node budget; 0 means no limit
  bool frustumCull = true;
  uint32_t maxOpsPerFrame = 4096;  // cap on refine/coarsen/split/merge operations per frame
  uint32_t maxRounds = 16;         // split/merge rounds per frame (0: refine/coarsen only)
};

struct BudgetStats {
  uint32_t refines = 0, coarsens = 0, splits = 0, merges = 0;
  uint32_t rounds = 0;             // refine/coarsen + split/merge rounds this frame
  uint32_t undos = 0;              // split/merge rounds undone because the max error got worse
  uint32_t tieUndos = 0;           // rounds undone because the max error did not improve (tie rule)
  uint32_t undoneOps = 0;          // operations of undone rounds (not in refines..merges)
  uint32_t boundedPriorities = 0;  // split priorities listed without the children's view data
  bool opCapBound = false;         // maxOpsPerFrame stopped the frame early
  uint32_t nodes = 0;              // drawn nodes (Cut::nodeCount: a closed group's roots once)
  uint64_t triangles = 0;          // drawn triangles (<= maxTriangles)
  double maxErrorPx = 0.0, meanErrorPx = 0.0;
  uint32_t constraintRaises = 0, constraintSplits = 0;
  uint32_t budgetMerges = 0;      // merges forced by maxNodes or by the triangle floor (in merges)
  uint32_t rootFloor = 0;         // the smallest cut (AdaptStats::rootFloor): no cut has fewer nodes
  bool budgetBelowRoots = false;  // maxNodes < rootFloor: the cut is the visible roots, over maxNodes
  uint32_t closedGroups = 0;      // closed groups drawn (AdaptStats::closedGroups)
  uint32_t groupedRoots = 0;      // chart roots those groups draw
};

// Lowers resolutions of cut nodes (least error increase per removed triangle first, never below
// minRes or a node's stitching level gap) until the cut has at most maxTriangles triangles. Keeps
// countStitchViolations at 0 when it was 0. Returns whether the budget was met.
bool fitTriangleBudget(const Hierarchy& h, Cut& cut, const ViewParams& view, uint64_t maxTriangles);

// Stateful adapter: keeps its cut and queues from frame to frame.
class QuadQueueAdapter {
 public:
  // parallelMin: kept cuts of at least this many nodes are evaluated in parallel (TBB), smaller
  // ones on the calling thread, and every one with 0; the cuts do not depend on it nor on the threads.
  explicit QuadQueueAdapter(const Hierarchy& h, uint32_t parallelMin = kDefaultParallelMin);
  // Adapts the kept cut to the view within the budgets; returns the drawn cut (stitching
  // constraint enforced, triangles never above maxTriangles, nodes never above maxNodes except:
  // the visible roots when maxNodes is below them (budgetBelowRoots); constraint splits
  // (constraintSplits) merge back, holdNodeBudget).
  const Cut& update(const ViewParams& view, const BudgetOptions& options, BudgetStats* stats = nullptr);
  void reset();  // forget the kept cut (next update starts from the roots)

 private:
  struct State;
  const Hierarchy& h_;
  std::shared_ptr<State> state_;
};

}  // namespace gimlod
