// The shader interface written once in shaders/interface.h: after linking, every attribute
// location, the stitching tables' storage binding, the sampler units and every uniform the C++
// sets on the atlas program are what the C++ assumes, for terrain and mesh atlases.
#include <gtest/gtest.h>

#include <epoxy/gl.h>

#include <stdexcept>
#include <string>

#include "runtime/gl/atlas_renderer.h"
#include "runtime/gl/egl_context.h"
#include "tests/gl/gl_context_test.h"
#include "runtime/gl/gl_objects.h"
#include "runtime/overlay.h"
#include "shaders/interface.h"

namespace gimlod {
namespace {

class ShaderInterfaceGlTest : public test::GlContextTest<::testing::TestWithParam<bool>> {};
// Uniforms AtlasRenderer sets on its program (setShading, bindAtlas, setPagePoolUnits).
constexpr const char* kAtlasUniforms[] = {"u_viewProj", "u_eye",     "u_lightDir", "u_background",     "u_fogDistance",
                                          "u_samples",  "u_normals", "u_leafLog2", "u_entriesPerSide", "u_overlay"};
// Set through optionalUniform: used by terrain atlases only.
constexpr const char* kTerrainUniforms[] = {"u_spacing", "u_validSamples", "u_heightRange"};

TEST_P(ShaderInterfaceGlTest, AtlasProgramMatchesTheSharedDefinitions) {
  const bool geometry = GetParam();
  const gl::GlObject p = gl::linkAtlasProgram(geometry);
  const GLuint id = p.id();
  EXPECT_EQ(glGetAttribLocation(id, "a_ij"), GIMLOD_ATTRIB_GRID);
  EXPECT_EQ(glGetAttribLocation(id, "a_nodeA"), GIMLOD_ATTRIB_NODE_A);
  EXPECT_EQ(glGetAttribLocation(id, "a_nodeB"), GIMLOD_ATTRIB_NODE_B);

  const GLuint block = glGetProgramResourceIndex(id, GL_SHADER_STORAGE_BLOCK, "Stitch");
  ASSERT_NE(block, GL_INVALID_INDEX);
  const GLenum prop = GL_BUFFER_BINDING;
  GLint binding = -1;
  glGetProgramResourceiv(id, GL_SHADER_STORAGE_BLOCK, block, 1, &prop, 1, nullptr, &binding);
  EXPECT_EQ(binding, GIMLOD_STITCH_BINDING);
  const GLuint overlayBlock = glGetProgramResourceIndex(id, GL_SHADER_STORAGE_BLOCK, "Overlay");
  ASSERT_NE(overlayBlock, GL_INVALID_INDEX);
  binding = -1;
  glGetProgramResourceiv(id, GL_SHADER_STORAGE_BLOCK, overlayBlock, 1, &prop, 1, nullptr, &binding);
  EXPECT_EQ(binding, GIMLOD_OVERLAY_BINDING);
  // The shader's record is runtime/overlay.h's NodeOverlay: 16 bytes a node.
  const GLuint member = glGetProgramResourceIndex(id, GL_BUFFER_VARIABLE, "u_overlays[0].rgba");
  ASSERT_NE(member, GL_INVALID_INDEX);
  const GLenum strideProp = GL_TOP_LEVEL_ARRAY_STRIDE;
  GLint stride = 0;
  glGetProgramResourceiv(id, GL_BUFFER_VARIABLE, member, 1, &strideProp, 1, nullptr, &stride);
  EXPECT_EQ(stride, GLint(sizeof(NodeOverlay)));

  for (const char* name : kAtlasUniforms)
    EXPECT_GE(glGetUniformLocation(id, name), 0) << name << (geometry ? " (mesh)" : " (terrain)");
  if (!geometry) {
    for (const char* name : kTerrainUniforms) EXPECT_GE(glGetUniformLocation(id, name), 0) << name;
  }

  GLint unit = -1;
  glGetUniformiv(id, glGetUniformLocation(id, "u_samples"), &unit);
  EXPECT_EQ(unit, GIMLOD_SAMPLES_UNIT);
  glGetUniformiv(id, glGetUniformLocation(id, "u_normals"), &unit);
  EXPECT_EQ(unit, GIMLOD_NORMALS_UNIT);
  EXPECT_EQ(glGetError(), GLenum(GL_NO_ERROR));
}

TEST_P(ShaderInterfaceGlTest, MissingUniformIsAnErrorInDebugBuilds) {
  const gl::GlObject p = gl::linkAtlasProgram(GetParam());
  EXPECT_EQ(gl::programName(p), GetParam() ? "atlas (mesh)" : "atlas");
  EXPECT_EQ(gl::optionalUniform(p, "u_noSuchUniform"), -1);
  EXPECT_GE(gl::uniform(p, "u_viewProj"), 0);
#ifndef NDEBUG
  try {
    gl::uniform(p, "u_noSuchUniform");
    ADD_FAILURE() << "no error for a missing uniform";
  } catch (const std::logic_error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("u_noSuchUniform"), std::string::npos) << what;
    EXPECT_NE(what.find(gl::programName(p)), std::string::npos) << what;
  }
#else
  EXPECT_EQ(gl::uniform(p, "u_noSuchUniform"), -1);
#endif
}

INSTANTIATE_TEST_SUITE_P(TerrainAndMesh, ShaderInterfaceGlTest, ::testing::Bool(),
                         [](const ::testing::TestParamInfo<bool>& i) { return i.param ? "Mesh" : "Terrain"; });

}  // namespace
}  // namespace gimlod
