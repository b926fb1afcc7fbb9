#!/usr/bin/env bash
# The tests again under sanitizers, each in its own build folder:
#   bash scripts/sanitize.sh address   AddressSanitizer + UndefinedBehaviorSanitizer (build-asan):
#                                      every test; leaks detected, the GL driver's own leaks
#                                      suppressed (tests/sanitizers/lsan.supp)
#   bash scripts/sanitize.sh thread    ThreadSanitizer (build-tsan): the page loader and the
#                                      asynchronous loading tests
# Any report stops the program, so the test fails.
set -euo pipefail
cd "$(dirname "$0")/.."
kind=${1:-address}
bash scripts/install-deps.sh
root=$(pwd)
case $kind in
  address)
    cmake -S . -B build-asan -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DGIMLOD_SANITIZE=ON \
      -DGIMLOD_BUILD_BENCHMARKS=OFF >/dev/null
    cmake --build build-asan -j"$(nproc)"
    # note: Mesa unloads its GL driver when the EGL display goes, and memory the driver still
    # held then looks leaked from an "<unknown module>". Preloading the driver keeps it mapped,
    # so LeakSanitizer sees what it references (and could name it, for the suppressions).
    multiarch=$(gcc -print-multiarch)
    preload=""
    for lib in /usr/lib/$multiarch/dri/swrast_dri.so /usr/lib/$multiarch/libEGL_mesa.so.0; do
      [ -f "$lib" ] && preload="$preload $lib"
    done
    export LD_PRELOAD="${preload# }"
    export ASAN_OPTIONS=halt_on_error=1:detect_leaks=1:verify_asan_link_order=0:strict_string_checks=1:detect_stack_use_after_return=1
    export LSAN_OPTIONS=suppressions=$root/tests/sanitizers/lsan.supp:print_suppressions=0
    export UBSAN_OPTIONS=halt_on_error=1:print_stacktrace=1
    ctest --test-dir build-asan --output-on-failure -j"$(nproc)"
    ;;
  thread)
    cmake -S . -B build-tsan -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DGIMLOD_SANITIZE=thread \
      -DGIMLOD_BUILD_BENCHMARKS=OFF >/dev/null
    cmake --build build-tsan -j"$(nproc)" --target gimlod_tests gimlod_gl_tests
    export TSAN_OPTIONS=halt_on_error=1:second_deadlock_stack=1:suppressions=$root/tests/sanitizers/tsan.supp
    ctest --test-dir build-tsan --output-on-failure -j"$(nproc)" -R 'PageLoader|AsyncLoading'
    ;;
  *)
    echo "usage: scripts/sanitize.sh address|thread" >&2
    exit 2
    ;;
esac
