// A per-frame pass over an adapter's kept nodes, in parallel when it is large enough to pay for
// waking the worker threads (kDefaultParallelMin, runtime/adapt.h). Included by the adapters'
// sources only: their headers need no TBB.
#pragma once

#include <algorithm>
#include <cstddef>

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

namespace gimlod {

// f(i) for i in [0, n): in parallel, in tasks of parallelMin / 8 indices, when n >= parallelMin
// (0: never); on the calling thread otherwise. Each call must write its own data only, so the
// result does not depend on the thread count.
template <typename F>
void parallelPass(size_t n, size_t parallelMin, F&& f) {
  if (parallelMin == 0 || n < parallelMin) {
    for (size_t i = 0; i < n; ++i) f(i);
    return;
  }
  const size_t grain = std::max<size_t>(parallelMin / 8, 1);
  tbb::parallel_for(tbb::blocked_range<size_t>(0, n, grain), [&](const tbb::blocked_range<size_t>& r) {
    for (size_t i = r.begin(); i != r.end(); ++i) f(i);
  });
}

}  // namespace gimlod
