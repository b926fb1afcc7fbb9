// Throughput baselines for the render benchmarks, drawn into an AtlasRenderer's framebuffer with
// its frame setup and shading: plain static meshes with no texture fetch and no stitching, so
// only the vertex path differs from the atlas draw. Needs a current GL context.
#pragma once

#include <cstdint>
#include <span>

#include <glm/glm.hpp>

#include "runtime/gl/atlas_renderer.h"
#include "runtime/gl/gl_objects.h"

namespace gimlod::bench {

class BaselineDraws {
 public:
  // Links the baseline programs; `renderer` must outlive this and its context be current.
  explicit BaselineDraws(gl::AtlasRenderer& renderer);

  // Draws one static indexed mesh with about `triangles` triangles (a plain VBO of positions, no
  // texture fetch, flat-shaded by height) `frames` times; returns ms per frame. Writes the
  // triangles actually drawn to drawnTriangles (may be null).
  double drawStaticMeshMs(uint64_t triangles, uint32_t frames, uint64_t* drawnTriangles);

  // Baseline at equal work: draws one static indexed triangle mesh (plain positions, one draw,
  // no texture fetch or stitching) with the atlas fragment shader (terrain), from the given
  // camera, `frames` times; returns ms per frame (submission + glFinish, as AtlasRenderer::draw).
  double drawMeshMs(std::span<const glm::vec3> positions, std::span<const uint32_t> triangles,
                    const glm::mat4& viewProj, const glm::vec3& eye, uint32_t frames);

 private:
  gl::AtlasRenderer& renderer_;
  gl::GlObject staticProgram_, staticTerrainProgram_;
};

}  // namespace gimlod::bench
