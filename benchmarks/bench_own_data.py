"""The costs behind docs/own-data.md's table of times for 1k / 10k / 50k meshes: per mesh, `geodata prepare`
and the landmark fields a run computes first; per step, the `--model landmark` preset and the paper's
256-channel network (plain `gegnn train`), on this machine's CPU.

    OMP_NUM_THREADS=1 python benchmarks/bench_own_data.py [--pairs 100000] [--steps 4] [--record]

Prepares the six sample soups of `geodata examples` (one job, --pairs as given) into a temporary store, timing
the CPU seconds of the command and its processes; then each training step is a batch of 4 of those meshes,
20,000 pairs each (the preset's schedule), fields read from a cache filled first; the first step is not timed.
CPU seconds are what other work on a shared machine does not inflate. --record writes the figures to
docs/results.json (benchmarks/results.py).
"""
from __future__ import annotations

import argparse
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from gegnn import GeGnn, GeGnnConfig
from gegnn.fields.cache import FieldCache, FieldSpec
from gegnn.training.data import BatchDataset, GeodesicStore
from gegnn.training.loop import lr_at, train_step
from gegnn.training.presets import preset
from machine import cpu_description  # benchmarks/ is on sys.path when a script there runs


def step_seconds(store: str, config: GeGnnConfig, steps: int, cache: str | None) -> tuple[float, float]:
    """Median wall and CPU seconds of a training step (batch 4, 20,000 pairs a mesh) after an untimed first
    one. CPU seconds (all threads) are what a shared machine does not inflate."""
    ids = GeodesicStore(store, "geodesic").mesh_ids
    spec = FieldSpec.of(config)
    data = BatchDataset(store, "geodesic", 0, 20_000, True, config.levels, config.sigma_c, config.sigma_n,
                        spec, cache, config.points)
    model = GeGnn(config)
    optimizer = torch.optim.AdamW(model.parameters(), lr=1e-4)
    times = []
    for k in range(steps + 1):
        batch = data[(k, tuple(ids[(4 * k + i) % len(ids)] for i in range(4)))]
        t0, c0 = time.perf_counter(), time.process_time()
        train_step(model.train(), batch, optimizer, lr_at(k, 100, 1e-4, 0), 1.0, torch.device("cpu"))
        times.append((time.perf_counter() - t0, time.process_time() - c0))
    wall, cpu = np.median(np.array(times[1:]), axis=0)
    return float(wall), float(cpu)


def fields_seconds(store: str, spec: FieldSpec, cache: str) -> float:
    """CPU seconds of one mesh's 4 landmark draws, the mean over the store's meshes; fills ``cache``."""
    s = GeodesicStore(store, "geodesic")
    fields = FieldCache(cache, spec)
    fields.create()
    t0 = time.process_time()
    for m in s.mesh_ids:
        g = s.geometry(m)
        fields.fill([(s.key(m), g.vertices, g.faces, seed) for seed in range(spec.draws)], progress=False)
    return (time.process_time() - t0) / len(s.mesh_ids)


def prepare_seconds(folder: Path, pairs: int) -> tuple[str, float]:
    """The sample soups prepared into ``folder/store.zarr`` with one job: the store and CPU seconds a mesh."""
    bin_dir = Path(sys.executable).parent
    subprocess.run([bin_dir / "geodata", "examples", folder / "raw"], check=True, capture_output=True)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    subprocess.run([bin_dir / "geodata", "prepare", folder / "raw", folder / "store.zarr", "--pairs", str(pairs),
                    "--jobs", "1"], check=True, capture_output=True)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    store = str(folder / "store.zarr")
    cpu = after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime
    return store, cpu / len(GeodesicStore(store, "geodesic").mesh_ids)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pairs", type=int, default=100_000)
    parser.add_argument("--steps", type=int, default=4)
    parser.add_argument("--record", action="store_true")
    args = parser.parse_args()
    print(cpu_description(), f"torch threads {torch.get_num_threads()}", sep="; ")
    landmark = preset("landmark").config
    with tempfile.TemporaryDirectory() as tmp, tempfile.TemporaryDirectory() as cache:
        args.store, prepare = prepare_seconds(Path(tmp), args.pairs)
        print(f"geodata prepare --pairs {args.pairs}: {prepare:.2f} CPU s a mesh")
        per_mesh = fields_seconds(args.store, FieldSpec.of(landmark), cache)
        print(f"landmark fields (K = {landmark.landmarks}, 4 draws): {per_mesh:.2f} CPU s a mesh")
        (lm_wall, lm), (paper_wall, paper) = (step_seconds(args.store, c, args.steps, cache)
                                              for c in (landmark, GeGnnConfig()))
    print(f"--model landmark step (batch 4, 20k pairs): {lm:.2f} CPU s ({lm_wall:.2f} s wall)")
    print(f"plain gegnn train (paper network, 256 channels) step: {paper:.2f} CPU s ({paper_wall:.2f} s wall; "
          f"{paper / lm:.1f}x the preset's)")
    if args.record:
        from results import record

        page = "docs/own-data.md#how-long-it-takes"
        record("train.step.landmark.cpu", f"{lm:.1f} s", "CPU seconds (all threads) of a training step of `gegnn train --model landmark` (batch "
               "4 meshes of ~5k vertices, 20,000 pairs each, fields cached), median after the first", page)
        record("train.step.paper256.cpu", f"{paper:.1f} s", "CPU seconds of the same step of plain `gegnn train` (the paper's "
               "256-channel network)", page)
        record("prepare.mesh.cpu", f"{prepare:.1f} s", f"CPU seconds a mesh of `geodata prepare --pairs {args.pairs}` "
               "(all stages, one job), the six sample soups", page)
        record("train.fields.landmark.cpu", f"{per_mesh:.2f} s", "CPU seconds of a mesh's 4 landmark draws at K = 256, one core, "
               "as a run computes them before its first step", page)


if __name__ == "__main__":
    main()
