// Linked into every test binary of a ThreadSanitizer build.
//
// Debian's TBB library is not built with ThreadSanitizer, so TSan cannot see the ordering that
// TBB's scheduler gives between spawning a task and another worker stealing it: it reports the
// partitioner's own state (tbb::detail::d1::check_being_stolen against the split constructor)
// as a race. Suppressing by frame would hide every race in a parallel_for body too, since those
// frames sit under the same TBB functions. So under TSan, TBB runs its algorithms on the calling
// thread alone, and TSan checks the threads the project starts itself (the page loader's, the
// asynchronous loads, the progress meter's).
#include <tbb/global_control.h>

namespace {
const tbb::global_control serialTbb(tbb::global_control::max_allowed_parallelism, 1);
}  // namespace
