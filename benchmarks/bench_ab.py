"""The speeds a change must keep, for comparing two trees: run it alternately with each tree's Python
(a worktree of the other commit with its compiled modules beside its packages), several rounds, and
compare the medians of the same line.

    python benchmarks/bench_ab.py NAME [--store data/val.zarr] [--mesh dragon-4af53808] [--rounds 5]

One line: the shipped landmark model's embed of the mesh and 1M random queries on it (what
bench_queries.py times), 128 farthest-point heat-method fields on one thread (bench_landmark_fields.py),
and the shipped point-cloud model's embed of 5k- and 8k-point bumpy spheres (bench_cloud_embed.py);
each the median of --rounds, on two torch threads.
"""
from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from gegnn import GeGnn
from gegnn.fields.heat import HeatDistance
from gegnn.fields.landmarks import farthest_point_fields
from geodata import store as geostore
from geodata.examples import bumpy_sphere
from stores import mesh_id  # benchmarks/ is on sys.path when a script there runs


def median_time(fn, rounds: int) -> float:
    times = []
    for _ in range(rounds):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("name", help="a label for the line (e.g. the commit)")
    ap.add_argument("--store", default="data/val.zarr")
    ap.add_argument("--mesh", default="dragon-4af53808", help="a mesh id of the store, or a unique prefix of one")
    ap.add_argument("--rounds", type=int, default=5)
    args = ap.parse_args()
    with geostore.read_mesh(args.store, mesh_id(args.store, args.mesh)) as group:
        v = np.asarray(group["vertices"][:], dtype=np.float64)
        f = np.asarray(group["faces"][:], dtype=np.int64)
    clouds = {n: np.asarray(bumpy_sphere(n, seed=0).vertices, dtype=np.float64) for n in (5000, 8000)}
    landmark, points = GeGnn.pretrained(), GeGnn.pretrained("points")
    torch.set_num_threads(2)
    emb = landmark.embed(v, f)
    i, j = np.random.default_rng(0).integers(0, len(v), (2, 1_000_000))
    times = {"mesh embed": median_time(lambda: landmark.embed(v, f), args.rounds),
             "1M queries": median_time(lambda: emb.distance(i, j), args.rounds)}
    torch.set_num_threads(1)
    times["128 fields, 1 thread"] = median_time(
        lambda: farthest_point_fields(HeatDistance(v, f).distance, len(v), 128, 0), args.rounds)
    torch.set_num_threads(2)
    for n, cloud in clouds.items():
        times[f"cloud {n // 1000}k embed"] = median_time(lambda: points.embed(cloud), args.rounds)
    print(args.name, " | ".join(f"{k} {1000 * t:.0f} ms" for k, t in times.items()), flush=True)


if __name__ == "__main__":
    main()
