#!/usr/bin/env bash
# Viewer frame time against render on the same path and size (the panel's and the window's cost).
# Usage: scripts/measure_view_overhead.sh ATLAS PATH.json WxH FRAMES OUT_DIR (needs xvfb-run).
set -euo pipefail
cd "$(dirname "$0")/.."
atlas=$1; path=$2; size=$3; n=$4; out=$5
mkdir -p "$out"
./build/gimlod render "$atlas" -o "$out/render" --path "$path" --size "$size" > /dev/null 2>&1
xvfb-run -a -s "-screen 0 1920x1080x24" ./build/gimlod view "$atlas" --path "$path" --size "$size" --frames "$n" --exit-after "$n" --stats "$out/view_ui.csv" > /dev/null 2>&1
xvfb-run -a -s "-screen 0 1920x1080x24" ./build/gimlod view "$atlas" --path "$path" --size "$size" --frames "$n" --exit-after "$n" --hide-ui --stats "$out/view_noui.csv" > /dev/null 2>&1
python3 - "$out" <<'PY'
import csv, sys, statistics as st
out = sys.argv[1]
def col(f, name, skip=2):
    rows = list(csv.DictReader(open(f)))[skip:]
    return [float(r[name]) for r in rows if r[name] not in ('', 'nan')]
r = col(f"{out}/render/stats.csv", "frame_ms")
u = col(f"{out}/view_ui.csv", "frame_ms"); h = col(f"{out}/view_noui.csv", "frame_ms")
ru, rh = st.median(u) / st.median(r), st.median(h) / st.median(r)
print(f"median frame ms: render {st.median(r):.2f}, view with panel {st.median(u):.2f} ({ru:.3f}x render), view --hide-ui {st.median(h):.2f} ({rh:.3f}x); panel alone {st.median(u)/st.median(h):.3f}x")
PY
