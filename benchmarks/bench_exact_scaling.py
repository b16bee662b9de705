"""Time and peak memory of geodata's exact solver (vtp, one source) with mesh size (issue 49, item 5).

    python benchmarks/bench_exact_scaling.py [--kinds irregular regular] [--sizes 10000 20000 40000 80000 160000 320000]

Each size runs in a fresh subprocess (``ru_maxrss`` is a process's peak): the mesh is built, the
solver prepared (``geodesic_solver``), then one source solved; the peak resident memory before and
after the solve and the solve's seconds are reported, with the estimate
:func:`geodata.geodesic.exact_memory_estimate` beside them. Meshes on a bumped, stretched sphere
(benchmarks/ablation_heat_time.py): ``irregular``, the convex hull of N random points on the unit sphere
(slivers, uneven valences); ``regular``, trimesh's icosphere at the level nearest N (2,562 x 4^k
vertices). A size whose estimate exceeds the memory available here is skipped, not run. The fits are
least squares of log(seconds) and log(solve memory) on log(N) over the rows of each kind.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys

import numpy as np

from machine import cpu_description  # benchmarks/ is on sys.path when a script there runs

CHILD = r"""
import json, resource, sys, time
import numpy as np
sys.path.insert(0, {bench!r})
from ablation_heat_time import bumped_stretched
from bench_exact_scaling import icosphere_level
from geodata.geodesic import geodesic_solver
from geodata.mesh import Mesh

kind, n = {kind!r}, {n}
if kind == "irregular":
    import trimesh
    x = np.random.default_rng(0).standard_normal((n, 3))
    m = trimesh.convex.convex_hull(x / np.linalg.norm(x, axis=1, keepdims=True))
else:
    import trimesh
    m = trimesh.creation.icosphere(icosphere_level(n))
v, f = bumped_stretched(m.vertices), np.asarray(m.faces)
t0 = time.perf_counter()
solve = geodesic_solver(Mesh(v, f))
prepare = time.perf_counter() - t0
before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
t0 = time.perf_counter()
d = solve(0)
seconds = time.perf_counter() - t0
after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
assert np.isfinite(d).all()
print(json.dumps(dict(vertices=len(v), prepare=prepare, seconds=seconds, before=before, after=after)))
"""


def icosphere_level(n: int) -> int:
    """trimesh's icosphere level whose vertex count (10 x 4^level + 2) is nearest n in log scale."""
    return int(round(np.log(max(n, 642) / 2562) / np.log(4))) + 4


def fit(n, y) -> tuple[float, float]:
    """y ~ a n^b by least squares in logs: (a, b)."""
    b, log_a = np.polyfit(np.log(n), np.log(y), 1)
    return float(np.exp(log_a)), float(b)


def main():
    from geodata.geodesic import available_memory, exact_memory_estimate

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--kinds", nargs="+", default=["irregular", "regular"])
    ap.add_argument("--sizes", type=int, nargs="+", default=[10000, 20000, 40000, 80000, 160000, 320000])
    args = ap.parse_args()
    bench = str(__import__("pathlib").Path(__file__).resolve().parent)
    print(f"CPU: {cpu_description()}; available memory {available_memory() / 2 ** 30:.1f} GiB")
    print("| mesh | vertices | solve s | peak before solve | peak after | solve memory | estimate |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for kind in args.kinds:
        rows = []
        sizes = args.sizes if kind == "irregular" else sorted({10 * 4 ** icosphere_level(n) + 2 for n in args.sizes})
        for n in sizes:
            estimate = exact_memory_estimate(n)
            if estimate > 0.8 * available_memory():
                print(f"| {kind} | ~{n} | skipped: estimate {estimate / 2 ** 30:.1f} GiB | | | | |", flush=True)
                continue
            out = subprocess.run([sys.executable, "-c", CHILD.format(bench=bench, kind=kind, n=n)],
                                 capture_output=True, text=True)
            if out.returncode:
                print(f"| {kind} | ~{n} | failed: {out.stderr.strip().splitlines()[-1]} | | | | |", flush=True)
                continue
            r = json.loads(out.stdout.strip().splitlines()[-1])
            r["solve_mem"] = r["after"] - r["before"]
            rows.append(r)
            print(f"| {kind} | {r['vertices']} | {r['seconds']:.1f} | {r['before'] / 2 ** 30:.2f} GiB | "
                  f"{r['after'] / 2 ** 30:.2f} GiB | {r['solve_mem'] / 2 ** 30:.2f} GiB | "
                  f"{exact_memory_estimate(r['vertices']) / 2 ** 30:.2f} GiB |", flush=True)
        if len(rows) >= 3:
            n = [r["vertices"] for r in rows]
            a, b = fit(n, [r["seconds"] for r in rows])
            print(f"{kind}: seconds ~ {a:.3g} N^{b:.2f}", flush=True)
            big = [r for r in rows if r["solve_mem"] > 2 ** 27]  # below 128 MiB the peak is the allocator's noise
            if len(big) >= 2:
                a, b = fit([r["vertices"] for r in big], [r["solve_mem"] for r in big])
                print(f"{kind}: solve memory ~ {a:.3g} N^{b:.2f} bytes (rows over 128 MiB)", flush=True)


if __name__ == "__main__":
    main()
