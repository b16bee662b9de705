"""Benchmark: exact biharmonic distances for 600k pairs on a ~5k-vertex mesh vs the dense spectral sum.

    python benchmarks/bench_biharmonic.py [--vertices 5000] [--pairs 600000]
        [--mesh PATH ...] [--no-dense] [--threads 1] [--repeat 3]

Runs on one core by default (BLAS threads pinned before numpy loads). The synthetic mesh is an
irregular triangulation of a random point set on a sphere (its convex hull), bumped and stretched, so
no shared data is needed; --mesh adds real meshes (loaded with trimesh, duplicate vertices merged).
The dense reference is scipy.linalg.eigh(L, M) over all eigenpairs and the spectral sum evaluated on
the same pairs; the table reports both times, their ratio and the max relative error.
"""
from __future__ import annotations

import argparse
import os
import sys


def _threads_from_argv() -> str:
    for i, a in enumerate(sys.argv):
        if a == "--threads" and i + 1 < len(sys.argv):
            return sys.argv[i + 1]
        if a.startswith("--threads="):
            return a.split("=", 1)[1]
    return "1"


_T = _threads_from_argv()
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = _T

import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from geodata.biharmonic import biharmonic_pairs  # noqa: E402
from geodata.examples import bumpy_sphere  # noqa: E402
from geodata.mesh import Mesh, MeshError, vertex_components  # noqa: E402
from machine import cpu_description  # benchmarks/ is on sys.path when a script there runs


def load_mesh(path: str) -> Mesh:
    import trimesh

    m = trimesh.load(path, force="mesh", process=True)
    m.update_faces(m.nondegenerate_faces())
    m.remove_unreferenced_vertices()
    v = np.asarray(m.vertices)
    # Normalize as the pipeline does (stage 5): longest half-extent 1.
    lo, hi = v.min(0), v.max(0)
    v = (v - (lo + hi) / 2) / ((hi - lo).max() / 2)
    return Mesh(v, np.asarray(m.faces))


def dense_reference(mesh: Mesh, pairs: np.ndarray) -> tuple[np.ndarray, float]:
    import igl
    import scipy.linalg as la

    t = time.perf_counter()
    v, f = mesh.vertices, mesh.faces
    L = igl.cotmatrix(v, f).toarray()
    M = igl.massmatrix(v, f, igl.MASSMATRIX_TYPE_VORONOI).toarray()
    lam, phi = la.eigh(L, M)
    n_comp = int(vertex_components(mesh).max()) + 1
    keep = np.argsort(np.abs(lam))[n_comp:]
    emb = phi[:, keep] / np.abs(lam[keep])
    d = np.empty(len(pairs))
    for a in range(0, len(pairs), 20000):
        p = pairs[a:a + 20000].astype(np.int64)
        diff = emb[p[:, 0]] - emb[p[:, 1]]
        d[a:a + len(p)] = np.sqrt(np.einsum("ij,ij->i", diff, diff))
    return d, time.perf_counter() - t


def run(name: str, mesh: Mesh, n_pairs: int, dense: bool, repeat: int) -> dict:
    t_fast = float("inf")
    for _ in range(repeat):                   # best of `repeat`: the machine may be shared
        t = time.perf_counter()
        pairs, dist = biharmonic_pairs(mesh, n_pairs, np.random.default_rng(0))
        t_fast = min(t_fast, time.perf_counter() - t)
    row = dict(name=name, n=mesh.n_vertices, pairs=len(pairs), fast=t_fast,
               dense=float("nan"), ratio=float("nan"), err=float("nan"))
    if dense:
        ref, t_dense = dense_reference(mesh, pairs)
        ok = ref > 0
        # Compare the float64 solver output (biharmonic_pairs rounds to float32 for the store).
        from geodata.biharmonic import BiharmonicSolver
        src = np.unique(pairs[:, 0]).astype(np.int64)
        full = BiharmonicSolver(mesh).distances(src)
        d64 = full[np.searchsorted(src, pairs[:, 0]), pairs[:, 1].astype(np.int64)]
        row.update(dense=t_dense, ratio=t_dense / t_fast,
                   err=float(np.max(np.abs(d64[ok] - ref[ok]) / ref[ok])),
                   err32=float(np.max(np.abs(dist[ok] - ref[ok]) / ref[ok])))
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--vertices", type=int, default=5000)
    ap.add_argument("--pairs", type=int, default=600_000)
    ap.add_argument("--mesh", action="append", default=[])
    ap.add_argument("--no-dense", action="store_true")
    ap.add_argument("--threads", default="1")
    ap.add_argument("--repeat", type=int, default=3, help="best of this many runs of the exact method")
    args = ap.parse_args()
    print(f"CPU: {cpu_description()}", flush=True)

    cases = [(f"synthetic-sphere-{args.vertices}", lambda: bumpy_sphere(args.vertices))]
    cases += [(Path(p).name, (lambda p=p: load_mesh(p))) for p in args.mesh]
    print(f"BLAS threads: {_T}; pairs requested: {args.pairs}")
    hdr = f"{'mesh':<28} {'N':>7} {'pairs':>8} {'exact s':>9} {'dense s':>9} {'ratio':>7} {'max rel err':>12} {'(float32)':>10}"
    print(hdr)
    print("-" * len(hdr))
    for name, make in cases:
        try:
            mesh = make()
            r = run(name, mesh, args.pairs, not args.no_dense, args.repeat)
        except MeshError as exc:
            print(f"{name:<28} failed: {exc}")
            continue
        print(f"{r['name']:<28} {r['n']:>7} {r['pairs']:>8} {r['fast']:>9.3f} {r['dense']:>9.2f} "
              f"{r['ratio']:>7.1f} {r['err']:>12.2e} {r.get('err32', float('nan')):>10.1e}", flush=True)


if __name__ == "__main__":
    main()
