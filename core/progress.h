// Progress of a long build: the running stage's work items done out of its total, handed at most
// every `interval` seconds to a sink the front end sets (a bar with an ETA on a terminal, log
// lines otherwise; apps/gimlod.cpp). Library code marks its stages with a ProgressStage and
// advances from any thread; without a sink all of it is a few atomic adds. Pure C++.
#pragma once

#include <cstdint>
#include <functional>
#include <string>

namespace gimlod::progress {

struct Report {
  std::string stage;
  uint64_t done = 0, total = 0;
  double seconds = 0.0;      // since the stage began
  double etaSeconds = -1.0;  // remaining at the rate so far; < 0: not known yet
  bool finished = false;     // the stage's last report
};
using Sink = std::function<void(const Report&)>;

// Sets (or, with an empty sink, clears) where reports go, and the least time between two reports
// of one stage (a stage's end is always reported). Not thread-safe against running stages.
void setSink(Sink sink, double intervalSeconds);

// The current stage while it lives (stages nest: an inner one is current until it ends).
class ProgressStage {
 public:
  ProgressStage(std::string name, uint64_t total);
  ~ProgressStage();
  ProgressStage(const ProgressStage&) = delete;
  ProgressStage& operator=(const ProgressStage&) = delete;
};

// Marks n more items of the current stage done (no-op without a stage). Thread-safe.
void advance(uint64_t n = 1);

// Advances by one when it goes out of scope: one item of a loop body with early returns.
struct Tick {
  ~Tick() { advance(); }
};

// The text of a report: "charts [#######.......] 45% 123/270, 12 s, ETA 15 s" (width: the bar's
// characters; 0: no bar).
std::string format(const Report& r, int width);

}  // namespace gimlod::progress
