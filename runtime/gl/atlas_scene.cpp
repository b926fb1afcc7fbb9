#include "runtime/gl/atlas_scene.h"

#include <algorithm>
#include <cassert>
#include <chrono>
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

RendererSetup rendererSetup(const AtlasView& a, const SceneOptions& o, const PageReader& pages) {
  RendererSetup s;
  s.geometry = a.manifest.kind == AtlasKind::Geometry;
  s.colours = pages.colours();
  s.colourScaleLog2 = pages.colourScaleLog2();
  s.width = o.width;
  s.height = o.height;
  s.background = o.background;
  s.pageIntervalsLog2 = a.manifest.maxNodeResLog2;
  s.pageCapacity = AtlasScene::pagePoolPages(o, a.hierarchy.chartCount(), !a.hierarchy.groups.empty());
  s.layersPerArray = o.layersPerArray;
  s.minResLog2 = a.manifest.minNodeResLog2;
  s.maxResLog2 = a.manifest.maxNodeResLog2;
  s.spacing = a.manifest.spacing;
  s.validSamples = {a.manifest.samplesX, a.manifest.samplesY};  // {0, 0} for mesh atlases: nothing discarded
  s.heightRange = a.manifest.heightRange;
  return s;
}

}  // namespace

AtlasScene::AtlasScene(const AtlasView& atlas, const SceneOptions& options)
    : atlas_(atlas),
      options_(options),
      pages_(atlas.dir, atlas.manifest, atlas.hierarchy.params),
      renderer_(std::make_unique<AtlasRenderer>(rendererSetup(atlas, options, pages_))),
      pool_(renderer_->pageCapacity()) {
  // The roots' pages stay resident (paper 7.2), so every frame can be drawn; pagePoolPages
  // leaves room for them.
  assert(atlas_.hierarchy.chartCount() < pool_.capacity());
  for (uint32_t c = 0; c < atlas_.hierarchy.chartCount(); ++c) {
    const NodeId root{c, 0, 0, 0};
    PagePool::Slot slot;
    pool_.acquire(root.key(), frame_, &slot);
    pages_.read(root, samples_, normals_, &colours_);
    renderer_->uploadPage(slot.layer, pages_.pageSamples(root), samples_.data(), normals_.data(),
                          colours_.empty() ? nullptr : colours_.data());
    pool_.lock(root.key());
  }
  if (options_.asyncLoads)
    loader_ = std::make_unique<PageLoader>(pages_, options_.ramCacheBytes);
}

void AtlasScene::waitForLoads() {
  if (loader_) loader_->waitIdle();
}

Cut AtlasScene::streamPages(const Cut& desired, const ViewParams& view, FrameResult* f) {
  ++frame_;
  frameStarted_ = true;
  const auto resident = [this](uint64_t key) { return pool_.contains(key); };
  // 1. Touch the resident desired pages, so the uploads below cannot evict them; request the
  // others. Requests for nodes no longer in the cut are dropped.
  loader_->cancelPending();
  std::unordered_set<uint64_t> ready;
  for (const LoadedPage& pg : ready_) ready.insert(pg.id.key());
  for (const CutNode& n : desired.nodes) {
    PagePool::Slot slot;
    if (pool_.contains(n.id.key())) pool_.acquire(n.id.key(), frame_, &slot);
  }
  const PageRequestPlan plan = planPageRequests(atlas_.hierarchy, desired, resident, ready);
  for (const PageRequest& r : plan.requests) loader_->request(r.id, r.priority);
  // 2. Upload a bounded number of loaded pages that this cut still wants; the rest of the wanted
  // ones wait for later frames, unwanted ones are dropped (they stay in the RAM cache).
  for (LoadedPage& pg : loader_->takeCompleted(std::numeric_limits<size_t>::max()))
    ready_.push_back(std::move(pg));
  uint32_t uploaded = 0;
  std::vector<LoadedPage> keep;
  for (LoadedPage& pg : ready_) {
    if (!plan.wanted.count(pg.id.key())) continue;
    if (uploaded >= options_.maxUploadsPerFrame) {
      keep.push_back(std::move(pg));
      continue;
    }
    PagePool::Slot slot;
    // note: when the pool is full this frame the page is dropped; it stays in the RAM cache.
    if (!pool_.acquire(pg.id.key(), frame_, &slot) || !slot.needsUpload) continue;
    renderer_->uploadPage(slot.layer, pages_.pageSamples(pg.id), pg.samples.data(), pg.normals.data(),
                          pg.colours.empty() ? nullptr : pg.colours.data());
    ++uploaded;
  }
  ready_.swap(keep);
  // 3. Every missing node draws as its nearest resident ancestor, stitched.
  ResidentCut drawn = substituteResident(atlas_.hierarchy, desired, view, resident);
  assert(drawn.stitchUnfixable == 0 && "stitching constraint needs a split into a non-resident node");
  standIns_.clear();
  if (drawn.nodesSubstituted > 0)
    for (const CutNode& n : drawn.cut.nodes)
      if (desired.find(n.id) < 0) standIns_.insert(n.id.key());
  if (f) {
    f->pagesRequested = uint32_t(plan.wanted.size());
    f->pagesUploaded = uploaded;
    f->nodesSubstituted = drawn.nodesSubstituted;
    f->stitchUnfixable = drawn.stitchUnfixable;
  }
  return std::move(drawn.cut);
}

void AtlasScene::resize(uint32_t width, uint32_t height) {
  renderer_->resize(width, height);
  options_.width = width;
  options_.height = height;
}

glm::dmat4 AtlasScene::viewProjection(const Camera& c) const {
  return projectionMatrix(c, double(options_.width) / double(options_.height)) * viewMatrix(c);
}

std::vector<DrawNode> AtlasScene::prepare(const Cut& cut, FrameResult* frame) {
  if (!frameStarted_) ++frame_;
  frameStarted_ = false;
  const auto t0 = std::chrono::steady_clock::now();
  std::vector<DrawNode> nodes;
  nodes.reserve(cut.nodes.size());
  uint32_t loaded = 0, missing = 0;
  for (const CutNode& n : cut.nodes) {
    PagePool::Slot slot;
    if (pool_.acquire(n.id.key(), frame_, &slot)) {
      if (slot.needsUpload) {
        pages_.read(n.id, samples_, normals_, &colours_);
        renderer_->uploadPage(slot.layer, pages_.pageSamples(n.id), samples_.data(), normals_.data(),
                              colours_.empty() ? nullptr : colours_.data());
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
  std::vector<NodeOverlay> records =
      colourNodes ? nodeOverlays(atlas_.hierarchy, cut, options_.overlay, options_.overlayColour, options_.overlayErrorPx)
                  : std::vector<NodeOverlay>();
  if (renderer_->inspectionViews().loading && !standIns_.empty()) {
    records.resize(cut.nodes.size());
    for (size_t i = 0; i < cut.nodes.size(); ++i)
      if (standIns_.count(cut.nodes[i].id.key())) records[i].flags |= kOverlayStandIn;
  }
  renderer_->setOverlay(std::move(records), colourNodes);
  const DrawStats stats = renderer_->draw(glm::mat4(viewProjection(camera)), glm::vec3(camera.eye), nodes, stitch);
  renderer_->setOverlay({});
  return stats;
}

namespace {

// AtlasScene::nodeRoom of a pool of `pages` with `roots` locked. grouped: the hierarchy has
// groups above the charts (hierarchy/root_groups.h); a closed group's roots count once against the
// budget, so only the bound by the free pages holds (every non-root node counts against the budget).
uint32_t nodeRoomOf(uint32_t pages, uint32_t roots, bool grouped) {
  const uint32_t free = (pages - roots) * 3 / 4;
  return grouped ? free : std::max(free, roots + free * 3 / 4);
}

}  // namespace

uint32_t AtlasScene::pagePoolPages(const SceneOptions& o, uint32_t charts, bool grouped) {
  const uint64_t want = std::max<uint64_t>(o.pageCapacity, 1);
  uint64_t pages = charts < want / 2 ? want : uint64_t(charts) + std::max<uint64_t>(want / 2, 1);
  // With groups, F = 4/3 N + 4 free pages hold cuts of N nodes (nodeRoomOf(R + F, R, true) >= N).
  if (grouped && o.minNodeRoom > 0) {
    const uint64_t n = o.minNodeRoom;
    return uint32_t(std::min<uint64_t>(std::max(pages, uint64_t(charts) + (4 * n + 2) / 3 + 4), UINT32_MAX));
  }
  // nodeRoomOf(R + F, R) >= R + 9/16 F - 2, so F = 16/9 (N - R) + 4 free pages hold cuts of N
  // nodes (with N <= R any pool does: the room is at least the roots).
  if (o.minNodeRoom > charts) {
    const uint64_t n = o.minNodeRoom;
    pages = std::max(pages, uint64_t(charts) + (16 * (n - charts) + 8) / 9 + 4);
  }
  return uint32_t(std::min<uint64_t>(pages, UINT32_MAX));
}

uint32_t AtlasScene::nodeRoom() const {
  // Keep the cut's pages within the pool. The roots' pages are locked, so the cut's other nodes
  // must fit in the rest, `free` (3/4 of it: the stitching constraint may add nodes past the
  // budget). A cut of at most `free` nodes does; so does one of at most roots + 3/4 free: each
  // split root leaves the cut but puts >= 4 nodes in it, so with k roots split the non-root nodes
  // N satisfy 4k <= N <= 3/4 free + k, hence k <= free / 4 and N <= free. The second bound is
  // the larger one for atlases of many charts (a scan's hundreds), where the first would leave
  // almost no room to split.
  return nodeRoomOf(pool_.capacity(), atlas_.hierarchy.chartCount(), !atlas_.hierarchy.groups.empty());
}

uint32_t AtlasScene::nodeBudget(uint32_t maxNodes) const {
  const uint32_t room = nodeRoom();
  return maxNodes == 0 || maxNodes > room ? room : maxNodes;
}

FrameResult AtlasScene::renderFrame(const Camera& camera, const AdaptOptions& options) {
  FrameResult f;
  const auto t0 = std::chrono::steady_clock::now();
  const ViewParams view = makeViewParams(camera, options_.width, options_.height);
  AdaptOptions o = options;
  o.maxNodes = nodeBudget(options.maxNodes);
  if (options_.coherentAdaptation) {
    if (!dualQueue_) dualQueue_ = std::make_unique<DualQueueAdapter>(atlas_.hierarchy);
    f.cut = dualQueue_->update(view, o, &f.adapt);
  } else {
    f.cut = adaptErrorThreshold(atlas_.hierarchy, view, o, &f.adapt);
  }
  finishFrame(camera, view, f, t0);
  return f;
}

FrameResult AtlasScene::renderFrame(const Camera& camera, const BudgetOptions& options) {
  FrameResult f;
  const auto t0 = std::chrono::steady_clock::now();
  const ViewParams view = makeViewParams(camera, options_.width, options_.height);
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
  finishFrame(camera, view, f, t0);
  return f;
}

void AtlasScene::finishFrame(const Camera& camera, const ViewParams& view, FrameResult& f,
                               std::chrono::steady_clock::time_point t0) {
  const Hierarchy& h = atlas_.hierarchy;
  if (options_.texelsPerPixel > 0.0)
    f.attributes = assignAttributeResolutions(h, f.cut, view, options_.texelsPerPixel);
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
    f.cut = streamPages(f.desiredCut, view, &f);
  } else {
    standIns_.clear();
  }
  const double substituteMs = msSince(t1);
  f.maxErrorPx = 0.0;
  for (CutNode& n : f.cut.nodes) {
    // The adapters set errorPx; substitution changes nodes and resolutions.
    if (loader_) n.errorPx = float(screenError(h, n.id, n.res, view));
    f.maxErrorPx = std::max(f.maxErrorPx, double(n.errorPx));
  }
  f.draw = drawCut(camera, f.cut, &f);
  f.uploadMs += substituteMs;
}

std::vector<std::vector<glm::vec3>> AtlasScene::capture(const Cut& cut, bool stitchOn) {
  StitchTables stitch = buildStitchTables(atlas_.hierarchy, cut);
  if (!stitchOn) std::fill(stitch.bytes.begin(), stitch.bytes.end(), uint8_t(0));
  const std::vector<DrawNode> nodes = prepare(cut, nullptr);
  return renderer_->captureVertices(nodes, stitch);
}

}  // namespace gimlod::gl
