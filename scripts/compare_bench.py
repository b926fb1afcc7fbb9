#!/usr/bin/env python3
"""Multi-grained against fixed granularity, from `gimlod bench --mode budget` output (python3 only).

Usage: python3 scripts/compare_bench.py OUT_DIR [OUT_DIR ...]

Reads each OUT_DIR/summary.csv with `ours` and `fixed` rows. Error mode (`--tolerance`): one
Markdown table of what each needs to hold the tolerance, nodes and triangles, and their ratios.
Budget mode (a node x triangle sweep): two tables:
  - at equal node and triangle budgets: the max-error p95 of ours and of fixed, and their ratio;
    rows whose node budget is below the visible roots (both draw the roots) are marked;
  - at equal error: per triangle budget and per node budget of ours, the nodes fixed granularity
    needs to reach ours' p95, interpolated on log(nodes) between the node budgets swept
    ("> N" when no swept budget reaches it), and ours' mean nodes against that.
"""
import csv
import math
import os
import sys


def read(out_dir):
    path = os.path.join(out_dir, "summary.csv")
    if not os.path.exists(path):
        sys.exit(f"{path}: no such file (run `gimlod bench ... --mode budget -o {out_dir}` first)")
    rows = {}
    modes = set()
    with open(path, newline="") as f:
        for r in csv.DictReader(f):
            modes.add(r["mode"])
            if r["mode"] == "budget":
                key = (r["algorithm"], int(r["max_nodes"]), int(r["max_triangles"]))
            else:
                key = (r["algorithm"], int(r["max_nodes"]), float(r["tolerance_px"]))
            rows[key] = r
    if len(modes) != 1:
        sys.exit(f"{path}: {'no rows' if not modes else 'mixed modes'}")
    for algo in ("ours", "fixed"):
        if not any(k[0] == algo for k in rows):
            sys.exit(f"{path}: no rows for {algo!r} (run with --algorithms ours,fixed)")
    return modes.pop(), rows


def nodes_for_error(fixed, target):
    """Nodes fixed granularity needs for p95 <= target: [(budget, nodes_mean, p95)] by budget."""
    for i, (budget, nodes, err) in enumerate(fixed):
        if err <= target:
            if i == 0:
                return nodes, False
            b0, n0, e0 = fixed[i - 1]
            if e0 == err:
                return nodes, False
            w = (e0 - target) / (e0 - err)  # linear in error, log-linear in nodes
            return math.exp(math.log(n0) + w * (math.log(nodes) - math.log(n0))), False
    return fixed[-1][1] if fixed else float("nan"), True


def error_table(out_dir, rows):
    print(f"\n### {out_dir}\n")
    print("| tolerance px | node cap | ours: nodes | ours: triangles | ours p95 px | fixed: nodes | fixed: triangles "
          "| fixed p95 px | nodes ours / fixed | triangles ours / fixed |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for algo, cap, tol in sorted(k for k in rows if k[0] == "ours"):
        f = rows.get(("fixed", cap, tol))
        if f is None:
            continue
        o = rows[("ours", cap, tol)]
        no, nf = float(o["nodes_mean"]), float(f["nodes_mean"])
        to, tf = float(o["triangles_mean"]), float(f["triangles_mean"])
        print(f"| {tol:g} | {cap} | {no:.1f} | {to / 1000:.1f}k | {float(o['max_error_px_p95']):.3f} | {nf:.1f} "
              f"| {tf / 1000:.1f}k | {float(f['max_error_px_p95']):.3f} | {no / nf:.2f} | {to / tf:.3f} |")


def main():
    if len(sys.argv) < 2 or sys.argv[1] in ("-h", "--help"):
        print(__doc__)
        return 0 if len(sys.argv) >= 2 else 2
    for out_dir in sys.argv[1:]:
        mode, rows = read(out_dir)
        if mode == "error":
            error_table(out_dir, rows)
            continue
        budgets = sorted({(k[1], k[2]) for k in rows if k[0] == "ours" and ("fixed",) + k[1:] in rows})
        print(f"\n### {out_dir}\n")
        print("| nodes / triangles | root floor | ours p95 px | fixed p95 px | ours / fixed | ours nodes | fixed nodes |")
        print("|---|---|---|---|---|---|---|")
        for n, t in budgets:
            o, f = rows[("ours", n, t)], rows[("fixed", n, t)]
            eo, ef = float(o["max_error_px_p95"]), float(f["max_error_px_p95"])
            floor = int(o["root_floor_max"])
            below = float(o["budget_below_roots_frac"]) > 0.0
            ratio = eo / ef if ef > 0 else float("nan")
            print(f"| {n} / {t // 1000}k | {floor}{' (above the budget)' if below else ''} | {eo:.3f} | {ef:.3f} "
                  f"| {ratio:.2f} | {float(o['nodes_mean']):.1f} | {float(f['nodes_mean']):.1f} |")
        print("\nAt equal error (fixed granularity's nodes interpolated on log(nodes)):\n")
        print("| triangles | ours: nodes budget | ours: nodes | ours p95 px | fixed: nodes for that p95 | ours / fixed |")
        print("|---|---|---|---|---|---|")
        for t in sorted({t for _, t in budgets}):
            fixed = sorted((n, float(rows[("fixed", n, t)]["nodes_mean"]), float(rows[("fixed", n, t)]["max_error_px_p95"]))
                           for n, tt in budgets if tt == t)
            for n, tt in budgets:
                if tt != t or float(rows[("ours", n, t)]["budget_below_roots_frac"]) > 0.0:
                    continue
                o = rows[("ours", n, t)]
                eo, no = float(o["max_error_px_p95"]), float(o["nodes_mean"])
                need, beyond = nodes_for_error(fixed, eo)
                shown = f"> {need:.0f}" if beyond else f"{need:.0f}"
                ratio = f"< {no / need:.2f}" if beyond else f"{no / need:.2f}"
                print(f"| {t // 1000}k | {n} | {no:.1f} | {eo:.3f} | {shown} | {ratio} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
