#!/usr/bin/env python3
"""Plots for `gimlod bench` output (python3 + matplotlib, Agg backend; no other dependencies).

Usage: python3 scripts/plot_bench.py OUT_DIR [--nodes N] [--triangles T]

Reads OUT_DIR/summary.csv and writes into OUT_DIR:
  nodes_time.png        nodes vs adaptation time per frame (like the paper's figure 6, left)
  nodes_error.png       nodes vs max screen error (figure 6, right)
  pareto_triangles.png  max error vs triangles of ours and each baseline (budget mode: at a fixed
                        node budget, --nodes, default the largest; error mode: one point per node
                        budget)
  error_vs_nodes.png    max error vs node budget (budget mode: at a fixed triangle budget,
                        --triangles, default the largest; error mode: all configurations)
In budget mode the figure-6 plots use the fixed triangle budget too.
"""
import argparse
import csv
import os
import sys
from collections import defaultdict

try:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
except ImportError:
    # note: another python3 first on PATH (a virtualenv, pyenv) does not see Debian's package;
    # fall back to the system interpreter once.
    system = "/usr/bin/python3"
    if os.path.realpath(sys.executable) != os.path.realpath(system) and os.path.exists(system):
        os.execv(system, [system] + sys.argv)
    sys.exit("plot_bench.py needs matplotlib (Debian: apt-get install python3-matplotlib)")

STYLE = {"ours": ("tab:blue", "o"), "fixed": ("tab:red", "s"), "greedy": ("tab:green", "^")}


def read_summary(out_dir):
    path = os.path.join(out_dir, "summary.csv")
    if not os.path.exists(path):
        sys.exit(f"{path}: not found (run `gimlod bench ... -o {out_dir}` first)")
    rows = []
    with open(path, newline="") as f:
        for r in csv.DictReader(f):
            r["max_nodes"] = int(r["max_nodes"])
            r["max_triangles"] = int(r["max_triangles"]) if r["max_triangles"] else 0
            for k in ("adapt_us_mean", "nodes_mean", "triangles_mean", "max_error_px_mean",
                      "max_error_px_p50", "max_error_px_p95", "max_error_px_max"):
                r[k] = float(r[k])
            rows.append(r)
    if not rows:
        sys.exit(f"{path}: no configurations")
    return rows


def by_algorithm(rows, xkey):
    groups = defaultdict(list)
    for r in rows:
        groups[r["algorithm"]].append(r)
    for algo in groups:
        groups[algo].sort(key=lambda r: r[xkey])
    return groups


def plot(rows, xkey, ykey, xlabel, ylabel, title, path, band=False, logx=False):
    fig, ax = plt.subplots(figsize=(6, 4.2), dpi=110)
    for algo, g in sorted(by_algorithm(rows, xkey).items()):
        color, marker = STYLE.get(algo, (None, "x"))
        xs = [r[xkey] for r in g]
        ax.plot(xs, [r[ykey] for r in g], marker=marker, color=color, label=algo)
        if band:
            ax.fill_between(xs, [r["max_error_px_p50"] for r in g], [r["max_error_px_p95"] for r in g],
                            color=color, alpha=0.15, linewidth=0)
    if logx:
        ax.set_xscale("log")
    if ykey.startswith("max_error"):
        ax.set_yscale("log")  # a few frames far over tolerance would hide the rest
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    print("wrote", path)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out_dir")
    ap.add_argument("--nodes", type=int, help="budget mode: node budget of the Pareto plot (default: largest)")
    ap.add_argument("--triangles", type=int, help="budget mode: triangle budget of the node plots (default: largest)")
    args = ap.parse_args()
    rows = read_summary(args.out_dir)
    budget = rows[0]["mode"] == "budget"
    out = lambda name: os.path.join(args.out_dir, name)
    band = "(shaded: max error p50..p95 over frames)"

    if budget:
        tris = args.triangles or max(r["max_triangles"] for r in rows)
        nodes = args.nodes or max(r["max_nodes"] for r in rows)
        at_tris = [r for r in rows if r["max_triangles"] == tris]
        at_nodes = [r for r in rows if r["max_nodes"] == nodes]
        if not at_tris or not at_nodes:
            sys.exit(f"no configurations with --triangles {tris} / --nodes {nodes} in summary.csv")
        sub = f"triangle budget {tris}"
        plot(at_tris, "nodes_mean", "adapt_us_mean", "drawn nodes (mean)", "adaptation time per frame (us)",
             f"Adaptation time vs nodes ({sub})", out("nodes_time.png"))
        plot(at_tris, "nodes_mean", "max_error_px_mean", "drawn nodes (mean)", "max screen error (px, mean)",
             f"Error vs nodes ({sub})\n{band}", out("nodes_error.png"), band=True)
        plot(at_nodes, "triangles_mean", "max_error_px_mean", "triangles (mean)", "max screen error (px, mean)",
             f"Error vs triangles at node budget {nodes}\n{band}", out("pareto_triangles.png"), band=True, logx=True)
        plot(at_tris, "max_nodes", "max_error_px_mean", "node budget", "max screen error (px, mean)",
             f"Error vs node budget ({sub})\n{band}", out("error_vs_nodes.png"), band=True, logx=True)
    else:
        tol = rows[0]["tolerance_px"]
        sub = f"tolerance {tol} px"
        plot(rows, "nodes_mean", "adapt_us_mean", "drawn nodes (mean)", "adaptation time per frame (us)",
             f"Adaptation time vs nodes ({sub})", out("nodes_time.png"))
        plot(rows, "nodes_mean", "max_error_px_mean", "drawn nodes (mean)", "max screen error (px, mean)",
             f"Error vs nodes ({sub})\n{band}", out("nodes_error.png"), band=True)
        plot(rows, "triangles_mean", "max_error_px_mean", "triangles (mean)", "max screen error (px, mean)",
             f"Error vs triangles, one point per node budget ({sub})", out("pareto_triangles.png"), band=True,
             logx=True)
        plot(rows, "max_nodes", "max_error_px_mean", "node budget", "max screen error (px, mean)",
             f"Error vs node budget ({sub})\n{band}", out("error_vs_nodes.png"), band=True, logx=True)


if __name__ == "__main__":
    main()
