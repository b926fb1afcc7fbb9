// The reference for QuadQueueAdapter (runtime/adapt_quad_queue.h): the adapter as it was before its per-frame work
// was made incremental, kept unchanged so that the equivalence tests and bench_adapt compare
// the runtime's adapter with it (same cuts, or equal or lower error within the same budgets).
// Triangle-budget adaptation: the paper's quad-queue algorithm (refine/coarsen queues plus
// split/merge queues, undo-based termination), coherent across frames.
// Based on: Niski, Purnomo, Cohen, I3D 2007, section 7.1 (second problem statement).
#pragma once

#include <cstdint>
#include <memory>

#include "runtime/adapt.h"
#include "runtime/adapt_quad_queue.h"
#include "runtime/cut.h"

namespace gimlod::reference {

// Stateful adapter: keeps its cut and queues from frame to frame.
class QuadQueueAdapter {
 public:
  explicit QuadQueueAdapter(const Hierarchy& h);
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

}  // namespace gimlod::reference
