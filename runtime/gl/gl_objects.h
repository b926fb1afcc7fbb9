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
// interleaved. The program is labelled `name`. Throws std::runtime_error with the compile or
// link log.
GlObject linkProgram(const char* name, const char* vertexSource, const char* fragmentSource,
                     const std::vector<const char*>& feedbackVaryings = {});

// Location of the uniform `name` of `program`. In debug builds a name the program does not have
// as an active uniform (a typo, or one the linker removed as unused) throws std::logic_error
// naming the uniform and the program (linkProgram's name); release builds return -1, which
// glUniform* ignores.
GLint uniform(const GlObject& program, const char* name);

// Location of a uniform that some variants of `program` legitimately do not use (the linker
// removes it there): -1 when absent, in every build.
inline GLint optionalUniform(const GlObject& program, const char* name) {
  return glGetUniformLocation(program.id(), name);
}

// The name linkProgram gave `program` (its GL object label); empty if none.
std::string programName(const GlObject& program);

}  // namespace gimlod::gl
