// Page residency for asynchronous loading (paper section 7.2): which pages a desired cut asks
// the loader for, and the drawable cut in which every node whose page is not resident is drawn
// as its nearest resident ancestor. Pure C++; residency is a predicate on NodeId::key().
#pragma once

#include <cstdint>
#include <functional>
#include <unordered_set>
#include <vector>

#include "hierarchy/hierarchy.h"
#include "runtime/adapt.h"
#include "runtime/cut.h"

namespace gimlod {

// Whether the page of the node with this key is in the GPU page pool now.
using ResidentFn = std::function<bool(uint64_t key)>;

struct PageRequest {
  NodeId id;
  double priority = 0.0;  // higher is served first: coarser levels, then larger screen error
};

struct PageRequestPlan {
  // Pages to ask the loader for, in request order: each non-resident desired node, then its
  // non-resident ancestors (coarser first by priority). Pages in `loaded` are not requested.
  std::vector<PageRequest> requests;
  // Keys of every non-resident page the cut wants (desired nodes and their ancestors up to the
  // first resident one), requested or already loaded: the pages worth uploading this frame.
  std::unordered_set<uint64_t> wanted;
};

// The pages `desired` needs that are not resident. `loaded` holds the keys of pages read and
// waiting for upload (not requested again).
PageRequestPlan planPageRequests(const Hierarchy& h, const Cut& desired, const ResidentFn& resident,
                                 const std::unordered_set<uint64_t>& loaded);

// Chart roots that may be drawn without their page in the pool: from a stand-in that holds the
// root at resLog2[chart] intervals per side (RendererSetup::standIns), so at that resolution or
// coarser. Empty: every root's page is resident.
struct RootStandIns {
  std::vector<uint8_t> resLog2;
  bool empty() const { return resLog2.empty(); }
};

struct ResidentCut {
  // The cut to draw: every node resident, a partition covering `desired`, the stitching
  // constraint enforced by raising resolutions; the same as desired when all is resident.
  Cut cut;
  uint32_t nodesSubstituted = 0;  // desired nodes drawn as a resident ancestor
  uint32_t stitchUnfixable = 0;   // drawn nodes left violating the stitching constraint
  uint32_t rootsOnStandIns = 0;   // chart roots drawn from their stand-ins (not resident)
  uint32_t chartsCoarsened = 0;   // charts held coarser beside a root on its stand-in
};

// Replaces every non-resident desired node by its nearest resident ancestor (roots must be
// resident, or have stand-ins). A substitute under another substitute is dropped, so the cut stays
// a partition; a substitute is drawn at the finest resolution of the nodes it stands for (within
// its level's maximum, or its stand-in's), then raised where the stitching constraint needs it
// (always possible when log2 R >= depth - 1; otherwise counted in stitchUnfixable). A root on its
// stand-in can be raised only to the stand-in's resolution s: where its neighbours are finer
// than that, the charts beside it are held to levels <= s (their nodes drawn as ancestors) until
// the constraint holds. Substitutes get their screen error for `view`; other nodes keep theirs.
ResidentCut substituteResident(const Hierarchy& h, const Cut& desired, const ViewParams& view,
                               const ResidentFn& resident, const RootStandIns& standIns = {});

}  // namespace gimlod
