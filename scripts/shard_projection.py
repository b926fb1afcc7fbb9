#!/usr/bin/env python3
"""The critical path of a sharded terrain build on a cluster, projected from a measured one.

    python3 scripts/shard_projection.py ATLAS [--machines 16 64] [--cores 2] [--efficiency 0.87]

ATLAS is an atlas built by a sharded build (its stats.json holds each step's figures,
docs/distributed.md). Each chart's estimated work is the plan's (pipeline/sharded_build.cpp
chartWork: its samples inside the DEM plus 0.8 of a whole chart's); the measured shards give the
CPU seconds per unit of work. On M machines of `cores` cores the build runs M shards, split as the
plan splits them, each taking its work times that rate over (cores x efficiency) seconds; the
critical path is the prepare (as measured) + the slowest shard + the merge (as measured).
"""
import argparse
import json
import os
import subprocess


def read_manifest(atlas):
    """The manifest, with its chart list read from its own file where it has one (version 3)."""
    m = json.load(open(os.path.join(atlas, "atlas.json")))
    if "chartList" in m:
        text = subprocess.run(["zstd", "-dc", os.path.join(atlas, m["chartList"])], check=True,
                              capture_output=True).stdout
        m["charts"] = json.loads(text)
    return m


def chart_work(m):
    M = m["chartSize"] - 1
    out = []
    for c in m["charts"]:
        w = min(max(m["samplesX"] - c["gridX"] * M, 1), M + 1)
        h = min(max(m["samplesY"] - c["gridY"] * M, 1), M + 1)
        out.append(w * h + 0.8 * (M + 1) * (M + 1))
    return out


def split(work, n):
    """The runs shardCharts gives: contiguous, the least largest run, none empty while charts >= n."""
    def runs_under(bound):
        runs, s = 1, 0.0
        for w in work:
            if s + w > bound and s > 0:
                runs, s = runs + 1, 0.0
            s += w
        return runs
    lo, hi = max(work), sum(work)
    for _ in range(100):
        if hi - lo <= 1e-9 * hi:
            break
        mid = 0.5 * (lo + hi)
        if runs_under(mid) <= n:
            hi = mid
        else:
            lo = mid
    shards, run, s = [[] for _ in range(n)], 0, 0.0
    for c, w in enumerate(work):
        few_left = len(work) - c <= n - 1 - min(run, n - 1)
        if s > 0 and (s + w > hi or few_left):
            run, s = run + 1, 0.0
        s += w
        shards[run].append(c)
    return shards


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("atlas")
    ap.add_argument("--machines", type=int, nargs="+", default=[16, 64])
    ap.add_argument("--cores", type=int, default=2)
    ap.add_argument("--efficiency", type=float, default=0.87,
                    help="CPU seconds a build's threads keep busy per core and second (one process on this "
                         "machine: 517 CPU s in 297 s on 2 cores)")
    a = ap.parse_args()
    m = read_manifest(a.atlas)
    st = json.load(open(os.path.join(a.atlas, "stats.json")))["sharded"]
    work = chart_work(m)
    measured = split(work, st["shards"])
    shard_work = sum(sum(work[c] for c in measured[s["shard"]]) for s in st["per_shard"])
    rate = sum(s["cpu_seconds"] for s in st["per_shard"]) / shard_work  # CPU seconds per unit of work
    prepare, merge = st["prepare"]["seconds"], st["merge"]["seconds"]
    print(f"measured: {st['shards']} shards, {len(work)} charts; prepare {prepare:.1f} s, merge {merge:.1f} s; "
          f"{rate * sum(work):.1f} CPU s of shard work")
    print("| machines | shards | slowest shard (charts, s) | critical path s | speed-up over one machine |")
    print("|---:|---:|---|---:|---:|")
    one = prepare + rate * sum(work) / (a.cores * a.efficiency) + merge
    for n in [1] + a.machines:
        runs = split(work, n)
        slowest = max(runs, key=lambda r: sum(work[c] for c in r))
        t = rate * sum(work[c] for c in slowest) / (a.cores * a.efficiency)
        path = prepare + t + merge
        print(f"| {n} | {n} | {len(slowest)}, {t:.1f} | {path:.1f} | {one / path:.2f} |")


if __name__ == "__main__":
    main()
