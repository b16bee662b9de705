"""Landmark field solvers on one error x time frontier: the exact solver (vtp), the same with windows pruned
within a relative tolerance (``Surface.distances(sources, tolerance)``: every value still a real path's length),
and virtual source propagation (vsp, the shipped models' fields). Per mesh and solver: mean relative error
against exact, the largest value below exact (relative; a real-path solver has none beyond rounding), and ms a
field, the least thread CPU time of two calls of 10 sources each, one thread.

    python benchmarks/bench_field_frontier.py [--write]  # two classic meshes and eight geodata.zoo shapes

--write puts the table into docs/benchmarks.md (benchmarks/results.py's write_table).
"""
import sys
import time

import numpy as np

from bench_field_solver import load as load_real  # benchmarks/ is on sys.path when a script there runs
from geodata._exact_geodesic import Surface
from geodata.approximate_geodesic import ApproximateGeodesicSolver
from geodata.zoo import zoo_mesh

CLASSIC = ["max", "homer"]
SHAPES = ["torus-r0.3", "u-bend", "coil", "trefoil", "genus-3-plate", "t-pipe", "slivers", "noisy"]
TOLERANCES = (1e-4, 3e-4, 1e-3, 1e-2)


def load(name):
    v, f = load_real(name) if name in CLASSIC else zoo_mesh(name)
    return np.asarray(v, dtype=np.float64), np.asarray(f, dtype=np.int32)


def timed(solve, sources):
    best, out = np.inf, None
    for _ in range(2):
        start = time.thread_time()
        out = solve(sources)
        best = min(best, time.thread_time() - start)
    return out, 1e3 * best / len(sources)


def main(write: bool):
    solvers = ["exact"] + [f"tolerance {t:g}" for t in TOLERANCES] + ["vsp"]
    lines = ["| mesh | vertices | " + " | ".join(f"{s}: mean, most short, ms" for s in solvers) + " |",
             "|---|---:|" + "---:|" * len(solvers)]
    print(lines[0])
    for name in [*CLASSIC, *SHAPES]:
        v, f = load(name)
        sources = np.linspace(0, len(v) - 1, 10).astype(np.int64)
        surface = Surface(v, f)
        vsp = ApproximateGeodesicSolver(v, f)
        truth, exact_ms = timed(surface.distances, sources)
        keep = truth > 1e-9
        cells = [f"0, 0, {exact_ms:.1f}"]
        for solve in [*(lambda s, t=t: surface.distances(s, t) for t in TOLERANCES),
                      lambda s: vsp.distances(s, threads=1)]:
            d, ms = timed(solve, sources)
            ratio = d[keep] / truth[keep] - 1
            cells.append(f"{100 * np.abs(ratio).mean():.4f}%, {max(0.0, -ratio.min()):.0e}, {ms:.1f}")
        lines.append(f"| {name} | {len(v):,} | " + " | ".join(cells) + " |")
        print(lines[-1], flush=True)
    if write:
        from results import write_table  # benchmarks/ is on sys.path when this script runs

        write_table("docs/benchmarks.md", lines)


if __name__ == "__main__":
    main("--write" in sys.argv)
