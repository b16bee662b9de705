"""Scalability and convergence of the shipped models with mesh resolution (the paper's Table 2 and its
sphere test), in one run.

    python benchmarks/bench_resolution.py data/val.zarr [--meshes 19] [--sources 4] [--out docs/img/app-resolution.png]

- validation meshes at ~5k, ~20k and ~80k vertices: the prepared mesh and its Loop subdivisions
  (trimesh), exact distances recomputed on each (geodata's vtp solver) from random sources to every
  vertex;
- spheres of 1k to 100k vertices (Fibonacci points on the unit sphere, their convex hull), against
  the great-circle distance, the answer the polyhedral distance converges to (the exact solver is
  timed on one source);

per model: the mean relative error (the training metric) and the precomputation time, `embed` (one
forward pass, and the landmark fields for the landmark model), next to the exact solver's time per
source. One torch thread; prints a table and draws MRE and seconds against vertex count.
"""
from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from geodata.geodesic import geodesic_solver
from geodata.mesh import Mesh
from gegnn import GeGnn
from gegnn.queries.files import relative_errors

from bench_applications import meshes  # benchmarks/ is on sys.path when a script there runs
from machine import cpu_description  # benchmarks/ is on sys.path when a script there runs

MODELS = ("landmark", "paper")


def fibonacci_sphere(n: int) -> tuple[np.ndarray, np.ndarray]:
    from scipy.spatial import ConvexHull

    k = np.arange(n) + 0.5
    z = 1 - 2 * k / n
    phi = np.pi * (1 + 5 ** 0.5) * k
    v = np.c_[np.sqrt(1 - z * z) * np.cos(phi), np.sqrt(1 - z * z) * np.sin(phi), z]
    f = ConvexHull(v).simplices
    flip = np.einsum("ij,ij->i", np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), v[f[:, 0]]) < 0
    f[flip] = f[flip][:, ::-1]
    return v, f


def measure(models, v, f, sources, reference=None) -> dict:
    """MRE per model over sources x all vertices against the exact solver's fields (or ``reference``,
    a function of the source), embed seconds per model, the exact solver's seconds per source."""
    solve = geodesic_solver(Mesh(v, f))
    t0 = time.perf_counter()
    exact = [solve(int(s)) for s in (sources if reference is None else sources[:1])]
    row = {"vertices": len(v), "exact_s": (time.perf_counter() - t0) / len(exact)}
    if reference is not None:
        exact = [reference(int(s)) for s in sources]
    scale = float(np.ptp(v, axis=0).max() / 2)
    for name, model in models.items():
        t0 = time.perf_counter()
        emb = model.embed(v, f)
        row[f"{name}_s"] = time.perf_counter() - t0
        errs = [relative_errors(emb.field(int(s)), d, scale, int(s)) for s, d in zip(sources, exact)]
        row[f"{name}_mre"] = float(np.nanmean(np.concatenate(errs)))
    return row


def main():
    import trimesh.remesh

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("store")
    ap.add_argument("--meshes", type=int, default=19)
    ap.add_argument("--sources", type=int, default=4)
    ap.add_argument("--spheres", type=int, nargs="+", default=[1000, 2000, 5000, 10000, 20000, 50000, 100000])
    ap.add_argument("--out", help="PNG of MRE and seconds against vertex count")
    args = ap.parse_args()
    print(f"CPU: {cpu_description()}", flush=True)
    torch.set_num_threads(1)
    models = {name: GeGnn.pretrained(name) for name in MODELS}
    rng = np.random.default_rng(0)

    mesh_rows = {0: [], 1: [], 2: []}
    for mesh_id, v, f in meshes(args.store, args.meshes):
        sources = rng.choice(len(v), args.sources, replace=False)  # subdivision keeps old vertex numbers
        for level in (0, 1, 2):
            if level:
                v, f = trimesh.remesh.subdivide_loop(v, f, iterations=1)
            row = measure(models, v, f, sources)
            mesh_rows[level].append(row)
            print(f"{mesh_id} level {level}: " + " ".join(f"{k} {x:.4g}" for k, x in row.items()), flush=True)

    sphere_rows = []
    for n in args.spheres:
        v, f = fibonacci_sphere(n)
        sources = rng.choice(n, args.sources, replace=False)
        row = measure(models, v, f, sources, lambda s: np.arccos(np.clip(v @ v[s], -1, 1)))
        sphere_rows.append(row)
        print(f"sphere {n}: " + " ".join(f"{k} {x:.4g}" for k, x in row.items()), flush=True)

    header = "| mesh | vertices | " + " | ".join(f"{m} MRE | {m} embed s" for m in MODELS) + " | exact s/source |"
    print("\n" + header + "\n|" + "---|" * (header.count("|") - 1))
    lines = [(f"validation, Loop x{level}", rows) for level, rows in mesh_rows.items() if rows]
    lines += [(f"sphere {r['vertices']}", [r]) for r in sphere_rows]
    for label, rows in lines:
        mean = {k: np.mean([r[k] for r in rows]) for k in rows[0]}
        cells = " | ".join(f"{100 * mean[f'{m}_mre']:.2f}% | {mean[f'{m}_s']:.2f}" for m in MODELS)
        print(f"| {label} | {mean['vertices']:.0f} | {cells} | {mean['exact_s']:.2f} |")
    if args.out:
        plot(args.out, mesh_rows, sphere_rows)


def plot(path, mesh_rows, sphere_rows):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    series = [("validation meshes", [r for rows in mesh_rows.values() if rows for r in [_mean(rows)]], "o-"),
              ("spheres vs great circle", sphere_rows, "s--")]
    for label, rows, style in series:
        n = [r["vertices"] for r in rows]
        for m in MODELS:
            axes[0].plot(n, [100 * r[f"{m}_mre"] for r in rows], style, label=f"{m}, {label}")
            axes[1].plot(n, [r[f"{m}_s"] for r in rows], style, label=f"{m} embed, {label}")
        axes[1].plot(n, [r["exact_s"] for r in rows], style, color="grey", label=f"exact, one source, {label}")
    axes[0].set(xscale="log", xlabel="vertices", ylabel="MRE %", title="error")
    axes[1].set(xscale="log", yscale="log", xlabel="vertices", ylabel="seconds (1 thread)", title="precomputation")
    for ax in axes:
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _mean(rows):
    return {k: float(np.mean([r[k] for r in rows])) for k in rows[0]}


if __name__ == "__main__":
    main()
