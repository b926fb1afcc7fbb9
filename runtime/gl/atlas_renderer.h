// OpenGL 4.3 renderer of terrain (height) and mesh (geometry image) atlases: reusable (u,v) grids
// drawn as strips, heights or positions by vertex texture fetch from a page pool (texture array),
// GPU border stitching (paper section 7.4), normal maps in the fragment shader, and
// transform-feedback capture of the stitched positions.
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
#include "runtime/normal_mips.h"
#include "runtime/overlay.h"

namespace gimlod::gl {

struct RendererSetup {
  uint32_t width = 640, height = 480;  // offscreen framebuffer size
  uint32_t samples = 1;                // samples per pixel (multisampling); 1: none
  std::array<float, 3> background{0.53f, 0.70f, 0.92f};
  uint32_t pageIntervalsLog2 = 6;  // page side = 2^this + 1 samples (= log2 R)
  // Pages in the page pool. A texture array holds at most GL_MAX_ARRAY_TEXTURE_LAYERS (2048 on
  // Mesa and NVIDIA), so the pool is as many arrays as it takes: page p is layer p % L of array
  // p / L, and a cut whose pages lie in k arrays is k multi-draws (one per array, whose textures
  // are bound for it).
  uint32_t pageCapacity = 1024;
  uint32_t layersPerArray = 0;                 // L; 0: the GL limit (smaller values are for tests)
  uint32_t minResLog2 = 0, maxResLog2 = 6;     // grids are built for these resolutions
  std::array<double, 2> spacing{1.0, 1.0};     // metres between samples (x, y)
  std::array<uint32_t, 2> validSamples{0, 0};  // fragments with gx > X-1 or gy > Y-1 are discarded
  std::array<float, 2> heightRange{0.f, 1.f};  // for colouring
  // Geometry images (mesh atlases): pages hold x, y, z per sample (3 floats) instead of a height,
  // and the vertex shader takes the position from the page; stitching is the same.
  bool geometry = false;
  // Pages also carry RGBA8 colours with mips: a mesh's vertex colours (read at each node's
  // attribute resolution like the normals), drawn instead of the neutral material; or terrain
  // imagery, drawn over the height colouring where its alpha covers.
  bool colours = false;
  // Colour texels per page sample interval, log2: a colour page has ((side - 1) << this) + 1
  // texels per side (terrain imagery finer than the heights; 0 for meshes).
  uint32_t colourScaleLog2 = 0;
  // Root stand-ins: `standIns` pages of 2^standInIntervalsLog2 + 1 samples per side (at most the
  // pool's), with their normals' and colours' mips, in texture arrays of their own beside the pool
  // (AtlasRenderer::standInPage). A chart root whose page is not in the pool draws from its
  // stand-in at that resolution or coarser. 0: none.
  uint32_t standIns = 0;
  uint32_t standInIntervalsLog2 = 0;
  // A planet atlas (core/planet.h; validSamples its lattice): heights drawn on the sphere, every
  // position relative to the anchor (setPlanetAnchor), so viewProj and eye are too.
  PlanetInfo planet;
};

// GPU bytes of one page of a pool made for `setup`: its samples (R32F, or RGB32F for geometry),
// its normals (RGBA8 with the mip chain) and its colours (RGBA8 with the mip chain, where the
// atlas has them). The pool's textures hold pageCapacity such pages. No GL needed.
uint64_t pagePoolPageBytes(const RendererSetup& setup);
// GPU bytes of one root stand-in (RendererSetup::standInIntervalsLog2), counted as pagePoolPageBytes.
uint64_t standInPageBytes(const RendererSetup& setup);

// The mips uploadPage makes for a page of samplesPerSide^2 samples (its normals, and its colours
// where the pool has them), made beforehand: on the page loader's threads. No GL needed.
PageMips pagePoolMips(const RendererSetup& setup, uint32_t samplesPerSide, const PackedNormal* normals,
                      const PackedColour* colours);
// The most bytes pagePoolMips gives for a page (a whole layer's mips).
uint64_t pagePoolMipBytes(const RendererSetup& setup);

struct DrawStats {
  double drawMs = 0.0;     // CPU wall time of submission + glFinish
  double gpuMs = 0.0;      // the GPU's own time for the draw (GL_TIME_ELAPSED query); NaN: unknown
  uint64_t triangles = 0;  // triangles submitted (grids, excluding strip degenerates)
  uint32_t drawCalls = 0;  // GL draw calls issued (one multi-draw per page-pool array the cut uses)
};

class GlObject;

// The back buffer of the current context's window (framebuffer 0), as drawn so far this frame:
// RGBA8, top row first, opaque.
std::vector<uint8_t> readWindowPixels(uint32_t width, uint32_t height);

// Points `program`'s samplers u_samples, u_normals and (where it has it) u_colours at the page
// pool's texture units (shaders/interface.h).
void setPagePoolUnits(const GlObject& program);

// Links atlas.vert + atlas.frag for terrain atlases or, with `geometry`, mesh atlases
// (GIMLOD_GEOMETRY), or with `planet` planet atlases (GIMLOD_PLANET), with v_world captured by
// transform feedback and the samplers set (setPagePoolUnits): the renderer's program. Needs a
// current context.
GlObject linkAtlasProgram(bool geometry, bool planet = false);

class AtlasRenderer {
 public:
  explicit AtlasRenderer(const RendererSetup& setup);
  ~AtlasRenderer();
  AtlasRenderer(const AtlasRenderer&) = delete;
  AtlasRenderer& operator=(const AtlasRenderer&) = delete;

  uint32_t pageCapacity() const;
  const RendererSetup& setup() const;
  // Texture arrays in the page pool (RendererSetup::pageCapacity) and layers in each; the
  // stand-ins' arrays are not counted.
  uint32_t pageArrays() const;
  // The page (DrawNode::pageLayer, uploadPage) of root stand-in k < RendererSetup::standIns:
  // pageCapacity() + k.
  uint32_t standInPage(uint32_t k) const;
  uint32_t layersPerArray() const;
  // Uploads one node page (page = its slot in the pool, 0..pageCapacity() - 1, or a stand-in's
  // standInPage, of at most 2^standInIntervalsLog2 + 1 samples per side): (n+1)^2 samples
  // and normals, n = 2^pageIntervalsLog2 at most.
  // Smaller pages (deep nodes) occupy the lower-left corner of the layer.
  // The normals also get their mip chain (normalMipLevel), for DrawNode::texLod. With
  // RendererSetup::geometry, `samples` holds 3 floats (x, y, z) per sample. `colours` (with
  // RendererSetup::colours; else ignored), ((samplesPerSide - 1) << colourScaleLog2) + 1 per side,
  // get their mip chain too.
  // mips, if given, are the page's (pagePoolMips), uploaded instead of made here.
  void uploadPage(uint32_t page, uint32_t samplesPerSide, const float* samples, const PackedNormal* normals,
                  const PackedColour* colours = nullptr, const PageMips* mips = nullptr);
  // Draws the pages' colours (RendererSetup::colours) or the neutral material.
  void setColours(bool on);

  // The overlay of the next draws, one record per node in the order draw() gets them (empty:
  // plain shading). With colourNodes the records' colours and chart borders replace the shading;
  // without, only their flags are read (the "pages loading" view). draw() throws
  // std::invalid_argument when the counts differ.
  void setOverlay(std::vector<NodeOverlay> perNode, bool colourNodes = true);

  // Draws the nodes into the offscreen framebuffer (clears first) and waits for completion.
  DrawStats draw(const glm::mat4& viewProj, const glm::vec3& eye, std::span<const DrawNode> nodes,
                 const StitchTables& stitch);

  // Binds the offscreen framebuffer, sets the draw state (depth test, no culling) and clears it,
  // as draw() does first: for drawing other geometry into the same picture (bench baselines).
  // endFrame, as draw() does last, resolves a multisampled picture for readPixels and the window.
  void beginFrame() const;
  void endFrame() const;
  // Planet atlases: the lattice sample positions are measured from in the next draws and captures
  // (v_world is the position minus anchor.position); the view and eye given to draw() must be
  // relative to it too.
  void setPlanetAnchor(const PlanetAnchor& anchor);
  const PlanetAnchor& planetAnchor() const;
  // Makes `program` current with the shading uniforms of atlas.frag (view, light, fog, extent;
  // the terrain-only ones where the program has them) and binds the page pool's textures to its
  // units (the first array's). `program` is one whose fragment stage is atlas.frag
  // (setPagePoolUnits done).
  void setShading(const GlObject& program, const glm::mat4& viewProj, const glm::vec3& eye) const;

  // Resizes the offscreen framebuffer (a window's new size); the next draw clears it.
  void resize(uint32_t width, uint32_t height);
  // Copies the offscreen picture into framebuffer 0 (a window's back buffer) at (0, 0), pixel
  // for pixel; leaves framebuffer 0 bound.
  void blitToDefaultFramebuffer() const;
  // Draws the triangles' edges instead of filling them (the wireframe view).
  void setWireframe(bool on);
  // Inspection views drawn over the shading: node borders (thin dark lines round every node),
  // normals as colours (n * 0.5 + 0.5 instead of the material), the border vertices the
  // stitching snapped onto a coarser neighbour (orange), and nodes standing in for pages still
  // loading (magenta stripes; NodeOverlay::flags kOverlayStandIn, set through setOverlay).
  // Capture is unaffected.
  struct InspectionViews {
    bool nodeBorders = false, normals = false, snapped = false, loading = false;
  };
  void setInspectionViews(const InspectionViews& views);
  const InspectionViews& inspectionViews() const;

  // Reads the framebuffer as RGBA8, top row first.
  std::vector<uint8_t> readPixels() const;

  // Runs the same vertex shader with transform feedback and returns, per node, the stitched
  // world position of every grid vertex, index j * (2^res + 1) + i.
  std::vector<std::vector<glm::vec3>> captureVertices(std::span<const DrawNode> nodes, const StitchTables& stitch);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace gimlod::gl
