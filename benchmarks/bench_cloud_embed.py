"""The precomputation of a cloud (``GeGnn.embed``: projection, graph, normals, landmark fields, network) and
of a mesh, on one torch thread and on several, alternated in one process, and where the time goes.

    python benchmarks/bench_cloud_embed.py [--points 5000 8000] [--threads 1 2] [--rounds 10] [--mesh]
        [--models points points-v2]

bumpy_sphere clouds (``geodata.examples.bumpy_sphere``: its vertices), embedded by each shipped cloud model of
``--models`` (default: the shipped ``points``); ``--mesh`` adds the landmark mesh model on the same meshes. Settings: each thread count (``torch.set_num_threads``: the k-d trees, the blocks of
rows, the U-Net beside the landmark fields and the fields' blocks of sources follow it, gegnn/threads.py)
and, as the reference, the last thread count with every step on the caller's thread one after the other
(``by_rows`` and ``beside`` run inline; the k-d trees and the fields' blocks still on all threads). Each
round embeds once per setting in turn, so slow spells of a shared machine fall on every setting alike;
best and median over the rounds, and the median's ratio to the reference's. Then, on the last thread
count, the wall-clock span of each step in one embed (steps overlap: the U-Net runs beside the landmark
fields).
"""
from __future__ import annotations

import argparse
import time
from concurrent.futures import Future
from contextlib import contextmanager, nullcontext

import numpy as np
import torch

import gegnn.fields.cloud_heat as cloud_heat
import gegnn.fields.cloud_vsp as cloud_vsp
import gegnn.fields.heat as heat
import gegnn.model
import gegnn.fields.pointcloud as pointcloud
from geodata.examples import bumpy_sphere
from gegnn import GeGnn, threads
from machine import cpu_description  # benchmarks/ is on sys.path when a script there runs

STEPS = [(pointcloud, "mls_project", "projection"), (pointcloud, "knn_edges", "k = 8 graph"),
         (pointcloud, "orient_normals", "normals' orientation (beside, before the U-Net)"),
         (pointcloud, "surface_neighbors", "surface neighbours"),
         (pointcloud, "cloud_landmark_solver", "row-by-row set-up: surface neighbours, local triangulations"),
         (cloud_heat, "CloudHeatDistance", "heat method: cover, flips, operators, factorizations"),
         (cloud_vsp, "CloudVirtualSources", "virtual sources: the local triangles glued"),
         (pointcloud, "graph_farthest_points", "landmarks along the surface neighbours"),
         (heat.HeatSolver, "distances", "heat method: their fields, all together"),
         (cloud_vsp.CloudVirtualSources, "distances", "virtual sources: their fields, one after the other")]


@contextmanager
def one_after_the_other():
    """The reference: blocks of rows as one block, the task beside as a call in line (torch's kernels on
    all threads)."""
    def inline(compute):
        done = Future()
        done.set_result(compute())
        return done

    saved = threads.by_rows, gegnn.model.beside, gegnn.model.fewer_for_torch
    threads.by_rows, gegnn.model.beside, gegnn.model.fewer_for_torch = (
        (lambda compute, n: compute(slice(0, n))), inline, nullcontext)
    try:
        yield
    finally:
        threads.by_rows, gegnn.model.beside, gegnn.model.fewer_for_torch = saved


def spans(model: GeGnn, points: np.ndarray) -> dict:
    """Start and end (s, from the call) of each step of one embed."""
    seen, saved = {}, []
    t0 = time.perf_counter()

    def traced(fn, name):
        def run(*args, **kwargs):
            start = time.perf_counter() - t0
            out = fn(*args, **kwargs)
            seen[name] = (start, time.perf_counter() - t0)
            return out
        return run

    for module, attr, name in STEPS:
        saved.append((module, attr, getattr(module, attr)))
        setattr(module, attr, traced(getattr(module, attr), name))
    unet = model._unet
    model._unet = traced(unet, "U-Net (beside the fields)")
    try:
        t0 = time.perf_counter()
        model.embed(points)
        seen["embed"] = (0.0, time.perf_counter() - t0)
    finally:
        model._unet = unet
        for module, attr, fn in saved:
            setattr(module, attr, fn)
    return seen


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--points", type=int, nargs="+", default=[5000, 8000])
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--rounds", type=int, default=10)
    ap.add_argument("--mesh", action="store_true", help="also the landmark mesh model on the same meshes")
    ap.add_argument("--models", nargs="+", default=["points"], help="shipped point-cloud models to compare")
    args = ap.parse_args()
    models = {name: GeGnn.pretrained(name) for name in args.models}
    if args.mesh:
        models["mesh"] = GeGnn.pretrained("landmark")
    print(f"{cpu_description()}; torch {torch.__version__}\n")
    print("| model | points | threads | best s | median s | median / reference |\n|---|---:|---|---:|---:|---:|")
    for n in args.points:
        mesh = bumpy_sphere(n)
        vertices, faces = np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces)
        for name, model in models.items():
            call = (lambda: model.embed(vertices)) if model.config.points else (lambda: model.embed(vertices, faces))
            settings = [(t, False) for t in args.threads] + [(args.threads[-1], True)]
            times = {s: [] for s in settings}
            call()  # warm-up
            for _ in range(args.rounds):
                for t, reference in settings:
                    torch.set_num_threads(t)
                    with one_after_the_other() if reference else nullcontext():
                        start = time.perf_counter()
                        call()
                        times[t, reference].append(time.perf_counter() - start)
            base = float(np.median(times[settings[-1]]))
            for (t, reference), values in times.items():
                median = float(np.median(values))
                label = f"{t}, one step after the other (reference)" if reference else f"{t}"
                print(f"| {name} | {len(vertices)} | {label} | {min(values):.3f} | {median:.3f} | {median / base:.2f} |")
    torch.set_num_threads(args.threads[-1])
    for n in args.points:
        for model_name in args.models:
            seen = spans(models[model_name], np.asarray(bumpy_sphere(n).vertices, dtype=np.float64))
            print(f"\nsteps of one {model_name} embed, {n} points, {args.threads[-1]} threads (start - end, ms):")
            for name, (a, b) in sorted(seen.items(), key=lambda item: item[1]):
                print(f"  {1000 * a:6.0f} - {1000 * b:6.0f}  {name}")


if __name__ == "__main__":
    main()
