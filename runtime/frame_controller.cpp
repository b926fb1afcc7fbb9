#include "runtime/frame_controller.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace gimlod {

FrameController::FrameController(const FrameControllerOptions& options, uint32_t startNodes, uint64_t startTriangles)
    : o_(options) {
  if (!(o_.targetMs > 0.0) || !std::isfinite(o_.targetMs))
    throw std::invalid_argument("FrameController: target must be > 0 ms");
  if (!(o_.gain > 0.0 && o_.gain <= 1.0) || !(o_.smoothing > 0.0 && o_.smoothing <= 1.0) ||
      !(o_.nodeShare > 0.0 && o_.nodeShare < 1.0) || !(o_.deadBand >= 0.0 && o_.deadBand < 0.5) || o_.minNodes == 0 ||
      o_.minNodes > o_.maxNodes || o_.minTriangles == 0 || o_.minTriangles > o_.maxTriangles)
    throw std::invalid_argument("FrameController: options out of range");
  nodes_ = std::clamp(startNodes, o_.minNodes, o_.maxNodes);
  triangles_ = std::clamp(startTriangles, o_.minTriangles, o_.maxTriangles);
}

void FrameController::setTarget(double targetMs) {
  if (!(targetMs > 0.0) || !std::isfinite(targetMs))
    throw std::invalid_argument("FrameController: target must be > 0 ms");
  o_.targetMs = targetMs;
}

double FrameController::predictedMs() const { return learned_ ? frameMs_ : 0.0; }

void FrameController::update(const FrameSample& f) {
  if (f.nodes == 0 || f.triangles == 0 || !(f.frameMs > 0.0) || !std::isfinite(f.frameMs)) return;
  const double node = std::max(f.adaptMs, 0.0) / double(f.nodes);
  const double rest = std::max(f.frameMs - f.adaptMs - f.drawMs, 0.0);
  const double tri = std::max(f.drawMs, 0.0) / double(f.triangles);
  if (!learned_) {
    perNode_ = node, perTriangle_ = tri, overhead_ = rest, frameMs_ = f.frameMs;
    learned_ = true;
  } else {
    const double s = o_.smoothing;
    perNode_ += s * (node - perNode_);
    perTriangle_ += s * (tri - perTriangle_);
    overhead_ += s * (rest - overhead_);
    frameMs_ += s * (f.frameMs - frameMs_);
  }
  // Inside the dead band (by the smoothed frame time) nothing moves: on a still view the budgets
  // settle.
  const double target = o_.targetMs;
  if (std::abs(frameMs_ - target) <= o_.deadBand * target) return;

  // Nodes: at most their share of the time, at the learned cost per node.
  const double available = std::max(target - overhead_, 0.1 * target);
  double wantNodes = perNode_ > 0.0 ? o_.nodeShare * available / perNode_ : double(o_.maxNodes);
  // A budget the cut does not use cannot buy anything: while it goes unused it may not grow past a
  // quarter over what was used (no wind-up), but it is not cut for that either (the adapter may
  // still be converging on a moving view, and a cut budget would starve it).
  if (f.nodes < uint32_t(0.9 * double(nodes_)))
    wantNodes = std::min(wantNodes, std::max(1.25 * double(f.nodes), double(nodes_)));
  wantNodes = std::clamp(wantNodes, double(o_.minNodes), double(o_.maxNodes));
  // Triangles: the drawing gets the rest. Drawing time is not proportional to the triangles (a GPU
  // has a fixed cost per frame), so the budget is scaled by the ratio of the time the drawing may
  // take to the time it took, which converges on the target whatever that fixed cost.
  const double drawAvailable = std::max(available - perNode_ * wantNodes, 0.05 * target);
  double wantTriangles = f.drawMs > 0.0 ? double(f.triangles) * drawAvailable / f.drawMs : double(o_.maxTriangles);
  // The same for the triangles (no wind-up while the view needs less than the budget allows).
  if (double(f.triangles) < 0.9 * double(triangles_))
    wantTriangles = std::min(wantTriangles, std::max(1.25 * double(f.triangles), double(triangles_)));
  wantTriangles = std::clamp(wantTriangles, double(o_.minTriangles), double(o_.maxTriangles));

  // Part of the way there, in proportion (nodes) and in ratio (triangles).
  const double g = o_.gain;
  nodes_ = uint32_t(
      std::clamp<long long>(std::llround(double(nodes_) + g * (wantNodes - double(nodes_))), o_.minNodes, o_.maxNodes));
  triangles_ =
      uint64_t(std::clamp<double>(std::round(double(triangles_) * std::pow(wantTriangles / double(triangles_), g)),
                                  double(o_.minTriangles), double(o_.maxTriangles)));
}

}  // namespace gimlod
