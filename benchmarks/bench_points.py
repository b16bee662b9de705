"""Geodesic distances on point clouds made from the validation meshes, against exact mesh geodesics.

    python benchmarks/bench_points.py data/val.zarr --model gegnn/weights/gegnn-points-v1.safetensors [--meshes 19]
        [--kinds clean noisy density 2k surface normals] [--pairs 20000] [--neurogf REPO] [--oracle] [--csv out.csv]

Each validation mesh's vertices become clouds (no faces): ``clean`` (all of them), ``noisy`` (Gaussian
noise of 0.5% of the longest bounding-box side on every coordinate), ``density`` (a random direction
along which the density falls tenfold, points kept with probability 10^-t, t from 0 to 1 across the
mesh), ``2k`` (2,000 of them, uniformly); ``surface``: the store's ``geodata points`` surface samples
(any count) with their own exact pairs, the mesh model answering at the same surface points; ``normals``:
the clean cloud with the mesh's vertex normals given to the model, as a scan's (the heat method and
NeuroGF take none). The truth is the stored exact distance between the original
vertices (sources x all vertices; ``--pairs`` of them per mesh, among the points a cloud kept), so noise
moves the points, not the answer. Compared: the point-cloud model (``--model``), potpourri3d's point-cloud
heat method (``PointCloudHeatSolver``, one field per source), and the shipped mesh model on the mesh itself
(the same for every kind), and with ``--neurogf REPO`` NeuroGF's generalizable model from a checkout of its
repository (benchmarks/neurogf.py). ``--oracle`` adds the exact geodesic between the cloud points' closest
points on the mesh (``gegnn.fields.exact.exact_at_points``, read linearly inside the faces): what an answer knowing
the surface exactly gives from these points, 0 on clouds of the vertices and on noisy ones the error that
the noise itself leaves, since it moves a point along the surface as much as off it. MRE is the training metric, |d - exact| / (exact + 1e-3), averaged over pairs,
then over meshes. One torch thread; embed = the whole precomputation of a cloud (graph, normals, landmark
fields, network).
"""
from __future__ import annotations

import argparse
import csv
import time

import numpy as np
import torch

from gegnn import GeGnn
from machine import cpu_description  # benchmarks/ is on sys.path when a script there runs
from gegnn.training.data import GeodesicStore
from geodata import store as geostore

KINDS = ("clean", "noisy", "density", "2k", "surface", "normals")
NOISE = 0.005       # of the longest bounding-box side
DENSITY_RATIO = 10.0


def make_cloud(vertices: np.ndarray, kind: str, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """The cloud's points and which vertex each one is."""
    n = len(vertices)
    if kind in ("clean", "normals"):
        keep = np.arange(n)
    elif kind == "noisy":
        keep = np.arange(n)
    elif kind == "density":
        d = rng.normal(size=3)
        t = vertices @ (d / np.linalg.norm(d))
        t = (t - t.min()) / max(np.ptp(t), 1e-12)
        keep = np.flatnonzero(rng.random(n) < DENSITY_RATIO ** -t)
    elif kind == "2k":
        keep = np.sort(rng.choice(n, min(2000, n), replace=False))
    else:
        raise ValueError(kind)
    points = vertices[keep].astype(np.float64)
    if kind == "noisy":
        points = points + rng.normal(scale=NOISE * np.ptp(vertices, axis=0).max(), size=points.shape)
    return points, keep


def mre(pred: np.ndarray, exact: np.ndarray) -> float:
    return float(np.mean(np.abs(pred - exact) / (exact + 1e-3)))


def heat_method(points: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    import potpourri3d as pp3d

    solver = pp3d.PointCloudHeatSolver(points)
    out = np.empty(len(pairs))
    for s in np.unique(pairs[:, 0]):
        rows = np.flatnonzero(pairs[:, 0] == s)
        out[rows] = solver.compute_distance(int(s))[pairs[rows, 1]]
    return out


def exact_between(g, points: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """Exact geodesic distances between the closest mesh points of ``points[pairs]`` (one field a source)."""
    from gegnn.fields.exact import exact_at_points
    from geodata.mesh import Mesh

    mesh = Mesh(np.asarray(g.vertices, dtype=np.float64), np.asarray(g.faces, dtype=np.int64))
    out = np.empty(len(pairs))
    for s in np.unique(pairs[:, 0]):
        rows = np.flatnonzero(pairs[:, 0] == s)
        out[rows] = exact_at_points(mesh, points, int(s))[0][pairs[rows, 1]]
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("store")
    ap.add_argument("--model", required=True, help="a point-cloud checkpoint (gegnn train --neighbors)")
    ap.add_argument("--meshes", type=int, default=19)
    ap.add_argument("--kinds", nargs="+", default=list(KINDS[:4]), choices=KINDS)
    ap.add_argument("--pairs", type=int, default=20000)
    ap.add_argument("--no-heat", action="store_true", help="skip the heat method (slow: a field per source)")
    ap.add_argument("--neurogf", metavar="REPO", help="a checkout of github.com/keeganhk/NeuroGF: its generalizable "
                                                     "model as one more column")
    ap.add_argument("--oracle", action="store_true", help="the exact distances between the points' closest "
                                                          "surface points as one more column")
    ap.add_argument("--csv")
    args = ap.parse_args()
    torch.set_num_threads(1)
    store = GeodesicStore(args.store)
    cloud_model, mesh_model = GeGnn.from_checkpoint(args.model), GeGnn.pretrained()
    if args.neurogf:
        from neurogf import NeuroGF
        neurogf = NeuroGF(args.neurogf)
    rows = []
    for mesh_id in store.mesh_ids[:args.meshes]:
        g = store.geometry(mesh_id)
        pairs, exact = store.pairs(mesh_id)
        mesh_emb = mesh_model.embed(g.vertices, g.faces)
        mesh_pred = mesh_emb.distance(pairs[:, 0], pairs[:, 1])
        for kind in args.kinds:
            pick = np.random.default_rng(0)
            if kind == "surface":  # `geodata points` samples (8k, 32k, ...): their own exact pairs
                with geostore.read_mesh(args.store, mesh_id, "points") as sub:
                    points = np.asarray(sub["xyz"][:], dtype=np.float64)
                    ok = pick.permutation(sub["pairs"].shape[0])[:args.pairs]
                    local, truth = np.asarray(sub["pairs"][:], dtype=np.int64)[ok], np.asarray(sub["distances"][:])[ok]
                    face, bary = (np.asarray(sub["face"][:], dtype=np.int64),
                                  np.asarray(sub["bary"][:], dtype=np.float64))
                reference = mesh_emb.surface_distance(face[local[:, 0]], bary[local[:, 0]], face[local[:, 1]],
                                                      bary[local[:, 1]])
            else:
                # Seeded by the length of the mesh's format-1 id (<stem>-<8 hex digits>), as before format 2's
                # longer ids: the same clouds as the published tables.
                id1 = len(mesh_id.rsplit("-", 1)[0]) + 9
                points, keep = make_cloud(g.vertices, kind, np.random.default_rng([id1, KINDS.index(kind)]))
                index = np.full(len(g.vertices), -1)
                index[keep] = np.arange(len(keep))
                ok = np.flatnonzero((index[pairs] >= 0).all(axis=1) & (pairs[:, 0] != pairs[:, 1]))
                ok = ok[pick.permutation(len(ok))[:args.pairs]]
                local, truth, reference = index[pairs[ok]], exact[ok], mesh_pred[ok]
            t = time.perf_counter()
            emb = cloud_model.embed(points, normals=g.normals[keep] if kind == "normals" else None)
            embed_s = time.perf_counter() - t
            row = dict(mesh_id=mesh_id, kind=kind, points=len(points), pairs=len(local), embed_s=round(embed_s, 3),
                       model=mre(emb.distance(local[:, 0], local[:, 1]), truth), mesh_model=mre(reference, truth))
            if not args.no_heat:
                row["heat"] = mre(heat_method(points, local), truth)
            if args.neurogf:
                row["neurogf"] = mre(neurogf.distances(points, local), truth)
            if args.oracle:
                row["oracle"] = mre(exact_between(g, points, local), truth)
            rows.append(row)
            print(" ".join(f"{k}={v:.4f}" if isinstance(v, float) else f"{k}={v}" for k, v in row.items()), flush=True)
    print(f"\n{cpu_description()}, one torch thread\n\n| cloud | points | ours | heat method (potpourri3d) "
          "| NeuroGF | mesh model on the mesh | exact at the points | embed s |\n|---|---:|---:|---:|---:|---:|---:|---:|")
    for kind in args.kinds:
        r = [x for x in rows if x["kind"] == kind]
        mean = {k: f"{100 * np.mean([x[k] for x in r]):.2f}%" if k in r[0] else "-"
                for k in ("model", "heat", "neurogf", "mesh_model", "oracle")}
        print(f"| {kind} | {np.mean([x['points'] for x in r]):.0f} | {mean['model']} | {mean['heat']} | "
              f"{mean['neurogf']} | {mean['mesh_model']} | {mean['oracle']} | {np.mean([x['embed_s'] for x in r]):.2f} |")
    if args.csv:
        with open(args.csv, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)


if __name__ == "__main__":
    main()
