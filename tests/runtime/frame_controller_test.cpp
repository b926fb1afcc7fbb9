// Tests for the frame-time controller against a simulated renderer whose adaptation costs a fixed
// time per node and whose drawing a fixed time per frame plus a time per triangle (with a fixed
// overhead): it reaches
// the target and then stays put on a static view, comes back within 10% of the target after a
// step in the triangle rate (and after a step down), does not wind up a budget the view cannot
// use, and refuses absurd options.
#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>

#include "runtime/frame_controller.h"

namespace gimlod {
namespace {

// The simulated frame: the cut uses the budgets, up to what the view can use.
struct Plant {
  double overheadMs = 1.0, msPerNode = 0.002, trianglesPerMs = 1e5;
  double drawFixedMs = 4.0;                    // clearing and shading the frame, whatever the triangles
  uint64_t viewTriangles = uint64_t(1) << 40;  // the most triangles the view can use
  FrameSample draw(uint32_t nodes, uint64_t triangles) const {
    FrameSample f;
    f.nodes = nodes;
    f.triangles = std::min(triangles, viewTriangles);
    f.adaptMs = msPerNode * nodes;
    f.drawMs = drawFixedMs + double(f.triangles) / trianglesPerMs;
    f.frameMs = overheadMs + f.adaptMs + f.drawMs;
    return f;
  }
};

// Runs `frames` frames; returns the frame times.
std::vector<double> run(FrameController& c, const Plant& p, int frames) {
  std::vector<double> ms;
  for (int i = 0; i < frames; ++i) {
    const FrameSample f = p.draw(c.maxNodes(), c.maxTriangles());
    ms.push_back(f.frameMs);
    c.update(f);
  }
  return ms;
}

TEST(FrameController, ReachesTheTargetAndStaysPutOnAStaticView) {
  FrameControllerOptions o;
  o.targetMs = 16.7;
  FrameController c(o, 500, 100000);
  Plant p;
  const std::vector<double> ms = run(c, p, 40);
  EXPECT_NEAR(ms.back(), o.targetMs, 0.1 * o.targetMs);
  // Settled: the budgets no longer change at all.
  const uint32_t n = c.maxNodes();
  const uint64_t t = c.maxTriangles();
  run(c, p, 50);
  EXPECT_EQ(c.maxNodes(), n);
  EXPECT_EQ(c.maxTriangles(), t);
  // Nodes take about their share of the time, the triangles the rest.
  EXPECT_NEAR(p.msPerNode * n, o.nodeShare * (o.targetMs - p.overheadMs), 0.1 * o.targetMs);
  EXPECT_GT(t, 500000u);
}

TEST(FrameController, ComesBackAfterALoadStep) {
  FrameControllerOptions o;
  o.targetMs = 16.7;
  FrameController c(o, 500, 100000);
  Plant p;
  run(c, p, 40);
  // The triangle rate halves (a heavier shader, a slower GPU): the frame jumps, then comes back.
  p.trianglesPerMs /= 2.0;
  const std::vector<double> ms = run(c, p, 30);
  EXPECT_GT(ms.front(), 1.3 * o.targetMs);
  int settled = -1;
  for (int i = 0; i < int(ms.size()); ++i) {
    bool within = true;
    for (int j = i; j < int(ms.size()); ++j) within &= std::abs(ms[j] - o.targetMs) <= 0.1 * o.targetMs;
    if (within) {
      settled = i;
      break;
    }
  }
  double undershoot = 0.0;  // the most the frame fell below the target on the way back
  for (double m : ms) undershoot = std::max(undershoot, o.targetMs - m);
  std::printf("  load step x2: back within 10%% of the target after %d frames (undershoot at most %.2f ms)\n", settled,
              undershoot);
  ASSERT_GE(settled, 0);
  EXPECT_LE(settled, 12);
  // And back up when the rate recovers.
  p.trianglesPerMs *= 2.0;
  const std::vector<double> back = run(c, p, 30);
  EXPECT_NEAR(back.back(), o.targetMs, 0.1 * o.targetMs);
}

TEST(FrameController, DoesNotWindUpABudgetTheViewCannotUse) {
  FrameControllerOptions o;
  o.targetMs = 50.0;
  FrameController c(o, 500, 100000);
  Plant p;
  p.viewTriangles = 200000;  // everything in view fits: the frame stays under the target
  run(c, p, 30);
  // Grown while it bound, then held: never far past what the view uses, and no longer growing.
  const uint64_t held = c.maxTriangles();
  EXPECT_LE(held, uint64_t(1.5 * 200000));
  EXPECT_GE(held, 200000u);
  run(c, p, 30);
  EXPECT_EQ(c.maxTriangles(), held);
}

// An adapter still converging on a moving view uses part of its budgets: they are held, not cut
// down to what it used (which would starve it, frame after frame, far below the target).
TEST(FrameController, HoldsBudgetsALaggingAdapterDoesNotFill) {
  FrameControllerOptions o;
  o.targetMs = 20.0;
  FrameController c(o, 400, 400000);
  for (int i = 0; i < 100; ++i) {
    FrameSample f;
    f.nodes = uint32_t(0.7 * c.maxNodes());  // the adapter fills 70% of each budget
    f.triangles = uint64_t(0.7 * double(c.maxTriangles()));
    f.adaptMs = 0.002 * f.nodes;
    f.drawMs = double(f.triangles) / 40000.0;  // 40k triangles per ms
    f.frameMs = f.adaptMs + f.drawMs + 0.5;
    c.update(f);
  }
  EXPECT_GE(c.maxTriangles(), 400000u);
  EXPECT_GE(c.maxNodes(), 400u);
}

TEST(FrameController, RefusesAbsurdOptions) {
  FrameControllerOptions o;
  o.targetMs = 0.0;
  EXPECT_THROW(FrameController(o, 100, 1000), std::invalid_argument);
  o.targetMs = std::nan("");
  EXPECT_THROW(FrameController(o, 100, 1000), std::invalid_argument);
  o = {};
  o.gain = 0.0;
  EXPECT_THROW(FrameController(o, 100, 1000), std::invalid_argument);
  o = {};
  FrameController c(o, 100, 1000);
  EXPECT_THROW(c.setTarget(-1.0), std::invalid_argument);
  // Frames without a cut teach nothing.
  c.update(FrameSample{});
  EXPECT_EQ(c.predictedMs(), 0.0);
}

}  // namespace
}  // namespace gimlod
