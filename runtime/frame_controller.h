// A frame-time controller: sets the node budget (CPU: adaptation time grows with the nodes) and
// the triangle budget (GPU: drawing time grows with the triangles) of the next frame so that the
// frame takes a target time. From the frames it is told about it learns (exponentially smoothed)
// the adaptation's cost per node, the overhead outside adaptation and drawing, and the frame time.
// The nodes get at most a share of the time left by the overhead; the triangle budget is scaled by
// the ratio of the time left for drawing to the time the drawing took (drawing time has a fixed
// part, so it is not proportional to the triangles; the ratio still converges on the target). Each
// frame moves part of the way there. Within a dead band round the target (by the smoothed frame
// time) it changes nothing, so on a still camera the budgets settle and stay put. Pure C++, no
// GL: `render` and the viewer feed it measured times.
// Based on: Niski, Purnomo, Cohen, I3D 2007, section 7.1 (node and triangle budgets set apart);
// the frame-rate controllers of Funkhouser and Sequin, SIGGRAPH 1993 (predictive cost model).
#pragma once

#include <cstdint>

namespace gimlod {

struct FrameControllerOptions {
  double targetMs = 16.7;   // the frame time to hold; > 0
  double nodeShare = 0.25;  // at most this share of the adapt+draw time goes to nodes
  double gain = 0.5;        // share of the way to the wanted budgets moved per frame, (0, 1]
  double deadBand = 0.03;   // no change while the smoothed frame time is within this of the target
  double smoothing = 0.3;   // weight of the newest frame in the smoothed unit costs, (0, 1]
  uint32_t minNodes = 16, maxNodes = 1u << 20;
  uint64_t minTriangles = 1000, maxTriangles = uint64_t(1) << 32;
};

// One frame as measured: what it drew and what it cost.
struct FrameSample {
  uint32_t nodes = 0;
  uint64_t triangles = 0;
  double adaptMs = 0.0;  // CPU: adaptation (and stitching tables)
  double drawMs = 0.0;   // GPU: drawing (or its CPU-side wait)
  double frameMs = 0.0;  // the whole frame, less page reads and uploads; the rest is overhead
};

class FrameController {
 public:
  FrameController(const FrameControllerOptions& options, uint32_t startNodes, uint64_t startTriangles);

  // Learns from the frame just drawn with the current budgets and sets the next frame's budgets.
  void update(const FrameSample& frame);

  uint32_t maxNodes() const { return nodes_; }
  uint64_t maxTriangles() const { return triangles_; }
  // The smoothed frame time (0 before the first frame).
  double predictedMs() const;
  double msPerNode() const { return perNode_; }
  double msPerTriangle() const { return perTriangle_; }
  double overheadMs() const { return overhead_; }
  const FrameControllerOptions& options() const { return o_; }
  void setTarget(double targetMs);

 private:
  FrameControllerOptions o_;
  uint32_t nodes_;
  uint64_t triangles_;
  double perNode_ = 0.0, perTriangle_ = 0.0, overhead_ = 0.0, frameMs_ = 0.0;
  bool learned_ = false;
};

}  // namespace gimlod
