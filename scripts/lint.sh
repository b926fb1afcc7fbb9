#!/usr/bin/env bash
# The code's shape, checked:
#   - every C++ source and header formatted as .clang-format says (clang-format --dry-run);
#   - no library or app function over about 150 lines or 6 parameters (.clang-tidy's
#     readability-function-size), outside the mesh stage (atlas/mesh/, whose charting and repair
#     are to be replaced whole; its long functions are listed in docs/architecture.md).
# clang-tidy reads the compile commands of a configured build folder (build/, made by
# scripts/test.sh; configured and built here if missing).
#   bash scripts/lint.sh [JOBS]     JOBS: clang-tidy processes (default: the cores)
#   bash scripts/lint.sh format     the formatting alone (seconds; CI runs it before it builds)
set -euo pipefail
cd "$(dirname "$0")/.."
jobs=${1:-$(nproc)}
bash scripts/install-deps.sh
mapfile -t files < <(git ls-files '*.cpp' '*.h' | grep -v '^tests/fuzz/corpus/')
if ! clang-format --dry-run --Werror "${files[@]}" 2>/tmp/gimlod-lint-format.$$; then
  head -40 /tmp/gimlod-lint-format.$$
  rm -f /tmp/gimlod-lint-format.$$
  echo "gimlod lint: some files are not formatted as .clang-format says (clang-format -i FILE)"
  exit 1
fi
rm -f /tmp/gimlod-lint-format.$$
echo "gimlod lint: ${#files[@]} files formatted as .clang-format says"
[ "$jobs" = format ] && exit 0
if [ ! -f build/compile_commands.json ]; then
  source scripts/build-env.sh
  cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release "${GIMLOD_CMAKE_CACHE_ARGS[@]}" >/dev/null
  cmake --build build -j"$(nproc)"  # the generated headers the sources include
fi
mapfile -t sources < <(git ls-files 'core/*.cpp' 'hierarchy/*.cpp' 'runtime/*.cpp' 'atlas/*.cpp' 'pipeline/*.cpp' \
  'inspect/*.cpp' 'apps/*.cpp' | grep -v '^atlas/mesh/')
if ! run-clang-tidy -p build -j "$jobs" -quiet "${sources[@]/#/$PWD/}" > build/lint-tidy.log 2>&1; then
  sed 's/\x1b\[[0-9;]*m//g' build/lint-tidy.log | grep -E -A3 "error:" | head -60
  echo "gimlod lint: functions over the size limits (.clang-tidy)"
  exit 1
fi
echo "gimlod lint: ${#sources[@]} library and app sources within .clang-tidy's function size limits"
