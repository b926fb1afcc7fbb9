#!/usr/bin/env python3
"""Streaming measures on a terrain atlas: a fast flight from high above down to the ground and
back, with a hold at the bottom, rendered with `gimlod render` under a simulated slow disk and
caches of a fraction of the atlas's pages, with prefetch and without, and once without latency.

Prints, per run: incomplete frames, the largest resident bytes against each budget, the median
and 99th-percentile frame time, the hit rate (pages the frames needed that were resident as they
began), and how many frames after the camera stops the error is back at the no-latency run's.

  python3 scripts/streaming_flight.py ATLAS [--gimlod build/gimlod] [--frames 120] [--hold 30]
      [--latency 20] [--cache-share 0.02] [--cache-of pages|disk] [--max-nodes 1000] [--size 640x360]
      [--out DIR]

The caches are cache-share of the atlas's pages as the GPU pool holds them: every node of every
chart, one pool page each (render's log gives a page's bytes); with --cache-of disk, of the atlas's
bytes on disk (its files, compressed), which is far less.
"""
import argparse
import csv
import json
import math
import os
import re
import statistics
import subprocess
import sys
import tempfile


def bounds(atlas):
    m = json.load(open(os.path.join(atlas, "atlas.json")))
    if m.get("kind") != "heightfield":
        sys.exit(f"{atlas}: a terrain atlas is needed (kind {m.get('kind')})")
    sx, sy = m["spacing"]
    lo = [0.0, 0.0, float(m["heightRange"][0])]
    hi = [(m["samplesX"] - 1) * sx, (m["samplesY"] - 1) * sy, float(m["heightRange"][1])]
    return lo, hi, m


def flight(lo, hi, frames, hold):
    """Down from a diagonal above the south-west towards the centre to 1/500 of it, a hold, and back."""
    ext = [h - l for l, h in zip(lo, hi)]
    diagonal = math.sqrt(sum(e * e for e in ext))
    centre = [(l + h) / 2 for l, h in zip(lo, hi)]
    start = (lo[0] + 0.1 * ext[0], lo[1] + 0.1 * ext[1])
    end = (centre[0], centre[1])
    ahead = (end[0] - start[0], end[1] - start[1])
    norm = math.hypot(*ahead) or 1.0
    ahead = (ahead[0] / norm, ahead[1] / norm)
    down = []
    for i in range(frames):
        s = i / (frames - 1) if frames > 1 else 0.0
        height = diagonal * 0.002 ** s
        at = (start[0] + s * (end[0] - start[0]), start[1] + s * (end[1] - start[1]))
        look = (at[0] + ahead[0] * 1.5 * height, at[1] + ahead[1] * 1.5 * height)
        down.append({"eye": [at[0], at[1], hi[2] + height], "target": [look[0], look[1], centre[2]],
                     "up": [0, 0, 1], "fov_deg": 45})
    return down + [down[-1]] * hold + list(reversed(down))


def render(gimlod, atlas, path, out, args, extra):
    cmd = [gimlod, "render", atlas, "-o", out, "--path", path, "--size", args.size, "--max-nodes",
           str(args.max_nodes)] + extra
    run = subprocess.run(cmd, capture_output=True, text=True)
    if run.returncode != 0:
        sys.exit("failed: " + " ".join(cmd) + "\n" + run.stdout + run.stderr)
    page = re.search(r"GPU page pool: (\d+) pages of (\d+) bytes", run.stdout + run.stderr)
    return list(csv.DictReader(open(os.path.join(out, "stats.csv")))), (int(page.group(2)) if page else 0)


def percentile(values, q):
    v = sorted(values)
    return v[min(len(v) - 1, int(math.ceil(q * len(v))) - 1)]


def summary(name, rows, stop, base):
    ms = [float(r["frame_ms"]) for r in rows]
    # The frame's own thread without the draw (llvmpipe rasterizes on the CPU beside the loader).
    cpu = [float(r["frame_ms"]) - float(r["draw_ms"]) for r in rows]
    need = sum(int(r["pages_needed"]) for r in rows)
    have = sum(int(r["pages_resident"]) for r in rows)
    back = None  # frames after the stop until the error is the no-latency run's (1% slack)
    for k in range(stop, len(rows)):
        if rows[k]["max_screen_error_px"] and base and float(rows[k]["max_screen_error_px"]) <= \
                1.01 * float(base[k]["max_screen_error_px"]) + 1e-9:
            back = k - stop
            break
        if k >= stop and rows[k]["eye_moved"] == "1":
            break
    over = lambda a, b: max(int(r[a]) / max(int(r[b]), 1) for r in rows)
    print(f"{name}: {len(rows)} frames, incomplete {sum(int(r['incomplete']) for r in rows)}, "
          f"GPU {max(int(r['resident_gpu_bytes']) for r in rows)} of {rows[0]['gpu_budget_bytes']} bytes "
          f"({over('resident_gpu_bytes', 'gpu_budget_bytes'):.3f}), RAM {max(int(r['resident_ram_bytes']) for r in rows)} "
          f"of {rows[0]['ram_budget_bytes']} ({over('resident_ram_bytes', 'ram_budget_bytes') if int(rows[0]['ram_budget_bytes']) else 0:.3f}), "
          f"frame ms median {statistics.median(ms):.2f} p99 {percentile(ms, 0.99):.2f} "
          f"(x{percentile(ms, 0.99) / max(statistics.median(ms), 1e-9):.2f}), without the draw median "
          f"{statistics.median(cpu):.2f} p99 {percentile(cpu, 0.99):.2f} (x{percentile(cpu, 0.99) / max(statistics.median(cpu), 1e-9):.2f}), hit rate {have / max(need, 1):.3f}, "
          f"stand-ins {sum(int(r['nodes_substituted']) for r in rows)}, loads {sum(int(r['loads_done']) for r in rows)} "
          f"done {sum(int(r['loads_cancelled']) for r in rows)} cancelled, prefetched "
          f"{sum(int(r['prefetch_requests']) for r in rows)}; error back {back} frames after the stop")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("atlas")
    ap.add_argument("--gimlod", default="build/gimlod")
    ap.add_argument("--frames", type=int, default=120, help="frames down (and as many back)")
    ap.add_argument("--hold", type=int, default=30, help="frames still at the bottom")
    ap.add_argument("--latency", default="20", help="--io-latency MS[,JITTER]")
    ap.add_argument("--cache-share", type=float, default=0.02)
    ap.add_argument("--cache-of", choices=["pages", "disk"], default="pages")
    ap.add_argument("--max-nodes", type=int, default=1000)
    ap.add_argument("--size", default="640x360")
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    lo, hi, manifest = bounds(args.atlas)
    out = args.out or tempfile.mkdtemp(prefix="gimlod-flight-")
    os.makedirs(out, exist_ok=True)
    path = os.path.join(out, "flight.json")
    cams = flight(lo, hi, args.frames, args.hold)
    json.dump({"frames": cams}, open(path, "w"))
    # A page's bytes from a first run; the atlas's pages: every node of every chart.
    stats = json.load(open(os.path.join(args.atlas, "stats.json")))
    charts, depth, hierarchy_nodes = stats["charts"], stats["hierarchy_depth"], stats["hierarchy_nodes"]
    _, page = render(args.gimlod, args.atlas, path, os.path.join(out, "probe"), args, ["--async-loads"])
    disk = sum(os.path.getsize(os.path.join(d, f)) for d, _, fs in os.walk(args.atlas) for f in fs)
    cache = int(args.cache_share * (hierarchy_nodes * page if args.cache_of == "pages" else disk))
    print(f"{args.atlas}: {charts} charts, depth {depth}, {hierarchy_nodes} nodes, pages of {page} bytes, {disk} bytes "
          f"on disk: caches of {cache} bytes ({args.cache_share:.0%} of the {args.cache_of}); {len(cams)} frames ({args.frames} down, {args.hold} "
          f"still, {args.frames} up), --io-latency {args.latency}, --max-nodes {args.max_nodes}")
    common = ["--gpu-cache", str(cache), "--ram-cache", str(cache)]
    stop = args.frames  # the first still frame
    base, _ = render(args.gimlod, args.atlas, path, os.path.join(out, "no_latency"), args, common + ["--prefetch", "0.5"])
    moved = [1 if i == 0 or cams[i] != cams[i - 1] else 0 for i in range(len(cams))]
    for rows in (base,):
        for r, m in zip(rows, moved):
            r["eye_moved"] = str(m)
    summary("no latency, prefetch 0.5 s", base, stop, base)
    for name, extra in (("latency, prefetch 0.5 s", ["--prefetch", "0.5"]), ("latency, no prefetch", ["--prefetch", "0"])):
        rows, _ = render(args.gimlod, args.atlas, path, os.path.join(out, name.replace(" ", "_").replace(",", "")), args,
                         common + ["--io-latency", args.latency] + extra)
        for r, m in zip(rows, moved):
            r["eye_moved"] = str(m)
        summary(name, rows, stop, base)


if __name__ == "__main__":
    main()
