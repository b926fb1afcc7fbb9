// Based on Niski, Purnomo, Cohen, "Multi-grained Level of Detail Using a Hierarchical Seamless
// Texture Atlas" (I3D 2007), section 7.3 (patch rendering with reusable (u,v) grids) and
// section 7.4 (border stitching in the vertex program).
#include "runtime/gl/atlas_renderer.h"

#include <epoxy/gl.h>

#include <algorithm>
#include <array>
#include <limits>
#include <chrono>
#include <cmath>
#include <cstring>
#include <numbers>
#include <stdexcept>
#include <string>

#include <glm/gtc/type_ptr.hpp>

#include "gimlod_shaders.h"
#include "runtime/gl/gl_objects.h"
#include "runtime/grid_strips.h"
#include "runtime/normal_mips.h"
#include "shaders/interface.h"

namespace gimlod::gl {
namespace {

// The shader interface (shaders/interface.h, shared with the GLSL).
constexpr GLuint kSamplesUnit = GIMLOD_SAMPLES_UNIT, kNormalsUnit = GIMLOD_NORMALS_UNIT,
                 kColoursUnit = GIMLOD_COLOURS_UNIT;
constexpr GLuint kStitchBinding = GIMLOD_STITCH_BINDING;
constexpr GLuint kOverlayBinding = GIMLOD_OVERLAY_BINDING;
constexpr GLuint kGridAttrib = GIMLOD_ATTRIB_GRID, kNodeAttribA = GIMLOD_ATTRIB_NODE_A,
                 kNodeAttribB = GIMLOD_ATTRIB_NODE_B;
constexpr uint32_t kMaxGridResLog2 = 12;  // (2^12+1)^2 vertices; ushort (i, j)

// std430 layout of atlas.vert's NodeRecord.
// Layout fixed by GL for glMultiDrawElementsIndirect.
struct DrawElementsIndirectCommand {
  GLuint count, instanceCount, firstIndex;
  GLint baseVertex;
  GLuint baseInstance;
};

struct NodeRecord {
  int32_t originX, originY, sizeLog2, res, pageResLog2, pageLayer, index, texLod;
};
static_assert(sizeof(NodeRecord) == 32);

GLint getInteger(GLenum name) {
  GLint v = 0;
  glGetIntegerv(name, &v);
  return v;
}

glm::vec3 lightDirection() { return glm::normalize(glm::vec3(-0.45f, -0.35f, 0.82f)); }

using Clock = std::chrono::steady_clock;
double msSince(Clock::time_point t0) { return std::chrono::duration<double, std::milli>(Clock::now() - t0).count(); }

// Mip levels of a texture of side `side` down to 1x1.
uint32_t mipLevels(uint32_t side) {
  uint32_t levels = 1;
  while ((side >> levels) >= 1) ++levels;
  return levels;
}

// Bytes of one square layer of side `side` with `levels` mip levels, bytesPerTexel each.
uint64_t layerBytes(uint32_t side, uint32_t levels, uint64_t bytesPerTexel) {
  uint64_t b = 0;
  for (uint32_t l = 0; l < levels; ++l) {
    const uint64_t t = std::max<uint32_t>(side >> l, 1);
    b += t * t * bytesPerTexel;
  }
  return b;
}

}  // namespace

PageMips pagePoolMips(const RendererSetup& setup, uint32_t samplesPerSide, const PackedNormal* normals,
                      const PackedColour* colours) {
  const uint32_t side = (1u << setup.pageIntervalsLog2) + 1;
  const uint32_t colourSide = ((side - 1) << setup.colourScaleLog2) + 1;
  const bool withColours = colours && setup.colours;
  return pageMips({normals, samplesPerSide, side, mipLevels(side)},
                  {withColours ? colours : nullptr, ((samplesPerSide - 1) << setup.colourScaleLog2) + 1, colourSide,
                   mipLevels(colourSide)});
}

uint64_t pagePoolMipBytes(const RendererSetup& setup) {
  const uint32_t side = (1u << setup.pageIntervalsLog2) + 1;
  const uint32_t colourSide = ((side - 1) << setup.colourScaleLog2) + 1;
  return layerBytes(side, mipLevels(side), 4) - layerBytes(side, 1, 4) +
         (setup.colours ? layerBytes(colourSide, mipLevels(colourSide), 4) - layerBytes(colourSide, 1, 4) : 0);
}

uint64_t standInPageBytes(const RendererSetup& setup) {
  RendererSetup s = setup;
  s.pageIntervalsLog2 = setup.standInIntervalsLog2;
  return pagePoolPageBytes(s);
}

uint64_t pagePoolPageBytes(const RendererSetup& setup) {
  // Level 0 of the samples, the normals and the colours, then their mips.
  const uint64_t side = (1u << setup.pageIntervalsLog2) + 1;
  const uint64_t colourSide = ((side - 1) << setup.colourScaleLog2) + 1;
  return side * side * ((setup.geometry ? 12 : 4) + 4) + (setup.colours ? colourSide * colourSide * 4 : 0) +
         pagePoolMipBytes(setup);
}

void setPagePoolUnits(const GlObject& program) {
  glUseProgram(program.id());
  glUniform1i(uniform(program, "u_samples"), kSamplesUnit);
  glUniform1i(uniform(program, "u_normals"), kNormalsUnit);
  glUniform1i(optionalUniform(program, "u_colours"), kColoursUnit);
  glUseProgram(0);
}

GlObject linkAtlasProgram(bool geometry, bool planet) {
  // note: mesh and planet atlases use the same shaders with GIMLOD_GEOMETRY or GIMLOD_PLANET
  // defined after the #version line.
  if (geometry && planet) throw std::invalid_argument("linkAtlasProgram: a planet atlas is a height field");
  auto variant = [&](const char* source) {
    std::string s = source;
    if (geometry) s.insert(s.find('\n') + 1, "#define GIMLOD_GEOMETRY 1\n");
    if (planet) s.insert(s.find('\n') + 1, "#define GIMLOD_PLANET 1\n");
    return s;
  };
  const std::string vert = variant(kShader_atlas_vert), frag = variant(kShader_atlas_frag);
  GlObject program = linkProgram(geometry ? "atlas (mesh)"
                                 : planet ? "atlas (planet)"
                                          : "atlas",
                                 vert.c_str(), frag.c_str(), {"v_world"});
  setPagePoolUnits(program);
  return program;
}

struct AtlasRenderer::Impl {
  // One reusable grid inside the shared vertex and index buffers.
  struct GridRange {
    GLint baseVertex = 0;
    GLsizei vertexCount = 0;
    size_t indexOffsetBytes = 0;
    GLsizei indexCount = 0;
  };

  RendererSetup setup;
  uint32_t pageSide = 0;        // P = 2^pageIntervalsLog2 + 1
  uint32_t capacity = 0;        // pages in the pool
  uint32_t layersPerArray = 0;  // page p is layer p % layersPerArray of array p / layersPerArray
  // Root stand-ins (RendererSetup::standIns): page capacity + k is stand-in k, layer
  // k % standInLayers of array poolArrays + k / standInLayers.
  uint32_t poolArrays = 0, standIns = 0, standInLayers = 1;
  uint32_t arrayOf(uint32_t page) const {
    return page < capacity ? page / layersPerArray : poolArrays + (page - capacity) / standInLayers;
  }
  uint32_t layerOf(uint32_t page) const {
    return page < capacity ? page % layersPerArray : (page - capacity) % standInLayers;
  }
  // The page side of `page`'s layer (the pool's, or the stand-ins').
  uint32_t sideOf(uint32_t page) const { return page < capacity ? pageSide : (1u << setup.standInIntervalsLog2) + 1; }
  GlObject colourBuffer, depthBuffer, framebuffer;
  // With setup.samples > 1: the multisampled target the frame is drawn into, resolved into
  // framebuffer at the end of each draw.
  GlObject msColourBuffer, msDepthBuffer, msFramebuffer;
  // The page pool's texture arrays: heights or positions, normals, and RGBA8 colours
  // (RendererSetup::colours; else empty).
  std::vector<GlObject> samples, normals, colours;
  bool drawColours = true;
  uint32_t normalLevels = 1;  // mip levels of the normal page pool
  uint32_t colourSide = 0;    // texels per side of a colour layer: ((pageSide - 1) << colourScaleLog2) + 1
  uint32_t colourLevels = 1;  // mip levels of the colour page pool
  GlObject gridVertices, gridIndices, vertexArray;
  std::vector<GridRange> grids;  // [res - minResLog2]
  GlObject nodeBuffer, stitchBuffer, indirectBuffer, feedbackBuffer, feedbackQuery;
  GLint morphWords = -1;  // the word of the stitch buffer where the neighbours' morph bytes begin; -1: none
  GlObject timerQuery;    // GL_TIME_ELAPSED round each draw
  GlObject overlayBuffer;
  std::vector<NodeOverlay> overlay;  // per node of the next draw; empty: no overlay
  bool overlayColours = false;       // the records colour the nodes (else only their flags count)
  InspectionViews inspection;        // setInspectionViews; u_views holds them as bits
  GlObject atlasProgram;
  bool wireframe = false;
  PlanetAnchor anchor;  // planet atlases: where positions are measured from (setPlanetAnchor)

  explicit Impl(const RendererSetup& s);
  void checkLimits() const;
  void createFramebuffer();
  void createPagePool();
  void createGrids();
  void createVertexArray();
  const GridRange& grid(uint32_t res) const { return grids[res - setup.minResLog2]; }
  void validate(std::span<const DrawNode> nodes, const StitchTables& stitch) const;
  // Node records in the order given (record j is node order[j]; empty order: node order); each
  // record keeps its node's index for the stitching tables.
  void uploadNodes(std::span<const DrawNode> nodes, const StitchTables& stitch, std::span<const uint32_t> order = {});
  void setShading(const GlObject& program, const glm::mat4& viewProj, const glm::vec3& eye) const;
  void bindAtlas(const glm::mat4& viewProj, const glm::vec3& eye, const StitchTables& stitch);
  void setPlanetUniforms() const;
  void beginFrame() const;
  void resolve() const;  // the multisampled frame into framebuffer (nothing with one sample)
  // Binds page-pool array `a`'s textures to the samplers' units.
  void bindPageArray(uint32_t a) const;
};

AtlasRenderer::Impl::Impl(const RendererSetup& s) : setup(s) {
  if (setup.width == 0 || setup.height == 0)
    throw std::invalid_argument("AtlasRenderer: framebuffer size must be positive");
  if (setup.minResLog2 > setup.maxResLog2 || setup.maxResLog2 > kMaxGridResLog2)
    throw std::invalid_argument("AtlasRenderer: need minResLog2 <= maxResLog2 <= " + std::to_string(kMaxGridResLog2));
  if (setup.pageIntervalsLog2 > kMaxGridResLog2)
    throw std::invalid_argument("AtlasRenderer: pageIntervalsLog2 too large");
  checkGl("context before AtlasRenderer setup");
  checkLimits();
  pageSide = (1u << setup.pageIntervalsLog2) + 1;
  createFramebuffer();
  createPagePool();
  createGrids();
  nodeBuffer = makeBuffer();
  createVertexArray();
  atlasProgram = linkAtlasProgram(setup.geometry, setup.planet.present);
  stitchBuffer = makeBuffer();
  overlayBuffer = makeBuffer();
  {
    const NodeOverlay none{};
    glBindBuffer(GL_SHADER_STORAGE_BUFFER, overlayBuffer.id());
    glBufferData(GL_SHADER_STORAGE_BUFFER, GLsizeiptr(sizeof none), &none, GL_STREAM_DRAW);
    glBindBuffer(GL_SHADER_STORAGE_BUFFER, 0);
  }
  indirectBuffer = makeBuffer();
  feedbackBuffer = makeBuffer();
  feedbackQuery = makeQuery();
  timerQuery = makeQuery();
  checkGl("AtlasRenderer setup");
}

// glClipControl (OpenGL 4.5, or ARB_clip_control), which the reversed depth of planets needs.
bool hasClipControl() { return epoxy_gl_version() >= 45 || epoxy_has_gl_extension("GL_ARB_clip_control"); }

void AtlasRenderer::Impl::checkLimits() const {
  if (setup.planet.present && !hasClipControl())
    throw std::runtime_error("AtlasRenderer: planet atlases need glClipControl (OpenGL 4.5 or ARB_clip_control)");
  if (getInteger(GL_MAX_VERTEX_SHADER_STORAGE_BLOCKS) < 2)
    throw std::runtime_error(
        "AtlasRenderer: the GL implementation offers fewer than 2 shader "
        "storage blocks in the vertex stage");
  const GLint maxSide = getInteger(GL_MAX_TEXTURE_SIZE);
  if (static_cast<int64_t>(setup.width) > getInteger(GL_MAX_RENDERBUFFER_SIZE) ||
      static_cast<int64_t>(setup.height) > getInteger(GL_MAX_RENDERBUFFER_SIZE) ||
      (int64_t(1) << setup.pageIntervalsLog2) + 1 > maxSide)
    throw std::runtime_error("AtlasRenderer: framebuffer or page size exceeds GL limits");
  if (setup.samples > 1 && int64_t(setup.samples) > getInteger(GL_MAX_SAMPLES))
    throw std::runtime_error("AtlasRenderer: " + std::to_string(setup.samples) +
                             " samples per pixel asked; the GL "
                             "implementation offers " +
                             std::to_string(getInteger(GL_MAX_SAMPLES)) + " at most");
}

namespace {

// A framebuffer of an RGBA8 colour and a 32-bit float depth renderbuffer of `samples` samples
// (1: not multisampled).
void makeTarget(uint32_t width, uint32_t height, uint32_t samples, GlObject& colour, GlObject& depth,
                GlObject& framebuffer) {
  auto storage = [&](GLenum format) {
    if (samples > 1)
      glRenderbufferStorageMultisample(GL_RENDERBUFFER, GLsizei(samples), format, GLsizei(width), GLsizei(height));
    else
      glRenderbufferStorage(GL_RENDERBUFFER, format, GLsizei(width), GLsizei(height));
  };
  colour = makeRenderbuffer();
  glBindRenderbuffer(GL_RENDERBUFFER, colour.id());
  storage(GL_RGBA8);
  depth = makeRenderbuffer();
  glBindRenderbuffer(GL_RENDERBUFFER, depth.id());
  storage(GL_DEPTH_COMPONENT32F);
  glBindRenderbuffer(GL_RENDERBUFFER, 0);
  framebuffer = makeFramebuffer();
  glBindFramebuffer(GL_FRAMEBUFFER, framebuffer.id());
  glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, colour.id());
  glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, depth.id());
  const GLenum status = glCheckFramebufferStatus(GL_FRAMEBUFFER);
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  if (status != GL_FRAMEBUFFER_COMPLETE)
    throw std::runtime_error("AtlasRenderer: offscreen framebuffer of " + std::to_string(samples) +
                             " samples incomplete (status 0x" + std::to_string(status) + ")");
}

}  // namespace

void AtlasRenderer::Impl::createFramebuffer() {
  makeTarget(setup.width, setup.height, 1, colourBuffer, depthBuffer, framebuffer);
  if (setup.samples > 1)
    makeTarget(setup.width, setup.height, setup.samples, msColourBuffer, msDepthBuffer, msFramebuffer);
  checkGl("framebuffer creation");
}

void AtlasRenderer::Impl::resolve() const {
  if (setup.samples <= 1) return;
  const GLint w = GLint(setup.width), h = GLint(setup.height);
  glBindFramebuffer(GL_READ_FRAMEBUFFER, msFramebuffer.id());
  glBindFramebuffer(GL_DRAW_FRAMEBUFFER, framebuffer.id());
  glBlitFramebuffer(0, 0, w, h, 0, 0, w, h, GL_COLOR_BUFFER_BIT, GL_NEAREST);
  glBindFramebuffer(GL_FRAMEBUFFER, framebuffer.id());
}

void AtlasRenderer::Impl::createPagePool() {
  capacity = std::max<uint32_t>(setup.pageCapacity, 1);
  const uint32_t maxLayers = static_cast<uint32_t>(std::max<GLint>(getInteger(GL_MAX_ARRAY_TEXTURE_LAYERS), 1));
  layersPerArray =
      std::min(setup.layersPerArray == 0 ? maxLayers : std::min(setup.layersPerArray, maxLayers), capacity);
  const uint32_t arrays = (capacity + layersPerArray - 1) / layersPerArray;
  auto makeLayers = [&](GLenum format, GLint levels, uint32_t side, uint32_t layers) {
    GlObject tex = makeTexture();
    glBindTexture(GL_TEXTURE_2D_ARRAY, tex.id());
    glTexStorage3D(GL_TEXTURE_2D_ARRAY, levels, format, GLsizei(side), GLsizei(side), GLsizei(layers));
    if (const GLenum e = glGetError(); e != GL_NO_ERROR)
      throw std::runtime_error(
          "AtlasRenderer: a page pool of " + std::to_string(capacity) + " pages of " + std::to_string(side) +
          "^2 samples: " +
          (e == GL_OUT_OF_MEMORY ? std::string("out of GPU memory") : "GL error " + std::to_string(e)));
    glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MIN_FILTER, levels > 1 ? GL_LINEAR_MIPMAP_LINEAR : GL_LINEAR);
    glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MAG_FILTER, GL_LINEAR);
    glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_WRAP_S, GL_CLAMP_TO_EDGE);
    glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_WRAP_T, GL_CLAMP_TO_EDGE);
    glTexParameteri(GL_TEXTURE_2D_ARRAY, GL_TEXTURE_MAX_LEVEL, levels - 1);
    checkGl("page pool glTexStorage3D");
    return tex;
  };
  auto makeArray = [&](GLenum format, GLint levels, uint32_t side, uint32_t a) {
    return makeLayers(format, levels, side, std::min(layersPerArray, capacity - a * layersPerArray));
  };
  // note: the vertex shader reads samples with texelFetch (no filtering); the fragment shader
  // samples heights bilinearly for colouring at page resolution, finer than the drawn grid. Normals
  // carry a mip chain so each node's normal map is read at its attribute resolution (texLod).
  normalLevels = mipLevels(pageSide);
  colourSide = ((pageSide - 1) << setup.colourScaleLog2) + 1;
  colourLevels = mipLevels(colourSide);
  for (uint32_t a = 0; a < arrays; ++a) {
    samples.push_back(makeArray(setup.geometry ? GL_RGB32F : GL_R32F, 1, pageSide, a));
    normals.push_back(makeArray(GL_RGBA8, GLint(normalLevels), pageSide, a));
    if (setup.colours) colours.push_back(makeArray(GL_RGBA8, GLint(colourLevels), colourSide, a));
  }
  poolArrays = arrays;
  // The root stand-ins: arrays of their own, of small layers, as many layers each as the GL allows.
  standIns = setup.standIns;
  if (standIns > 0) {
    if (setup.standInIntervalsLog2 > setup.pageIntervalsLog2)
      throw std::invalid_argument("AtlasRenderer: stand-ins finer than the pool's pages");
    standInLayers = std::min(maxLayers, standIns);
    const uint32_t side = (1u << setup.standInIntervalsLog2) + 1;
    const uint32_t cSide = ((side - 1) << setup.colourScaleLog2) + 1;
    for (uint32_t first = 0; first < standIns; first += standInLayers) {
      const uint32_t layers = std::min(standInLayers, standIns - first);
      samples.push_back(makeLayers(setup.geometry ? GL_RGB32F : GL_R32F, 1, side, layers));
      normals.push_back(makeLayers(GL_RGBA8, GLint(mipLevels(side)), side, layers));
      if (setup.colours) colours.push_back(makeLayers(GL_RGBA8, GLint(mipLevels(cSide)), cSide, layers));
    }
  }
  glBindTexture(GL_TEXTURE_2D_ARRAY, 0);
}

void AtlasRenderer::Impl::createGrids() {
  std::vector<uint16_t> vertices;  // (i, j) pairs of every grid, back to back
  std::vector<uint32_t> indices;   // grid-local indices; base vertex selects the grid
  for (uint32_t res = setup.minResLog2; res <= setup.maxResLog2; ++res) {
    const uint32_t side = (1u << res) + 1;
    GridRange range;
    range.baseVertex = GLint(vertices.size() / 2);
    range.vertexCount = GLsizei(side * side);
    for (uint32_t j = 0; j < side; ++j)
      for (uint32_t i = 0; i < side; ++i) {
        vertices.push_back(uint16_t(i));
        vertices.push_back(uint16_t(j));
      }
    const std::vector<uint32_t> strips = buildGridStripIndices(res);
    range.indexOffsetBytes = indices.size() * sizeof(uint32_t);
    range.indexCount = GLsizei(strips.size());
    indices.insert(indices.end(), strips.begin(), strips.end());
    grids.push_back(range);
  }
  gridVertices = makeBuffer();
  glBindBuffer(GL_ARRAY_BUFFER, gridVertices.id());
  glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(vertices.size() * sizeof(uint16_t)), vertices.data(), GL_STATIC_DRAW);
  glBindBuffer(GL_ARRAY_BUFFER, 0);
  gridIndices = makeBuffer();
  glBindBuffer(GL_ARRAY_BUFFER, gridIndices.id());  // bound to the VAO as element buffer later
  glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(indices.size() * sizeof(uint32_t)), indices.data(), GL_STATIC_DRAW);
  glBindBuffer(GL_ARRAY_BUFFER, 0);
  checkGl("grid buffers");
}

void AtlasRenderer::Impl::createVertexArray() {
  vertexArray = makeVertexArray();
  glBindVertexArray(vertexArray.id());
  glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, gridIndices.id());
  glBindBuffer(GL_ARRAY_BUFFER, gridVertices.id());
  glEnableVertexAttribArray(kGridAttrib);
  glVertexAttribIPointer(kGridAttrib, 2, GL_UNSIGNED_SHORT, 2 * sizeof(uint16_t), nullptr);
  glBindBuffer(GL_ARRAY_BUFFER, nodeBuffer.id());
  for (GLuint a : {kNodeAttribA, kNodeAttribB}) {
    glEnableVertexAttribArray(a);
    glVertexAttribIPointer(a, 4, GL_INT, sizeof(NodeRecord),
                           reinterpret_cast<const void*>(a == kNodeAttribA ? 0 : 4 * sizeof(int32_t)));
    glVertexAttribDivisor(a, 1);  // baseinstance picks the node record
  }
  glBindVertexArray(0);
  glBindBuffer(GL_ARRAY_BUFFER, 0);
  checkGl("vertex array setup");
}

void AtlasRenderer::Impl::validate(std::span<const DrawNode> nodes, const StitchTables& stitch) const {
  if (stitch.entriesPerSide == 0) throw std::invalid_argument("StitchTables: entriesPerSide = 0");
  if (!stitch.bytes.empty() && stitch.bytes.size() < nodes.size() * 4 * stitch.entriesPerSide)
    throw std::invalid_argument("StitchTables: fewer bytes than nodes * 4 * entriesPerSide");
  if (!stitch.morphs.empty() && stitch.morphs.size() != stitch.bytes.size())
    throw std::invalid_argument("StitchTables: morphs and bytes differ in size");
  for (const DrawNode& n : nodes) {
    const bool ok = n.resLog2 >= setup.minResLog2 && n.resLog2 <= setup.maxResLog2 && n.resLog2 <= n.pageResLog2 &&
                    n.pageResLog2 <= setup.pageIntervalsLog2 && n.pageResLog2 <= n.sizeLog2 && n.sizeLog2 < 30 &&
                    (n.pageLayer < capacity ||
                     (n.pageLayer - capacity < standIns && n.pageResLog2 <= setup.standInIntervalsLog2)) &&
                    n.texLod <= n.pageResLog2 && n.texLodFrac <= 255 && n.morph <= 255;
    if (!ok)
      throw std::invalid_argument("AtlasRenderer: bad DrawNode (origin " + std::to_string(n.originX) + "," +
                                  std::to_string(n.originY) + " sizeLog2 " + std::to_string(n.sizeLog2) + " res " +
                                  std::to_string(n.resLog2) + " pageResLog2 " + std::to_string(n.pageResLog2) +
                                  " layer " + std::to_string(n.pageLayer) + ")");
  }
}

void AtlasRenderer::Impl::uploadNodes(std::span<const DrawNode> nodes, const StitchTables& stitch,
                                      std::span<const uint32_t> order) {
  validate(nodes, stitch);
  std::vector<NodeRecord> records(std::max<size_t>(nodes.size(), 1), NodeRecord{});
  for (size_t j = 0; j < nodes.size(); ++j) {
    const size_t k = order.empty() ? j : order[j];
    const DrawNode& n = nodes[k];
    records[j] = {n.originX,
                  n.originY,
                  int32_t(n.sizeLog2),
                  int32_t(n.resLog2),
                  int32_t(n.pageResLog2),
                  int32_t(layerOf(n.pageLayer)),
                  int32_t(k),
                  int32_t(n.texLod | (n.morph << 8) | (n.texLodFrac << 16))};
  }
  glBindBuffer(GL_ARRAY_BUFFER, nodeBuffer.id());
  glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(records.size() * sizeof(NodeRecord)), records.data(), GL_STREAM_DRAW);
  glBindBuffer(GL_ARRAY_BUFFER, 0);
  // note: an empty table means "no neighbours anywhere"; the shader still needs the words.
  // The neighbours' morph bytes follow, from the next whole word (u_morphWords).
  const size_t tableBytes = nodes.size() * 4 * stitch.entriesPerSide;
  const size_t tableWords = (tableBytes + 3) / 4;
  const bool morphs = !stitch.morphs.empty() && tableBytes > 0;
  std::vector<uint32_t> words(std::max<size_t>(morphs ? 2 * tableWords : tableWords, 1), 0u);
  if (!stitch.bytes.empty()) std::memcpy(words.data(), stitch.bytes.data(), tableBytes);
  if (morphs) std::memcpy(words.data() + tableWords, stitch.morphs.data(), tableBytes);
  morphWords = morphs ? GLint(tableWords) : -1;
  glBindBuffer(GL_SHADER_STORAGE_BUFFER, stitchBuffer.id());
  glBufferData(GL_SHADER_STORAGE_BUFFER, GLsizeiptr(words.size() * sizeof(uint32_t)), words.data(), GL_STREAM_DRAW);
  glBindBuffer(GL_SHADER_STORAGE_BUFFER, 0);
  glBindBufferBase(GL_SHADER_STORAGE_BUFFER, kStitchBinding, stitchBuffer.id());
  // The overlays by node index (as the stitching tables), uploaded only when there are some: the
  // shader reads them only with u_overlay set, and the buffer always holds at least one record.
  if (!overlay.empty()) {
    if (overlay.size() != nodes.size())
      throw std::invalid_argument("AtlasRenderer: " + std::to_string(overlay.size()) + " overlays for " +
                                  std::to_string(nodes.size()) + " nodes");
    glBindBuffer(GL_SHADER_STORAGE_BUFFER, overlayBuffer.id());
    glBufferData(GL_SHADER_STORAGE_BUFFER, GLsizeiptr(overlay.size() * sizeof(NodeOverlay)), overlay.data(),
                 GL_STREAM_DRAW);
    glBindBuffer(GL_SHADER_STORAGE_BUFFER, 0);
  }
  glBindBufferBase(GL_SHADER_STORAGE_BUFFER, kOverlayBinding, overlayBuffer.id());
  checkGl("node and stitch table upload");
}

void AtlasRenderer::Impl::setShading(const GlObject& p, const glm::mat4& viewProj, const glm::vec3& eye) const {
  glUseProgram(p.id());
  const glm::vec2 spacing(float(setup.spacing[0]), float(setup.spacing[1]));
  const glm::vec2 valid(float(setup.validSamples[0]), float(setup.validSamples[1]));
  const glm::vec3 light = lightDirection();
  glUniformMatrix4fv(uniform(p, "u_viewProj"), 1, GL_FALSE, glm::value_ptr(viewProj));
  glUniform3fv(uniform(p, "u_eye"), 1, glm::value_ptr(eye));
  // note: terrain only; the mesh variant (GIMLOD_GEOMETRY) does not use them.
  glUniform2fv(optionalUniform(p, "u_spacing"), 1, glm::value_ptr(spacing));
  glUniform2fv(optionalUniform(p, "u_validSamples"), 1, glm::value_ptr(valid));
  glUniform2f(optionalUniform(p, "u_heightRange"), setup.heightRange[0], setup.heightRange[1]);
  glUniform3fv(uniform(p, "u_lightDir"), 1, glm::value_ptr(light));
  glUniform3f(uniform(p, "u_background"), setup.background[0], setup.background[1], setup.background[2]);
  // note: fog scale from the valid extent; no fog when the extent is unknown.
  const float fog = 1.5f * glm::length(valid * spacing);
  glUniform1f(uniform(p, "u_fogDistance"), fog);
  bindPageArray(0);
  glUniform1i(optionalUniform(p, "u_hasColours"), setup.colours && drawColours ? 1 : 0);
  glUniform1f(optionalUniform(p, "u_colourScale"), float(1u << setup.colourScaleLog2));
}

void AtlasRenderer::Impl::bindAtlas(const glm::mat4& viewProj, const glm::vec3& eye, const StitchTables& stitch) {
  setShading(atlasProgram, viewProj, eye);
  glUniform1i(uniform(atlasProgram, "u_leafLog2"), GLint(stitch.leafLog2));
  glUniform1i(uniform(atlasProgram, "u_entriesPerSide"), GLint(stitch.entriesPerSide));
  glUniform1i(uniform(atlasProgram, "u_morphWords"), morphWords);
  if (setup.planet.present) setPlanetUniforms();
  glUniform1i(uniform(atlasProgram, "u_overlay"), overlay.empty() || !overlayColours ? 0 : 1);
  glUniform1i(uniform(atlasProgram, "u_overlayRecords"), overlay.empty() ? 0 : 1);
  const InspectionViews& v = inspection;
  glUniform1i(uniform(atlasProgram, "u_views"),
              (v.nodeBorders ? 1 : 0) | (v.normals ? 2 : 0) | (v.snapped ? 4 : 0) | (v.loading ? 8 : 0));
  glBindVertexArray(vertexArray.id());
  checkGl("atlas state");
}

void AtlasRenderer::Impl::setPlanetUniforms() const {
  const GlObject& p = atlasProgram;
  const PlanetInfo& info = setup.planet;
  const PlanetFrame frame(info, setup.validSamples[0], setup.validSamples[1]);
  const double deg = std::numbers::pi / 180.0;
  glUniform2i(uniform(p, "u_anchor"), GLint(anchor.gx), GLint(anchor.gy));
  glUniform4f(uniform(p, "u_anchorTrig"), float(anchor.sinLat), float(anchor.cosLat), float(anchor.sinLon),
              float(anchor.cosLon));
  glUniform2f(uniform(p, "u_anchorPoles"), float(anchor.latBelow), float(anchor.latAbove));
  glUniform3i(uniform(p, "u_planetLattice"), GLint(setup.validSamples[0]) - 1, GLint(setup.validSamples[1]) - 1,
              GLint(info.wrapColumns));
  glUniform2i(uniform(p, "u_poleRows"), GLint(frame.southPoleRow()), GLint(frame.northPoleRow()));
  glUniform3f(uniform(p, "u_planetStep"), float(info.dlonDeg * deg), float(info.dlatDeg * deg), float(info.radius));
  glUniform3f(uniform(p, "u_ellipsoid"), float(info.eccentricity2()), float(anchor.normalRadius), float(anchor.w));
}

void AtlasRenderer::Impl::bindPageArray(uint32_t a) const {
  glActiveTexture(GL_TEXTURE0 + kSamplesUnit);
  glBindTexture(GL_TEXTURE_2D_ARRAY, samples[a].id());
  glActiveTexture(GL_TEXTURE0 + kNormalsUnit);
  glBindTexture(GL_TEXTURE_2D_ARRAY, normals[a].id());
  glActiveTexture(GL_TEXTURE0 + kColoursUnit);
  glBindTexture(GL_TEXTURE_2D_ARRAY, setup.colours ? colours[a].id() : 0);
  glActiveTexture(GL_TEXTURE0);
}

void AtlasRenderer::Impl::beginFrame() const {
  glBindFramebuffer(GL_FRAMEBUFFER, setup.samples > 1 ? msFramebuffer.id() : framebuffer.id());
  glViewport(0, 0, GLsizei(setup.width), GLsizei(setup.height));
  glDisable(GL_RASTERIZER_DISCARD);
  glDisable(GL_CULL_FACE);
  glEnable(GL_DEPTH_TEST);
  glDepthMask(GL_TRUE);
  glClearColor(setup.background[0], setup.background[1], setup.background[2], 1.0f);
  // Planets: reversed depth (camera.h reversedProjectionMatrix) in a [0, 1] clip depth; the float
  // depth buffer then holds its precision from the near plane to infinity.
  const bool reversed = setup.planet.present;
  if (hasClipControl()) glClipControl(GL_LOWER_LEFT, reversed ? GL_ZERO_TO_ONE : GL_NEGATIVE_ONE_TO_ONE);
  glDepthFunc(reversed ? GL_GREATER : GL_LESS);
  glClearDepth(reversed ? 0.0 : 1.0);
  glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
  // Multisampled: shaded per sample, so that the terrain's edge, where fragments are discarded
  // past the DEM's last samples, is smoothed like the triangles' edges.
  if (setup.samples > 1) {
    glEnable(GL_SAMPLE_SHADING);
    glMinSampleShading(1.0f);
  } else {
    glDisable(GL_SAMPLE_SHADING);
  }
}

AtlasRenderer::AtlasRenderer(const RendererSetup& setup) : impl_(std::make_unique<Impl>(setup)) {}

AtlasRenderer::~AtlasRenderer() = default;

uint32_t AtlasRenderer::pageCapacity() const { return impl_->capacity; }

uint32_t AtlasRenderer::pageArrays() const { return impl_->poolArrays; }

uint32_t AtlasRenderer::standInPage(uint32_t k) const {
  if (k >= impl_->standIns) throw std::invalid_argument("AtlasRenderer::standInPage: no stand-in " + std::to_string(k));
  return impl_->capacity + k;
}

uint32_t AtlasRenderer::layersPerArray() const { return impl_->layersPerArray; }

const RendererSetup& AtlasRenderer::setup() const { return impl_->setup; }

void AtlasRenderer::beginFrame() const { impl_->beginFrame(); }

void AtlasRenderer::endFrame() const { impl_->resolve(); }

void AtlasRenderer::setPlanetAnchor(const PlanetAnchor& anchor) { impl_->anchor = anchor; }

const PlanetAnchor& AtlasRenderer::planetAnchor() const { return impl_->anchor; }

void AtlasRenderer::setOverlay(std::vector<NodeOverlay> perNode, bool colourNodes) {
  impl_->overlay = std::move(perNode);
  impl_->overlayColours = colourNodes;
}

void AtlasRenderer::setShading(const GlObject& program, const glm::mat4& viewProj, const glm::vec3& eye) const {
  impl_->setShading(program, viewProj, eye);
}

void AtlasRenderer::setColours(bool on) { impl_->drawColours = on; }

void AtlasRenderer::uploadPage(uint32_t page, uint32_t samplesPerSide, const float* samples,
                               const PackedNormal* normals, const PackedColour* colours, const PageMips* mips) {
  if (page >= impl_->capacity + impl_->standIns || samplesPerSide == 0 || samplesPerSide > impl_->sideOf(page) ||
      !samples)
    throw std::invalid_argument("AtlasRenderer::uploadPage: page " + std::to_string(page) + " / side " +
                                std::to_string(samplesPerSide) + " out of range");
  const uint32_t array = impl_->arrayOf(page), layer = impl_->layerOf(page);
  const GLsizei s = GLsizei(samplesPerSide);
  glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
  glBindTexture(GL_TEXTURE_2D_ARRAY, impl_->samples[array].id());
  glTexSubImage3D(GL_TEXTURE_2D_ARRAY, 0, 0, 0, GLint(layer), s, s, 1, impl_->setup.geometry ? GL_RGB : GL_RED,
                  GL_FLOAT, samples);
  // An RGBA8 attribute map of `texelsPerSide`^2 and its mip chain (levels 1 and up, with their sides).
  const auto uploadAttribute = [&](const GlObject& texture, const auto* texels, uint32_t texelsPerSide,
                                   const auto& levels, const std::vector<uint32_t>& sides) {
    glBindTexture(GL_TEXTURE_2D_ARRAY, texture.id());
    glTexSubImage3D(GL_TEXTURE_2D_ARRAY, 0, 0, 0, GLint(layer), GLsizei(texelsPerSide), GLsizei(texelsPerSide), 1,
                    GL_RGBA, GL_UNSIGNED_BYTE, texels);
    for (size_t l = 0; l < levels.size(); ++l)
      glTexSubImage3D(GL_TEXTURE_2D_ARRAY, GLint(l + 1), 0, 0, GLint(layer), GLsizei(sides[l]), GLsizei(sides[l]), 1,
                      GL_RGBA, GL_UNSIGNED_BYTE, levels[l].data());
  };
  RendererSetup layerSetup = impl_->setup;  // a stand-in's mips are its layers'
  if (page >= impl_->capacity) layerSetup.pageIntervalsLog2 = layerSetup.standInIntervalsLog2;
  const PageMips made = mips ? PageMips{} : pagePoolMips(layerSetup, samplesPerSide, normals, colours);
  const PageMips& m = mips ? *mips : made;
  if (normals) uploadAttribute(impl_->normals[array], normals, samplesPerSide, m.normals, m.normalSides);
  if (colours && impl_->setup.colours)
    uploadAttribute(impl_->colours[array], colours, ((samplesPerSide - 1) << impl_->setup.colourScaleLog2) + 1,
                    m.colours, m.colourSides);
  glBindTexture(GL_TEXTURE_2D_ARRAY, 0);
  checkGl("uploadPage glTexSubImage3D");
}

DrawStats AtlasRenderer::draw(const glm::mat4& viewProj, const glm::vec3& eye, std::span<const DrawNode> nodes,
                              const StitchTables& stitch) {
  Impl& m = *impl_;
  DrawStats stats;
  const auto t0 = Clock::now();
  glBeginQuery(GL_TIME_ELAPSED, m.timerQuery.id());
  m.beginFrame();
  if (!nodes.empty()) {
    // Records grouped by page-pool array, then by resolution (stable: front to back within a
    // group), so the cut is one multi-draw per array (the arrays the cut's pages lie in; one for
    // a pool within the GL's layer limit) of one instanced command per resolution: the per-node
    // cost on the GPU side is an instance, not a draw command.
    std::vector<uint32_t> order(nodes.size());
    for (uint32_t k = 0; k < order.size(); ++k) order[k] = k;
    std::stable_sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) {
      const uint32_t arrayA = m.arrayOf(nodes[a].pageLayer), arrayB = m.arrayOf(nodes[b].pageLayer);
      return arrayA != arrayB ? arrayA < arrayB : nodes[a].resLog2 < nodes[b].resLog2;
    });
    m.uploadNodes(nodes, stitch, order);
    m.bindAtlas(viewProj, eye, stitch);
    glEnable(GL_PRIMITIVE_RESTART_FIXED_INDEX);  // 0xFFFFFFFF for 32-bit indices
    std::vector<DrawElementsIndirectCommand> commands;
    std::vector<std::array<uint32_t, 3>> draws;  // (array, first command, commands)
    for (size_t j = 0; j < order.size();) {
      const uint32_t array = m.arrayOf(nodes[order[j]].pageLayer), res = nodes[order[j]].resLog2;
      if (draws.empty() || draws.back()[0] != array) draws.push_back({array, uint32_t(commands.size()), 0});
      size_t e = j;
      while (e < order.size() && nodes[order[e]].resLog2 == res && m.arrayOf(nodes[order[e]].pageLayer) == array) ++e;
      const Impl::GridRange& g = m.grid(res);
      commands.push_back({GLuint(g.indexCount), GLuint(e - j), GLuint(g.indexOffsetBytes / sizeof(uint32_t)),
                          g.baseVertex, GLuint(j)});
      ++draws.back()[2];
      stats.triangles += uint64_t(e - j) * (uint64_t(2) << (2 * res));
      j = e;
    }
    glBindBuffer(GL_DRAW_INDIRECT_BUFFER, m.indirectBuffer.id());
    glBufferData(GL_DRAW_INDIRECT_BUFFER, GLsizeiptr(commands.size() * sizeof(commands[0])), commands.data(),
                 GL_STREAM_DRAW);
    if (m.wireframe) glPolygonMode(GL_FRONT_AND_BACK, GL_LINE);
    for (const auto& [array, first, count] : draws) {
      m.bindPageArray(array);
      glMultiDrawElementsIndirect(GL_TRIANGLE_STRIP, GL_UNSIGNED_INT,
                                  reinterpret_cast<const void*>(size_t(first) * sizeof(DrawElementsIndirectCommand)),
                                  GLsizei(count), 0);
    }
    if (m.wireframe) glPolygonMode(GL_FRONT_AND_BACK, GL_FILL);
    glBindBuffer(GL_DRAW_INDIRECT_BUFFER, 0);
    m.bindPageArray(0);
    stats.drawCalls = uint32_t(draws.size());
    glDisable(GL_PRIMITIVE_RESTART_FIXED_INDEX);
    glBindVertexArray(0);
    glUseProgram(0);
  }
  m.resolve();
  glEndQuery(GL_TIME_ELAPSED);
  glFinish();
  stats.drawMs = msSince(t0);
  GLuint64 gpuNs = 0;
  glGetQueryObjectui64v(m.timerQuery.id(), GL_QUERY_RESULT, &gpuNs);
  // note: a GPU time longer than the wall time round it is a driver's bad value (Mesa llvmpipe's
  // first query); it is reported as unknown.
  stats.gpuMs = double(gpuNs) * 1e-6 <= stats.drawMs ? double(gpuNs) * 1e-6 : std::numeric_limits<double>::quiet_NaN();
  checkGl("AtlasRenderer::draw");
  return stats;
}

void AtlasRenderer::resize(uint32_t width, uint32_t height) {
  if (width == 0 || height == 0) throw std::invalid_argument("AtlasRenderer::resize: size must be positive");
  if (width == impl_->setup.width && height == impl_->setup.height) return;
  impl_->setup.width = width;
  impl_->setup.height = height;
  impl_->checkLimits();
  impl_->createFramebuffer();
}

void AtlasRenderer::blitToDefaultFramebuffer() const {
  const GLint w = GLint(impl_->setup.width), h = GLint(impl_->setup.height);
  glBindFramebuffer(GL_READ_FRAMEBUFFER, impl_->framebuffer.id());
  glBindFramebuffer(GL_DRAW_FRAMEBUFFER, 0);
  glBlitFramebuffer(0, 0, w, h, 0, 0, w, h, GL_COLOR_BUFFER_BIT, GL_NEAREST);
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  checkGl("blitToDefaultFramebuffer");
}

void AtlasRenderer::setWireframe(bool on) { impl_->wireframe = on; }

const AtlasRenderer::InspectionViews& AtlasRenderer::inspectionViews() const { return impl_->inspection; }

void AtlasRenderer::setInspectionViews(const InspectionViews& v) { impl_->inspection = v; }

namespace {

// RGBA8 pixels of `buffer` of framebuffer `framebuffer`, top row first.
std::vector<uint8_t> readFramebuffer(GLuint framebuffer, GLenum buffer, uint32_t w, uint32_t h) {
  std::vector<uint8_t> bottomUp(size_t(w) * h * 4), out(bottomUp.size());
  glBindFramebuffer(GL_READ_FRAMEBUFFER, framebuffer);
  glReadBuffer(buffer);
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  glReadPixels(0, 0, GLsizei(w), GLsizei(h), GL_RGBA, GL_UNSIGNED_BYTE, bottomUp.data());
  glBindFramebuffer(GL_READ_FRAMEBUFFER, 0);
  checkGl("readPixels");
  const size_t row = size_t(w) * 4;
  for (uint32_t y = 0; y < h; ++y)
    std::memcpy(out.data() + size_t(y) * row, bottomUp.data() + size_t(h - 1 - y) * row, row);
  return out;
}

}  // namespace

std::vector<uint8_t> AtlasRenderer::readPixels() const {
  return readFramebuffer(impl_->framebuffer.id(), GL_COLOR_ATTACHMENT0, impl_->setup.width, impl_->setup.height);
}

std::vector<uint8_t> readWindowPixels(uint32_t width, uint32_t height) {
  std::vector<uint8_t> rgba = readFramebuffer(0, GL_BACK, width, height);
  for (size_t i = 3; i < rgba.size(); i += 4) rgba[i] = 255;  // a window's alpha means nothing
  return rgba;
}

std::vector<std::vector<glm::vec3>> AtlasRenderer::captureVertices(std::span<const DrawNode> nodes,
                                                                   const StitchTables& stitch) {
  Impl& m = *impl_;
  std::vector<std::vector<glm::vec3>> out(nodes.size());
  if (nodes.empty()) return out;
  m.uploadNodes(nodes, stitch);
  m.bindAtlas(glm::mat4(1.0f), glm::vec3(0.0f), stitch);
  size_t total = 0;
  for (const DrawNode& n : nodes) total += size_t(m.grid(n.resLog2).vertexCount);
  const GLsizeiptr bytes = GLsizeiptr(total * sizeof(glm::vec3));
  glBindBuffer(GL_TRANSFORM_FEEDBACK_BUFFER, m.feedbackBuffer.id());
  glBufferData(GL_TRANSFORM_FEEDBACK_BUFFER, bytes, nullptr, GL_STREAM_READ);
  glBindBufferBase(GL_TRANSFORM_FEEDBACK_BUFFER, 0, m.feedbackBuffer.id());
  // note: draws need a complete framebuffer even with rasterizer discard, and a surfaceless
  // context has no default one.
  glBindFramebuffer(GL_FRAMEBUFFER, m.framebuffer.id());
  glEnable(GL_RASTERIZER_DISCARD);
  glBeginQuery(GL_TRANSFORM_FEEDBACK_PRIMITIVES_WRITTEN, m.feedbackQuery.id());
  glBeginTransformFeedback(GL_POINTS);
  uint32_t bound = 0;  // the page-pool array bound (bindAtlas binds the first)
  for (size_t k = 0; k < nodes.size(); ++k) {
    const uint32_t array = m.arrayOf(nodes[k].pageLayer);
    if (array != bound) m.bindPageArray(bound = array);
    const Impl::GridRange& g = m.grid(nodes[k].resLog2);
    glDrawArraysInstancedBaseInstance(GL_POINTS, g.baseVertex, g.vertexCount, 1, GLuint(k));
  }
  glEndTransformFeedback();
  if (bound != 0) m.bindPageArray(0);
  glEndQuery(GL_TRANSFORM_FEEDBACK_PRIMITIVES_WRITTEN);
  glDisable(GL_RASTERIZER_DISCARD);
  glBindVertexArray(0);
  glUseProgram(0);
  checkGl("captureVertices transform feedback");
  GLuint written = 0;
  glGetQueryObjectuiv(m.feedbackQuery.id(), GL_QUERY_RESULT, &written);
  if (written != total)
    throw std::runtime_error("captureVertices: transform feedback wrote " + std::to_string(written) + " of " +
                             std::to_string(total) + " vertices");
  const auto* mapped =
      static_cast<const glm::vec3*>(glMapBufferRange(GL_TRANSFORM_FEEDBACK_BUFFER, 0, bytes, GL_MAP_READ_BIT));
  if (!mapped) {
    checkGl("captureVertices glMapBufferRange");
    throw std::runtime_error("captureVertices: glMapBufferRange returned null");
  }
  size_t offset = 0;
  for (size_t k = 0; k < nodes.size(); ++k) {
    const size_t count = size_t(m.grid(nodes[k].resLog2).vertexCount);
    out[k].assign(mapped + offset, mapped + offset + count);
    offset += count;
  }
  glUnmapBuffer(GL_TRANSFORM_FEEDBACK_BUFFER);
  glBindBuffer(GL_TRANSFORM_FEEDBACK_BUFFER, 0);
  glBindBufferBase(GL_TRANSFORM_FEEDBACK_BUFFER, 0, 0);
  checkGl("captureVertices read back");
  return out;
}

}  // namespace gimlod::gl
