// One frame of terrain rendering: adapt (runtime core), build stitching tables, make the cut's
// pages resident in the GPU page pool, and draw. Also the transform-feedback capture used by the
// crack tests. Needs a current GL context.
#pragma once

#include <memory>
#include <vector>

#include "runtime/adapt.h"
#include "runtime/atlas_view.h"
#include "runtime/gl/renderer.h"
#include "runtime/page_cache.h"
#include "runtime/stitch.h"

namespace gimlod::gl {

struct SceneOptions {
  uint32_t width = 640, height = 480;
  std::array<float, 3> background{0.53f, 0.70f, 0.92f};
  uint32_t pageCapacity = 4096;  // GPU page pool layers (clamped by the GL limit)
};

struct FrameResult {
  Cut cut;
  AdaptStats adapt;
  DrawStats draw;
  double adaptMs = 0.0, stitchMs = 0.0, uploadMs = 0.0;
  uint32_t pagesLoaded = 0;
  uint32_t pagesMissing = 0;  // nodes drawn with an ancestor's page because the pool was full
};

class TerrainScene {
 public:
  TerrainScene(const AtlasView& atlas, const SceneOptions& options);
  const AtlasView& atlas() const { return atlas_; }
  TerrainRenderer& renderer() { return *renderer_; }

  // Adapts to the camera and draws; the picture is then in renderer().readPixels().
  FrameResult renderFrame(const Camera& camera, const AdaptOptions& options);
  // Draws a given cut (stitching constraint already enforced).
  DrawStats drawCut(const Camera& camera, const Cut& cut, FrameResult* frame = nullptr);
  // Stitched world positions of every vertex of every cut node, from the real vertex shader.
  // stitch = false zeroes the stitching tables (a negative control for the crack tests).
  std::vector<std::vector<glm::vec3>> capture(const Cut& cut, bool stitch = true);

  glm::dmat4 viewProjection(const Camera& camera) const;

 private:
  std::vector<DrawNode> prepare(const Cut& cut, FrameResult* frame);
  AtlasView atlas_;
  SceneOptions options_;
  std::unique_ptr<TerrainRenderer> renderer_;
  AtlasPages pages_;
  PageCache cache_;
  uint64_t frame_ = 0;
  std::vector<float> heights_;
  std::vector<PackedNormal> normals_;
};

}  // namespace gimlod::gl
