// GPU timing for the render benchmarks. Needs a current context.
#pragma once

#include "runtime/gl/gl_objects.h"

namespace gimlod::bench {

// GPU time of the commands issued between begin() and endMs() (a GL_TIME_ELAPSED query);
// endMs waits for the result. Needs a current context; one timer runs at a time.
class GpuTimer {
 public:
  GpuTimer();
  void begin();
  double endMs();

 private:
  gl::GlObject query_;
};

}  // namespace gimlod::bench
