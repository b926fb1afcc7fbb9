#!/usr/bin/env bash
# The demo: installs what is missing, builds gimlod in Release, builds the atlases of the shipped
# SRTM tile and the shipped scan, renders them to PNG frames with per-frame statistics, and takes
# a picture of each in the viewer (a scripted run on a virtual display), which become the README's
# pictures (docs/images).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/install-deps.sh
cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build build -j"$(nproc)" --target gimlod
mkdir -p out
./build/gimlod build data/terrain/mt_rainier_90m.tif -o out/rainier.atlas --imagery data/terrain/mt_rainier_imagery.tif
./build/gimlod render out/rainier.atlas -o out/rainier_orbit --orbit 24 --size 640x480 --tolerance 1
./build/gimlod render out/rainier.atlas -o out/rainier_flyby --path scenes/rainier_flyby.json --size 640x480 --tolerance 1
./build/gimlod build data/meshes/bun_zipper.ply -o out/bunny.atlas
./build/gimlod render out/bunny.atlas -o out/bunny_orbit --path scenes/bunny_orbit.json --size 640x480 --tolerance 1
./build/gimlod build data/terrain/etopo_30min.tif -o out/earth.atlas --planet
./build/gimlod render out/earth.atlas -o out/earth_orbit --orbit 24 --distance 0.6 --size 640x480 --tolerance 1
xvfb-run -a -s "-screen 0 1280x1024x24" ./build/gimlod view out/rainier.atlas --path scenes/rainier_flyby.json \
  --frames 12 --size 960x540 --screenshot out/view_rainier.png
xvfb-run -a -s "-screen 0 1280x1024x24" ./build/gimlod view out/bunny.atlas --path scenes/bunny_orbit.json \
  --frames 3 --size 960x540 --overlay chart --screenshot out/view_bunny_charts.png
# The README's two pictures are these.
cp out/view_rainier.png out/view_bunny_charts.png docs/images/
echo "frames and stats.csv are in out/rainier_orbit, out/rainier_flyby and out/bunny_orbit;"
echo "the viewer's pictures are out/view_rainier.png and out/view_bunny_charts.png."
echo "To fly through them: ./build/gimlod view out/rainier.atlas (or out/bunny.atlas)"
