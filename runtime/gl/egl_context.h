// Headless OpenGL 4.3+ core context through EGL (device platform, then Mesa surfaceless, then
// the default display). Works on Mesa llvmpipe and on NVIDIA.
#pragma once

#include <memory>
#include <string>

namespace gimlod::gl {

class EglContext {
 public:
  // Creates and makes current a context; throws std::runtime_error with the EGL reason.
  static std::unique_ptr<EglContext> create();
  ~EglContext();
  std::string renderer() const;  // GL_RENDERER
  std::string version() const;   // GL_VERSION
  std::string vendor() const;    // GL_VENDOR
  // The display the context was made on ("EGL device 0", "Mesa surfaceless platform", "default
  // display") and the EGL vendor.
  const std::string& display() const { return displayName_; }

 private:
  EglContext() = default;
  void* display_ = nullptr;
  void* context_ = nullptr;
  void* surface_ = nullptr;  // 1x1 pbuffer when EGL_KHR_surfaceless_context is missing
  std::string displayName_;
};

}  // namespace gimlod::gl
