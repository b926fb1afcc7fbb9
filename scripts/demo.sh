#!/usr/bin/env bash
# The demo: installs what is missing, builds gimlod in Release, builds the atlases of the shipped
# SRTM tile and the shipped scan, and renders them to PNG frames with per-frame statistics.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build build -j"$(nproc)" --target gimlod
mkdir -p out
./build/gimlod build data/terrain/mt_rainier_90m.tif -o out/rainier.atlas
./build/gimlod render out/rainier.atlas -o out/rainier_orbit --orbit 24 --size 640x480 --tolerance 1
./build/gimlod render out/rainier.atlas -o out/rainier_flyby --path scenes/rainier_flyby.json --size 640x480 --tolerance 1
./build/gimlod build data/meshes/bun_zipper.ply -o out/bunny.atlas
./build/gimlod render out/bunny.atlas -o out/bunny_orbit --path scenes/bunny_orbit.json --size 640x480 --tolerance 1
echo "frames and stats.csv are in out/rainier_orbit, out/rainier_flyby and out/bunny_orbit"
