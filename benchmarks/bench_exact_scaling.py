"""Time and peak memory of geodata's exact solver (vtp, one source) with mesh size, beside libigl where it
runs (issue 49, item 5; issue 58).

    python benchmarks/bench_exact_scaling.py [--kinds irregular regular]
        [--sizes 10000 40000 160000 320000 1000000] [--libigl-max 40000]

Meshes on a bumped, stretched sphere (benchmarks/ablation_heat_time.py): ``irregular``, the convex hull
of N random points on the unit sphere (slivers, uneven valences); ``regular``, trimesh's icosphere at the
level nearest N (2,562 x 4^k vertices). Each mesh is built once in a child process and written to a
temporary folder; then each solver runs in a fresh child of its own: the child loads the mesh, resets
its peak resident memory (``/proc/self/clear_refs``, Linux), notes its resident memory,
prepares the solver (``geodesic_solver``: the refusal check, then the mesh's half-edge tables), solves
source 0 and reports the seconds of each step (and the solve's CPU seconds, which other work on the
machine inflates less) and its peak resident memory over what it held before the
solver (the tables, the wavefront and the distances: the memory a solve needs), with the estimate
:func:`geodata.exact_memory.exact_memory_estimate` beside it. libigl runs the same source on meshes up to
``--libigl-max`` vertices (it keeps every window: minutes and gigabytes beyond), and the largest
relative difference of the two is reported. A size whose estimate exceeds the memory available here is
skipped, not run. The fits are least squares of log(CPU seconds) and log(memory) on log(N) over the
rows of each kind.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from machine import cpu_description  # benchmarks/ is on sys.path when a script there runs

MAKE = r"""
import sys
import numpy as np
import trimesh
sys.path.insert(0, {bench!r})
from ablation_heat_time import bumped_stretched
from bench_exact_scaling import icosphere_level

kind, n = {kind!r}, {n}
if kind == "irregular":
    x = np.random.default_rng(0).standard_normal((n, 3))
    m = trimesh.convex.convex_hull(x / np.linalg.norm(x, axis=1, keepdims=True))
else:
    m = trimesh.creation.icosphere(icosphere_level(n))
np.savez({path!r}, vertices=bumped_stretched(m.vertices), faces=np.asarray(m.faces, dtype=np.int32))
"""

SOLVE = r"""
import json, time
import numpy as np
from geodata.geodesic import geodesic_solver
from geodata.mesh import Mesh

def status(key):
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) * 1024 for line in f if line.startswith(key))

data = np.load({path!r})
mesh = Mesh(data["vertices"], data["faces"])
with open("/proc/self/clear_refs", "w") as f:
    f.write("5")  # the peak resident memory (VmHWM) restarts from here: imports and loading left out
start = status("VmRSS:")
t0 = time.perf_counter()
solve = geodesic_solver(mesh, {backend!r})
prepare = time.perf_counter() - t0
t0, c0 = time.perf_counter(), time.process_time()
d = solve(0)
seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
peak = status("VmHWM:")
assert np.isfinite(d).all()
np.save({out!r}, d)
print(json.dumps(dict(vertices=mesh.n_vertices, prepare=prepare, seconds=seconds, cpu=cpu, memory=peak - start)))
"""


def icosphere_level(n: int) -> int:
    """trimesh's icosphere level whose vertex count (10 x 4^level + 2) is nearest n in log scale."""
    return int(round(np.log(max(n, 642) / 2562) / np.log(4))) + 4


def fit(n, y) -> tuple[float, float]:
    """y ~ a n^b by least squares in logs: (a, b)."""
    b, log_a = np.polyfit(np.log(n), np.log(y), 1)
    return float(np.exp(log_a)), float(b)


def child(code: str) -> dict | str:
    """Run ``code`` in a fresh interpreter: its last line of output as JSON, or the last line of its error."""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    if out.returncode:
        return (out.stderr.strip().splitlines() or [f"exit {out.returncode}"])[-1]
    lines = out.stdout.strip().splitlines()
    return json.loads(lines[-1]) if lines else {}


def gib(b: float) -> str:
    return f"{b / 2 ** 30:.2f} GiB" if b >= 2 ** 30 else f"{b / 2 ** 20:.0f} MiB"


def main():
    from geodata.exact_memory import available_memory, exact_memory_estimate

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--kinds", nargs="+", default=["irregular", "regular"])
    ap.add_argument("--sizes", type=int, nargs="+", default=[10000, 40000, 160000, 320000, 1000000])
    ap.add_argument("--libigl-max", type=int, default=40000, help="largest mesh libigl is run on")
    args = ap.parse_args()
    bench = str(Path(__file__).resolve().parent)
    print(f"CPU: {cpu_description()}; available memory {available_memory() / 2 ** 30:.1f} GiB")
    print("| mesh | vertices | prepare s | solve s (CPU s) | memory | estimate | libigl s | libigl memory | max rel. diff. |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    with tempfile.TemporaryDirectory() as tmp:
        for kind in args.kinds:
            rows = []
            sizes = args.sizes if kind == "irregular" else sorted({10 * 4 ** icosphere_level(n) + 2 for n in args.sizes})
            for n in sizes:
                estimate = exact_memory_estimate(n)
                if estimate > 0.8 * available_memory():
                    print(f"| {kind} | ~{n} | skipped: estimate {gib(estimate)} | | | | | | |", flush=True)
                    continue
                path = f"{tmp}/{kind}{n}.npz"
                made = child(MAKE.format(bench=bench, kind=kind, n=n, path=path))
                if isinstance(made, str):
                    print(f"| {kind} | ~{n} | mesh failed: {made} | | | | | | |", flush=True)
                    continue
                r = child(SOLVE.format(path=path, backend="vtp", out=f"{tmp}/vtp.npy"))
                if isinstance(r, str):
                    print(f"| {kind} | ~{n} | failed: {r} | | | | | | |", flush=True)
                    continue
                rows.append(r)
                igl = child(SOLVE.format(path=path, backend="libigl", out=f"{tmp}/igl.npy")) \
                    if r["vertices"] <= args.libigl_max else None
                if isinstance(igl, dict):
                    a, b = np.load(f"{tmp}/vtp.npy"), np.load(f"{tmp}/igl.npy")
                    diff = float((np.abs(a - b) / np.maximum(b, 1e-300))[1:].max())
                    ref = f"{igl['seconds']:.2f} | {gib(igl['memory'])} | {diff:.1e}"
                else:
                    ref = f"failed: {igl} | | " if isinstance(igl, str) else "not run | | "
                print(f"| {kind} | {r['vertices']} | {r['prepare']:.2f} | {r['seconds']:.2f} ({r['cpu']:.2f}) | {gib(r['memory'])} | "
                      f"{gib(exact_memory_estimate(r['vertices']))} | {ref} |", flush=True)
                Path(path).unlink()
            if len(rows) >= 3:
                n = [r["vertices"] for r in rows]
                a, b = fit(n, [r["cpu"] for r in rows])
                print(f"{kind}: CPU seconds ~ {a:.3g} N^{b:.2f}", flush=True)
                a, b = fit(n, [r["memory"] for r in rows])
                print(f"{kind}: memory ~ {a:.3g} N^{b:.2f} bytes, {max(r['memory'] / r['vertices'] for r in rows):.0f} "
                      f"bytes a vertex at most", flush=True)


if __name__ == "__main__":
    main()
