#!/usr/bin/env bash
# The multi-grained tables of an atlas: ours against fixed granularity along an orbit and a
# fly-down, at equal budgets (--mode budget: node budgets 100, 1,000 and 10,000 by triangle
# budgets of 400,000 and 4M) and at equal error (--mode error: 1 px, the same node budgets), and
# the frames whose node count is over its budget (there should be none).
#   bash scripts/bench_tables.sh ATLAS OUT_DIR [GIMLOD]
# Writes OUT_DIR/{orbit,descent}_{budget,error}/ (bench.csv, summary.csv) and prints a line per
# configuration.
set -euo pipefail
atlas=$1
out=$2
gimlod=${3:-$(dirname "$0")/../build/gimlod}
mkdir -p "$out"
for path in orbit descent; do
  camera=(--descent 24)
  [ "$path" = orbit ] && camera=(--orbit 24 --distance 0.9 --elevation 45)
  "$gimlod" bench "$atlas" "${camera[@]}" --mode budget --nodes 100,1000,10000 --triangles 400000,4000000 \
    --algorithms ours,fixed -o "$out/${path}_budget" >/dev/null
  "$gimlod" bench "$atlas" "${camera[@]}" --mode error --tolerance 1 --nodes 100,1000,10000 \
    --algorithms ours,fixed -o "$out/${path}_error" >/dev/null
done
python3 - "$out" <<'PY'
import csv, sys
out = sys.argv[1]
for table in ("orbit_budget", "descent_budget", "orbit_error", "descent_error"):
    print(f"== {table}")
    for r in csv.DictReader(open(f"{out}/{table}/summary.csv")):
        print(f"{r['algorithm']:6} nodes<={r['max_nodes']:>6} tris<={r['max_triangles'] or '-':>8} "
              f"tol={r['tolerance_px'] or '-':>3} | nodes mean {float(r['nodes_mean']):8.0f} max {r['nodes_max']:>6} | "
              f"tris mean {float(r['triangles_mean']):9.0f} | max error p50 {float(r['max_error_px_p50']):7.2f} "
              f"max {float(r['max_error_px_max']):7.2f} px | adapt {float(r['adapt_us_mean']):7.0f} us")
    over = splits = frames = 0
    for r in csv.DictReader(open(f"{out}/{table}/bench.csv")):
        frames += 1
        splits += int(r["constraint_splits"])
        over += int(r["nodes"]) > int(r["max_nodes"]) and int(r["max_nodes"]) >= int(r["root_floor"])
    print(f"   {over} of {frames} frames over their node budget; {splits} constraint splits")
PY
