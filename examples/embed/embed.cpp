// Embedding gimlod: open an atlas, adapt a cut to a camera of our own and draw it with gimlod's
// renderer in a GL context that this program makes itself: a GLFW window where there is a
// display, a headless EGL context otherwise. Writes the frame it drew to a PNG and fails on an
// empty frame (nothing but the background).
//   embed ATLAS OUT.png [WIDTHxHEIGHT]
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include <EGL/egl.h>
#include <EGL/eglext.h>
#include <GLFW/glfw3.h>
#include <png.h>

#include "runtime/atlas_view.h"
#include "runtime/camera.h"
#include "runtime/gl/atlas_scene.h"

namespace {

// A headless OpenGL 4.3 core context: Mesa's surfaceless platform, else the first EGL device
// (NVIDIA without a display), else the default display.
struct HeadlessContext {
  EGLDisplay display = EGL_NO_DISPLAY;
  EGLContext context = EGL_NO_CONTEXT;

  HeadlessContext() {
    auto getPlatformDisplay =
        reinterpret_cast<PFNEGLGETPLATFORMDISPLAYEXTPROC>(eglGetProcAddress("eglGetPlatformDisplayEXT"));
    auto queryDevices = reinterpret_cast<PFNEGLQUERYDEVICESEXTPROC>(eglGetProcAddress("eglQueryDevicesEXT"));
    std::vector<EGLDisplay> candidates;
    if (getPlatformDisplay) {
      candidates.push_back(getPlatformDisplay(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr));
      EGLDeviceEXT device;
      EGLint devices = 0;
      if (queryDevices && queryDevices(1, &device, &devices) && devices > 0)
        candidates.push_back(getPlatformDisplay(EGL_PLATFORM_DEVICE_EXT, device, nullptr));
    }
    candidates.push_back(eglGetDisplay(EGL_DEFAULT_DISPLAY));
    for (EGLDisplay d : candidates) {
      if (d == EGL_NO_DISPLAY || !eglInitialize(d, nullptr, nullptr)) continue;
      const EGLint configAttribs[] = {EGL_SURFACE_TYPE, EGL_PBUFFER_BIT, EGL_RENDERABLE_TYPE, EGL_OPENGL_BIT, EGL_NONE};
      EGLConfig config;
      EGLint configs = 0;
      if (!eglChooseConfig(d, configAttribs, &config, 1, &configs) || configs == 0 || !eglBindAPI(EGL_OPENGL_API))
        continue;
      const EGLint contextAttribs[] = {
          EGL_CONTEXT_MAJOR_VERSION,           4,       EGL_CONTEXT_MINOR_VERSION, 3, EGL_CONTEXT_OPENGL_PROFILE_MASK,
          EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT, EGL_NONE};
      context = eglCreateContext(d, config, EGL_NO_CONTEXT, contextAttribs);
      if (context != EGL_NO_CONTEXT && eglMakeCurrent(d, EGL_NO_SURFACE, EGL_NO_SURFACE, context)) {
        display = d;
        return;
      }
    }
    throw std::runtime_error("no EGL display gives an OpenGL 4.3 core context");
  }
  ~HeadlessContext() {
    eglMakeCurrent(display, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT);
    eglDestroyContext(display, context);
    eglTerminate(display);
  }
};

// A window of the given size with an OpenGL 4.3 core context made current; null without a display.
GLFWwindow* openWindow(int width, int height) {
  const char* display = std::getenv("DISPLAY");
  if (!display || !*display || !glfwInit()) return nullptr;
  glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 4);
  glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 3);
  glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
  glfwWindowHint(GLFW_RESIZABLE, GLFW_FALSE);
  GLFWwindow* window = glfwCreateWindow(width, height, "gimlod embedded", nullptr, nullptr);
  if (!window) {
    glfwTerminate();
    return nullptr;
  }
  glfwMakeContextCurrent(window);
  return window;
}

// Our own camera: the atlas's bounds seen obliquely from above at twice their radius. Terrains
// are z-up; meshes are shown y-up; planets from space, z up.
gimlod::Camera cameraFor(const gimlod::AtlasView& atlas) {
  const glm::dvec3 centre = 0.5 * (atlas.lo + atlas.hi);
  const double radius = 0.5 * glm::length(atlas.hi - atlas.lo);
  const bool mesh = atlas.manifest.kind != gimlod::AtlasKind::Heightfield;
  gimlod::Camera camera;
  camera.fovYDeg = 45.0;
  camera.target = centre;
  camera.up = mesh ? glm::dvec3(0, 1, 0) : glm::dvec3(0, 0, 1);
  const glm::dvec3 direction = mesh ? glm::dvec3(0.35, 0.3, 1.0) : glm::dvec3(0.4, -1.0, 0.9);
  camera.eye = centre + glm::normalize(direction) * (2.0 * radius);
  camera.nearPlane = camera.farPlane = 0.0;
  gimlod::fitClipPlanes(camera, atlas.lo, atlas.hi);
  return camera;
}

// RGBA rows, top first, to an 8-bit PNG.
void writePng(const std::string& path, uint32_t width, uint32_t height, const std::vector<uint8_t>& rgba) {
  png_image image{};
  image.version = PNG_IMAGE_VERSION;
  image.width = width;
  image.height = height;
  image.format = PNG_FORMAT_RGBA;
  if (!png_image_write_to_file(&image, path.c_str(), 0, rgba.data(), 0, nullptr))
    throw std::runtime_error(path + ": cannot write the PNG: " + image.message);
}

// The share of pixels that differ from the background.
double coverage(const std::vector<uint8_t>& rgba, const std::array<float, 3>& background) {
  size_t drawn = 0;
  for (size_t i = 0; i + 3 < rgba.size(); i += 4)
    for (int c = 0; c < 3; ++c)
      if (std::abs(int(rgba[i + c]) - int(std::lround(background[c] * 255.0f))) > 2) {
        ++drawn;
        break;
      }
  return double(drawn) / double(rgba.size() / 4);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 3) {
    std::fprintf(stderr, "usage: embed ATLAS OUT.png [WIDTHxHEIGHT]\n");
    return 2;
  }
  uint32_t width = 640, height = 480;
  if (argc > 3 && std::sscanf(argv[3], "%ux%u", &width, &height) != 2) {
    std::fprintf(stderr, "embed: %s: expected WIDTHxHEIGHT\n", argv[3]);
    return 2;
  }
  try {
    const gimlod::AtlasView atlas = gimlod::openAtlas(argv[1]);
    GLFWwindow* window = openWindow(int(width), int(height));
    std::unique_ptr<HeadlessContext> headless;
    if (!window) headless = std::make_unique<HeadlessContext>();

    std::vector<uint8_t> pixels;
    gimlod::gl::SceneOptions options;
    options.width = width;
    options.height = height;
    {
      gimlod::gl::AtlasScene scene(atlas, options);  // GL objects: made and freed in our context
      gimlod::AdaptOptions adapt;
      adapt.tolerancePx = 1.0;
      adapt.maxNodes = scene.nodeBudget(0);
      const gimlod::gl::FrameResult frame = scene.renderFrame(cameraFor(atlas), adapt);
      std::printf("%s: %u nodes, %llu triangles, largest error %.3f px, drawn in %.2f ms (%s)\n", argv[1],
                  frame.cut.nodeCount(), static_cast<unsigned long long>(frame.draw.triangles), frame.maxErrorPx,
                  frame.draw.drawMs, window ? "GLFW window" : "headless EGL");
      if (window) {
        // Our window shows the picture; what it holds is what we write.
        scene.renderer().blitToDefaultFramebuffer();
        pixels = gimlod::gl::readWindowPixels(width, height);
        glfwSwapBuffers(window);
      } else {
        pixels = scene.renderer().readPixels();
      }
    }
    if (window) {
      glfwDestroyWindow(window);
      glfwTerminate();
    }
    writePng(argv[2], width, height, pixels);
    const double drawn = coverage(pixels, options.background);
    std::printf("%s: %.1f%% of the pixels drawn\n", argv[2], 100.0 * drawn);
    if (drawn < 0.01) {
      std::fprintf(stderr, "embed: %s: the frame is empty (%.3f%% of the pixels differ from the background)\n", argv[2],
                   100.0 * drawn);
      return 1;
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "embed: %s\n", e.what());
    return 1;
  }
  return 0;
}
