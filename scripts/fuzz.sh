#!/usr/bin/env bash
# Builds the libFuzzer harnesses (tests/fuzz) with clang, AddressSanitizer and
# UndefinedBehaviorSanitizer in build-fuzz, and runs each for a fixed number of executions (as
# many harnesses at once as there are cores) from its checked-in corpus (tests/fuzz/corpus/NAME)
# plus seeds cut from the real scans in ../shared/data when it is there. A crash, leak, sanitizer
# report, timeout or memory blow-up fails the script and leaves the input in
# build-fuzz/artifacts/NAME/; add it to the harness's corpus once fixed, where the normal test run
# replays it.
#
#   bash scripts/fuzz.sh [RUNS] [NAME...]      RUNS per harness (default 100000); NAMEs default to all
set -euo pipefail
cd "$(dirname "$0")/.."
RUNS=${1:-100000}
shift || true
ALL=(fuzz_mesh_ply fuzz_mesh_obj fuzz_mesh_off fuzz_mesh_stl fuzz_manifest fuzz_chart_list fuzz_chart_file fuzz_block_codec fuzz_hierarchy fuzz_camera_path)
NAMES=("$@")
[ ${#NAMES[@]} -eq 0 ] && NAMES=("${ALL[@]}")

bash scripts/install-deps.sh
source scripts/build-env.sh
CC=clang CXX=clang++ cmake -S . -B build-fuzz -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo -DGIMLOD_FUZZ=ON \
  -DGIMLOD_BUILD_BENCHMARKS=OFF "${GIMLOD_CMAKE_CACHE_ARGS[@]}" >/dev/null
cmake --build build-fuzz -j"$(nproc)" --target "${NAMES[@]}"

SHARED=../shared/data/meshes
export ASAN_OPTIONS=detect_leaks=1:halt_on_error=1
export UBSAN_OPTIONS=halt_on_error=1:print_stacktrace=1
failed=0
# One harness from its corpus; non-zero when it found something.
fuzz_one() {
  local name=$1 work=build-fuzz/corpus/$1 artifacts=build-fuzz/artifacts/$1 start execs f
  local shared=() dict=()
  mkdir -p "$work" "$artifacts"
  cp -n tests/fuzz/corpus/$name/* "$work"/ 2>/dev/null || true
  # Seeds from the real scans: the first 64 KiB of each file of the harness's format.
  case $name in
    fuzz_mesh_ply) shared=(bun_zipper.ply horse.ply igea.ply turbineblade.ply) ;;
    fuzz_mesh_obj) shared=(armadillo.obj) ;;
  esac
  for f in "${shared[@]}"; do
    [ -f "$SHARED/$f" ] && head -c 65536 "$SHARED/$f" > "$work/shared_$f"
  done
  case $name in fuzz_manifest|fuzz_camera_path) dict=(-dict=tests/fuzz/json.dict) ;; esac
  start=$(date +%s)
  if ! ./build-fuzz/tests/fuzz/$name "$work" "${dict[@]}" -runs="$RUNS" -max_len=65536 -timeout=30 -rss_limit_mb=2048 \
      -artifact_prefix="$artifacts/" -print_final_stats=1 > "build-fuzz/$name.log" 2>&1; then
    echo "gimlod fuzz: $name FAILED; input in $artifacts/, log build-fuzz/$name.log"
    tail -40 "build-fuzz/$name.log"
    return 1
  fi
  execs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "build-fuzz/$name.log" | grep -o '[0-9]*$' || echo "?")
  echo "gimlod fuzz: $name: $execs executions in $(( $(date +%s) - start )) s, no crash"
}

# The harnesses run side by side, one a core (each is one process on one thread); each failure
# leaves a mark in build-fuzz/failed.
rm -rf build-fuzz/failed
mkdir -p build-fuzz/failed
for name in "${NAMES[@]}"; do
  while [ "$(jobs -rp | wc -l)" -ge "$(nproc)" ]; do wait -n || true; done
  (fuzz_one "$name" || touch "build-fuzz/failed/$name") &
done
wait
[ -z "$(ls build-fuzz/failed)" ] || failed=1
exit $failed
