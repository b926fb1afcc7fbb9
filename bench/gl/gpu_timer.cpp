#include "bench/gl/gpu_timer.h"

namespace gimlod::bench {

GpuTimer::GpuTimer() : query_(gl::makeQuery()) {}

void GpuTimer::begin() { glBeginQuery(GL_TIME_ELAPSED, query_.id()); }

double GpuTimer::endMs() {
  glEndQuery(GL_TIME_ELAPSED);
  GLuint64 ns = 0;
  glGetQueryObjectui64v(query_.id(), GL_QUERY_RESULT, &ns);
  return double(ns) * 1e-6;
}

}  // namespace gimlod::bench
