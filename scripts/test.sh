#!/usr/bin/env bash
# The tests: installs what is missing, builds everything in Release (build/), and runs ctest tier by
# tier, printing each tier's time:
#   cpu     the library modules' tests and the fuzz corpus replays (no GL, no app)
#   gl      the renderer, headless through EGL (Mesa llvmpipe without a GPU)
#   cli     the gimlod program as a user runs it
#   window  the viewer's GLFW window under Xvfb, driven by xdotool
#   bash scripts/test.sh [TIER...]     default: all four
# GIMLOD_ASSERTS=1 keeps the project's assert()s in the Release build (as CI runs it).
# Every tier runs even when an earlier one fails; the exit status is non-zero if any failed.
set -euo pipefail
cd "$(dirname "$0")/.."
tiers=("$@")
[ ${#tiers[@]} -eq 0 ] && tiers=(cpu gl cli window)
bash scripts/install-deps.sh
source scripts/build-env.sh
t0=$(date +%s)
# GIMLOD_ASSERTS=1 (CI): the project's assertions kept in the Release build.
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release -DGIMLOD_ASSERTS="${GIMLOD_ASSERTS:-0}" \
  "${GIMLOD_CMAKE_CACHE_ARGS[@]}" >/dev/null
cmake --build build -j"$(nproc)"
echo "gimlod tests: built in $(( $(date +%s) - t0 )) s"
failed=()
for tier in "${tiers[@]}"; do
  t=$(date +%s)
  ctest --test-dir build --output-on-failure -j"$(nproc)" -L "^${tier}\$" || failed+=("$tier")
  echo "gimlod tests: tier $tier in $(( $(date +%s) - t )) s"
done
if [ ${#failed[@]} -gt 0 ]; then
  echo "gimlod tests: failed in tier(s) ${failed[*]}"
  exit 1
fi
