#!/usr/bin/env bash
# The tests: installs what is missing, builds everything, and runs ctest (GL tests run headless
# through EGL; on a machine without a GPU that is Mesa llvmpipe).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build build -j"$(nproc)"
ctest --test-dir build --output-on-failure -j"$(nproc)"
