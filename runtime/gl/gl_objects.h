// Small RAII wrappers and error checks for OpenGL objects. Needs a current context (epoxy).
#pragma once

#include <epoxy/gl.h>

#include <string>
#include <utility>
#include <vector>

namespace gimlod::gl {

// Throws std::runtime_error naming `what` if glGetError reports an error (drains the queue).
void checkGl(const char* what);

// Owns one GL object name; move-only.
class GlObject {
 public:
  using Deleter = void (*)(GLuint);
  GlObject() = default;
  GlObject(GLuint id, Deleter deleter) : id_(id), deleter_(deleter) {}
  GlObject(GlObject&& o) noexcept : id_(std::exchange(o.id_, 0)), deleter_(o.deleter_) {}
  GlObject& operator=(GlObject&& o) noexcept {
    if (this != &o) {
      reset();
      id_ = std::exchange(o.id_, 0);
      deleter_ = o.deleter_;
    }
    return *this;
  }
  GlObject(const GlObject&) = delete;
  GlObject& operator=(const GlObject&) = delete;
  ~GlObject() { reset(); }
  GLuint id() const { return id_; }
  void reset() {
    if (id_ && deleter_) deleter_(id_);
    id_ = 0;
  }

 private:
  GLuint id_ = 0;
  Deleter deleter_ = nullptr;
};

GlObject makeBuffer();
GlObject makeTexture();
GlObject makeVertexArray();
GlObject makeFramebuffer();
GlObject makeRenderbuffer();
GlObject makeQuery();

// Compiles and links vertex + fragment sources; `feedbackVaryings` (may be empty) are captured
// interleaved. Throws std::runtime_error with the compile or link log.
GlObject linkProgram(const char* name, const char* vertexSource, const char* fragmentSource,
                     const std::vector<const char*>& feedbackVaryings = {});

// Uniform location; -1 (silently ignored by glUniform*) when the linker removed it.
// GPU time of the commands issued between begin() and endMs() (a GL_TIME_ELAPSED query);
// endMs waits for the result. Needs a current context; one timer runs at a time.
class GpuTimer {
 public:
  GpuTimer();
  void begin();
  double endMs();

 private:
  GlObject query_;
};

inline GLint uniform(const GlObject& program, const char* name) {
  return glGetUniformLocation(program.id(), name);
}

}  // namespace gimlod::gl
