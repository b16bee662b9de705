"""Large meshes: the shipped model (through its proxy above 40,000 vertices) against the heat method, from 5k to
~1M vertices, on regular and irregular triangulations of surfaces whose exact distances are known.

    python benchmarks/bench_large_meshes.py [--meshes spot homer bumpy] [--levels 4] [--sources 6]

Truth without solving at the large sizes: each surface is a ~5k-vertex mesh (a validation mesh through the
pipeline's geometry stages, or a bumped, stretched icosphere) whose exact distances (geodata's exact solver)
between its own vertices stay exact on every refinement that keeps the surface:
- regular: midpoint subdivision (each triangle into 4; ~4x the vertices a level);
- irregular: each triangle split at a random interior point (into 3; ~3x a level), which piles up slivers.
The original vertices come first in every refinement. MRE: |d - exact| / (exact + 1e-3) over sources x all
original vertices. Embed runs in a fresh process per mesh (its peak memory, VmHWM, is the embed's);
the heat method (potpourri3d: factorization + one solve per source) in this one.
"""
from __future__ import annotations

import argparse
import multiprocessing
import time

import numpy as np
import trimesh
from machine import cpu_description  # benchmarks/ is on sys.path when a script there runs

DEV = "../shared/meshes/dev"
MESHES = {"spot": "common-3d-test-models/spot.obj", "homer": "common-3d-test-models/homer.obj",
          "dragon": "rohan-sawhney-correspondence/dragon.obj"}


def base_mesh(name: str) -> tuple[np.ndarray, np.ndarray]:
    if name == "bumpy":  # a bumped, stretched sphere, regular
        s = trimesh.creation.icosphere(5)
        v = np.asarray(s.vertices)
        v = v * (1 + 0.1 * np.sin(5 * v[:, :1]) * np.cos(4 * v[:, 1:2])) * np.array([1.0, 0.7, 0.5])
        return v, np.asarray(s.faces)
    from geodata.prepare import PrepareConfig, prepare_geometry
    from geodata.stages.load import load_mesh_file

    mesh = prepare_geometry(load_mesh_file(f"{DEV}/{MESHES[name]}")[0], PrepareConfig())
    return np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces)


def split_randomly(v: np.ndarray, f: np.ndarray, rng) -> tuple[np.ndarray, np.ndarray]:
    """Each triangle into 3 at a random interior point (barycentric weights Dirichlet(1,1,1) clipped away from
    the edges by 1e-3): the same surface, an irregular triangulation."""
    w = np.clip(rng.dirichlet(np.ones(3), len(f)), 1e-3, None)
    w /= w.sum(axis=1, keepdims=True)
    c = len(v) + np.arange(len(f))
    points = np.einsum("fk,fkd->fd", w, v[f])
    a, b, d = f.T
    return np.vstack([v, points]), np.concatenate([np.stack([a, b, c], 1), np.stack([b, d, c], 1),
                                                   np.stack([d, a, c], 1)])


def _embed_child(v, f, n0, sources, queue):
    import torch

    from gegnn import GeGnn

    torch.set_num_threads(2)
    model = GeGnn.pretrained()
    t = time.perf_counter()
    emb = model.embed(v, f)
    seconds = time.perf_counter() - t
    t = time.perf_counter()
    field = emb.field(int(sources[0]))
    field_s = time.perf_counter() - t
    pred = np.stack([emb.distance(np.full(n0, s), np.arange(n0)) for s in sources])
    queue.put((seconds, field_s, peak_memory(), pred, len(field)))


def peak_memory() -> float:
    """This process's peak resident memory in GB (VmHWM: unlike ru_maxrss, not inherited across exec from the
    parent the process was forked from)."""
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith("VmHWM:")) / 2**20


def embed_in_child(v, f, n0, sources):
    ctx = multiprocessing.get_context("spawn")
    queue = ctx.Queue()
    p = ctx.Process(target=_embed_child, args=(v, f, n0, sources, queue))
    p.start()
    out = queue.get()
    p.join()
    return out


def heat(v, f, sources, n0):
    import potpourri3d as pp3d

    t = time.perf_counter()
    solver = pp3d.MeshHeatMethodDistanceSolver(v, f)
    first = solver.compute_distance(int(sources[0]))
    seconds = time.perf_counter() - t
    rest = [solver.compute_distance(int(s)) for s in sources[1:]]
    return seconds, np.stack([first, *rest])[:, :n0]


def mre(pred, exact):
    keep = exact > 0
    return float(np.mean(np.abs(pred - exact)[keep] / (exact[keep] + 1e-3)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--meshes", nargs="+", default=["spot", "bumpy"])
    ap.add_argument("--levels", type=int, default=3, help="refinements (regular: 5k 20k 80k 320k 1.3M)")
    ap.add_argument("--kinds", nargs="+", default=["regular", "irregular"])
    ap.add_argument("--sources", type=int, default=6)
    ap.add_argument("--max-vertices", type=int, default=1_500_000, help="skip larger refinements")
    ap.add_argument("--min-vertices", type=int, default=0, help="skip smaller refinements")
    args = ap.parse_args()
    from geodata.geodesic import geodesic_solver
    from geodata.mesh import Mesh
    from geodata.stages.normalize import normalization

    print(f"{cpu_description()}; times in seconds, peak memory of the embed's process")
    print("| mesh | kind | vertices | embed | peak memory | field (1 source) | model MRE | heat (factor + 1) | heat MRE |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|")
    for name in args.meshes:
        v0, f0 = base_mesh(name)
        _, scale = normalization(v0)
        v0 = v0 / scale  # the model's and the metric's units: longest half-extent 1
        n0, rng = len(v0), np.random.default_rng(0)
        sources = rng.choice(n0, args.sources, replace=False)
        solve = geodesic_solver(Mesh(v0, f0))
        exact = np.stack([solve(int(s)) for s in sources])
        for kind in args.kinds:
            v, f = v0, f0
            for level in range(args.levels + 1):
                if level:
                    v, f = trimesh.remesh.subdivide(v, f) if kind == "regular" else split_randomly(v, f, rng)
                if len(v) > args.max_vertices:
                    break
                if len(v) < args.min_vertices:
                    continue
                seconds, field_s, peak, pred, _ = embed_in_child(v, f, n0, sources)
                heat_s, heat_d = heat(v, f, sources, n0)
                print(f"| {name} | {kind} | {len(v):,} | {seconds:.2f} | {peak:.2f} GB | {field_s:.2f} | "
                      f"{100 * mre(pred, exact):.2f}% | {heat_s:.2f} | {100 * mre(heat_d, exact):.2f}% |", flush=True)


if __name__ == "__main__":
    main()
