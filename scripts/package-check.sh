#!/usr/bin/env bash
# The installed package as a user's project meets it: installs the Release build (build/, made by
# scripts/test.sh) into a fresh prefix, builds examples/embed against it as a separate CMake
# project, builds the shipped bunny and Rainier atlases with the installed tool, and draws each
# with the example twice: in a headless EGL context and in a GLFW window under Xvfb. The example
# fails on an empty frame. As root, also the Debian package (cpack -G DEB): installed with dpkg,
# the example built against it from /usr and run, and the package removed again.
#   bash scripts/package-check.sh
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
source scripts/build-env.sh
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cmake --install build --prefix "$work/prefix" >/dev/null
cmake -S examples/embed -B "$work/build" -G Ninja -DCMAKE_PREFIX_PATH="$work/prefix" \
  "${GIMLOD_CMAKE_CACHE_ARGS[@]}" >/dev/null
cmake --build "$work/build"
gimlod="$work/prefix/bin/gimlod"
"$gimlod" build data/meshes/bun_zipper.ply -o "$work/bunny.atlas" >/dev/null
"$gimlod" build data/terrain/mt_rainier_90m.tif -o "$work/rainier.atlas" >/dev/null
for atlas in bunny rainier; do
  env -u DISPLAY "$work/build/embed" "$work/$atlas.atlas" "$work/$atlas.png" | tee "$work/out.txt"
  grep -q "headless EGL" "$work/out.txt"
  xvfb-run -a -s "-screen 0 1280x1024x24" "$work/build/embed" "$work/$atlas.atlas" "$work/${atlas}_window.png" \
    | tee "$work/out.txt"
  grep -q "GLFW window" "$work/out.txt"
done
if [ "$(id -u)" = 0 ]; then
  (cd build && cpack -G DEB >/dev/null)
  deb=$(ls build/gimlod_*_*.deb | head -1)
  dpkg -i "$deb" >/dev/null
  trap 'dpkg -r gimlod >/dev/null 2>&1 || true; rm -rf "$work"' EXIT
  cmake -S examples/embed -B "$work/build-deb" -G Ninja "${GIMLOD_CMAKE_CACHE_ARGS[@]}" >/dev/null
  cmake --build "$work/build-deb" >/dev/null
  env -u DISPLAY "$work/build-deb/embed" "$work/bunny.atlas" "$work/bunny-deb.png"
  /usr/bin/gimlod --help >/dev/null
  dpkg -r gimlod >/dev/null
  echo "gimlod package: $deb installs with dpkg, and examples/embed built against it draws"
fi
echo "gimlod package: installed; examples/embed built against it drew the bunny and Rainier headless and in a window"
