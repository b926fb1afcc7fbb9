// The render benchmarks' baselines (bench/gl) draw into the atlas renderer's framebuffer, and
// their programs match the shared shader interface.
#include <gtest/gtest.h>

#include <epoxy/gl.h>

#include <array>
#include <cmath>
#include <cstdlib>
#include <vector>

#include "bench/gl/baseline_draws.h"
#include "gimlod_bench_shaders.h"
#include "runtime/gl/atlas_renderer.h"
#include "runtime/gl/egl_context.h"
#include "tests/gl/gl_context_test.h"
#include "runtime/gl/gl_objects.h"
#include "shaders/interface.h"

namespace gimlod {
namespace {

class BaselineDrawsGlTest : public test::GlContextTest<> {};
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

bool nearColour(const uint8_t* px, const std::array<float, 3>& c, int tolerance) {
  for (int k = 0; k < 3; ++k)
    if (std::abs(int(px[k]) - int(std::lround(c[k] * 255.0f))) > tolerance) return false;
  return true;
}

TEST_F(BaselineDrawsGlTest, StaticMeshBaselineDraws) {
  gl::AtlasRenderer r(smallSetup(4));
  bench::BaselineDraws baselines(r);
  uint64_t drawn = 0;
  const double ms = baselines.drawStaticMeshMs(5000, 3, &drawn);
  EXPECT_GT(ms, 0.0);
  EXPECT_NEAR(double(drawn), 5000.0, 200.0);
  const std::vector<uint8_t> px = r.readPixels();
  EXPECT_FALSE(nearColour(px.data() + (size_t(48) * 128 + 64) * 4, smallSetup(4).background, 8))
      << "the baseline mesh should cover the centre";
}

TEST_F(BaselineDrawsGlTest, ProgramsMatchTheSharedDefinitions) {
  const gl::GlObject mesh = gl::linkProgram("static_mesh", kShader_static_mesh_vert, kShader_static_mesh_frag);
  EXPECT_EQ(glGetAttribLocation(mesh.id(), "a_position"), GIMLOD_ATTRIB_POSITION);
  for (const char* name : {"u_viewProj", "u_heightRange"}) EXPECT_GE(glGetUniformLocation(mesh.id(), name), 0) << name;
  const gl::GlObject terrain = gl::linkProgram("static_terrain", kShader_static_terrain_vert, kShader_atlas_frag);
  EXPECT_EQ(glGetAttribLocation(terrain.id(), "a_position"), GIMLOD_ATTRIB_POSITION);
  // Every uniform AtlasRenderer::setShading sets, terrain-only ones included.
  for (const char* name : {"u_viewProj", "u_eye", "u_spacing", "u_validSamples", "u_heightRange", "u_lightDir",
                           "u_background", "u_fogDistance", "u_samples", "u_normals"})
    EXPECT_GE(glGetUniformLocation(terrain.id(), name), 0) << name;
  EXPECT_EQ(glGetError(), GLenum(GL_NO_ERROR));
}

}  // namespace
}  // namespace gimlod
