// One frame of atlas rendering (terrain or mesh): adapt (runtime core), build stitching tables,
// make the cut's pages resident in the GPU page pool, and draw. Also the transform-feedback capture used by the
// crack tests. Needs a current GL context.
#pragma once

#include <chrono>
#include <functional>
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
#include "runtime/residency.h"
#include "runtime/stitch.h"

namespace gimlod::gl {

struct SceneOptions {
  uint32_t width = 640, height = 480;
  uint32_t samples = 1;  // samples per pixel (multisampling); 1: none
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
  // The GPU page pool by its bytes (0: by pageCapacity and minNodeRoom): as many pages as fit
  // (AtlasRenderer's pagePoolPageBytes: samples, normals and colours alike). The chart roots stay
  // resident while they fit with room to split one; past that each root gets a stand-in, a page of
  // the root at a coarser resolution in small texture arrays of their own (RendererSetup::standIns),
  // and the pool is the rest of the bytes (InputError below the stand-ins and 4 pages, naming the
  // least).
  uint64_t gpuCacheBytes = 0;
  // The roots' stand-ins hold them at 2^this intervals (within the pages' resolution less one and
  // the coarsest a node is drawn at); 0: the finest whose stand-ins take at most half the cache.
  uint32_t standInResLog2 = 0;
  // Paper 7.2: pages load on loader threads and missing nodes draw with a resident ancestor.
  // Off (the default): every page is read synchronously, so frames are deterministic.
  bool asyncLoads = false;
  uint32_t maxUploadsPerFrame = 64;  // async: loaded pages uploaded per frame
  uint64_t uploadBytesPerFrame = 0;  // async: and their bytes (0: no limit; one page always)
  // async: the RAM the loader holds, its cache of read pages and the pages read for upload
  // (PageLoaderOptions::ramBytes; those may take at most half, and twice a frame's uploads).
  size_t ramCacheBytes = size_t(256) << 20;
  uint32_t loaderThreads = 2;                  // async: loader threads
  double ioLatencyMs = 0.0, ioJitterMs = 0.0;  // async: simulated slow storage (PageLoaderOptions)
  uint32_t ioDepth = 32;                       // async: reads the simulated storage serves at once (PageLoaderOptions)
  // async: prefetch the cut of the view this many seconds ahead, the camera extrapolated from the
  // last two frames at frameSeconds apart, at a priority below every page the frame needs (0: off).
  double prefetchSeconds = 0.0;
  double frameSeconds = 1.0 / 60.0;
  // Geomorphs (geomorphFactor): each node's inner vertices move onto its next coarser resolution
  // as that resolution's error comes within (1 + geomorph) times the tolerance (budget mode: the
  // frame's largest error). 0: off.
  double geomorph = 0.0;
  // async: called once for each page that cannot be read (on a loader thread); the node stays on
  // its resident ancestor.
  std::function<void(const PageFailure&)> onPageFailure;
  // Error mode: the coherent dual-queue adapter (paper 7.1); false: the stateless top-down
  // greedy (adaptErrorThreshold). Budget mode always uses the quad-queue adapter.
  bool coherentAdaptation = true;
  // Pixel-to-texel ratio for the attribute (normal map) resolutions, in texels per pixel; 0
  // draws every node's normals at its page's resolution.
  double texelsPerPixel = 1.0;
  // Sample the attributes between the two mips the need lies between (CutNode::texBlend); false:
  // at the finer one, so they switch as the need crosses a mip.
  bool blendAttributes = true;
  // Drawn over the shading (runtime/overlay.h): charts, levels or resolutions told apart, seams
  // and open borders marked. Capture is unaffected.
  OverlayMode overlay = OverlayMode::kNone;
  NodeColour overlayColour;     // the colours of OverlayMode::kCustom
  double overlayErrorPx = 0.0;  // OverlayMode::kError: the error drawn red (0: the cut's largest)
};

struct FrameResult {
  Cut cut;  // the cut actually drawn (async: with resident ancestors substituted)
  // The cut the adaptation chose, where the drawn one may differ (async, or roots on stand-ins);
  // else empty (`cut` is it).
  Cut desiredCut;
  AdaptStats adapt;           // of the desired cut (rootFloor, budgetBelowRoots: in both modes)
  BudgetStats budget;         // budget mode: the quad-queue's stats (adapt holds its counts too)
  AttributeStats attributes;  // attribute resolutions of the desired cut (texelsPerPixel > 0)
  double maxErrorPx = 0.0;    // of the drawn cut: above the tolerance while ancestors stand in
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
  uint32_t rootsOnStandIns = 0;   // chart roots drawn from their stand-ins (not in the pool)
  uint32_t chartsCoarsened = 0;   // charts held coarser beside a root on its stand-in
  // Streaming (async): what the caches hold after the frame, against their budgets.
  uint64_t residentGpuBytes = 0;  // pages in the GPU pool times a page's bytes (both modes)
  uint64_t gpuBudgetBytes = 0;    // the pool's pages times a page's bytes (both modes)
  uint64_t residentRamBytes = 0;  // the loader's cache and staged pages
  uint64_t uploadBytes = 0;       // bytes uploaded this frame (both modes)
  // The pages the desired cut needs and those of them already in the GPU pool as the frame began
  // (the hit rate is their ratio).
  uint32_t pagesNeeded = 0, pagesResident = 0;
  uint32_t loadsIssued = 0, loadsDone = 0, loadsCancelled = 0, loadsFailed = 0;  // this frame's
  uint32_t prefetchRequests = 0;  // pages of the predicted view's cut requested this frame
  // Drawn nodes without their page's data (pagesMissing or stitchUnfixable): the frame is not
  // complete. Always false unless the pool is too small for the cut.
  bool incomplete = false;
};

class AtlasScene {
 public:
  AtlasScene(const AtlasView& atlas, const SceneOptions& options);
  const AtlasView& atlas() const { return atlas_; }
  // The largest node budget a frame gets such that the cut's pages fit the page pool beside the
  // locked roots: 3/4 of the other pages (see the .cpp); larger budgets are lowered to it.
  uint32_t nodeRoom() const;
  // The pages of the pool a scene of `options` makes for an atlas of `charts` charts.
  // With gpuCacheBytes, as many pages of pageBytes as it holds.
  static uint32_t pagePoolPages(const SceneOptions& options, uint32_t charts, uint64_t pageBytes = 0);
  // maxNodes within nodeRoom (0: nodeRoom).
  uint32_t nodeBudget(uint32_t maxNodes) const;
  AtlasRenderer& renderer() { return *renderer_; }
  // GPU bytes of one page of the pool (pagePoolPageBytes); the pool holds renderer().pageCapacity().
  uint64_t pageBytes() const { return pageBytes_; }
  // The roots' stand-ins (empty: the roots' pages are locked in the pool) and their GPU bytes.
  const RootStandIns& rootStandIns() const { return rootStandIns_; }
  uint64_t standInBytes() const { return standInBytes_; }
  // The atlas carries per-sample colours (a mesh's vertex colours or terrain imagery), which are drawn.
  bool hasColours() const { return pages_.colours(); }
  // A new frame size (a resized window): the projection and the screen-space errors follow.
  void resize(uint32_t width, uint32_t height);
  uint32_t width() const { return options_.width; }
  uint32_t height() const { return options_.height; }
  // Error mode: the coherent dual queue (true) or the stateless top-down greedy.
  void setCoherentAdaptation(bool on) { options_.coherentAdaptation = on; }
  void setTexelsPerPixel(double ratio) { options_.texelsPerPixel = ratio; }
  void setGeomorph(double range) { options_.geomorph = range; }
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

  // The camera's view and projection as draw() takes them: planet atlases relative to the
  // renderer's anchor (setPlanetAnchor), with a reversed depth to infinity.
  glm::dmat4 viewProjection(const Camera& camera) const;
  // Planet atlases: the camera as the scene draws it (near plane a few centimetres, far beyond the
  // planet: the depth is reversed), and its view with horizon culling; other atlases: as they are.
  Camera sceneCamera(const Camera& camera) const;
  ViewParams viewParams(const Camera& camera) const;
  // Planet atlases: measures positions from the lattice sample under the eye (no-op otherwise).
  void anchorAt(const Camera& camera);
  // Planet atlases: the planet-centred point captured positions are relative to ({0} otherwise).
  glm::dvec3 captureOrigin() const;
  // Blocks until the page loader has nothing queued or being read (no-op without asyncLoads).
  void waitForLoads();
  // The page loader, or null without asyncLoads.
  const PageLoader* loader() const { return loader_.get(); }

 private:
  std::vector<DrawNode> prepare(const Cut& cut, FrameResult* frame);
  // Everything after adaptation: attribute resolutions, ordering, loads, drawing.
  // tolPx: the tolerance the frame's cut meets (prefetch of the predicted view's cut, geomorphs);
  // maxNodes: the predicted view's node budget.
  void finishFrame(const Camera& camera, const ViewParams& view, double tolPx, uint32_t maxNodes, FrameResult& f,
                   std::chrono::steady_clock::time_point t0);
  // Async: requests missing pages (and the predicted view's, prefetchTolPx > 0), uploads loaded
  // ones, and returns the drawable cut: every node's page resident, stitching constraint
  // enforced. Starts the frame that prepare draws.
  Cut streamPages(const Cut& desired, const ViewParams& view, const Camera& camera, double prefetchTolPx,
                  uint32_t maxNodes, FrameResult* frame);
  // The desired roots whose stand-ins draw them as their pages would (RootStandIns): they need no
  // page in the pool.
  std::unordered_set<uint64_t> rootsServedByStandIns(const Cut& desired) const;
  // The cut drawn for `desired` with `resident` pages (substituteResident, stand-ins included),
  // noting the nodes standing in (standIns_) and the counts in f.
  Cut drawableCut(const Cut& desired, const ViewParams& view, const ResidentFn& resident, FrameResult* f);
  // Without the loader, with root stand-ins: reads the desired pages into the pool while it has
  // room this frame (coarser first) and returns the drawable cut. Starts the frame prepare draws.
  Cut loadSynchronously(const Cut& desired, const ViewParams& view, FrameResult* f);
  // Reads every chart root and uploads its stand-in (RendererSetup::standIns).
  void makeRootStandIns();
  // The view prefetchSeconds ahead, from the last two cameras; false without a previous one.
  bool predictedView(const Camera& camera, ViewParams* view) const;
  // Uploads a loaded page into the pool; false when no layer is free this frame (keepFrom:
  // PagePool::acquire's).
  bool uploadLoaded(const LoadedPage& page, uint64_t keepFrom = 0);
  // Uploads n's page into pool layer `layer` (mips: made beforehand, or null) and counts its bytes.
  void upload(uint32_t layer, const NodeId& n, const std::vector<float>& samples,
              const std::vector<PackedNormal>& normals, const std::vector<PackedColour>& colours,
              const PageMips* mips = nullptr);
  AtlasView atlas_;
  SceneOptions options_;
  PageReader pages_;
  std::unique_ptr<AtlasRenderer> renderer_;
  PagePool pool_;
  uint64_t frame_ = 0;
  bool frameStarted_ = false;              // streamPages began frame_; prepare must not advance it
  std::unordered_set<uint64_t> standIns_;  // async: drawn nodes standing in for pages still loading
  std::vector<float> samples_;
  std::vector<PackedNormal> normals_;
  std::vector<PackedColour> colours_;
  uint64_t pageBytes_ = 0;      // GPU bytes of one pool page
  uint64_t uploadBytes_ = 0;    // this frame's
  RootStandIns rootStandIns_;   // empty: the roots are locked in the pool
  uint64_t standInBytes_ = 0;   // GPU bytes of the stand-ins
  uint32_t syncLoaded_ = 0;     // pages loadSynchronously read this frame
  PageLoaderStats lastLoads_;   // the loader's counts at the end of the last frame
  bool hasLastCamera_ = false;  // prefetch: the last frame's camera
  Camera lastCamera_;
  std::unique_ptr<DualQueueAdapter> dualQueue_;
  std::unique_ptr<QuadQueueAdapter> quadQueue_;
  std::unique_ptr<PageLoader> loader_;  // last: its thread reads pages_
};

}  // namespace gimlod::gl
