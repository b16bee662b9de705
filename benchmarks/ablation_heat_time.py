"""Ablation of the heat method's time step t with mesh size (issue 49, item 2).

    python benchmarks/ablation_heat_time.py [--meshes regular irregular max homer camel]
        [--levels 0 1 2 3] [--sources 4] [--coefs 0.5 1 2 4 8 16]

A base mesh of ~2.5k-6k vertices, its exact distances (geodata's vtp solver) from a few sources to its
own vertices, then its midpoint subdivisions (trimesh.remesh.subdivide keeps the first vertices and the
surface, so the base's exact distances stay the truth for every level, taken at the base's vertices):

- ``regular``: trimesh's icosphere (2,562 vertices) mapped onto a bumped, stretched sphere;
- ``irregular``: the convex hull of 5,000 random points on the unit sphere, mapped the same way
  (slivers and uneven valences, kept by the subdivisions);
- real meshes from ../shared/meshes/dev (``max``: decimated-max, ``homer``, ``camel``: isoblend's).

Per mesh and level: vertex count, hbar (the mean cover edge length after mollification and flips, the
length the time step is measured in), D/hbar with D the bounding-box diagonal, and the mean relative
error (the training metric, |d - exact| / (exact + 1e-3 D/2)) over sources x base vertices of the heat
method with t = c hbar^2 for each --coefs c and the Poisson shift of today (POISSON_SHIFT), and of
HeatDistance's rule (:func:`gegnn.fields.heat.time_step` and :func:`~gegnn.fields.heat.poisson_shift`;
'rule c': its t / hbar^2). The cover, flips and operators are built once per mesh; each t costs one
factorization.
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from geodata.geodesic import geodesic_solver
from geodata.mesh import Mesh
from gegnn.fields import heat

from machine import cpu_description  # benchmarks/ is on sys.path when a script there runs

DEV = Path(__file__).resolve().parents[1] / ".." / "shared" / "meshes" / "dev"
REAL = {"max": "libigl-tutorial-data/decimated-max.obj", "homer": "common-3d-test-models/homer.obj",
        "camel": "isoblend/camel.obj"}


def bumped_stretched(points: np.ndarray) -> np.ndarray:
    """Unit-sphere points onto a smooth star-shaped surface: three bumps, stretched 1.6 x 1 x 0.7."""
    p = points / np.linalg.norm(points, axis=1, keepdims=True)
    r = 1 + 0.25 * np.sin(3 * p[:, 0]) * np.cos(2 * p[:, 1]) + 0.15 * np.sin(5 * p[:, 2] + 1)
    return p * r[:, None] * [1.6, 1.0, 0.7]


def base_mesh(name: str, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    import trimesh

    if name == "regular":
        m = trimesh.creation.icosphere(4)
        return bumped_stretched(m.vertices), np.asarray(m.faces)
    if name == "irregular":
        x = np.random.default_rng(seed).standard_normal((5000, 3))
        m = trimesh.convex.convex_hull(x / np.linalg.norm(x, axis=1, keepdims=True))
        return bumped_stretched(m.vertices), np.asarray(m.faces)
    m = trimesh.load(DEV / REAL[name], process=True, force="mesh")  # merge coincident vertices
    return np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces)


def subdivisions(v, f, levels: int):
    import trimesh.remesh

    out = [(v, f)]
    for _ in range(levels):
        v, f = trimesh.remesh.subdivide(v, f)
        out.append((v, f))
    return out


class Fields(heat.HeatSolver):
    """HeatDistance's cover, flips and operators, built once; :meth:`with_t` factors for one time step."""

    def __init__(self, v, f):
        v = np.ascontiguousarray(v, dtype=np.float64)
        f = np.ascontiguousarray(f, dtype=np.int64)
        self.n = len(v)
        cover = heat.tufted_cover(v, f)
        heat.mollify(cover, cover.length.sum() / len(cover.length))
        heat.flip_to_delaunay(cover)
        self.hbar = cover.length.sum() / len(cover.length)
        self.ops = heat.operators(cover, self.n)

    def with_t(self, t: float, shift: float = heat.POISSON_SHIFT) -> heat.HeatSolver:
        self.t, self.shift = t, shift
        self._factor("ablation", *self.ops)
        return self


def mre(fields: np.ndarray, exact: list[np.ndarray], sources, scale: float) -> float:
    errs = []
    for j, (s, d) in enumerate(zip(sources, exact)):
        e = np.abs(fields[:len(d), j] - d) / (d + 1e-3 * scale)
        e[s] = np.nan
        errs.append(e)
    return float(np.nanmean(np.concatenate(errs)))


def run_mesh(name: str, levels: list[int], n_sources: int, coefs: list[float]) -> None:
    v0, f0 = base_mesh(name)
    sources = np.random.default_rng(1).choice(len(v0), n_sources, replace=False)
    solve = geodesic_solver(Mesh(v0, f0))
    exact = [solve(int(s)) for s in sources]
    diag = float(np.linalg.norm(np.ptp(v0, axis=0)))
    scale = float(np.ptp(v0, axis=0).max() / 2)
    print(f"\n{name}: base {len(v0)} vertices, D = bbox diagonal {diag:.3f}, "
          f"largest exact distance from the sources {max(d.max() for d in exact) / diag:.2f} D", flush=True)
    print(f"| vertices | D/hbar | rule c | " + " | ".join(f"c={c:g}" for c in coefs) + " | rule | seconds |")
    print("|---:|---:|---:|" + "---:|" * len(coefs) + "---:|---:|")
    meshes = subdivisions(v0, f0, max(levels))
    for level in levels:
        v, f = meshes[level]
        t0 = time.perf_counter()
        fields = Fields(v, f)
        rule_t = heat.time_step(fields.hbar, diag, len(v))
        cells = []
        for c in coefs:
            d = fields.with_t(c * fields.hbar ** 2).distances(sources)
            cells.append(f"{100 * mre(d, exact, sources, scale):.2f}%")
        if len(v) <= heat.SAME_UP_TO and 0.5 in coefs:  # the rule is today's there, by construction
            rule = cells[coefs.index(0.5)]
        else:
            d = fields.with_t(rule_t, heat.poisson_shift(len(v))).distances(sources)
            rule = f"{100 * mre(d, exact, sources, scale):.2f}%"
        print(f"| {len(v)} | {diag / fields.hbar:.0f} | {rule_t / fields.hbar ** 2:.2f} | " + " | ".join(cells)
              + f" | {rule} | {time.perf_counter() - t0:.0f} |", flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--meshes", nargs="+", default=["regular", "irregular", "max", "homer", "camel"])
    ap.add_argument("--levels", type=int, nargs="+", default=[0, 1, 2, 3])
    ap.add_argument("--sources", type=int, default=4)
    ap.add_argument("--coefs", type=float, nargs="+", default=[0.5, 1, 2, 4, 8, 16])
    args = ap.parse_args()
    print(f"CPU: {cpu_description()}")
    print("MRE of HeatDistance against the exact distances of the base mesh, at its vertices; "
          "t = c hbar^2 per column (Poisson shift 1e-6), "
          "'rule': HeatDistance's time_step and poisson_shift")
    for name in args.meshes:
        run_mesh(name, args.levels, args.sources, args.coefs)


if __name__ == "__main__":
    main()
