// OpenGL 4.3 terrain renderer: reusable (u,v) grids drawn as strips, heights by vertex texture
// fetch from a page pool (texture array), GPU border stitching (paper section 7.4), normal
// maps in the fragment shader, and transform-feedback capture of the stitched positions.
// Needs a current GL context (see egl_context.h).
#pragma once

#include <array>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include <glm/glm.hpp>

#include "core/atlas_format.h"
#include "runtime/draw_list.h"

namespace gimlod::gl {

struct RendererSetup {
  uint32_t width = 640, height = 480;          // offscreen framebuffer size
  std::array<float, 3> background{0.53f, 0.70f, 0.92f};
  uint32_t pageIntervalsLog2 = 6;              // page side = 2^this + 1 samples (= log2 R)
  uint32_t pageCapacity = 1024;                // layers in the page pool
  uint32_t minResLog2 = 0, maxResLog2 = 6;     // grids are built for these resolutions
  std::array<double, 2> spacing{1.0, 1.0};     // metres between samples (x, y)
  std::array<uint32_t, 2> validSamples{0, 0};  // fragments with gx > X-1 or gy > Y-1 are discarded
  std::array<float, 2> heightRange{0.f, 1.f};  // for colouring
  // Geometry images (mesh atlases): pages hold x, y, z per sample (3 floats) instead of a height,
  // and the vertex shader takes the position from the page; stitching is the same.
  bool geometry = false;
};

struct DrawStats {
  double drawMs = 0.0;     // CPU wall time of submission + glFinish
  uint64_t triangles = 0;  // triangles submitted (grids, excluding strip degenerates)
  uint32_t drawCalls = 0;  // GL draw calls issued (one multi-draw for the whole cut)
};

// Mip `level` (>= 1) of a page's normal map of samplesPerSide^2 texels in a pageSide^2 pool layer:
// each texel is the renormalised mean of the level-0 texels it covers. Writes side^2 normals
// (row-major) to out and returns side, the texels of that level that cover the page's data.
uint32_t normalMipLevel(const PackedNormal* normals, uint32_t samplesPerSide, uint32_t pageSide, uint32_t level,
                        std::vector<PackedNormal>& out);

class TerrainRenderer {
 public:
  explicit TerrainRenderer(const RendererSetup& setup);
  ~TerrainRenderer();
  TerrainRenderer(const TerrainRenderer&) = delete;
  TerrainRenderer& operator=(const TerrainRenderer&) = delete;

  uint32_t pageCapacity() const;
  // Uploads one node page: (n+1)^2 heights and normals, n = 2^pageIntervalsLog2 at most.
  // Smaller pages (deep nodes) occupy the lower-left corner of the layer.
  // The normals also get their mip chain (normalMipLevel), for DrawNode::texLod. With
  // RendererSetup::geometry, `heights` holds 3 floats (x, y, z) per sample.
  void uploadPage(uint32_t layer, uint32_t samplesPerSide, const float* heights,
                  const PackedNormal* normals);

  // Draws the nodes into the offscreen framebuffer (clears first) and waits for completion.
  DrawStats draw(const glm::mat4& viewProj, const glm::vec3& eye, std::span<const DrawNode> nodes,
                 const StitchTables& stitch);

  // Reads the framebuffer as RGBA8, top row first.
  std::vector<uint8_t> readPixels() const;

  // Runs the same vertex shader with transform feedback and returns, per node, the stitched
  // world position of every grid vertex, index j * (2^res + 1) + i.
  std::vector<std::vector<glm::vec3>> captureVertices(std::span<const DrawNode> nodes,
                                                      const StitchTables& stitch);

  // Baseline for throughput: draws one static indexed mesh with about `triangles` triangles
  // (a plain VBO of positions, no texture fetch) `frames` times; returns ms per frame.
  double drawStaticMeshMs(uint64_t triangles, uint32_t frames, uint64_t* drawnTriangles);

  // Baseline at equal work: draws one static indexed triangle mesh (plain positions, one draw,
  // no texture fetch or stitching) with the terrain fragment shader, from the given camera,
  // `frames` times; returns ms per frame (submission + glFinish, as draw()).
  double drawMeshMs(std::span<const glm::vec3> positions, std::span<const uint32_t> triangles,
                    const glm::mat4& viewProj, const glm::vec3& eye, uint32_t frames);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace gimlod::gl
