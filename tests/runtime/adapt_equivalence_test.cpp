// The adapters against their references (tests/reference: each adapter as it was before its
// per-frame work was made incremental): on random small forests, random camera paths and random
// budgets, every frame's cut is the same, node for node and resolution for resolution, with the
// same errors and counts. And the dual queue's parallel pass gives the same cuts on 1 thread as
// on several.
#include <gtest/gtest.h>

#include <tbb/global_control.h>
#include <tbb/task_arena.h>

#include <memory>
#include <random>

#include "hierarchy/root_groups.h"
#include "tests/adapt_fixture.h"
#include "tests/reference/adapt_dual_queue.h"
#include "tests/reference/adapt_quad_queue.h"

namespace gimlod::test {
namespace {

// A random forest: 1 to 4 x 1 to 3 charts of 33 to 129 samples, depth 3 to 5, with top groups
// above the charts in half of them.
World randomWorld(std::mt19937& rng) {
  const uint32_t sizes[] = {33, 65, 129};
  const uint32_t size = sizes[rng() % 3];
  const uint32_t maxDepth = size == 33 ? 4 : 5;
  World w = makeWorld(size, 1 + rng() % 4, 1 + rng() % 3, 3 + rng() % (maxDepth - 2));
  if (rng() % 2 == 0) w.h.groups = buildRootGroups(w.h, 2 + rng() % 3);
  return w;
}

// A camera path: from a random eye, moving a random step per frame towards and around the
// world, looking at random points over it (near views, far views, views with most charts culled).
std::vector<ViewParams> randomPath(const World& w, std::mt19937& rng, uint32_t frames) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const glm::dvec3 size = w.hi - w.lo;
  auto inside = [&]() { return w.lo + glm::dvec3(u(rng), u(rng), u(rng)) * size; };
  glm::dvec3 eye = inside() + glm::dvec3(0, 0, size.z + u(rng) * glm::length(size));
  const glm::dvec3 step = (inside() - eye) * (0.02 + 0.1 * u(rng));
  std::vector<ViewParams> views;
  for (uint32_t f = 0; f < frames; ++f) {
    glm::dvec3 target = inside();
    if (glm::length(target - eye) < 1e-6) target.x += 1.0;
    views.push_back(viewAt(w, eye, target));
    eye += step + glm::dvec3(u(rng) - 0.5, u(rng) - 0.5, 0.0) * 0.05 * glm::length(size);
  }
  return views;
}

void expectSameCut(const Cut& a, const Cut& b, const std::string& where) {
  ASSERT_EQ(sortedNodes(a), sortedNodes(b)) << where;
  std::vector<float> ea, eb;
  for (const CutNode& n : a.nodes) ea.push_back(n.errorPx);
  for (const CutNode& n : b.nodes) eb.push_back(n.errorPx);
  std::sort(ea.begin(), ea.end());
  std::sort(eb.begin(), eb.end());
  EXPECT_EQ(ea, eb) << where;
}

// One quad-queue frame against the reference's: the same cut, errors and counts.
void expectSameQuadFrame(const Cut& a, const BudgetStats& st, const Cut& b, const BudgetStats& rst,
                         const std::string& where) {
  expectSameCut(a, b, where);
  EXPECT_EQ(st.maxErrorPx, rst.maxErrorPx) << where;
  EXPECT_EQ(st.triangles, rst.triangles) << where;
  EXPECT_EQ(st.nodes, rst.nodes) << where;
  EXPECT_EQ(st.rounds, rst.rounds) << where;
  EXPECT_EQ(st.undos + st.tieUndos, rst.undos + rst.tieUndos) << where;
  EXPECT_EQ(st.constraintSplits, rst.constraintSplits) << where;
  EXPECT_EQ(st.refines + st.coarsens + st.splits + st.merges + st.undoneOps,
            rst.refines + rst.coarsens + rst.splits + rst.merges + rst.undoneOps)
      << where;
  EXPECT_EQ(st.refines + st.coarsens + st.splits + st.merges, rst.refines + rst.coarsens + rst.splits + rst.merges)
      << where;
}

// keptGap (from the coarse side, over kept nodes some of which are not drawn) equals stitchGaps
// (from the fine side, over the drawn cut) on random partitions.
TEST(AdaptEquivalence, TheGapsFromTheCoarseSideAreStitchGaps) {
  std::mt19937 rng(5);
  uint32_t raised = 0;
  for (int world = 0; world < 20; ++world) {
    const World w = randomWorld(rng);
    const Hierarchy& h = w.h;
    struct Kept {
      NodeId id;
      bool drawn;
    };
    std::vector<Kept> kept;
    for (uint32_t c = 0; c < h.chartCount(); ++c) kept.push_back({{c, 0, 0, 0}, true});
    for (int split = 0; split < 40; ++split) {  // split random nodes, deeper ones more often
      const size_t i = rng() % kept.size();
      const NodeId n = kept[i].id;
      if (n.level + 1 >= h.params.depth) continue;
      kept.erase(kept.begin() + long(i));
      for (uint32_t c = 0; c < 4; ++c) kept.push_back({n.child(c), rng() % 6 != 0});
    }
    auto find = [&](const NodeId& n) -> const Kept* {
      for (const Kept& k : kept)
        if (k.id == n) return &k;
      return nullptr;
    };
    Cut cut;
    for (const Kept& k : kept)
      if (k.drawn) cut.nodes.push_back({k.id, 0, 0.f});
    cut.rebuildIndex();
    std::vector<uint32_t> gaps;
    stitchGaps(h, cut, gaps);
    for (uint32_t i = 0; i < cut.nodes.size(); ++i) {
      EXPECT_EQ(keptGap(h, cut.nodes[i].id, find), gaps[i]) << "world " << world << ", node " << i;
      raised += uint32_t(gaps[i] > 1);
    }
  }
  EXPECT_GT(raised, 0u) << "no gap of two levels or more";
}

TEST(AdaptEquivalence, TheQuadQueueCutsAreTheReferencesOnRandomForests) {
  std::mt19937 rng(20261129);
  uint32_t frames = 0, split = 0;
  for (int world = 0; world < 60; ++world) {
    const World w = randomWorld(rng);
    const Hierarchy& h = w.h;
    BudgetOptions o;
    o.maxNodes = rng() % 4 == 0 ? 0 : 1 + rng() % 120;
    o.maxTriangles = (uint64_t(h.chartCount()) * 32) << (2 * (rng() % 6));
    o.maxOpsPerFrame = rng() % 3 == 0 ? 8 + rng() % 64 : 4096;
    o.maxRounds = rng() % 18;
    o.frustumCull = rng() % 5 != 0;
    QuadQueueAdapter ours(h);
    reference::QuadQueueAdapter ref(h);
    for (const ViewParams& v : randomPath(w, rng, 16)) {
      BudgetStats st, rst;
      const Cut& a = ours.update(v, o, &st);
      const Cut& b = ref.update(v, o, &rst);
      expectSameQuadFrame(a, st, b, rst, "world " + std::to_string(world) + ", frame " + std::to_string(frames));
      if (HasFatalFailure()) return;
      ++frames;
      split += uint32_t(st.splits > 0);
    }
  }
  // The paths adapt: the cuts change, not only the resolutions.
  EXPECT_GT(split, frames / 8);
}

// Deep forests (7 levels) on an orbit, with node budgets in the thousands and triangles to spare:
// many rounds a frame, with trades of splits for merges whose parents cannot hold their
// children's errors, undone rounds, and split priorities settled from bounds.
TEST(AdaptEquivalence, TheQuadQueueCutsAreTheReferencesOnDeepForests) {
  struct Case {
    uint32_t chartsX, nodes;
  };
  uint32_t frames = 0, rounds = 0, undone = 0, bounded = 0;
  for (const Case& c : {Case{2, 1335}, Case{3, 1669}}) {
    const World w = makeWorld(1025, c.chartsX, 2, 7);
    BudgetOptions o;
    o.maxNodes = c.nodes;
    o.maxTriangles = 1600000;
    QuadQueueAdapter ours(w.h);
    reference::QuadQueueAdapter ref(w.h);
    const glm::dvec3 centre = (w.lo + w.hi) * 0.5;
    const double radius = glm::length(w.hi - w.lo) * 0.35;
    for (uint32_t f = 0; f < 24; ++f) {
      const double a = 2.0 * M_PI * f / 60.0;
      const ViewParams v = viewAt(w, centre + radius * glm::dvec3(std::cos(a), std::sin(a), 0.4), centre);
      BudgetStats st, rst;
      const Cut& x = ours.update(v, o, &st);
      const Cut& y = ref.update(v, o, &rst);
      expectSameQuadFrame(x, st, y, rst, std::to_string(c.chartsX) + " charts, frame " + std::to_string(f));
      if (HasFatalFailure()) return;
      ++frames;
      rounds += st.rounds;
      undone += st.undoneOps;
      bounded += st.boundedPriorities;
    }
  }
  EXPECT_GT(rounds, 2 * frames) << "too few rounds a frame to check the kept queues";
  EXPECT_GT(undone, 0u) << "no round undone";
  EXPECT_GT(bounded, 0u) << "no split priority settled without the children's view data";
}

TEST(AdaptEquivalence, TheDualQueueCutsAreTheReferencesOnRandomForests) {
  std::mt19937 rng(1129);
  uint32_t frames = 0, split = 0;
  for (int world = 0; world < 60; ++world) {
    const World w = randomWorld(rng);
    const Hierarchy& h = w.h;
    AdaptOptions o;
    o.tolerancePx = std::pow(10.0, -2.0 + 3.0 * double(rng() % 1000) / 1000.0);
    o.maxNodes = rng() % 4 == 0 ? 0 : 1 + rng() % 120;
    o.frustumCull = rng() % 5 != 0;
    const uint32_t maxOps = rng() % 3 == 0 ? 4 + rng() % 32 : 1024;
    const bool reuse = rng() % 4 != 0;
    DualQueueAdapter ours(h, maxOps, reuse);
    reference::DualQueueAdapter ref(h, maxOps, reuse);
    for (const ViewParams& v : randomPath(w, rng, 16)) {
      AdaptStats st, rst;
      const Cut& a = ours.update(v, o, &st);
      const Cut& b = ref.update(v, o, &rst);
      const std::string where = "world " + std::to_string(world) + ", frame " + std::to_string(frames);
      expectSameCut(a, b, where);
      EXPECT_EQ(st.maxErrorPx, rst.maxErrorPx) << where;
      EXPECT_EQ(st.nodes, rst.nodes) << where;
      EXPECT_EQ(ours.frameStats().splits, ref.frameStats().splits) << where;
      EXPECT_EQ(ours.frameStats().merges, ref.frameStats().merges) << where;
      EXPECT_EQ(ours.frameStats().priorityReuses, ref.frameStats().priorityReuses) << where;
      if (HasFatalFailure()) return;
      ++frames;
      split += uint32_t(st.splits > 0);
    }
  }
  EXPECT_GT(split, frames / 8);
}

// Low over a 3 x 2 world of 513-sample charts, looking along it: near nodes and far ones, some
// culled.
std::vector<ViewParams> lowPath(const World& w) {
  std::vector<ViewParams> path;
  for (uint32_t f = 0; f < 12; ++f) {
    const glm::dvec3 eye = w.lo + (w.hi - w.lo) * glm::dvec3(0.1 + 0.02 * f, 0.3, 1.5);
    path.push_back(viewAt(w, eye, eye + glm::dvec3(1.0, 0.3 + 0.05 * f, -0.4)));
  }
  return path;
}

// The cuts of makeAdapter()'s adapter along path, run in an arena of `threads` threads (up to 4
// even on a machine with fewer cores); kept: the largest cut the adapter held.
template <typename Make, typename Update>
std::vector<std::vector<std::pair<uint64_t, uint32_t>>> cutsOnThreads(int threads, const std::vector<ViewParams>& path,
                                                                      Make&& makeAdapter, Update&& update,
                                                                      uint32_t* kept) {
  const tbb::global_control most(tbb::global_control::max_allowed_parallelism, 4);
  std::vector<std::vector<std::pair<uint64_t, uint32_t>>> cuts;
  tbb::task_arena arena(threads);
  arena.execute([&] {
    auto a = makeAdapter();
    for (const ViewParams& v : path) cuts.push_back(sortedNodes(update(*a, v, kept)));
  });
  return cuts;
}

// The parallel pass on a partition of thousands of nodes, in tasks of 32 (parallelMin 256).
TEST(AdaptEquivalence, TheDualQueueCutsDoNotDependOnTheThreadCount) {
  const World w = makeWorld(513, 3, 2, 5);
  AdaptOptions o;
  o.tolerancePx = 0.01;
  o.maxNodes = 30000;
  uint32_t kept = 0;
  auto make = [&] { return std::make_unique<DualQueueAdapter>(w.h, 1024, true, 256); };
  auto update = [&](DualQueueAdapter& a, const ViewParams& v, uint32_t* largest) -> const Cut& {
    const Cut& c = a.update(v, o);
    *largest = std::max(*largest, a.frameStats().partitionNodes);
    return c;
  };
  const auto one = cutsOnThreads(1, lowPath(w), make, update, &kept);
  EXPECT_GT(kept, 1024u) << "too small a partition for the parallel pass";
  EXPECT_EQ(one, cutsOnThreads(2, lowPath(w), make, update, &kept));
  EXPECT_EQ(one, cutsOnThreads(4, lowPath(w), make, update, &kept));
}

// The quad queue's parallel passes likewise (parallelMin 256), under budgets that keep it busy.
TEST(AdaptEquivalence, TheQuadQueueCutsDoNotDependOnTheThreadCount) {
  const World w = makeWorld(513, 3, 2, 5);
  BudgetOptions o;
  o.maxNodes = 3000;
  o.maxTriangles = 400000;
  uint32_t drawn = 0;
  auto make = [&] { return std::make_unique<QuadQueueAdapter>(w.h, 256); };
  auto update = [&](QuadQueueAdapter& a, const ViewParams& v, uint32_t* largest) -> const Cut& {
    const Cut& c = a.update(v, o);
    *largest = std::max(*largest, uint32_t(c.nodes.size()));
    return c;
  };
  const auto one = cutsOnThreads(1, lowPath(w), make, update, &drawn);
  EXPECT_GT(drawn, 512u) << "too small a cut for the parallel passes (256 nodes, in tasks of 32)";
  EXPECT_EQ(one, cutsOnThreads(2, lowPath(w), make, update, &drawn));
  EXPECT_EQ(one, cutsOnThreads(4, lowPath(w), make, update, &drawn));
}

}  // namespace
}  // namespace gimlod::test
