"""Landmark fields (K farthest-point landmarks and their heat-method distance fields) on CPU: potpourri3d's
solver against gegnn.fields.heat, exact sequential farthest-point sampling and a batched variant.

    python benchmarks/bench_landmark_fields.py [STORE] [--mesh ID] [--k 128] [--batch 8 16] [--repeat 3]

STORE is a geodata store and --mesh one of its meshes (an id or a unique prefix of one; default
dragon-4af53808); without STORE, data/val.zarr's dragon when it is there (STORE/meshes/ID, a format-1
mesh path, is read as STORE and --mesh ID). A synthetic 5,000-vertex torus always runs. The reference
(potpourri3d, one ``compute_distance`` a landmark) is timed in the same run; times are the best of --repeat, one thread.

Batched sampling (what landmark_fields does, with B = FPS_BATCH, since 0.3.0): rounds of B landmarks, the first of a round the exact
farthest vertex, the others chosen greedily with the Euclidean distance to the round's earlier picks as a
stand-in for their fields; then one B-column solve. And landmarks chosen along the mesh's edges
(``graph_farthest_points``, as point clouds choose theirs), then all fields in one call. Both change the
landmarks, so their covering radius (max_i min_k d(i, l_k), from the fields) is compared with sequential
farthest-point sampling's.
"""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np
import trimesh
from bench_gegnn import timed  # benchmarks/ is on sys.path when a script there runs
from machine import cpu_description  # benchmarks/ is on sys.path when a script there runs
from stores import MeshIdError, mesh_id

from geodata import store as geostore
from geodata.mesh import unique_edges
from gegnn.fields.heat import HeatDistance
from gegnn.fields.landmarks import (T_COEF, batched_farthest_point_fields, farthest_point_fields, graph_farthest_points,
                                    landmark_columns, landmark_fields)

STORE, DRAGON = "data/val.zarr", "dragon-4af53808"


def torus_mesh():
    m = trimesh.creation.torus(major_radius=1.0, minor_radius=0.35, major_sections=100, minor_sections=50)
    return np.asarray(m.vertices), np.asarray(m.faces)


def store_mesh(store, mesh):
    with geostore.read_mesh(store, mesh) as g:
        return np.asarray(g["vertices"][:], dtype=np.float64), np.asarray(g["faces"][:], dtype=np.int64)


def pick_mesh(store, mesh) -> tuple[str, str] | None:
    """(store, mesh id) of the command line's STORE and --mesh; None where neither is given and data/val.zarr's
    dragon is not there."""
    if store is not None and Path(store).parent.name == "meshes":  # STORE/meshes/ID: a format-1 mesh path
        store, mesh = str(Path(store).parent.parent), mesh or Path(store).name
    if store is not None:
        return store, mesh_id(store, mesh or DRAGON)
    if mesh is not None:
        return STORE, mesh_id(STORE, mesh)
    try:
        return (STORE, mesh_id(STORE, DRAGON)) if os.path.isdir(STORE) else None
    except (MeshIdError, geostore.StoreError) as exc:
        print(f"{STORE}: {exc}; only the torus runs", file=sys.stderr)
        return None


def potpourri3d_fps(v, f, k, first):
    import potpourri3d as pp3d

    solver = pp3d.MeshHeatMethodDistanceSolver(v, f, t_coef=T_COEF, use_robust=True)
    return farthest_point_fields(solver.compute_distance, len(v), k, first)


def heat_fps(v, f, k, first):
    return farthest_point_fields(HeatDistance(v, f, T_COEF).distance, len(v), k, first)


def batched_fps(v, f, k, first, batch):
    """Rounds of `batch` landmarks (gegnn.fields.landmarks.batched_farthest_point_fields, what landmark_fields
    does with FPS_BATCH); one multi-source solve a round."""
    return batched_farthest_point_fields(HeatDistance(v, f, T_COEF).distances, v, k, first, batch)


def graph_fps(v, f, k, first):
    """Landmarks along the mesh's edges (what point clouds do along their neighbours), then all fields in one
    call."""
    solver = HeatDistance(v, f, T_COEF)
    chosen = graph_farthest_points(v, unique_edges(f), k, first)
    return chosen.tolist(), landmark_columns(solver.distances(chosen), chosen)


def covering_radius(fields) -> tuple[float, float]:
    """max_i min_k d(i, l_k) and its mean over vertices."""
    near = np.asarray(fields, dtype=np.float64).min(axis=1)
    return float(near.max()), float(near.mean())


def bench_mesh(name, v, f, k, batches, repeat):
    first = int(np.random.default_rng([0, 0]).integers(len(v)))  # landmark_fields' seed-0 first pick
    ref_s, (ref_lm, ref) = timed(lambda: potpourri3d_fps(v, f, k, first), repeat)
    ours_s, (ours_lm, ours) = timed(lambda: heat_fps(v, f, k, first), repeat)
    full_s, lf = timed(lambda: landmark_fields(v, f, k, seed=0), repeat)
    setup_s, solver = timed(lambda: HeatDistance(v, f, T_COEF), repeat)
    field_s, _ = timed(lambda: [solver.distance(s) for s in ours_lm[:32]], repeat)
    diff = np.abs(ours.astype(np.float64) - ref).max() / np.abs(ref).max()
    exact = HeatDistance(v, f).distances(ours_lm[:8])
    import potpourri3d as pp3d

    pp = pp3d.MeshHeatMethodDistanceSolver(v, f, t_coef=T_COEF, use_robust=True)
    diff64 = max(np.abs(exact[:, j] - pp.compute_distance(s)).max() / np.abs(exact).max()
                 for j, s in enumerate(ours_lm[:8]))
    radius, mean_near = covering_radius(ours)
    print(f"\n{name}: {len(v)} vertices, {len(f)} faces, K = {k}; {solver.n_flips} intrinsic flips (cover)")
    rows = [("potpourri3d fields, sequential FPS (reference)", ref_s, f"{ref_s / k * 1e3:.2f} ms a field"),
            ("gegnn.fields.heat fields, sequential FPS", ours_s,
             f"{ref_s / ours_s:.2f}x; same landmarks: {ours_lm == ref_lm}; max |diff| / max d: {diff:.1e} "
             f"(float32), {diff64:.1e} (float64, 8 fields)"),
            ("  of which setup (cover, flips, two factorizations)", setup_s, ""),
            ("  one field (heat solve, gradient, divergence, Poisson)", field_s / 32, ""),
            ("landmark_fields (components, float32 output)", full_s,
             f"same landmarks: {lf.landmarks[0].tolist() == ours_lm}"),
            ("covering radius (sequential): max, mean of min_k d", radius, f"mean {mean_near:.4f}")]
    for b in batches:
        b_s, (b_lm, b_fields) = timed(lambda: batched_fps(v, f, k, first, b), repeat)
        r, m = covering_radius(b_fields)
        rows.append((f"batched FPS, {b} landmarks a solve", b_s,
                     f"{ours_s / b_s:.2f}x vs sequential; covering radius {r:.4f} ({r / radius:.3f}x), "
                     f"mean {m:.4f} ({m / mean_near:.3f}x); {len(set(b_lm) & set(ours_lm))} landmarks shared"))
    g_s, (g_lm, g_fields) = timed(lambda: graph_fps(v, f, k, first), repeat)
    r, m = covering_radius(g_fields)
    rows.append(("FPS along the edges, all fields in one call", g_s,
                 f"{ours_s / g_s:.2f}x vs sequential; covering radius {r:.4f} ({r / radius:.3f}x), "
                 f"mean {m:.4f} ({m / mean_near:.3f}x); {len(set(g_lm) & set(ours_lm))} landmarks shared"))
    width = max(len(r[0]) for r in rows)
    print(f"{'measurement':<{width}}  {'seconds':>9}  note")
    for label, seconds, note in rows:
        print(f"{label:<{width}}  {seconds:>9.4f}  {note}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("store", nargs="?", help=f"a geodata store (default {STORE} where it holds {DRAGON})")
    ap.add_argument("--mesh", help=f"a mesh id of the store, or a unique prefix of one (default {DRAGON})")
    ap.add_argument("--k", type=int, default=128)
    ap.add_argument("--batch", type=int, nargs="*", default=[8, 16])
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    try:
        import torch

        torch.set_num_threads(1)
    except ImportError:
        pass
    print(f"CPU: {cpu_description()}, {os.cpu_count()} cores; load average {os.getloadavg()[0]:.1f}")
    picked = pick_mesh(args.store, args.mesh)
    if picked:
        bench_mesh(picked[1], *store_mesh(*picked), args.k, args.batch, args.repeat)
    bench_mesh("torus (trimesh.creation.torus)", *torus_mesh(), args.k, args.batch, args.repeat)


if __name__ == "__main__":
    main()
