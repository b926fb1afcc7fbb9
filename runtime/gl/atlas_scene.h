// One frame of atlas rendering (terrain or mesh): adapt (runtime core), build stitching tables,
// make the cut's pages resident in the GPU page pool, and draw. Also the transform-feedback capture used by the
// crack tests. Needs a current GL context.
#pragma once

#include <chrono>
#include <memory>
#include <unordered_set>
#include <vector>

#include "runtime/adapt.h"
#include "runtime/adapt_dual_queue.h"
#include "runtime/adapt_quad_queue.h"
#include "runtime/atlas_view.h"
#include "runtime/draw_list.h"
#include "runtime/gl/atlas_renderer.h"
#include "runtime/page_loader.h"
#include "runtime/page_pool.h"
#include "runtime/page_reader.h"
#include "runtime/overlay.h"
#include "runtime/stitch.h"

namespace gimlod::gl {

struct SceneOptions {
  uint32_t width = 640, height = 480;
  std::array<float, 3> background{0.53f, 0.70f, 0.92f};
  // GPU page pool pages. The pool is made larger where the atlas needs it: every chart's root
  // page stays resident, so an atlas of more charts than half of this gets the roots plus half
  // of this; and minNodeRoom below. Past GL_MAX_ARRAY_TEXTURE_LAYERS the pool is several texture
  // arrays (RendererSetup::pageCapacity).
  uint32_t pageCapacity = 2048;
  // The pool is made large enough for cuts of this many nodes (nodeRoom() >= it): a node budget
  // the frames are to hold (render --max-nodes, bench's largest). 0: none.
  uint32_t minNodeRoom = 0;
  uint32_t layersPerArray = 0;  // RendererSetup::layersPerArray (0: the GL limit; tests set less)
  // Paper 7.2: pages load on a separate thread and missing nodes draw with a resident ancestor.
  // Off (the default): every page is read synchronously, so frames are deterministic.
  bool asyncLoads = false;
  uint32_t maxUploadsPerFrame = 64;            // async: loaded pages uploaded per frame
  size_t ramCacheBytes = size_t(256) << 20;    // async: RAM page cache budget
  // Error mode: the coherent dual-queue adapter (paper 7.1); false: the stateless top-down
  // greedy (adaptErrorThreshold). Budget mode always uses the quad-queue adapter.
  bool coherentAdaptation = true;
  // Pixel-to-texel ratio for the attribute (normal map) resolutions, in texels per pixel; 0
  // draws every node's normals at its page's resolution.
  double texelsPerPixel = 1.0;
  // Drawn over the shading (runtime/overlay.h): charts, levels or resolutions told apart, seams
  // and open borders marked. Capture is unaffected.
  OverlayMode overlay = OverlayMode::kNone;
  NodeColour overlayColour;  // the colours of OverlayMode::kCustom
  double overlayErrorPx = 0.0;  // OverlayMode::kError: the error drawn red (0: the cut's largest)
};

struct FrameResult {
  Cut cut;         // the cut actually drawn (async: with resident ancestors substituted)
  Cut desiredCut;  // async: the cut the adaptation chose; empty without asyncLoads (`cut` is it)
  AdaptStats adapt;        // of the desired cut (rootFloor, budgetBelowRoots: in both modes)
  BudgetStats budget;      // budget mode: the quad-queue's stats (adapt holds its counts too)
  AttributeStats attributes;  // attribute resolutions of the desired cut (texelsPerPixel > 0)
  double maxErrorPx = 0.0;  // of the drawn cut: above the tolerance while ancestors stand in
  DrawStats draw;
  double adaptMs = 0.0, stitchMs = 0.0, uploadMs = 0.0;
  uint32_t pagesLoaded = 0;
  // Nodes that found no free page-pool layer this frame (their data is wrong); the node budget
  // is clamped to the pool so this stays 0.
  uint32_t pagesMissing = 0;
  uint32_t pagesRequested = 0;    // async: desired nodes whose page was not GPU-resident
  uint32_t pagesUploaded = 0;     // async: loaded pages uploaded this frame
  uint32_t nodesSubstituted = 0;  // async: desired nodes drawn as a resident ancestor
  uint32_t stitchUnfixable = 0;   // async: drawn nodes left violating the stitching constraint
};

class AtlasScene {
 public:
  AtlasScene(const AtlasView& atlas, const SceneOptions& options);
  const AtlasView& atlas() const { return atlas_; }
  // The largest node budget a frame gets such that the cut's pages fit the page pool beside the
  // locked roots: the larger of 3/4 of the unlocked pages and the root count plus 9/16 of them
  // (see the .cpp); larger budgets are lowered to it.
  uint32_t nodeRoom() const;
  // The pages of the pool a scene of `options` makes for an atlas of `charts` charts.
  static uint32_t pagePoolPages(const SceneOptions& options, uint32_t charts, bool grouped = false);
  // maxNodes within nodeRoom (0: nodeRoom).
  uint32_t nodeBudget(uint32_t maxNodes) const;
  AtlasRenderer& renderer() { return *renderer_; }
  // The atlas carries per-sample colours (a mesh's vertex colours or terrain imagery), which are drawn.
  bool hasColours() const { return pages_.colours(); }
  // A new frame size (a resized window): the projection and the screen-space errors follow.
  void resize(uint32_t width, uint32_t height);
  uint32_t width() const { return options_.width; }
  uint32_t height() const { return options_.height; }
  // Error mode: the coherent dual queue (true) or the stateless top-down greedy.
  void setCoherentAdaptation(bool on) { options_.coherentAdaptation = on; }
  void setTexelsPerPixel(double ratio) { options_.texelsPerPixel = ratio; }
  void setMaxUploadsPerFrame(uint32_t n) { options_.maxUploadsPerFrame = n; }
  void setOverlay(OverlayMode mode, NodeColour colour = {}, double errorPx = 0.0) {
    options_.overlay = mode;
    options_.overlayColour = std::move(colour);
    options_.overlayErrorPx = errorPx;
  }

  // Adapts to the camera (error threshold, paper 7.1 problem 1) and draws; the picture is then in
  // renderer().readPixels().
  FrameResult renderFrame(const Camera& camera, const AdaptOptions& options);
  // The same under a triangle budget (problem 2, quad-queue adapter).
  FrameResult renderFrame(const Camera& camera, const BudgetOptions& options);
  // Draws a given cut (stitching constraint already enforced).
  DrawStats drawCut(const Camera& camera, const Cut& cut, FrameResult* frame = nullptr);
  // Stitched world positions of every vertex of every cut node, from the real vertex shader.
  // stitch = false zeroes the stitching tables (a negative control for the crack tests).
  std::vector<std::vector<glm::vec3>> capture(const Cut& cut, bool stitch = true);

  glm::dmat4 viewProjection(const Camera& camera) const;
  // Blocks until the page loader has nothing queued or being read (no-op without asyncLoads).
  void waitForLoads();
  // The page loader, or null without asyncLoads.
  const PageLoader* loader() const { return loader_.get(); }

 private:
  std::vector<DrawNode> prepare(const Cut& cut, FrameResult* frame);
  // Everything after adaptation: attribute resolutions, ordering, loads, drawing.
  void finishFrame(const Camera& camera, const ViewParams& view, FrameResult& f,
                   std::chrono::steady_clock::time_point t0);
  // Async: requests missing pages, uploads loaded ones, and returns the drawable cut: every
  // node's page resident, stitching constraint enforced. Starts the frame that prepare draws.
  Cut streamPages(const Cut& desired, const ViewParams& view, FrameResult* frame);
  AtlasView atlas_;
  SceneOptions options_;
  PageReader pages_;
  std::unique_ptr<AtlasRenderer> renderer_;
  PagePool pool_;
  uint64_t frame_ = 0;
  bool frameStarted_ = false;  // streamPages began frame_; prepare must not advance it
  std::unordered_set<uint64_t> standIns_;  // async: drawn nodes standing in for pages still loading
  std::vector<float> samples_;
  std::vector<PackedNormal> normals_;
  std::vector<PackedColour> colours_;
  std::vector<LoadedPage> ready_;        // loaded pages waiting for the per-frame upload budget
  std::unique_ptr<DualQueueAdapter> dualQueue_;
  std::unique_ptr<QuadQueueAdapter> quadQueue_;
  std::unique_ptr<PageLoader> loader_;  // last: its thread reads pages_
};

}  // namespace gimlod::gl
