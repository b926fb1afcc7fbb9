// AtlasRenderer on headless EGL (llvmpipe in CI): context, GPU border stitching
// checked bit-exactly through transform feedback, and drawing into the offscreen framebuffer.
#include <gtest/gtest.h>

#include <epoxy/gl.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <set>
#include <stdexcept>

#include <glm/gtc/matrix_transform.hpp>

#include "runtime/gl/atlas_renderer.h"
#include "runtime/gl/egl_context.h"
#include "tests/gl/gl_context_test.h"

namespace gimlod {
namespace {

// ---------------------------------------------------------------------------------------------
// GL fixture: one context per test suite.

class RendererGlTest : public test::GlContextTest<> {};

TEST_F(RendererGlTest, ContextIsCore43OrNewer) {
  ASSERT_NE(context_, nullptr);
  GLint major = 0, minor = 0, profile = 0;
  glGetIntegerv(GL_MAJOR_VERSION, &major);
  glGetIntegerv(GL_MINOR_VERSION, &minor);
  glGetIntegerv(GL_CONTEXT_PROFILE_MASK, &profile);
  EXPECT_GE(major * 10 + minor, 43) << context_->version();
  EXPECT_TRUE(profile & GL_CONTEXT_CORE_PROFILE_BIT);
  EXPECT_FALSE(context_->renderer().empty());
  EXPECT_NE(context_->version().find(std::to_string(major) + "." + std::to_string(minor)), std::string::npos);
  EXPECT_EQ(glGetError(), GLenum(GL_NO_ERROR));
  EXPECT_NE(context_->display().find("EGL vendor"), std::string::npos) << context_->display();
  EXPECT_FALSE(context_->vendor().empty());
  std::printf("GL_RENDERER: %s\nGL_VERSION: %s\nEGL display: %s\n", context_->renderer().c_str(),
              context_->version().c_str(), context_->display().c_str());
}

// ---------------------------------------------------------------------------------------------
// Synthetic terrain: a global height function sampled into per-node pages.

using HeightFn = float (*)(int32_t gx, int32_t gy);

float randomHeight(int32_t gx, int32_t gy) {
  uint32_t h = uint32_t(gx) * 0x9E3779B1u ^ (uint32_t(gy) + 0x7F4A7C15u) * 0x85EBCA77u;
  h ^= h >> 15;
  h *= 0x2C1B3C6Du;
  h ^= h >> 13;
  return float(h & 0xFFFFu) / 65535.0f * 50.0f;
}

float slopedHeight(int32_t gx, int32_t gy) { return 0.25f * float(gx) + 0.5f * float(gy); }

float smoothHeight(int32_t gx, int32_t gy) {
  return 6.0f + 5.0f * std::sin(0.15f * float(gx)) * std::cos(0.11f * float(gy));
}

struct Scene {
  std::vector<DrawNode> nodes;
  StitchTables stitch;
};

DrawNode makeNode(int32_t x, int32_t y, uint32_t sizeLog2, uint32_t res, uint32_t pageResLog2, uint32_t layer) {
  return DrawNode{x, y, sizeLog2, res, pageResLog2, layer};
}

// Uploads each node's page, sampled from `h` at the node's page spacing.
void uploadPages(gl::AtlasRenderer& r, const std::vector<DrawNode>& nodes, HeightFn h) {
  for (const DrawNode& n : nodes) {
    const uint32_t s = (1u << n.pageResLog2) + 1, ps = n.sizeLog2 - n.pageResLog2;
    std::vector<float> heights(size_t(s) * s);
    std::vector<PackedNormal> normals(size_t(s) * s, PackedNormal{128, 128, 255, 255});
    for (uint32_t v = 0; v < s; ++v)
      for (uint32_t u = 0; u < s; ++u)
        heights[size_t(v) * s + u] = h(n.originX + int32_t(u << ps), n.originY + int32_t(v << ps));
    r.uploadPage(n.pageLayer, s, heights.data(), normals.data());
  }
}

// Test-side stitch tables by brute force over the node rectangles (independent of
// runtime/stitch.cpp): each entry holds the log2 spacing of the node across that side.
StitchTables bruteForceStitch(const std::vector<DrawNode>& nodes, uint32_t leafLog2, uint32_t entriesPerSide) {
  StitchTables t;
  t.leafLog2 = leafLog2;
  t.entriesPerSide = entriesPerSide;
  t.bytes.assign(nodes.size() * 4 * entriesPerSide, 0);
  for (size_t k = 0; k < nodes.size(); ++k) {
    const DrawNode& a = nodes[k];
    const int32_t size = 1 << a.sizeLog2;
    for (uint32_t side = 0; side < 4; ++side)
      for (uint32_t e = 0; e < entriesPerSide && int32_t(e << leafLog2) < size; ++e) {
        // A point just across the side, in the middle of the entry's span (doubled coords).
        const int32_t t2 = 2 * int32_t(e << leafLog2) + (1 << leafLog2);
        const int32_t px2 = side == 0 || side == 2 ? 2 * a.originX + t2
                            : side == 1            ? 2 * (a.originX + size) + 1
                                                   : 2 * a.originX - 1;
        const int32_t py2 = side == 1 || side == 3 ? 2 * a.originY + t2
                            : side == 2            ? 2 * (a.originY + size) + 1
                                                   : 2 * a.originY - 1;
        for (const DrawNode& b : nodes) {
          const int32_t bs = 1 << b.sizeLog2;
          if (px2 > 2 * b.originX && px2 < 2 * (b.originX + bs) && py2 > 2 * b.originY && py2 < 2 * (b.originY + bs))
            t.side(k, side)[e] = uint8_t(b.sizeLog2 - b.resLog2);
        }
      }
  }
  return t;
}

struct BorderCheck {
  size_t borderVertices = 0;  // vertices on shared sides that were checked
  size_t mismatches = 0;      // of those, without a bit-identical vertex across the side
};

bool sameBits(const glm::vec3& a, const glm::vec3& b) { return std::memcmp(&a, &b, sizeof a) == 0; }

// Every vertex of node a on its side `side` (0 bottom, 1 right, 2 top, 3 left) within the span
// shared with node b must equal, bit for bit, a vertex of b on the opposite side.
void checkSharedSide(const DrawNode& a, const std::vector<glm::vec3>& va, const DrawNode& b,
                     const std::vector<glm::vec3>& vb, uint32_t side, BorderCheck* out) {
  const int32_t as = 1 << a.sizeLog2, bs = 1 << b.sizeLog2;
  const bool horizontal = side == 0 || side == 2;
  const int32_t aLine = side == 0 ? a.originY : side == 1 ? a.originX + as : side == 2 ? a.originY + as : a.originX;
  const int32_t bLine = side == 0 ? b.originY + bs : side == 1 ? b.originX : side == 2 ? b.originY : b.originX + bs;
  if (aLine != bLine) return;
  const int32_t aLo = horizontal ? a.originX : a.originY, bLo = horizontal ? b.originX : b.originY;
  const int32_t lo = std::max(aLo, bLo), hi = std::min(aLo + as, bLo + bs);
  if (lo >= hi) return;
  auto sideVertices = [](const DrawNode& d, const std::vector<glm::vec3>& v, uint32_t s, int32_t from, int32_t to) {
    const uint32_t n = 1u << d.resLog2, so = d.sizeLog2 - d.resLog2;
    const int32_t start = s == 0 || s == 2 ? d.originX : d.originY;
    std::vector<glm::vec3> out;
    for (uint32_t k = 0; k <= n; ++k) {
      const int32_t t = start + int32_t(k << so);
      if (t < from || t > to) continue;
      const uint32_t i = s == 1 ? n : s == 3 ? 0 : k, j = s == 2 ? n : s == 0 ? 0 : k;
      out.push_back(v[size_t(j) * (n + 1) + i]);
    }
    return out;
  };
  const auto mine = sideVertices(a, va, side, lo, hi);
  const auto theirs = sideVertices(b, vb, (side + 2) % 4, INT32_MIN, INT32_MAX);
  for (const glm::vec3& p : mine) {
    ++out->borderVertices;
    const bool found = std::any_of(theirs.begin(), theirs.end(), [&](const glm::vec3& q) { return sameBits(p, q); });
    out->mismatches += !found;
  }
}

BorderCheck checkAllBorders(const std::vector<DrawNode>& nodes, const std::vector<std::vector<glm::vec3>>& verts) {
  BorderCheck c;
  for (size_t a = 0; a < nodes.size(); ++a)
    for (size_t b = 0; b < nodes.size(); ++b)
      if (a != b)
        for (uint32_t side = 0; side < 4; ++side) checkSharedSide(nodes[a], verts[a], nodes[b], verts[b], side, &c);
  return c;
}

StitchTables zeroed(StitchTables t) {
  std::fill(t.bytes.begin(), t.bytes.end(), uint8_t(0));
  return t;
}

gl::RendererSetup smallSetup(uint32_t pageIntervalsLog2) {
  gl::RendererSetup s;
  s.width = 128;
  s.height = 96;
  s.pageIntervalsLog2 = pageIntervalsLog2;
  s.pageCapacity = 64;
  s.minResLog2 = 0;
  s.maxResLog2 = pageIntervalsLog2;
  s.spacing = {1.5, 2.0};
  s.heightRange = {0.f, 50.f};
  return s;
}

// Captures with the given tables and with zeroed tables; checks the stitched run is exact, the
// negative control cracks (when expected), and the captured layout is the grid order.
void expectCrackFree(gl::AtlasRenderer& r, const Scene& s, bool controlMustCrack, const std::string& label) {
  const auto verts = r.captureVertices(s.nodes, s.stitch);
  ASSERT_EQ(verts.size(), s.nodes.size());
  for (size_t k = 0; k < s.nodes.size(); ++k) {
    const uint32_t side = (1u << s.nodes[k].resLog2) + 1;
    ASSERT_EQ(verts[k].size(), size_t(side) * side);
  }
  const BorderCheck c = checkAllBorders(s.nodes, verts);
  EXPECT_GT(c.borderVertices, 0u) << label;
  EXPECT_EQ(c.mismatches, 0u) << label << ": " << c.mismatches << " of " << c.borderVertices;
  const BorderCheck control = checkAllBorders(s.nodes, r.captureVertices(s.nodes, zeroed(s.stitch)));
  if (controlMustCrack) {
    EXPECT_GT(control.mismatches, 0u) << label << ": control did not crack";
  }
}

TEST_F(RendererGlTest, CapturedInteriorVerticesAreTheExactSamples) {
  gl::AtlasRenderer r(smallSetup(4));
  const std::vector<DrawNode> nodes = {makeNode(16, 32, 4, 2, 3, 5), makeNode(-16, 0, 4, 4, 4, 9)};
  uploadPages(r, nodes, randomHeight);
  const StitchTables stitch = bruteForceStitch(nodes, 4, 1);
  const auto verts = r.captureVertices(nodes, stitch);
  ASSERT_EQ(verts.size(), 2u);
  for (size_t k = 0; k < nodes.size(); ++k) {
    const DrawNode& d = nodes[k];
    const uint32_t n = 1u << d.resLog2, so = d.sizeLog2 - d.resLog2;
    ASSERT_EQ(verts[k].size(), size_t(n + 1) * (n + 1));
    for (uint32_t j = 0; j <= n; ++j)
      for (uint32_t i = 0; i <= n; ++i) {
        const int32_t gx = d.originX + int32_t(i << so), gy = d.originY + int32_t(j << so);
        const glm::vec3 want(float(gx) * 1.5f, float(gy) * 2.0f, randomHeight(gx, gy));
        EXPECT_TRUE(sameBits(verts[k][size_t(j) * (n + 1) + i], want)) << "node " << k << " (" << i << "," << j << ")";
      }
  }
}

TEST_F(RendererGlTest, HandBuiltTablesStitchTwoResolutions) {
  gl::AtlasRenderer r(smallSetup(4));
  // Same size (16 intervals), res 4 (spacing 1) left of res 2 (spacing 4).
  Scene s;
  s.nodes = {makeNode(0, 0, 4, 4, 4, 0), makeNode(16, 0, 4, 2, 4, 1)};
  s.stitch.leafLog2 = 4;
  s.stitch.entriesPerSide = 1;
  s.stitch.bytes = {0, 2, 0, 0,   // node 0: right side meets spacing 2^2
                    0, 0, 0, 0};  // node 1: left side meets spacing 2^0 (finer: no move)
  EXPECT_EQ(bruteForceStitch(s.nodes, 4, 1).bytes, (std::vector<uint8_t>{0, 2, 0, 0, 0, 0, 0, 0}));
  uploadPages(r, s.nodes, randomHeight);
  expectCrackFree(r, s, true, "random heights");
  // On a plane the unstitched T-junctions lie on the coarse edge, but their vertices still do
  // not coincide with the coarse node's: the check is on positions, not only on heights.
  uploadPages(r, s.nodes, slopedHeight);
  expectCrackFree(r, s, true, "sloped plane");
}

TEST_F(RendererGlTest, BigNodeAgainstTwoSmallerNodes) {
  gl::AtlasRenderer r(smallSetup(5));
  for (uint32_t bigRes : {2u, 3u, 4u, 5u}) {
    Scene s;
    // Big node 32 wide (page mostly at half resolution) left of two 16-wide nodes, a level below.
    s.nodes = {makeNode(0, 0, 5, bigRes, std::max(4u, bigRes), 0), makeNode(32, 0, 4, 4, 4, 1),
               makeNode(32, 16, 4, 1, 4, 2)};
    s.stitch = bruteForceStitch(s.nodes, 4, 2);
    EXPECT_EQ(s.stitch.side(0, 1)[0], 0);  // spacing 2^0 below
    EXPECT_EQ(s.stitch.side(0, 1)[1], 3);  // spacing 2^3 above
    uploadPages(r, s.nodes, randomHeight);
    expectCrackFree(r, s, true, "big res " + std::to_string(bigRes));
  }
}

TEST_F(RendererGlTest, BigNodeAgainstEightNodesThreeLevelsDown) {
  gl::AtlasRenderer r(smallSetup(5));
  for (uint32_t bigRes : {3u, 4u, 5u}) {
    Scene s;
    s.nodes.push_back(makeNode(0, 0, 5, bigRes, 5, 0));
    // Eight 4-wide nodes along the big node's right side, resolutions 0..2 mixed.
    for (uint32_t k = 0; k < 8; ++k) s.nodes.push_back(makeNode(32, int32_t(4 * k), 2, k % 3, 2, 1 + k));
    // A few more on top of the big node so its top side is checked too.
    s.nodes.push_back(makeNode(0, 32, 4, 2, 4, 9));
    s.nodes.push_back(makeNode(16, 32, 3, 3, 3, 10));
    s.nodes.push_back(makeNode(24, 32, 3, 0, 3, 11));
    s.stitch = bruteForceStitch(s.nodes, 2, 8);
    uploadPages(r, s.nodes, randomHeight);
    expectCrackFree(r, s, true, "big res " + std::to_string(bigRes));
  }
}

// ---------------------------------------------------------------------------------------------
// Drawing.

bool nearColour(const uint8_t* px, const std::array<float, 3>& c, int tolerance) {
  for (int k = 0; k < 3; ++k)
    if (std::abs(int(px[k]) - int(std::lround(c[k] * 255.0f))) > tolerance) return false;
  return true;
}

// 2x2 nodes over [0,64]^2 at mixed resolutions, smooth heights.
Scene quadScene(gl::AtlasRenderer& r) {
  Scene s;
  s.nodes = {makeNode(0, 0, 5, 5, 5, 0), makeNode(32, 0, 5, 3, 5, 1), makeNode(0, 32, 5, 4, 5, 2),
             makeNode(32, 32, 5, 2, 5, 3)};
  s.stitch = bruteForceStitch(s.nodes, 5, 2);
  uploadPages(r, s.nodes, smoothHeight);
  return s;
}

TEST_F(RendererGlTest, DrawShowsTerrainBelowAndSkyAbove) {
  gl::RendererSetup setup = smallSetup(5);
  setup.spacing = {1.0, 1.0};
  setup.heightRange = {0.f, 12.f};
  gl::AtlasRenderer r(setup);
  const Scene s = quadScene(r);
  const glm::vec3 eye(32.f, -30.f, 20.f);
  const glm::mat4 viewProj = glm::perspective(glm::radians(50.f), 128.f / 96.f, 0.5f, 500.f) *
                             glm::lookAt(eye, glm::vec3(32.f, 20.f, 0.f), glm::vec3(0.f, 0.f, 1.f));
  const auto t0 = std::chrono::steady_clock::now();
  const gl::DrawStats stats = r.draw(viewProj, eye, s.nodes, s.stitch);
  const double callMs = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  uint64_t triangles = 0;
  for (const DrawNode& n : s.nodes) triangles += uint64_t(2) << (2 * n.resLog2);
  EXPECT_EQ(stats.triangles, triangles);
  EXPECT_EQ(stats.drawCalls, 1u);  // one multi-draw-indirect for the cut (its pages in one array)
  // The draw's own time (submission and glFinish) is within the call; the GPU's, when the timer
  // query answers, within that.
  EXPECT_GT(stats.drawMs, 0.0);
  EXPECT_LE(stats.drawMs, callMs);
  if (!std::isnan(stats.gpuMs)) {
    EXPECT_GE(stats.gpuMs, 0.0);
    EXPECT_LE(stats.gpuMs, stats.drawMs);
  }
  const std::vector<uint8_t> px = r.readPixels();
  ASSERT_EQ(px.size(), size_t(128) * 96 * 4);
  auto at = [&](int x, int y) { return px.data() + (size_t(y) * 128 + x) * 4; };
  EXPECT_FALSE(nearColour(at(64, 48), setup.background, 8)) << "centre should be terrain";
  EXPECT_TRUE(nearColour(at(0, 0), setup.background, 2)) << "top-left should be sky";
  EXPECT_TRUE(nearColour(at(127, 0), setup.background, 2)) << "top-right should be sky";
  size_t terrain = 0;
  for (int y = 0; y < 96; ++y)
    for (int x = 0; x < 128; ++x) terrain += !nearColour(at(x, y), setup.background, 2);
  EXPECT_GT(terrain, size_t(128 * 96 / 5));
  EXPECT_EQ(glGetError(), GLenum(GL_NO_ERROR));
}

TEST_F(RendererGlTest, FragmentsOutsideTheValidExtentAreDiscarded) {
  gl::RendererSetup setup = smallSetup(5);
  setup.spacing = {1.0, 1.0};
  setup.heightRange = {0.f, 12.f};
  setup.validSamples = {33, 65};  // x beyond sample 32 is padding
  gl::AtlasRenderer r(setup);
  const Scene s = quadScene(r);
  // Straight down onto [0,64]^2, x to the right, y up.
  const glm::mat4 viewProj = glm::ortho(0.f, 64.f, 0.f, 64.f, -100.f, 100.f);
  r.draw(viewProj, glm::vec3(32.f, 32.f, 100.f), s.nodes, s.stitch);
  const std::vector<uint8_t> px = r.readPixels();
  auto at = [&](int x, int y) { return px.data() + (size_t(y) * 128 + x) * 4; };
  for (int y : {10, 48, 85}) {
    EXPECT_FALSE(nearColour(at(20, y), setup.background, 8)) << "x=20 y=" << y;
    EXPECT_TRUE(nearColour(at(100, y), setup.background, 2)) << "x=100 y=" << y;
  }
  // Same view without the limit: the right half is drawn.
  setup.validSamples = {0, 0};
  gl::AtlasRenderer all(setup);
  const Scene s2 = quadScene(all);
  all.draw(viewProj, glm::vec3(32.f, 32.f, 100.f), s2.nodes, s2.stitch);
  const std::vector<uint8_t> px2 = all.readPixels();
  EXPECT_FALSE(nearColour(px2.data() + (size_t(48) * 128 + 100) * 4, setup.background, 8));
}

TEST_F(RendererGlTest, AttributeLevelChangesShadingNotGeometry) {
  gl::RendererSetup setup = smallSetup(5);
  setup.spacing = {1.0, 1.0};
  setup.heightRange = {0.f, 1.f};
  gl::AtlasRenderer r(setup);
  // A flat page whose normal map alternates tilts every texel: full detail at texLod 0, an even
  // mean at the coarsest level.
  const uint32_t side = 33;
  std::vector<float> heights(side * side, 0.f);
  std::vector<PackedNormal> normals(side * side);
  for (uint32_t v = 0; v < side; ++v)
    for (uint32_t u = 0; u < side; ++u)
      normals[v * side + u] = (u + v) % 2 ? packNormal(0.7f, 0.f, 0.714f) : packNormal(-0.7f, 0.f, 0.714f);
  r.uploadPage(0, side, heights.data(), normals.data());
  StitchTables t;
  t.bytes.assign(4, 0);
  const glm::mat4 viewProj = glm::ortho(0.f, 32.f, 0.f, 32.f, -10.f, 10.f);
  auto spread = [&](uint32_t texLod) {
    std::vector<DrawNode> nodes = {makeNode(0, 0, 5, 5, 5, 0)};
    nodes[0].texLod = texLod;
    r.draw(viewProj, glm::vec3(16.f, 16.f, 10.f), nodes, t);
    const std::vector<uint8_t> px = r.readPixels();
    int lo = 255, hi = 0;
    for (int y = 20; y < 76; ++y)
      for (int x = 20; x < 108; ++x) {
        const int g = px[(size_t(y) * 128 + x) * 4 + 1];
        lo = std::min(lo, g), hi = std::max(hi, g);
      }
    return std::make_pair(hi - lo, r.captureVertices(nodes, t));
  };
  const auto fine = spread(0), coarse = spread(5);
  EXPECT_GT(fine.first, 20) << "full-resolution normals should vary";
  EXPECT_LT(coarse.first, fine.first / 3) << "the coarsest normal level should be nearly even";
  ASSERT_EQ(fine.second.size(), coarse.second.size());
  for (size_t k = 0; k < fine.second.size(); ++k)
    EXPECT_EQ(0,
              std::memcmp(fine.second[k].data(), coarse.second[k].data(), fine.second[k].size() * sizeof(glm::vec3)));
  std::vector<DrawNode> bad = {makeNode(0, 0, 5, 5, 5, 0)};
  bad[0].texLod = 6;  // beyond the page's levels
  EXPECT_THROW(r.draw(viewProj, glm::vec3(0.f), bad, t), std::invalid_argument);
  EXPECT_EQ(glGetError(), GLenum(GL_NO_ERROR));
}

// A page pool of several texture arrays (RendererSetup::layersPerArray below the GL limit, as an
// atlas of more pages than the limit gets): the quad scene with its four pages in three arrays
// draws in one multi-draw per array, and its picture and stitched vertices are those of the same
// pages in one array, bit for bit.
TEST_F(RendererGlTest, PagesInSeveralTextureArraysDrawAsInOne) {
  gl::RendererSetup setup = smallSetup(5);
  setup.spacing = {1.0, 1.0};
  setup.heightRange = {0.f, 12.f};
  gl::AtlasRenderer one(setup);
  setup.layersPerArray = 2;
  setup.pageCapacity = 6;
  gl::AtlasRenderer three(setup);
  EXPECT_EQ(one.pageArrays(), 1u);
  ASSERT_EQ(three.pageArrays(), 3u);
  EXPECT_EQ(three.layersPerArray(), 2u);
  Scene a = quadScene(one);
  // The same pages at pages 5, 0, 3, 4 of the three-array pool: arrays 2, 0, 1, 2, so pages 5
  // and 3 (and 4 and 0) share a layer index in different arrays and a draw that bound the wrong
  // array would read another node's data.
  Scene b = a;
  const uint32_t pages[4] = {5, 0, 3, 4};
  for (size_t k = 0; k < b.nodes.size(); ++k) b.nodes[k].pageLayer = pages[k];
  uploadPages(three, b.nodes, smoothHeight);
  const glm::vec3 eye(32.f, -30.f, 20.f);
  const glm::mat4 viewProj = glm::perspective(glm::radians(50.f), 128.f / 96.f, 0.5f, 500.f) *
                             glm::lookAt(eye, glm::vec3(32.f, 20.f, 0.f), glm::vec3(0.f, 0.f, 1.f));
  const gl::DrawStats sa = one.draw(viewProj, eye, a.nodes, a.stitch);
  const gl::DrawStats sb = three.draw(viewProj, eye, b.nodes, b.stitch);
  EXPECT_EQ(sa.drawCalls, 1u);
  EXPECT_EQ(sb.drawCalls, 3u);
  EXPECT_EQ(sa.triangles, sb.triangles);
  const std::vector<uint8_t> pa = one.readPixels(), pb = three.readPixels();
  ASSERT_EQ(pa.size(), pb.size());
  size_t differ = 0, terrain = 0;
  for (size_t i = 0; i < pa.size(); i += 4) {
    differ += std::memcmp(pa.data() + i, pb.data() + i, 4) != 0;
    terrain += pa[i + 1] != uint8_t(setup.background[1] * 255.f + 0.5f);
  }
  EXPECT_EQ(differ, 0u);
  EXPECT_GT(terrain, pa.size() / 4 / 4) << "the terrain should fill part of the picture";
  const auto va = one.captureVertices(a.nodes, a.stitch), vb = three.captureVertices(b.nodes, b.stitch);
  ASSERT_EQ(va.size(), vb.size());
  for (size_t k = 0; k < va.size(); ++k) {
    ASSERT_EQ(va[k].size(), vb[k].size());
    EXPECT_EQ(0, std::memcmp(va[k].data(), vb[k].data(), va[k].size() * sizeof(glm::vec3))) << "node " << k;
  }
}

TEST_F(RendererGlTest, BadInputsThrowAndThePoolSpansTextureArrays) {
  gl::RendererSetup setup = smallSetup(4);
  GLint maxLayers = 0;
  glGetIntegerv(GL_MAX_ARRAY_TEXTURE_LAYERS, &maxLayers);
  // One page past the GL's layer limit: two texture arrays, the second of one layer.
  setup.pageCapacity = uint32_t(maxLayers) + 1;
  gl::AtlasRenderer r(setup);
  EXPECT_EQ(r.pageCapacity(), uint32_t(maxLayers) + 1);
  EXPECT_EQ(r.layersPerArray(), uint32_t(maxLayers));
  EXPECT_EQ(r.pageArrays(), 2u);
  std::vector<float> h(18 * 18, 0.f);
  EXPECT_NO_THROW(r.uploadPage(r.pageCapacity() - 1, 17, h.data(), nullptr));
  EXPECT_THROW(r.uploadPage(r.pageCapacity(), 17, h.data(), nullptr), std::invalid_argument);
  EXPECT_THROW(r.uploadPage(0, 18, h.data(), nullptr), std::invalid_argument);
  EXPECT_NO_THROW(r.uploadPage(0, 5, h.data(), nullptr));
  const std::vector<DrawNode> bad = {makeNode(0, 0, 4, 5, 4, 0)};  // res above the page
  StitchTables t;
  t.bytes.assign(4, 0);
  EXPECT_THROW(r.draw(glm::mat4(1.f), glm::vec3(0.f), bad, t), std::invalid_argument);
  EXPECT_EQ(glGetError(), GLenum(GL_NO_ERROR));
}

}  // namespace
}  // namespace gimlod
