#include "bench/gl/baseline_draws.h"

#include <epoxy/gl.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <vector>

#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/type_ptr.hpp>

#include "gimlod_bench_shaders.h"
#include "shaders/interface.h"

namespace gimlod::bench {
namespace {

using gl::checkGl;
using gl::GlObject;
using gl::makeBuffer;
using gl::makeVertexArray;
using gl::uniform;

using Clock = std::chrono::steady_clock;

// Mean wall time in ms of `frames` calls of frame() (each ends with glFinish); 0 for no frames.
template <typename Frame>
double meanFrameMs(uint32_t frames, Frame&& frame) {
  double total = 0.0;
  for (uint32_t f = 0; f < frames; ++f) {
    const auto t0 = Clock::now();
    frame();
    total += std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
  }
  return frames ? total / frames : 0.0;
}

// A plain indexed grid over [0,1]^2 with a smooth height field, for the throughput baseline.
struct StaticMesh {
  GlObject vertices, indices, vertexArray;
  GLsizei indexCount = 0;
  uint64_t triangles = 0;
};

float staticHeight(float x, float y) {
  return 0.08f * std::sin(6.0f * x) * std::cos(5.0f * y) + 0.04f * std::sin(17.0f * x + 3.0f * y);
}

StaticMesh buildStaticMesh(uint64_t triangles) {
  const uint32_t side = std::max<uint32_t>(1, static_cast<uint32_t>(std::lround(std::sqrt(double(triangles) / 2.0))));
  if (uint64_t(side) * side * 6 > uint64_t(std::numeric_limits<GLsizei>::max()))
    throw std::invalid_argument("drawStaticMeshMs: too many triangles");
  std::vector<glm::vec3> positions;
  positions.reserve(size_t(side + 1) * (side + 1));
  for (uint32_t j = 0; j <= side; ++j)
    for (uint32_t i = 0; i <= side; ++i) {
      const float x = float(i) / float(side), y = float(j) / float(side);
      positions.emplace_back(x, y, staticHeight(x, y));
    }
  std::vector<uint32_t> idx;
  idx.reserve(size_t(side) * side * 6);
  for (uint32_t j = 0; j < side; ++j)
    for (uint32_t i = 0; i < side; ++i) {
      const uint32_t a = j * (side + 1) + i, b = a + 1, c = b + side + 1, d = a + side + 1;
      idx.insert(idx.end(), {a, b, c, a, c, d});
    }
  StaticMesh mesh;
  mesh.triangles = uint64_t(2) * side * side;
  mesh.indexCount = GLsizei(idx.size());
  mesh.vertexArray = makeVertexArray();
  glBindVertexArray(mesh.vertexArray.id());
  mesh.vertices = makeBuffer();
  glBindBuffer(GL_ARRAY_BUFFER, mesh.vertices.id());
  glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(positions.size() * sizeof(glm::vec3)), positions.data(), GL_STATIC_DRAW);
  glEnableVertexAttribArray(GIMLOD_ATTRIB_POSITION);
  glVertexAttribPointer(GIMLOD_ATTRIB_POSITION, 3, GL_FLOAT, GL_FALSE, sizeof(glm::vec3), nullptr);
  mesh.indices = makeBuffer();
  glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, mesh.indices.id());
  glBufferData(GL_ELEMENT_ARRAY_BUFFER, GLsizeiptr(idx.size() * sizeof(uint32_t)), idx.data(), GL_STATIC_DRAW);
  glBindVertexArray(0);
  glBindBuffer(GL_ARRAY_BUFFER, 0);
  checkGl("static mesh upload");
  return mesh;
}

}  // namespace

BaselineDraws::BaselineDraws(gl::AtlasRenderer& renderer)
    : renderer_(renderer),
      staticProgram_(gl::linkProgram("static_mesh", kShader_static_mesh_vert, kShader_static_mesh_frag)),
      staticTerrainProgram_(gl::linkProgram("static_terrain", kShader_static_terrain_vert, kShader_atlas_frag)) {
  gl::setPagePoolUnits(staticTerrainProgram_);
}

double BaselineDraws::drawStaticMeshMs(uint64_t triangles, uint32_t frames, uint64_t* drawnTriangles) {
  const StaticMesh mesh = buildStaticMesh(triangles);
  if (drawnTriangles) *drawnTriangles = mesh.triangles;
  const float aspect = float(renderer_.setup().width) / float(renderer_.setup().height);
  const glm::mat4 viewProj =
      glm::perspective(glm::radians(50.0f), aspect, 0.01f, 10.0f) *
      glm::lookAt(glm::vec3(0.5f, -0.55f, 0.75f), glm::vec3(0.5f, 0.45f, 0.0f), glm::vec3(0.0f, 0.0f, 1.0f));
  glUseProgram(staticProgram_.id());
  glUniformMatrix4fv(uniform(staticProgram_, "u_viewProj"), 1, GL_FALSE, glm::value_ptr(viewProj));
  glUniform2f(uniform(staticProgram_, "u_heightRange"), -0.12f, 0.12f);
  auto frame = [&] {
    renderer_.beginFrame();
    glUseProgram(staticProgram_.id());
    glBindVertexArray(mesh.vertexArray.id());
    glDrawElements(GL_TRIANGLES, mesh.indexCount, GL_UNSIGNED_INT, nullptr);
    renderer_.endFrame();
    glFinish();
  };
  frame();  // warm-up: first use compiles shader variants and faults in buffers
  checkGl("drawStaticMeshMs warm-up");
  const double ms = meanFrameMs(frames, frame);
  glBindVertexArray(0);
  glUseProgram(0);
  checkGl("drawStaticMeshMs");
  return ms;
}

double BaselineDraws::drawMeshMs(std::span<const glm::vec3> positions, std::span<const uint32_t> triangles,
                                 const glm::mat4& viewProj, const glm::vec3& eye, uint32_t frames) {
  if (triangles.size() % 3 != 0) throw std::invalid_argument("drawMeshMs: index count not a multiple of 3");
  GlObject vao = makeVertexArray(), vbo = makeBuffer(), ibo = makeBuffer();
  glBindVertexArray(vao.id());
  glBindBuffer(GL_ARRAY_BUFFER, vbo.id());
  glBufferData(GL_ARRAY_BUFFER, GLsizeiptr(positions.size_bytes()), positions.data(), GL_STATIC_DRAW);
  glEnableVertexAttribArray(GIMLOD_ATTRIB_POSITION);
  glVertexAttribPointer(GIMLOD_ATTRIB_POSITION, 3, GL_FLOAT, GL_FALSE, sizeof(glm::vec3), nullptr);
  glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, ibo.id());
  glBufferData(GL_ELEMENT_ARRAY_BUFFER, GLsizeiptr(triangles.size_bytes()), triangles.data(), GL_STATIC_DRAW);
  glBindVertexArray(0);
  glBindBuffer(GL_ARRAY_BUFFER, 0);
  checkGl("drawMeshMs upload");
  auto frame = [&] {
    renderer_.beginFrame();
    renderer_.setShading(staticTerrainProgram_, viewProj, eye);
    glBindVertexArray(vao.id());
    glDrawElements(GL_TRIANGLES, GLsizei(triangles.size()), GL_UNSIGNED_INT, nullptr);
    renderer_.endFrame();
    glFinish();
  };
  frame();  // warm-up
  const double ms = meanFrameMs(frames, frame);
  glBindVertexArray(0);
  glUseProgram(0);
  checkGl("drawMeshMs");
  return ms;
}

}  // namespace gimlod::bench
