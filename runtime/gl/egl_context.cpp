// Headless OpenGL 4.3+ core context through EGL (libepoxy): EGL device platform (hardware
// devices first), then Mesa's surfaceless platform, then the default display.
#include "runtime/gl/egl_context.h"

#include <epoxy/egl.h>
#include <epoxy/gl.h>

#include <cstdio>
#include <cstring>
#include <map>
#include <mutex>
#include <stdexcept>
#include <string>
#include <vector>

namespace gimlod::gl {
namespace {

std::string eglErrorName(EGLint e) {
  switch (e) {
    case EGL_SUCCESS: return "EGL_SUCCESS";
    case EGL_NOT_INITIALIZED: return "EGL_NOT_INITIALIZED";
    case EGL_BAD_ACCESS: return "EGL_BAD_ACCESS";
    case EGL_BAD_ALLOC: return "EGL_BAD_ALLOC";
    case EGL_BAD_ATTRIBUTE: return "EGL_BAD_ATTRIBUTE";
    case EGL_BAD_CONFIG: return "EGL_BAD_CONFIG";
    case EGL_BAD_CONTEXT: return "EGL_BAD_CONTEXT";
    case EGL_BAD_CURRENT_SURFACE: return "EGL_BAD_CURRENT_SURFACE";
    case EGL_BAD_DISPLAY: return "EGL_BAD_DISPLAY";
    case EGL_BAD_MATCH: return "EGL_BAD_MATCH";
    case EGL_BAD_PARAMETER: return "EGL_BAD_PARAMETER";
    case EGL_BAD_SURFACE: return "EGL_BAD_SURFACE";
    default: {
      char buf[32];
      std::snprintf(buf, sizeof buf, "EGL error 0x%04x", static_cast<unsigned>(e));
      return buf;
    }
  }
}

// Thrown inside one display attempt; the caller collects these reasons.
[[noreturn]] void failEgl(const std::string& what) {
  throw std::runtime_error(what + " failed (" + eglErrorName(eglGetError()) + ")");
}

bool hasExtension(const char* list, const char* name) {
  if (!list) return false;
  const size_t n = std::strlen(name);
  for (const char* p = list; (p = std::strstr(p, name)) != nullptr; p += n) {
    const bool startOk = p == list || p[-1] == ' ';
    const bool endOk = p[n] == '\0' || p[n] == ' ';
    if (startOk && endOk) return true;
  }
  return false;
}

const char* clientExtensions() {
  const char* s = eglQueryString(EGL_NO_DISPLAY, EGL_EXTENSIONS);
  if (!s) eglGetError();  // note: EGL 1.4 without EGL_EXT_client_extensions sets an error here
  return s;
}

// eglInitialize/eglTerminate are per display, and a display is a per-platform singleton, so two
// live contexts may share one: terminate only when the last user goes away.
std::mutex gDisplayMutex;
std::map<EGLDisplay, int> gDisplayUsers;

bool initializeDisplay(EGLDisplay dpy) {
  std::lock_guard lock(gDisplayMutex);
  EGLint major = 0, minor = 0;
  if (!eglInitialize(dpy, &major, &minor)) return false;
  ++gDisplayUsers[dpy];
  return true;
}

void releaseDisplay(EGLDisplay dpy) {
  std::lock_guard lock(gDisplayMutex);
  auto it = gDisplayUsers.find(dpy);
  if (it == gDisplayUsers.end()) return;
  if (--it->second == 0) {
    gDisplayUsers.erase(it);
    eglTerminate(dpy);
  }
}

struct Candidate {
  EGLDisplay display;
  std::string name;
};

// Devices from EGL_EXT_device_enumeration; hardware devices before Mesa's software device.
// note: NVIDIA's libEGL (through glvnd) advertises only EGL_EXT_device_base, which is by its spec
// EGL_EXT_device_enumeration plus EGL_EXT_device_query, so accept either spelling.
void addDeviceDisplays(const char* clientExts, std::vector<Candidate>* out) {
  const bool deviceBase = hasExtension(clientExts, "EGL_EXT_device_base");
  if (!(deviceBase || hasExtension(clientExts, "EGL_EXT_device_enumeration")) ||
      !hasExtension(clientExts, "EGL_EXT_platform_device"))
    return;
  EGLint count = 0;
  if (!eglQueryDevicesEXT(0, nullptr, &count) || count <= 0) {
    eglGetError();
    return;
  }
  std::vector<EGLDeviceEXT> devices(static_cast<size_t>(count));
  if (!eglQueryDevicesEXT(count, devices.data(), &count)) {
    eglGetError();
    return;
  }
  devices.resize(static_cast<size_t>(count));
  std::vector<Candidate> hardware, software;
  for (size_t i = 0; i < devices.size(); ++i) {
    const bool hasDeviceQuery = deviceBase || hasExtension(clientExts, "EGL_EXT_device_query");
    const char* devExts = hasDeviceQuery ? eglQueryDeviceStringEXT(devices[i], EGL_EXTENSIONS) : nullptr;
    if (hasDeviceQuery && !devExts) eglGetError();
    EGLDisplay dpy = eglGetPlatformDisplayEXT(EGL_PLATFORM_DEVICE_EXT, devices[i], nullptr);
    if (dpy == EGL_NO_DISPLAY) {
      eglGetError();
      continue;
    }
    const bool isSoftware = hasExtension(devExts, "EGL_MESA_device_software");
    Candidate c{dpy, "EGL device " + std::to_string(i) + (isSoftware ? " (software)" : "")};
    (isSoftware ? software : hardware).push_back(c);
  }
  out->insert(out->end(), hardware.begin(), hardware.end());
  out->insert(out->end(), software.begin(), software.end());
}

std::vector<Candidate> candidateDisplays() {
  std::vector<Candidate> out;
  const char* exts = clientExtensions();
  addDeviceDisplays(exts, &out);
  if (hasExtension(exts, "EGL_MESA_platform_surfaceless")) {
    EGLDisplay dpy = eglGetPlatformDisplayEXT(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr);
    if (dpy != EGL_NO_DISPLAY)
      out.push_back({dpy, "Mesa surfaceless platform"});
    else
      eglGetError();
  }
  EGLDisplay dpy = eglGetDisplay(EGL_DEFAULT_DISPLAY);
  if (dpy != EGL_NO_DISPLAY)
    out.push_back({dpy, "default display"});
  else
    eglGetError();
  return out;
}

EGLConfig chooseConfig(EGLDisplay dpy, bool needPbuffer) {
  const EGLint attribs[] = {EGL_SURFACE_TYPE,
                            needPbuffer ? EGL_PBUFFER_BIT : 0,
                            EGL_RENDERABLE_TYPE,
                            EGL_OPENGL_BIT,
                            EGL_RED_SIZE,
                            8,
                            EGL_GREEN_SIZE,
                            8,
                            EGL_BLUE_SIZE,
                            8,
                            EGL_NONE};
  EGLConfig config = nullptr;
  EGLint n = 0;
  if (!eglChooseConfig(dpy, attribs, &config, 1, &n)) failEgl("eglChooseConfig");
  if (n < 1) throw std::runtime_error("eglChooseConfig found no OpenGL config");
  return config;
}

// Core profile, newest first down to 4.3.
EGLContext createCoreContext(EGLDisplay dpy, EGLConfig config) {
  for (int minor = 6; minor >= 3; --minor) {
    const EGLint attribs[] = {
        EGL_CONTEXT_MAJOR_VERSION,           4,       EGL_CONTEXT_MINOR_VERSION, minor, EGL_CONTEXT_OPENGL_PROFILE_MASK,
        EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT, EGL_NONE};
    EGLContext ctx = eglCreateContext(dpy, config, EGL_NO_CONTEXT, attribs);
    if (ctx != EGL_NO_CONTEXT) return ctx;
    eglGetError();
  }
  throw std::runtime_error("eglCreateContext failed for OpenGL 4.6 .. 4.3 core profile");
}

}  // namespace

std::unique_ptr<EglContext> EglContext::create() {
  std::vector<Candidate> candidates = candidateDisplays();
  std::string reasons;
  for (const Candidate& c : candidates) {
    std::unique_ptr<EglContext> result(new EglContext());
    try {
      if (!initializeDisplay(c.display)) failEgl("eglInitialize");
      result->display_ = c.display;
      if (!eglBindAPI(EGL_OPENGL_API)) failEgl("eglBindAPI(EGL_OPENGL_API)");
      const bool surfaceless = hasExtension(eglQueryString(c.display, EGL_EXTENSIONS), "EGL_KHR_surfaceless_context");
      EGLConfig config = chooseConfig(c.display, !surfaceless);
      result->context_ = createCoreContext(c.display, config);
      EGLSurface surface = EGL_NO_SURFACE;
      if (!surfaceless) {
        const EGLint pbufferAttribs[] = {EGL_WIDTH, 1, EGL_HEIGHT, 1, EGL_NONE};
        surface = eglCreatePbufferSurface(c.display, config, pbufferAttribs);
        if (surface == EGL_NO_SURFACE) failEgl("eglCreatePbufferSurface(1x1)");
        result->surface_ = surface;
      }
      if (!eglMakeCurrent(c.display, surface, surface, static_cast<EGLContext>(result->context_)))
        failEgl("eglMakeCurrent");
      GLint major = 0, minor = 0;
      glGetIntegerv(GL_MAJOR_VERSION, &major);
      glGetIntegerv(GL_MINOR_VERSION, &minor);
      if (major * 10 + minor < 43)
        throw std::runtime_error("context reports OpenGL " + std::to_string(major) + "." + std::to_string(minor) +
                                 " (< 4.3)");
      const char* eglVendor = eglQueryString(c.display, EGL_VENDOR);
      result->displayName_ = c.name + ", EGL vendor " + (eglVendor ? eglVendor : "?");
      return result;
    } catch (const std::exception& e) {
      reasons += "\n  " + c.name + ": " + e.what();
      // result's destructor releases what was created for this candidate
    }
  }
  if (candidates.empty()) reasons = "\n  no EGL display available";
  throw std::runtime_error("EglContext: no headless OpenGL 4.3 core context could be created:" + reasons);
}

EglContext::~EglContext() {
  if (!display_) return;
  EGLDisplay dpy = static_cast<EGLDisplay>(display_);
  if (context_ && eglGetCurrentContext() == static_cast<EGLContext>(context_))
    eglMakeCurrent(dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
  if (surface_) eglDestroySurface(dpy, static_cast<EGLSurface>(surface_));
  if (context_) eglDestroyContext(dpy, static_cast<EGLContext>(context_));
  releaseDisplay(dpy);
}

std::string EglContext::renderer() const {
  const auto* s = reinterpret_cast<const char*>(glGetString(GL_RENDERER));
  return s ? s : "";
}

std::string EglContext::vendor() const {
  const auto* s = reinterpret_cast<const char*>(glGetString(GL_VENDOR));
  return s ? s : "";
}

std::string EglContext::version() const {
  const auto* s = reinterpret_cast<const char*>(glGetString(GL_VERSION));
  return s ? s : "";
}

}  // namespace gimlod::gl
