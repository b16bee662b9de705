"""Does the loader keep a GPU fed? Batches per second of the training loader with 0, 1, 2 (or --workers)
loader processes, the model's step time on this machine, and the loader processes one GPU needs.

    python benchmarks/bench_train_throughput.py [--meshes 8] [--batch-size 4] [--pairs-per-mesh 100000]
        [--landmarks 128] [--workers 0,1,2] [--gpu-step-ms 40] [--channels 256]

Runs on synthetic 5,000-vertex tori in a temporary store (600k stored pairs each, Euclidean stand-in
distances: only throughput matters). Three loaders: the paper's model (no landmarks); a landmark model
reading its fields from the cache training fills first (gegnn.fields.cache); and, as the reference,
a landmark model computing its fields per draw (what a worker did at every new draw before the cache).
The step time is measured on CUDA where there is one, else on this CPU; the GPU step used for the
loader processes needed is then --gpu-step-ms (an estimate, labelled so).
"""
from __future__ import annotations

import argparse
import logging
import math
import os
import platform
import tempfile
import time

import numpy as np
import torch
import trimesh

from bench_gegnn import write_store  # benchmarks/ is on sys.path when a script there runs
from gegnn import GeGnn, GeGnnConfig
from gegnn.training.data import BatchDataset, EpochSampler
from gegnn.fields.cache import LANDMARK_DRAWS, FieldCache, FieldSpec
from gegnn.distributed import Dist
from gegnn.training.devices import cpus_per_process
from gegnn.training.loop import fill_field_cache, lr_at, make_loader, train_step
from machine import cpu_description  # benchmarks/ is on sys.path when a script there runs


def tori(n: int) -> dict:
    """n tori of ~5k vertices with different tube radii (distinct meshes, distinct cache keys)."""
    out = {}
    for k in range(n):
        m = trimesh.creation.torus(major_radius=1.0, minor_radius=0.25 + 0.02 * k, major_sections=100,
                                   minor_sections=50)
        out[f"torus{k}"] = (np.asarray(m.vertices), np.asarray(m.faces))
    return out


def loader_rate(dataset, mesh_ids, batch_size: int, workers: int, epochs: int) -> float:
    """Batches per second after the first (worker start-up excluded), consumed as fast as they come."""
    sampler = EpochSampler(mesh_ids, 0, batch_size)
    loader = make_loader(dataset, sampler, workers, torch.device("cpu"))
    count, t0 = 0, None
    for epoch in range(epochs):
        sampler.set_epoch(epoch)
        for _ in loader:
            if t0 is None:
                t0 = time.perf_counter()
            else:
                count += 1
    return count / (time.perf_counter() - t0)


def step_seconds(dataset, mesh_ids, batch_size: int, channels: int, landmarks: int, device, steps: int = 3):
    torch.manual_seed(0)
    model = GeGnn(GeGnnConfig(channels=channels, embed_dim=channels, decoder_hidden=channels,
                              landmarks=landmarks)).to(device)
    opt = torch.optim.AdamW(model.parameters(), lr=1e-4, weight_decay=0.01)
    batch = dataset[(0, tuple(mesh_ids[:batch_size]))].to(device)
    times = []
    for s in range(steps + 1):  # the first: kernel selection, allocator
        if device.type == "cuda":
            torch.cuda.synchronize()
        t = time.perf_counter()
        train_step(model, batch, opt, lr_at(s, 10, 1e-4, 0), 1.0, device).item()
        times.append(time.perf_counter() - t)
    return min(times[1:])


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--meshes", type=int, default=8)
    ap.add_argument("--batch-size", type=int, default=4)
    ap.add_argument("--pairs-per-mesh", type=int, default=100_000)
    ap.add_argument("--landmarks", type=int, default=128)
    ap.add_argument("--workers", default="0,1,2")
    ap.add_argument("--epochs", type=int, default=3, help="passes over the meshes per loader measured")
    ap.add_argument("--gpu-step-ms", type=float, default=40.0,
                    help="GPU step time where no GPU is present (the paper model at batch 4: an estimate)")
    ap.add_argument("--channels", type=int, default=256)
    ap.add_argument("--steps", type=int, default=3)
    args = ap.parse_args()
    print(f"CPU: {cpu_description()}", flush=True)
    workers = [int(w) for w in args.workers.split(",")]
    print(f"CPU: {platform.processor() or platform.machine()}, {os.cpu_count()} cores; torch {torch.__version__}; "
          f"{torch.get_num_threads()} threads; batch {args.batch_size} meshes of ~5k vertices, "
          f"{args.pairs_per_mesh} pairs each")
    meshes = tori(args.meshes)
    ids = sorted(meshes)
    with tempfile.TemporaryDirectory() as d:
        store = f"{d}/s.zarr"
        write_store(store, meshes)
        spec = FieldSpec("landmark", args.landmarks)
        cache = FieldCache(f"{d}/fields", spec)
        plain = BatchDataset(store, "geodesic", 0, args.pairs_per_mesh, True, 5, 1 / 16, 3 / 16)
        t = time.perf_counter()
        fill_field_cache(cache.path, spec, [(plain, ids, range(LANDMARK_DRAWS))], Dist(),
                            torch.device("cpu"), logging.getLogger(__name__))
        fill, n = time.perf_counter() - t, len(ids) * LANDMARK_DRAWS
        print(f"landmark cache: {n} fields (K = {args.landmarks}) in {fill:.1f} s with {cpus_per_process()} "
              f"processes, {fill / n * cpus_per_process() * 1000:.0f} ms per field and core")
        cached = BatchDataset(store, "geodesic", 0, args.pairs_per_mesh, True, 5, 1 / 16, 3 / 16, spec,
                              cache.path)
        live = BatchDataset(store, "geodesic", 0, args.pairs_per_mesh, True, 5, 1 / 16, 3 / 16, spec)

        rates = {}
        print("\nloader (batches/s, after the first batch)")
        print(f"{'workers':>8} {'paper':>10} {'landmark, cached':>18} {'landmark, per draw':>20}")
        for w in workers:
            row = [loader_rate(ds, ids, args.batch_size, w, args.epochs) for ds in (plain, cached)]
            row.append(loader_rate(live, ids, args.batch_size, w, 1) if w == workers[0] else float("nan"))
            rates[w] = row
            print(f"{w:>8} {row[0]:>10.2f} {row[1]:>18.2f} {row[2]:>20.2f}")
        base = rates[workers[0]]
        print(f"cache speed-up at {workers[0]} workers: {base[1] / base[2]:.1f}x (landmark, cached / per draw)")

        device = torch.device("cuda" if torch.cuda.is_available() else "cpu")
        step = {name: step_seconds(ds, ids, args.batch_size, args.channels, k, device, args.steps)
                for name, ds, k in (("paper", plain, 0), ("landmark", cached, args.landmarks))}
        print(f"\nstep on {device} ({args.channels} channels): paper {step['paper'] * 1000:.0f} ms, "
              f"landmark {step['landmark'] * 1000:.0f} ms")
        gpu = step if device.type == "cuda" else {k: args.gpu_step_ms / 1000 for k in step}
        label = "measured" if device.type == "cuda" else f"--gpu-step-ms {args.gpu_step_ms:g}, an estimate"
        w1 = 1 if 1 in rates else workers[0]
        build = {name: 1 / rates[w1][i] for i, name in enumerate(("paper", "landmark"))}
        print(f"\nloader processes one GPU needs: one process builds a batch in {build['paper'] * 1000:.0f} ms "
              f"(paper) / {build['landmark'] * 1000:.0f} ms (landmark, cached) (at --workers {w1}); GPU step {label}")
        for name in ("paper", "landmark"):
            print(f"  {name}: {math.ceil(build[name] / gpu[name])} (with one, the GPU would be busy "
                  f"{min(1.0, gpu[name] / build[name]):.0%} of the time)")

if __name__ == "__main__":
    main()
