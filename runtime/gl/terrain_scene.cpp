#include "runtime/gl/terrain_scene.h"

#include <algorithm>
#include <chrono>
#include <stdexcept>

namespace gimlod::gl {
namespace {

double msSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
}

RendererSetup rendererSetup(const AtlasView& a, const SceneOptions& o) {
  RendererSetup s;
  s.width = o.width;
  s.height = o.height;
  s.background = o.background;
  s.pageIntervalsLog2 = a.manifest.maxNodeResLog2;
  s.pageCapacity = o.pageCapacity;
  s.minResLog2 = a.manifest.minNodeResLog2;
  s.maxResLog2 = a.manifest.maxNodeResLog2;
  s.spacing = a.manifest.spacing;
  s.validSamples = {a.manifest.samplesX, a.manifest.samplesY};
  s.heightRange = a.manifest.heightRange;
  return s;
}

}  // namespace

TerrainScene::TerrainScene(const AtlasView& atlas, const SceneOptions& options)
    : atlas_(atlas),
      options_(options),
      renderer_(std::make_unique<TerrainRenderer>(rendererSetup(atlas, options))),
      pages_(atlas.dir, atlas.manifest, atlas.hierarchy.params),
      cache_(renderer_->pageCapacity()) {
  // The roots' pages stay resident (paper 7.2), so every frame can be drawn.
  if (atlas_.hierarchy.chartCount() > cache_.capacity())
    throw std::runtime_error("page pool too small for the root pages of every chart");
  for (uint32_t c = 0; c < atlas_.hierarchy.chartCount(); ++c) {
    const NodeId root{c, 0, 0, 0};
    PageCache::Slot slot;
    cache_.acquire(root.key(), frame_, &slot);
    pages_.read(root, heights_, normals_);
    renderer_->uploadPage(slot.layer, pages_.pageSamples(0), heights_.data(), normals_.data());
    cache_.lock(root.key());
  }
}

glm::dmat4 TerrainScene::viewProjection(const Camera& c) const {
  return projectionMatrix(c, double(options_.width) / double(options_.height)) * viewMatrix(c);
}

std::vector<DrawNode> TerrainScene::prepare(const Cut& cut, FrameResult* frame) {
  ++frame_;
  const auto t0 = std::chrono::steady_clock::now();
  std::vector<DrawNode> nodes;
  nodes.reserve(cut.nodes.size());
  uint32_t loaded = 0, missing = 0;
  for (const CutNode& n : cut.nodes) {
    PageCache::Slot slot;
    if (cache_.acquire(n.id.key(), frame_, &slot)) {
      if (slot.needsUpload) {
        pages_.read(n.id, heights_, normals_);
        renderer_->uploadPage(slot.layer, pages_.pageSamples(n.id.level), heights_.data(),
                              normals_.data());
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

DrawStats TerrainScene::drawCut(const Camera& camera, const Cut& cut, FrameResult* frame) {
  auto t0 = std::chrono::steady_clock::now();
  const StitchTables stitch = buildStitchTables(atlas_.hierarchy, cut);
  if (frame) frame->stitchMs = msSince(t0);
  const std::vector<DrawNode> nodes = prepare(cut, frame);
  return renderer_->draw(glm::mat4(viewProjection(camera)), glm::vec3(camera.eye), nodes, stitch);
}

FrameResult TerrainScene::renderFrame(const Camera& camera, const AdaptOptions& options) {
  FrameResult f;
  const auto t0 = std::chrono::steady_clock::now();
  const ViewParams view = makeViewParams(camera, options_.width, options_.height);
  // Keep the cut within the page pool: the roots are locked, and the stitching constraint may
  // add a few nodes beyond the budget.
  AdaptOptions o = options;
  const uint32_t room = (cache_.capacity() - atlas_.hierarchy.chartCount()) * 3 / 4;
  if (o.maxNodes == 0 || o.maxNodes > room) o.maxNodes = room;
  f.cut = adaptErrorThreshold(atlas_.hierarchy, view, o, &f.adapt);
  // Front to back, so early depth testing rejects hidden fragments.
  const Hierarchy& h = atlas_.hierarchy;
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
  f.draw = drawCut(camera, f.cut, &f);
  return f;
}

std::vector<std::vector<glm::vec3>> TerrainScene::capture(const Cut& cut, bool stitchOn) {
  StitchTables stitch = buildStitchTables(atlas_.hierarchy, cut);
  if (!stitchOn) std::fill(stitch.bytes.begin(), stitch.bytes.end(), uint8_t(0));
  const std::vector<DrawNode> nodes = prepare(cut, nullptr);
  return renderer_->captureVertices(nodes, stitch);
}

}  // namespace gimlod::gl
