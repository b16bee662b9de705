"""Pairs stage: the vtp solver against tvb-gdist and libigl's exact_geodesic, measured in the same run.

    python benchmarks/bench_geodesic.py [--meshes NAME ...] [--pairs 600000] [--sources 8] [--subdivide 2]

Each mesh of ../shared/meshes/train goes through the pipeline's stages first (what the pairs stage
really sees, ~5k vertices); the first one is also Loop-subdivided to ~20k and ~80k vertices. Every
backend computes the same sources, timed per source as the pipeline calls it (vtp prepares the mesh
once per mesh, gdist rebuilds it per call) and scaled to the sources that --pairs needs. Peak memory is
the growth of the maximum resident set of a forked child that runs one backend on one mesh. Distances
must agree to 1e-9 relative with the shorter of libigl and gdist, except where vtp is shorter than both
and potpourri3d's edge-flip geodesic finds a path as short (Kirsanov's code is then wrong: counted in
the last column).
"""
from __future__ import annotations

import argparse
import multiprocessing
import resource
import time
from pathlib import Path

import numpy as np

from geodata.geodesic import BACKENDS, edge_flip_paths, geodesic_solver, polyline_length, sample_sources
from geodata.mesh import Mesh, vertex_components
from geodata.prepare import PrepareConfig, prepare_geometry
from geodata.stages.load import load_mesh_bytes
from machine import cpu_description  # benchmarks/ is on sys.path when a script there runs

SHARED = Path(__file__).resolve().parents[2] / "shared" / "meshes" / "train"
DEFAULT = ["sweethome3d/armchair.obj", "sweethome3d/lamp.obj", "trimesh-models/featuretype.STL"]


def timed_run(mesh: Mesh, backend: str, sources: np.ndarray, out) -> None:
    """In a forked child: seconds per source, peak RSS growth (MiB) and the distances."""
    base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    start = time.perf_counter()
    solve = geodesic_solver(mesh, backend)
    d = np.stack([solve(int(s)) for s in sources])
    seconds = (time.perf_counter() - start) / len(sources)
    peak = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - base) / 1024
    out.send((seconds, peak, d))


def measure(mesh: Mesh, backend: str, sources: np.ndarray):
    ctx = multiprocessing.get_context("fork")
    recv, send = ctx.Pipe(duplex=False)
    child = ctx.Process(target=timed_run, args=(mesh, backend, sources, send))
    child.start()
    result = recv.recv()
    child.join()
    return result


def loop_subdivisions(mesh: Mesh, times: int) -> list[Mesh]:
    """``mesh`` Loop-subdivided once, twice, ... ``times`` times (each level from the one before)."""
    import trimesh

    levels, v, f = [], mesh.vertices, mesh.faces
    for _ in range(times):
        v, f = trimesh.remesh.subdivide_loop(v, f, iterations=1)
        levels.append(Mesh(np.asarray(v, dtype=np.float64), np.asarray(f, dtype=np.int64)))
    return levels


def compare(mesh: Mesh, sources, d, ref) -> tuple[float, int, float]:
    """Max relative difference where vtp agrees, and the count and largest gap of vertices where vtp is
    shorter than the reference by more than 1e-9 and an edge-flip path confirms it."""
    labels = vertex_components(mesh)
    rels = [np.where(labels == labels[s], (a - b) / np.maximum(b, 1e-300), 0.0) for s, b, a in zip(sources, ref, d)]
    shorter = [(k, s, t) for k, (s, rel) in enumerate(zip(sources, rels)) for t in np.flatnonzero(rel < -1e-9)]
    paths = edge_flip_paths(mesh, [(s, t) for _, s, t in shorter], converged=True) if shorter else []
    n_wrong, gap = 0, 0.0
    for (k, s, t), path in zip(shorter, paths):  # one solver for every path of the mesh
        length = polyline_length(path)
        assert length <= d[k][t] * (1 + 1e-9), f"vtp shorter than any path found: {d[k][t]} < {length}"
        n_wrong, gap, rels[k][t] = n_wrong + 1, max(gap, -rels[k][t]), 0.0
    worst = max(float(np.abs(rel).max()) for rel in rels)
    return worst, n_wrong, gap


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--meshes", nargs="*", default=DEFAULT, help="paths under shared/meshes/train")
    ap.add_argument("--pairs", type=int, default=600_000)
    ap.add_argument("--subdivide", type=int, default=2, help="Loop-subdivide the first mesh 1..K times")
    ap.add_argument("--sources", type=int, default=8, help="sources timed per mesh at ~5k vertices "
                                                          "(half at 20k, a quarter at 80k, at least 2)")
    args = ap.parse_args()
    print(f"CPU: {cpu_description()}", flush=True)
    cases = []
    for i, name in enumerate(args.meshes):
        path = SHARED / name
        mesh = prepare_geometry(load_mesh_bytes(path.read_bytes(), path.suffix), PrepareConfig())
        cases.append((name, mesh, args.sources))
        if i == 0:
            cases += [(f"{name} x Loop {k}", finer, max(2, args.sources // 2 ** k))
                      for k, finer in enumerate(loop_subdivisions(mesh, args.subdivide), start=1)]
    print(f"{'mesh':42s} {'verts':>6s} {'sources':>7s} " + " ".join(f"{b + ' s':>9s}" for b in BACKENDS)
          + f" {'vs libigl':>9s} {'vs gdist':>8s} " + " ".join(f"{b + ' MiB':>10s}" for b in BACKENDS)
          + f" {'max rel diff':>12s} {'reference wrong':>15s}")
    ratios = []
    for name, mesh, n_timed in cases:
        sources = sample_sources(vertex_components(mesh), args.pairs, np.random.default_rng(0))
        timed = sources[:n_timed]
        results = {b: measure(mesh, b, timed) for b in BACKENDS}
        total = {b: results[b][0] * len(sources) for b in BACKENDS}
        reference = np.minimum(results["libigl"][2], results["gdist"][2])
        diff, n_wrong, gap = compare(mesh, timed, results["vtp"][2], reference)
        assert diff <= 1e-9, f"vtp differs from the reference on {name}: {diff}"
        ratios.append((total["libigl"] / total["vtp"], total["gdist"] / total["vtp"]))
        print(f"{name:42s} {mesh.n_vertices:6d} {len(sources):7d} "
              + " ".join(f"{total[b]:9.2f}" for b in BACKENDS)
              + f" {ratios[-1][0]:8.2f}x {ratios[-1][1]:7.2f}x "
              + " ".join(f"{results[b][1]:10.1f}" for b in BACKENDS) + f" {diff:12.1e} "
              + (f"{n_wrong:4d} by {gap:.1e}" if n_wrong else f"{0:15d}"))
    libigl, gdist = np.exp(np.log(ratios).mean(axis=0))
    print(f"geometric mean over these meshes: {libigl:.2f}x libigl, {gdist:.2f}x gdist")


if __name__ == "__main__":
    main()
