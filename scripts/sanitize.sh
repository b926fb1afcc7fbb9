#!/usr/bin/env bash
# The tests again under sanitizers, each in its own build folder:
#   bash scripts/sanitize.sh address [TIER...]
#       The assertions build (build-asan): line tables and assertions on (no NDEBUG), warnings
#       are errors in project code (-Werror), at -O1, under AddressSanitizer + UndefinedBehavior-
#       Sanitizer. Tiers (default: cpu gl cli-input): the CPU tests, every GL test, and the
#       command-line tests of bad input and options (cli-input); `cli` and `window` run the
#       whole tiers. The tests that rebuild whole real scans are left to Release (SCAN_BUILDS). Leaks detected, the GL driver's own leaks suppressed
#       (tests/sanitizers/lsan.supp).
#   bash scripts/sanitize.sh thread
#       ThreadSanitizer (build-tsan): the tests that run threads of the project's own (the page
#       loader, asynchronous loading, progress from many threads, the TBB build stages that run
#       under it, the runtime's tests).
# Any report stops the program, so the test fails. Each tier's time is printed.
set -euo pipefail
cd "$(dirname "$0")/.."
kind=${1:-address}
shift || true
bash scripts/install-deps.sh
source scripts/build-env.sh
root=$(pwd)

# The command-line tests of bad input and bad options: where the app's own parsing and error
# paths run (the other command-line tests draw through library code the cpu and gl tiers cover).
CLI_INPUT='^(BadMesh|CliTest|ViewCli|InputKindTest)\.|Bad|Invalid'

# Left to the Release run: the tests that build whole real scans again and again (the bunny and
# the shared scans through every layout, repair and report variant). Under ASan+UBSan they took
# 2,460 s of the 3,330 s of test time: 38 tests, up to 257 s each (the planar igea).
# The sanitized tiers still build the bunny (ScanAtlasTest.Invariants/bunny,
# CrackTest.SidesQuadLayoutOfTheBunnyHasNoCracks, EvenSides.TheBunnysOddPatches...) and every
# hand-made mesh, and run every test of bad input. GIMLOD_SANITIZE_ALL=1 runs them all.
SCAN_BUILDS='^(SideQuads|InspectReportTest|SeamsTest|RootFloorScan|OpenSides|LayoutRefine|FidelityOutOfCore)\.|^SharedScans/PlanarScanTest\.|^PatchSplit\.FlipRepair|^CompressedAtlas\.(MeshPositions|SparseMesh)|^EvenSides\.MendTwo|^InspectCli\.ChartOverlay|ScanAtlasTest\.Invariants/armadillo'
[ "${GIMLOD_SANITIZE_ALL:-0}" = 1 ] && SCAN_BUILDS='^$'

# ctest over the tiers in $@ of build folder $1, each timed; non-zero if any failed. cli-input:
# the cli tier's tests of bad input (CLI_INPUT). $EXCLUDE: tests left out (a ctest -E regex).
run_tiers() {
  local dir=$1 failed=0 tier t
  shift
  for tier in "$@"; do
    t=$(date +%s)
    if [ "$tier" = cli-input ]; then
      ctest --test-dir "$dir" --output-on-failure -j"$(nproc)" -L '^cli$' -R "$CLI_INPUT" -E "${EXCLUDE:-^$}" || failed=1
    else
      ctest --test-dir "$dir" --output-on-failure -j"$(nproc)" -L "^${tier}\$" -E "${EXCLUDE:-^$}" || failed=1
    fi
    echo "gimlod sanitize: $dir tier $tier in $(( $(date +%s) - t )) s"
  done
  return $failed
}

case $kind in
  address)
    tiers=("$@")
    [ ${#tiers[@]} -eq 0 ] && tiers=(cpu gl cli-input)
    t=$(date +%s)
    # note: RelWithDebInfo without NDEBUG: the project's asserts run. CMAKE_BUILD_TYPE=Debug
    # (TBB_USE_DEBUG) with _GLIBCXX_ASSERTIONS made the sanitized mesh tests 6 to 16 times their
    # Release time (e.g. 156 s against 26 s); Eigen's and CGAL's internal checks stay off, as
    # NDEBUG had them. -O1 -g1 (line tables, enough for the reports' file:line): the sanitizers'
    # own advice, and half the compile time of -O2 -g (layout_refine.cpp: 26 s against 52 s).
    cmake -S . -B build-asan -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
      "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O1 -g1 -DEIGEN_NO_DEBUG -DCGAL_NDEBUG" \
      -DGIMLOD_SANITIZE=ON -DGIMLOD_WERROR=ON -DGIMLOD_BUILD_BENCHMARKS=OFF "${GIMLOD_CMAKE_CACHE_ARGS[@]}" >/dev/null
    cmake --build build-asan -j"$(nproc)"
    echo "gimlod sanitize: build-asan built in $(( $(date +%s) - t )) s"
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
    EXCLUDE=$SCAN_BUILDS run_tiers build-asan "${tiers[@]}"
    ;;
  thread)
    t=$(date +%s)
    cmake -S . -B build-tsan -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DGIMLOD_SANITIZE=thread \
      "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O1 -g1 -DNDEBUG" \
      -DGIMLOD_BUILD_BENCHMARKS=OFF "${GIMLOD_CMAKE_CACHE_ARGS[@]}" >/dev/null
    cmake --build build-tsan -j"$(nproc)" --target gimlod_runtime_tests gimlod_core_tests gimlod_pipeline_tests gimlod_gl_tests
    echo "gimlod sanitize: build-tsan built in $(( $(date +%s) - t )) s"
    export TSAN_OPTIONS=halt_on_error=1:second_deadlock_stack=1:suppressions=$root/tests/sanitizers/tsan.supp
    t=$(date +%s)
    failed=0
    # The runtime's tests, all of them, in one process.
    ./build-tsan/tests/gimlod_runtime_tests || failed=1
    ctest --test-dir build-tsan --output-on-failure -j"$(nproc)" -R '^(PageLoaderTest|AsyncLoadingTest|Progress)\.' || failed=1
    echo "gimlod sanitize: build-tsan threaded tests in $(( $(date +%s) - t )) s"
    exit $failed
    ;;
  *)
    echo "usage: scripts/sanitize.sh address [cpu|gl|cli|cli-input|window...] | thread" >&2
    exit 2
    ;;
esac
