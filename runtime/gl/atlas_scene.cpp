#include "runtime/gl/atlas_scene.h"

#include <algorithm>
#include <cassert>
#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <unordered_set>
#include <utility>

#include "runtime/residency.h"

namespace gimlod::gl {
namespace {

double msSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

// Pages a cut needs beside the roots at least: room to split one of them.
constexpr uint32_t kRoomToSplit = 4;

// A GPU cache of `bytes` that cannot hold every root's page and room to split one: each root gets
// a stand-in, the root at 2^s intervals (s below the pages' resolution, and at least the coarsest
// a node is drawn at), the finest s whose stand-ins take at most half the cache; the pool gets the
// rest, at least kRoomToSplit pages (InputError otherwise, naming the least).
// resLog2 > 0: that resolution instead, within the same limits.
void standInSetup(RendererSetup& s, uint64_t bytes, uint32_t charts, uint32_t resLog2) {
  const uint64_t pageBytes = pagePoolPageBytes(s);
  s.standIns = charts;
  const uint32_t lowest = std::min(s.minResLog2, s.pageIntervalsLog2);
  const uint32_t highest = std::max(lowest, s.pageIntervalsLog2 - std::min(s.pageIntervalsLog2, 1u));
  s.standInIntervalsLog2 = lowest;
  for (uint32_t r = lowest + 1; r <= highest && resLog2 == 0; ++r) {
    RendererSetup t = s;
    t.standInIntervalsLog2 = r;
    if (uint64_t(charts) * standInPageBytes(t) > bytes / 2) break;
    s.standInIntervalsLog2 = r;
  }
  if (resLog2 > 0) s.standInIntervalsLog2 = std::clamp(resLog2, lowest, highest);
  const uint64_t standIns = uint64_t(charts) * standInPageBytes(s);
  const uint64_t least = standIns + kRoomToSplit * pageBytes;
  if (bytes < least)
    throw InputError("a GPU page cache of " + std::to_string(bytes) + " bytes cannot hold the atlas's " +
                     std::to_string(charts) + " chart roots' stand-ins of " +
                     std::to_string((1u << s.standInIntervalsLog2) + 1) + "^2 samples (" + std::to_string(standIns) +
                     " bytes) and " + std::to_string(kRoomToSplit) + " pages of " + std::to_string(pageBytes) +
                     " bytes: it needs " + std::to_string(least) + " bytes at least");
  s.pageCapacity = uint32_t(std::min<uint64_t>((bytes - standIns) / pageBytes, UINT32_MAX));
}

RendererSetup rendererSetup(const AtlasView& a, const SceneOptions& o, const PageReader& pages) {
  RendererSetup s;
  s.geometry = a.manifest.kind == AtlasKind::Geometry;
  s.colours = pages.colours();
  s.colourScaleLog2 = pages.colourScaleLog2();
  s.width = o.width;
  s.height = o.height;
  s.samples = o.samples;
  s.background = o.background;
  s.pageIntervalsLog2 = a.manifest.maxNodeResLog2;
  s.layersPerArray = o.layersPerArray;
  s.minResLog2 = a.manifest.minNodeResLog2;
  s.maxResLog2 = a.manifest.maxNodeResLog2;
  s.spacing = a.manifest.spacing;
  s.validSamples = {a.manifest.samplesX, a.manifest.samplesY};  // {0, 0} for mesh atlases: nothing discarded
  s.heightRange = a.manifest.heightRange;
  s.planet = a.manifest.planet;
  const uint64_t pageBytes = pagePoolPageBytes(s);
  const uint32_t charts = a.hierarchy.chartCount();
  s.pageCapacity = AtlasScene::pagePoolPages(o, charts, pageBytes);
  // The roots stay resident while they fit with room to split one of them; past that, every
  // root gets a stand-in (standInSetup).
  if (o.gpuCacheBytes > 0 && s.pageCapacity < uint64_t(charts) + kRoomToSplit)
    standInSetup(s, o.gpuCacheBytes, charts, o.standInResLog2);
  return s;
}

PageLoaderOptions loaderOptions(const SceneOptions& o, const RendererSetup& setup, const PageReader& pages,
                                uint64_t largestPage) {
  PageLoaderOptions l;
  // The normals' and colours' mips are made on the loader threads, not at upload.
  l.prepare = [setup, &pages](LoadedPage& p) {
    p.mips =
        pagePoolMips(setup, pages.pageSamples(p.id), p.normals.data(), p.colours.empty() ? nullptr : p.colours.data());
  };
  const uint64_t mipBytes = pagePoolMipBytes(setup);
  l.preparedBytes = [mipBytes](const NodeId&) { return size_t(mipBytes); };
  l.ramBytes = o.ramCacheBytes;
  // Pages read ahead of their upload: two frames' worth, within half the RAM.
  const uint64_t frame =
      o.uploadBytesPerFrame > 0 ? o.uploadBytesPerFrame : uint64_t(std::max(o.maxUploadsPerFrame, 1u)) * largestPage;
  l.stagedBytes = size_t(std::max<uint64_t>(std::min<uint64_t>(2 * frame, o.ramCacheBytes / 2), largestPage));
  l.threads = std::max(o.loaderThreads, 1u);
  l.ioLatencyMs = o.ioLatencyMs;
  l.ioJitterMs = o.ioJitterMs;
  l.ioDepth = o.ioDepth;
  l.onFailure = o.onPageFailure;
  return l;
}

}  // namespace

AtlasScene::AtlasScene(const AtlasView& atlas, const SceneOptions& options)
    : atlas_(atlas),
      options_(options),
      pages_(atlas.dir, atlas.manifest, atlas.hierarchy.params),
      renderer_(std::make_unique<AtlasRenderer>(rendererSetup(atlas, options, pages_))),
      pool_(renderer_->pageCapacity()),
      pageBytes_(pagePoolPageBytes(renderer_->setup())) {
  // The roots' pages stay resident (paper 7.2), so every frame can be drawn; pagePoolPages
  // leaves room for them. Where they do not fit, each root gets a stand-in instead.
  if (renderer_->setup().standIns > 0) {
    makeRootStandIns();
  } else {
    assert(atlas_.hierarchy.chartCount() < pool_.capacity());
    for (uint32_t c = 0; c < atlas_.hierarchy.chartCount(); ++c) {
      const NodeId root{c, 0, 0, 0};
      PagePool::Slot slot;
      pool_.acquire(root.key(), frame_, &slot);
      pages_.read(root, samples_, normals_, &colours_);
      upload(slot.layer, root, samples_, normals_, colours_);
      pool_.lock(root.key());
    }
  }
  if (options_.asyncLoads) {
    uint64_t largest = 0;
    for (uint32_t c = 0; c < atlas_.hierarchy.chartCount(); ++c)
      largest = std::max<uint64_t>(largest, pages_.pageBytes({c, 0, 0, 0}));
    largest += pagePoolMipBytes(renderer_->setup());  // a page waits for its upload with its mips
    // A page waiting for its upload and one in the cache at least.
    if (options_.ramCacheBytes < 2 * largest)
      throw InputError("the loader's RAM of " + std::to_string(options_.ramCacheBytes) +
                       " bytes must hold two of the "
                       "atlas's pages, " +
                       std::to_string(2 * largest) + " bytes");
    loader_ = std::make_unique<PageLoader>(pages_, loaderOptions(options_, renderer_->setup(), pages_, largest));
  }
}

void AtlasScene::makeRootStandIns() {
  const RendererSetup& setup = renderer_->setup();
  const uint32_t charts = atlas_.hierarchy.chartCount();
  rootStandIns_.resLog2.assign(charts, 0);
  const size_t channels = setup.geometry ? 3 : 1;
  std::vector<float> samples;
  std::vector<PackedNormal> normals;
  std::vector<PackedColour> colours;
  for (uint32_t c = 0; c < charts; ++c) {
    const NodeId root{c, 0, 0, 0};
    pages_.read(root, samples_, normals_, &colours_);
    // The root at the stand-in's resolution: every stride-th sample, as a node drawn that coarse
    // reads them, so its vertices are the page's bit for bit.
    const uint32_t pageRes = atlas_.hierarchy.maxResLog2(root);
    const uint32_t res = std::min(pageRes, setup.standInIntervalsLog2);
    rootStandIns_.resLog2[c] = uint8_t(res);
    const uint32_t stride = 1u << (pageRes - res), side = (1u << res) + 1, pageSide = (1u << pageRes) + 1;
    samples.resize(size_t(side) * side * channels);
    normals.resize(size_t(side) * side);
    for (uint32_t j = 0; j < side; ++j)
      for (uint32_t i = 0; i < side; ++i) {
        const size_t from = size_t(j) * stride * pageSide + size_t(i) * stride, to = size_t(j) * side + i;
        for (size_t k = 0; k < channels; ++k) samples[to * channels + k] = samples_[from * channels + k];
        normals[to] = normals_[from];
      }
    colours.clear();
    if (!colours_.empty()) {
      const uint32_t cs = setup.colourScaleLog2;
      const uint32_t cSide = ((side - 1) << cs) + 1, cPageSide = ((pageSide - 1) << cs) + 1;
      colours.resize(size_t(cSide) * cSide);
      for (uint32_t j = 0; j < cSide; ++j)
        for (uint32_t i = 0; i < cSide; ++i)
          colours[size_t(j) * cSide + i] = colours_[size_t(j) * stride * cPageSide + size_t(i) * stride];
    }
    renderer_->uploadPage(renderer_->standInPage(c), side, samples.data(), normals.data(),
                          colours.empty() ? nullptr : colours.data());
  }
  standInBytes_ = uint64_t(charts) * standInPageBytes(setup);
}

void AtlasScene::waitForLoads() {
  if (loader_) loader_->waitIdle();
}

bool AtlasScene::predictedView(const Camera& camera, ViewParams* view) const {
  if (!hasLastCamera_ || !(options_.prefetchSeconds > 0.0) || !(options_.frameSeconds > 0.0)) return false;
  // Linear: the eye and the target keep the last frame's motion.
  const double k = options_.prefetchSeconds / options_.frameSeconds;
  Camera ahead = camera;
  ahead.eye += (camera.eye - lastCamera_.eye) * k;
  ahead.target += (camera.target - lastCamera_.target) * k;
  if (ahead.eye == camera.eye && ahead.target == camera.target) return false;  // standing still
  if (glm::length(ahead.target - ahead.eye) <= 0.0) return false;
  *view = viewParams(ahead);
  return true;
}

bool AtlasScene::uploadLoaded(const LoadedPage& pg, uint64_t keepFrom) {
  PagePool::Slot slot;
  if (!pool_.acquire(pg.id.key(), frame_, &slot, keepFrom)) return false;
  if (slot.needsUpload) upload(slot.layer, pg.id, pg.samples, pg.normals, pg.colours, &pg.mips);
  return true;
}

void AtlasScene::upload(uint32_t layer, const NodeId& n, const std::vector<float>& samples,
                        const std::vector<PackedNormal>& normals, const std::vector<PackedColour>& colours,
                        const PageMips* mips) {
  renderer_->uploadPage(layer, pages_.pageSamples(n), samples.data(), normals.data(),
                        colours.empty() ? nullptr : colours.data(), mips);
  uploadBytes_ += pageBytes_;
}

Cut AtlasScene::streamPages(const Cut& desired, const ViewParams& view, const Camera& camera, double prefetchTolPx,
                            uint32_t maxNodes, FrameResult* f) {
  ++frame_;
  frameStarted_ = true;
  const Hierarchy& h = atlas_.hierarchy;
  const std::unordered_set<uint64_t> served = rootsServedByStandIns(desired);
  const auto resident = [&](uint64_t key) { return pool_.contains(key) || served.count(key) != 0; };
  // 1. Touch the resident desired pages, so the uploads below cannot evict them.
  uint32_t residentNow = 0;
  for (const CutNode& n : desired.nodes) {
    PagePool::Slot slot;
    if (!pool_.contains(n.id.key())) continue;
    pool_.acquire(n.id.key(), frame_, &slot);
    ++residentNow;
  }
  // 2. The pages this cut wants, then those of the view predicted ahead (below every page this
  // frame needs); queued requests for anything else are cancelled before they are read.
  const PageRequestPlan plan = planPageRequests(h, desired, resident, {});
  PageRequestPlan ahead;
  ViewParams aheadView;
  if (prefetchTolPx > 0.0 && predictedView(camera, &aheadView)) {
    AdaptOptions o;
    o.tolerancePx = prefetchTolPx;
    o.maxNodes = maxNodes;
    ahead = planPageRequests(h, adaptErrorThreshold(h, aheadView, o), resident, {});
  }
  constexpr double kPrefetchBelow = 1e6;  // request priorities stay below 1e5 (planPageRequests)
  const auto wanted = [&](uint64_t key) { return plan.wanted.count(key) != 0 || ahead.wanted.count(key) != 0; };
  loader_->retainOnly(wanted);
  for (const PageRequest& r : plan.requests) loader_->request(r.id, r.priority);
  uint32_t prefetches = 0;
  for (const PageRequest& r : ahead.requests)
    if (!plan.wanted.count(r.id.key())) loader_->request(r.id, r.priority - kPrefetchBelow), ++prefetches;
  // 3. Upload loaded pages still wanted, within the frame's upload budget; the loader drops the
  // others (they stay in its RAM cache). The pool never evicts a page this frame touched, so a
  // page that finds no layer is dropped too.
  // An upload counts a whole pool page (pagePoolPageBytes), whatever the node's page size; one
  // page a frame at least.
  size_t maxPages = std::max(options_.maxUploadsPerFrame, 1u);
  if (options_.uploadBytesPerFrame > 0)
    maxPages = std::min<size_t>(maxPages, std::max<uint64_t>(options_.uploadBytesPerFrame / pageBytes_, 1));
  uint32_t uploaded = 0;
  // A prefetched page takes a free layer, or one no frame drew from over the prefetch horizon:
  // never one the cut may go back to (it then waits in the loader's RAM cache until needed).
  const uint64_t horizon = uint64_t(std::ceil(options_.prefetchSeconds / std::max(options_.frameSeconds, 1e-6)));
  const uint64_t keepFrom = frame_ > horizon ? frame_ - horizon : 1;
  const auto thisFrame = [&](uint64_t key) { return plan.wanted.count(key) != 0; };
  for (const LoadedPage& pg : loader_->takeCompleted(wanted, maxPages, SIZE_MAX, thisFrame))
    uploaded += uint32_t(uploadLoaded(pg, thisFrame(pg.id.key()) ? 0 : keepFrom));
  if (f) {
    f->pagesRequested = uint32_t(plan.wanted.size());
    f->pagesUploaded = uploaded;
    f->pagesNeeded = uint32_t(desired.nodes.size());
    f->pagesResident = residentNow;
    f->prefetchRequests = prefetches;
  }
  // 4. Every missing node draws as its nearest resident ancestor, stitched.
  return drawableCut(desired, view, resident, f);
}

std::unordered_set<uint64_t> AtlasScene::rootsServedByStandIns(const Cut& desired) const {
  std::unordered_set<uint64_t> served;
  if (rootStandIns_.empty()) return served;
  for (const CutNode& n : desired.nodes) {
    if (n.id.level != 0) continue;
    const uint32_t s = rootStandIns_.resLog2[n.id.chart];
    // Its vertices are the page's at that resolution; its attributes too where it asks no finer.
    const bool attributes = n.texRes != 0 ? n.texRes <= s : s == atlas_.hierarchy.maxResLog2(n.id);
    if (n.resLog2 <= s && attributes) served.insert(n.id.key());
  }
  return served;
}

Cut AtlasScene::drawableCut(const Cut& desired, const ViewParams& view, const ResidentFn& resident, FrameResult* f) {
  ResidentCut drawn = substituteResident(atlas_.hierarchy, desired, view, resident, rootStandIns_);
  assert(drawn.stitchUnfixable == 0 && "stitching constraint needs a split into a non-resident node");
  standIns_.clear();
  if (drawn.nodesSubstituted > 0)
    for (const CutNode& n : drawn.cut.nodes)
      if (desired.find(n.id) < 0 || (n.id.level == 0 && !resident(n.id.key()))) standIns_.insert(n.id.key());
  if (f) {
    f->nodesSubstituted = drawn.nodesSubstituted;
    f->stitchUnfixable = drawn.stitchUnfixable;
    f->rootsOnStandIns = drawn.rootsOnStandIns;
    f->chartsCoarsened = drawn.chartsCoarsened;
  }
  return std::move(drawn.cut);
}

Cut AtlasScene::loadSynchronously(const Cut& desired, const ViewParams& view, FrameResult* f) {
  ++frame_;
  frameStarted_ = true;
  const std::unordered_set<uint64_t> served = rootsServedByStandIns(desired);
  const auto resident = [&](uint64_t key) { return pool_.contains(key) || served.count(key) != 0; };
  for (const CutNode& n : desired.nodes) {
    PagePool::Slot slot;
    if (pool_.contains(n.id.key())) pool_.acquire(n.id.key(), frame_, &slot);  // the reads below keep it
  }
  // The missing pages and their missing ancestors, as the loader would be asked for them (coarser
  // first), while the pool has a layer this frame has not used: a node whose page does not fit
  // then draws as its parent rather than its root.
  std::vector<PageRequest> requests = planPageRequests(atlas_.hierarchy, desired, resident, {}).requests;
  std::stable_sort(requests.begin(), requests.end(),
                   [](const PageRequest& a, const PageRequest& b) { return a.priority > b.priority; });
  syncLoaded_ = 0;
  for (const PageRequest& r : requests) {
    PagePool::Slot slot;
    if (!pool_.acquire(r.id.key(), frame_, &slot)) break;
    if (!slot.needsUpload) continue;
    pages_.read(r.id, samples_, normals_, &colours_);
    upload(slot.layer, r.id, samples_, normals_, colours_);
    ++syncLoaded_;
  }
  return drawableCut(desired, view, resident, f);
}

void AtlasScene::resize(uint32_t width, uint32_t height) {
  renderer_->resize(width, height);
  options_.width = width;
  options_.height = height;
}

glm::dmat4 AtlasScene::viewProjection(const Camera& c) const {
  const double aspect = double(options_.width) / double(options_.height);
  if (!atlas_.manifest.planet.present) return projectionMatrix(c, aspect) * viewMatrix(c);
  const glm::dvec3 a = renderer_->planetAnchor().position;
  Camera r = sceneCamera(c);
  r.eye -= a;
  r.target -= a;
  return reversedProjectionMatrix(r, aspect) * viewMatrix(r);
}

Camera AtlasScene::sceneCamera(const Camera& camera) const {
  if (!atlas_.manifest.planet.present) return camera;
  Camera c = camera;
  c.nearPlane = kPlanetNearPlane;
  c.farPlane = glm::length(c.eye) + atlas_.manifest.planet.radius + std::max(0.0f, atlas_.manifest.heightRange[1]);
  return c;
}

ViewParams AtlasScene::viewParams(const Camera& camera) const {
  const Camera c = sceneCamera(camera);
  ViewParams v = makeViewParams(c, options_.width, options_.height);
  if (atlas_.manifest.planet.present)
    // The sphere within the surface: an ellipsoid's polar radius (it holds the sphere of that radius).
    v.frustum.setHorizon(c.eye, atlas_.manifest.planet.polarRadius() + std::min(0.0f, atlas_.manifest.heightRange[0]));
  return v;
}

void AtlasScene::anchorAt(const Camera& camera) {
  const AtlasManifest& m = atlas_.manifest;
  if (!m.planet.present) return;
  const PlanetFrame frame(m.planet, m.samplesX, m.samplesY);
  const auto g = frame.sampleUnder(camera.eye);
  renderer_->setPlanetAnchor(planetAnchor(frame, g[0], g[1]));
}

glm::dvec3 AtlasScene::captureOrigin() const {
  return atlas_.manifest.planet.present ? renderer_->planetAnchor().position : glm::dvec3(0.0);
}

std::vector<DrawNode> AtlasScene::prepare(const Cut& cut, FrameResult* frame) {
  if (!frameStarted_) ++frame_;
  frameStarted_ = false;
  const auto t0 = std::chrono::steady_clock::now();
  std::vector<DrawNode> nodes;
  nodes.reserve(cut.nodes.size());
  uint32_t loaded = syncLoaded_, missing = 0;
  syncLoaded_ = 0;
  for (const CutNode& n : cut.nodes) {
    PagePool::Slot slot;
    // A root not in the pool, drawn no finer than its stand-in, draws from it.
    if (n.id.level == 0 && !rootStandIns_.empty() && !pool_.contains(n.id.key()) &&
        n.resLog2 <= rootStandIns_.resLog2[n.id.chart]) {
      nodes.push_back(makeDrawNode(atlas_.manifest, atlas_.hierarchy.params, n, renderer_->standInPage(n.id.chart),
                                   rootStandIns_.resLog2[n.id.chart]));
      continue;
    }
    if (pool_.acquire(n.id.key(), frame_, &slot)) {
      if (slot.needsUpload) {
        pages_.read(n.id, samples_, normals_, &colours_);
        upload(slot.layer, n.id, samples_, normals_, colours_);
        ++loaded;
      }
      nodes.push_back(makeDrawNode(atlas_.manifest, atlas_.hierarchy.params, n, slot.layer));
    } else {
      // note: the pool is full this frame; a node cannot borrow an ancestor page yet, so the
      // cut must fit the pool. Count it so callers see it.
      ++missing;
      nodes.push_back(makeDrawNode(atlas_.manifest, atlas_.hierarchy.params, n, 0));
    }
  }
  if (frame) {
    frame->uploadMs = msSince(t0);
    frame->pagesLoaded = loaded;
    frame->pagesMissing = missing;
  }
  return nodes;
}

DrawStats AtlasScene::drawCut(const Camera& camera, const Cut& cut, FrameResult* frame) {
  auto t0 = std::chrono::steady_clock::now();
  const StitchTables stitch = buildStitchTables(atlas_.hierarchy, cut);
  if (frame) frame->stitchMs = msSince(t0);
  const std::vector<DrawNode> nodes = prepare(cut, frame);
  // The overlay records: the colouring's, and the stand-in flags for the "pages loading" view.
  const bool colourNodes = options_.overlay != OverlayMode::kNone;
  std::vector<NodeOverlay> records = colourNodes ? nodeOverlays(atlas_.hierarchy, cut, options_.overlay,
                                                                options_.overlayColour, options_.overlayErrorPx)
                                                 : std::vector<NodeOverlay>();
  if (renderer_->inspectionViews().loading && !standIns_.empty()) {
    records.resize(cut.nodes.size());
    for (size_t i = 0; i < cut.nodes.size(); ++i)
      if (standIns_.count(cut.nodes[i].id.key())) records[i].flags |= kOverlayStandIn;
  }
  renderer_->setOverlay(std::move(records), colourNodes);
  anchorAt(camera);
  const DrawStats stats =
      renderer_->draw(glm::mat4(viewProjection(camera)), glm::vec3(camera.eye - captureOrigin()), nodes, stitch);
  renderer_->setOverlay({});
  return stats;
}

namespace {

// AtlasScene::nodeRoom of a pool of `pages` with `roots` locked: 3/4 of the other pages. Every
// node of a cut but the locked roots may need a page, the culled roots do not make room for more
// (a view of one chart of many may split it as deep as the pages allow), and the stitching
// constraint may add nodes past the budget; 3/4 also holds a cut's ancestors (a quadtree cut of N
// nodes has at most N/3), which the loaders ask for so that a missing node draws as its parent.
uint32_t nodeRoomOf(uint32_t pages, uint32_t roots) { return (pages - std::min(pages, roots)) * 3 / 4; }

}  // namespace

uint32_t AtlasScene::pagePoolPages(const SceneOptions& o, uint32_t charts, uint64_t pageBytes) {
  if (o.gpuCacheBytes > 0 && pageBytes > 0)
    return uint32_t(std::min<uint64_t>(o.gpuCacheBytes / pageBytes, UINT32_MAX));
  const uint64_t want = std::max<uint64_t>(o.pageCapacity, 1);
  uint64_t pages = charts < want / 2 ? want : uint64_t(charts) + std::max<uint64_t>(want / 2, 1);
  // F = 4/3 N + 4 free pages hold cuts of N nodes (nodeRoomOf(R + F, R) >= N).
  if (o.minNodeRoom > 0) pages = std::max(pages, uint64_t(charts) + (4 * uint64_t(o.minNodeRoom) + 2) / 3 + 4);
  return uint32_t(std::min<uint64_t>(pages, UINT32_MAX));
}

uint32_t AtlasScene::nodeRoom() const {
  // With stand-ins no page is locked.
  return nodeRoomOf(pool_.capacity(), rootStandIns_.empty() ? atlas_.hierarchy.chartCount() : 0);
}

uint32_t AtlasScene::nodeBudget(uint32_t maxNodes) const {
  const uint32_t room = nodeRoom();
  return maxNodes == 0 || maxNodes > room ? room : maxNodes;
}

FrameResult AtlasScene::renderFrame(const Camera& camera, const AdaptOptions& options) {
  FrameResult f;
  const auto t0 = std::chrono::steady_clock::now();
  const ViewParams view = viewParams(camera);
  AdaptOptions o = options;
  o.maxNodes = nodeBudget(options.maxNodes);
  if (options_.coherentAdaptation) {
    if (!dualQueue_) dualQueue_ = std::make_unique<DualQueueAdapter>(atlas_.hierarchy);
    f.cut = dualQueue_->update(view, o, &f.adapt);
  } else {
    f.cut = adaptErrorThreshold(atlas_.hierarchy, view, o, &f.adapt);
  }
  finishFrame(camera, view, o.tolerancePx, o.maxNodes, f, t0);
  return f;
}

FrameResult AtlasScene::renderFrame(const Camera& camera, const BudgetOptions& options) {
  FrameResult f;
  const auto t0 = std::chrono::steady_clock::now();
  const ViewParams view = viewParams(camera);
  BudgetOptions o = options;
  o.maxNodes = nodeBudget(options.maxNodes);
  if (!quadQueue_) quadQueue_ = std::make_unique<QuadQueueAdapter>(atlas_.hierarchy);
  f.cut = quadQueue_->update(view, o, &f.budget);
  f.adapt.splits = f.budget.splits;
  f.adapt.constraintRaises = f.budget.constraintRaises;
  f.adapt.constraintSplits = f.budget.constraintSplits;
  f.adapt.maxErrorPx = f.budget.maxErrorPx;
  f.adapt.triangles = f.budget.triangles;
  f.adapt.nodeBudgetBound = f.budget.nodes >= o.maxNodes;
  f.adapt.rootFloor = f.budget.rootFloor;
  f.adapt.budgetBelowRoots = f.budget.budgetBelowRoots;
  f.adapt.nodes = f.budget.nodes;
  f.adapt.closedGroups = f.budget.closedGroups;
  f.adapt.groupedRoots = f.budget.groupedRoots;
  // Prefetch and geomorphs: at the error this frame reached.
  finishFrame(camera, view, std::max(f.budget.maxErrorPx, 0.25), o.maxNodes, f, t0);
  return f;
}

void AtlasScene::finishFrame(const Camera& camera, const ViewParams& view, double tolPx, uint32_t maxNodes,
                             FrameResult& f, std::chrono::steady_clock::time_point t0) {
  const Hierarchy& h = atlas_.hierarchy;
  uploadBytes_ = 0;
  if (options_.texelsPerPixel > 0.0) {
    f.attributes = assignAttributeResolutions(h, f.cut, view, options_.texelsPerPixel);
    if (!options_.blendAttributes)
      for (CutNode& n : f.cut.nodes) n.texBlend = 0.f;
  }
  // Front to back, so early depth testing rejects hidden fragments.
  auto distance2 = [&](const CutNode& n) {
    const auto& b = h.bounds(n.id);
    const glm::dvec3 c{0.5 * (b[0] + b[3]), 0.5 * (b[1] + b[4]), 0.5 * (b[2] + b[5])};
    const glm::dvec3 d = c - camera.eye;
    return glm::dot(d, d);
  };
  std::sort(f.cut.nodes.begin(), f.cut.nodes.end(),
            [&](const CutNode& a, const CutNode& b) { return distance2(a) < distance2(b); });
  f.cut.rebuildIndex();
  f.adaptMs = msSince(t0);
  // Page requests, uploads and ancestor substitution count as upload time.
  const auto t1 = std::chrono::steady_clock::now();
  if (loader_) {
    f.desiredCut = std::move(f.cut);
    f.cut = streamPages(f.desiredCut, view, camera, tolPx, maxNodes, &f);
  } else if (!rootStandIns_.empty()) {
    f.desiredCut = std::move(f.cut);
    f.cut = loadSynchronously(f.desiredCut, view, &f);
  } else {
    standIns_.clear();
  }
  const double substituteMs = msSince(t1);
  f.maxErrorPx = 0.0;
  for (CutNode& n : f.cut.nodes) {
    // The adapters set errorPx; substitution changes nodes and resolutions.
    if (!f.desiredCut.nodes.empty()) n.errorPx = float(screenError(h, n.id, n.resLog2, view));
    f.maxErrorPx = std::max(f.maxErrorPx, double(n.errorPx));
    if (options_.geomorph > 0.0) n.morph = float(geomorphFactor(h, n, view, tolPx, options_.geomorph));
  }
  f.draw = drawCut(camera, f.cut, &f);
  f.uploadMs += substituteMs;
  // What the caches hold now, and this frame's loads.
  f.residentGpuBytes = uint64_t(pool_.resident()) * pageBytes_ + standInBytes_;
  f.gpuBudgetBytes = uint64_t(pool_.capacity()) * pageBytes_ + standInBytes_;
  f.uploadBytes = uploadBytes_;
  if (loader_) {
    const PageLoaderStats s = loader_->stats();
    f.residentRamBytes = s.ramBytes + s.stagedBytes;
    f.loadsIssued = uint32_t(s.requested - lastLoads_.requested);
    f.loadsDone = uint32_t(s.loadedFromDisk + s.ramHits - lastLoads_.loadedFromDisk - lastLoads_.ramHits);
    f.loadsCancelled = uint32_t(s.cancelled - lastLoads_.cancelled);
    f.loadsFailed = uint32_t(s.failed - lastLoads_.failed);
    lastLoads_ = s;
  } else {
    f.pagesNeeded = uint32_t(f.desiredCut.nodes.empty() ? f.cut.nodes.size() : f.desiredCut.nodes.size());
    f.pagesResident = f.pagesNeeded - std::min(f.pagesNeeded, f.pagesLoaded);
  }
  f.incomplete = f.pagesMissing > 0 || f.stitchUnfixable > 0;
  lastCamera_ = camera;
  hasLastCamera_ = true;
}

std::vector<std::vector<glm::vec3>> AtlasScene::capture(const Cut& cut, bool stitchOn) {
  StitchTables stitch = buildStitchTables(atlas_.hierarchy, cut);
  if (!stitchOn) std::fill(stitch.bytes.begin(), stitch.bytes.end(), uint8_t(0));
  const std::vector<DrawNode> nodes = prepare(cut, nullptr);
  return renderer_->captureVertices(nodes, stitch);
}

}  // namespace gimlod::gl
