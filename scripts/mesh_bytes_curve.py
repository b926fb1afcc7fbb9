#!/usr/bin/env python3
"""Mesh atlas bytes per input triangle against the Hausdorff distance (python3 only).

Usage: python3 scripts/mesh_bytes_curve.py [--gimlod BIN] [--sizes 33,65,129,auto]
                                           [--bits 18,22] [--tolerances 0.005/1,0/0/stored]
                                           [--sample-errors default,0.1] [--full-charts]
                                           [--work DIR] MESH [MESH ...]

Builds each MESH with `gimlod build MESH -o ATLAS` once per chart size (`--chart-size N`; `auto`
is the default chart size, chosen by density and doubled to the sampling bound), per position
lattice (`--position-bits B`) and per settling tolerance P/N[/NORMALS] (`--position-tolerance P`,
in % of the diagonal, `--normal-tolerance N`, and `--normals NORMALS` if given: auto, stored or
derived; 0/0/stored stores the nearest lattice points and every sampled normal) and per sampling
bound (`--sample-error E`, in % of the diagonal; `default`: the build's own), with `--full-charts`
passed on if given (every chart keeps its finest level), the other options at their defaults (normals derived where the atlas holds at most 16 samples per triangle; the
table gives the derived normals' median and 99th-percentile angle from the resampled ones), one
build after another.
Prints one Markdown table: per build, charts, samples (every chart at the chart size, and the
samples the charts keep from their finest levels), bytes on disk per input triangle (the whole
atlas: charts, hierarchy, manifest), flipped texels and the two-sided Hausdorff distance in % of
the bounding-box diagonal, from each atlas's stats.json. The atlases go to a temporary directory
(or --work) and are removed after their row is read.
"""
import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile


def build(gimlod, mesh, size, bits, tolerance, bound, full, work):
    out = os.path.join(work, "curve.atlas")
    shutil.rmtree(out, ignore_errors=True)
    cmd = [gimlod, "build", mesh, "-o", out, "--position-bits", str(bits),
           "--position-tolerance", tolerance[0], "--normal-tolerance", tolerance[1], "--normals", tolerance[2]]
    if size != "auto":
        cmd += ["--chart-size", str(size)]
    if bound != "default":
        cmd += ["--sample-error", bound]
    if full:
        cmd += ["--full-charts"]
    r = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    if r.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed ({r.returncode}):\n{r.stdout[-2000:]}")
    with open(os.path.join(out, "stats.json")) as f:
        st = json.load(f)
    shutil.rmtree(out, ignore_errors=True)
    return st


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("meshes", nargs="+")
    ap.add_argument("--gimlod", default=os.path.join(os.path.dirname(__file__), "..", "build", "gimlod"))
    ap.add_argument("--sizes", default="33,65,129,auto")
    ap.add_argument("--bits", default="18,22")
    ap.add_argument("--tolerances", default="0.005/1,0/0/stored")
    ap.add_argument("--sample-errors", default="default")
    ap.add_argument("--full-charts", action="store_true")
    ap.add_argument("--work", default=None)
    a = ap.parse_args()
    bounds = [b.strip() for b in a.sample_errors.split(",") if b.strip()]
    for b in bounds:
        try:
            if b != "default":
                float(b)
        except ValueError:
            sys.exit(f"--sample-errors: {b!r} is neither a % of the diagonal nor default")
    sizes = [s.strip() for s in a.sizes.split(",") if s.strip()]
    for s in sizes:
        if s != "auto" and not s.isdigit():
            sys.exit(f"--sizes: {s!r} is neither a chart size nor auto")
    bits = [int(b) for b in a.bits.split(",") if b.strip()]
    tolerances = []
    for t in a.tolerances.split(","):
        parts = t.strip().split("/")
        if len(parts) == 2:
            parts.append("auto")
        if len(parts) != 3 or parts[2] not in ("auto", "stored", "derived"):
            sys.exit(f"--tolerances: {t!r} is not POSITION/NORMAL[/auto|stored|derived]")
        try:
            float(parts[0]), int(parts[1])
        except ValueError:
            sys.exit(f"--tolerances: {t!r} is not a number of % and a whole number of packed steps")
        tolerances.append(tuple(parts))
    work = a.work or tempfile.mkdtemp(prefix="gimlod-bytes-curve-")
    os.makedirs(work, exist_ok=True)
    print("| mesh | triangles | chart size | position bits | tolerance (% / steps) | sample error % | normals "
          "| charts | samples | kept samples | bytes per triangle | flipped texels | Hausdorff % of diagonal |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    try:
        for mesh in a.meshes:
            for size in sizes:
                for b in bits:
                    for t, bound in ((t, bound) for t in tolerances for bound in bounds):
                        st = build(a.gimlod, mesh, size, b, t, bound, a.full_charts, work)
                        tri = st["charting"]["triangles"]
                        shown = f"{st['chart_size']}² (auto)" if size == "auto" else f"{st['chart_size']}²"
                        normals = st.get("normals", {})
                        shown_normals = "derived" if normals.get("derived") else "stored"
                        if normals.get("derived"):
                            deg = normals["degrees_from_resampled"]
                            shown_normals += f" ({deg['median']:.1f}° / {deg['p99']:.1f}°)"
                        diag = st["fidelity"]["diagonal"]
                        shown_bound = f"{100 * st['resample']['max_sample_error'] / diag:.3f}" if diag > 0 else "-"
                        kept = st.get("finest_samples", st["samples"])
                        print(f"| {os.path.basename(mesh)} | {tri} | {shown} | {b} | {t[0]} / {t[1]} | {shown_bound} "
                              f"| {shown_normals} | {st['charts']} | {st['samples'] / 1e6:.2f}M | {kept / 1e6:.2f}M "
                              f"| {st['bytes_on_disk'] / tri:.1f} "
                              f"| {st['resample']['flipped_texels']} "
                              f"| {st['fidelity']['hausdorff_percent_of_diagonal']:.4f} |", flush=True)
    finally:
        if a.work is None:
            shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
