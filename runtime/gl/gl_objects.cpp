// RAII wrappers and error checks for OpenGL objects.
#include "runtime/gl/gl_objects.h"

#include <algorithm>
#include <cstdio>
#include <stdexcept>

namespace gimlod::gl {
namespace {

std::string glErrorName(GLenum e) {
  switch (e) {
    case GL_INVALID_ENUM: return "GL_INVALID_ENUM";
    case GL_INVALID_VALUE: return "GL_INVALID_VALUE";
    case GL_INVALID_OPERATION: return "GL_INVALID_OPERATION";
    case GL_INVALID_FRAMEBUFFER_OPERATION: return "GL_INVALID_FRAMEBUFFER_OPERATION";
    case GL_OUT_OF_MEMORY: return "GL_OUT_OF_MEMORY";
    case GL_STACK_OVERFLOW: return "GL_STACK_OVERFLOW";
    case GL_STACK_UNDERFLOW: return "GL_STACK_UNDERFLOW";
    default: {
      char buf[32];
      std::snprintf(buf, sizeof buf, "GL error 0x%04x", e);
      return buf;
    }
  }
}

GlObject compileShader(const char* programName, GLenum stage, const char* source) {
  GlObject shader(glCreateShader(stage), [](GLuint id) { glDeleteShader(id); });
  glShaderSource(shader.id(), 1, &source, nullptr);
  glCompileShader(shader.id());
  GLint ok = GL_FALSE, length = 0;
  glGetShaderiv(shader.id(), GL_COMPILE_STATUS, &ok);
  if (!ok) {
    glGetShaderiv(shader.id(), GL_INFO_LOG_LENGTH, &length);
    std::string log(static_cast<size_t>(std::max(length, 1)), '\0');
    glGetShaderInfoLog(shader.id(), length, nullptr, log.data());
    throw std::runtime_error(std::string("compiling the ") + (stage == GL_VERTEX_SHADER ? "vertex" : "fragment") +
                             " shader of " + programName + " failed:\n" + log);
  }
  return shader;
}

}  // namespace

void checkGl(const char* what) {
  GLenum e = glGetError();
  if (e == GL_NO_ERROR) return;
  std::string names = glErrorName(e);
  for (int k = 0; k < 16 && (e = glGetError()) != GL_NO_ERROR; ++k) names += ", " + glErrorName(e);
  throw std::runtime_error(std::string("OpenGL error after ") + what + ": " + names);
}

GlObject makeBuffer() {
  GLuint id = 0;
  glGenBuffers(1, &id);
  return GlObject(id, [](GLuint x) { glDeleteBuffers(1, &x); });
}

GlObject makeTexture() {
  GLuint id = 0;
  glGenTextures(1, &id);
  return GlObject(id, [](GLuint x) { glDeleteTextures(1, &x); });
}

GlObject makeVertexArray() {
  GLuint id = 0;
  glGenVertexArrays(1, &id);
  return GlObject(id, [](GLuint x) { glDeleteVertexArrays(1, &x); });
}

GlObject makeFramebuffer() {
  GLuint id = 0;
  glGenFramebuffers(1, &id);
  return GlObject(id, [](GLuint x) { glDeleteFramebuffers(1, &x); });
}

GlObject makeRenderbuffer() {
  GLuint id = 0;
  glGenRenderbuffers(1, &id);
  return GlObject(id, [](GLuint x) { glDeleteRenderbuffers(1, &x); });
}

GlObject makeQuery() {
  GLuint id = 0;
  glGenQueries(1, &id);
  return GlObject(id, [](GLuint x) { glDeleteQueries(1, &x); });
}

GlObject linkProgram(const char* name, const char* vertexSource, const char* fragmentSource,
                     const std::vector<const char*>& feedbackVaryings) {
  GlObject vs = compileShader(name, GL_VERTEX_SHADER, vertexSource);
  GlObject fs = compileShader(name, GL_FRAGMENT_SHADER, fragmentSource);
  GlObject program(glCreateProgram(), [](GLuint id) { glDeleteProgram(id); });
  glAttachShader(program.id(), vs.id());
  glAttachShader(program.id(), fs.id());
  if (!feedbackVaryings.empty())
    glTransformFeedbackVaryings(program.id(), static_cast<GLsizei>(feedbackVaryings.size()), feedbackVaryings.data(),
                                GL_INTERLEAVED_ATTRIBS);
  glLinkProgram(program.id());
  GLint ok = GL_FALSE, length = 0;
  glGetProgramiv(program.id(), GL_LINK_STATUS, &ok);
  if (!ok) {
    glGetProgramiv(program.id(), GL_INFO_LOG_LENGTH, &length);
    std::string log(static_cast<size_t>(std::max(length, 1)), '\0');
    glGetProgramInfoLog(program.id(), length, nullptr, log.data());
    throw std::runtime_error(std::string("linking ") + name + " failed:\n" + log);
  }
  glDetachShader(program.id(), vs.id());
  glDetachShader(program.id(), fs.id());
  glObjectLabel(GL_PROGRAM, program.id(), -1, name);
  checkGl(name);
  return program;
}

std::string programName(const GlObject& program) {
  GLsizei length = 0;
  char label[256] = {};
  glGetObjectLabel(GL_PROGRAM, program.id(), GLsizei(sizeof label), &length, label);
  return std::string(label, size_t(std::max<GLsizei>(length, 0)));
}

GLint uniform(const GlObject& program, const char* name) {
  const GLint location = glGetUniformLocation(program.id(), name);
#ifndef NDEBUG
  if (location < 0)
    throw std::logic_error(std::string("uniform ") + name + " is not an active uniform of program " +
                           programName(program) + " (use optionalUniform for one a variant drops)");
#endif
  return location;
}

}  // namespace gimlod::gl
