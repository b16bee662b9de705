"""Point-cloud heat distances: gegnn.fields.cloud_heat against potpourri3d's PointCloudHeatSolver (the reference,
timed in the same run), on the validation clouds (each mesh's vertices) and on a bumpy_sphere(8000) cloud.

    python benchmarks/bench_cloud_heat.py [--store data/val.zarr] [--sources 16] [--landmarks 128]
                                          [--big 8000] [--repeat 3] [--clouds N]

Per cloud: setup (the constructor; potpourri3d factors on its first field, reported apart), the time of a
field one source at a time (``distance`` / ``compute_distance``, mean over --sources sources) and, for
ours, of a field in a 128-source solve (``distances``); the largest difference to potpourri3d over those
sources, relative to the field's largest value; and --landmarks farthest-point landmark fields end to end
(setup included, one field at a time as farthest-point sampling needs), with the landmarks' lower bound
max_k |d(i, l_k) - d(j, l_k)| on the store's exact geodesic pairs (mean ratio to the true distance, and
the share of pairs it overestimates by more than 1%). Times are the best of --repeat, one thread.
"""
from __future__ import annotations

import argparse
import os
import time
from importlib.metadata import version

import numpy as np

os.environ.setdefault("OMP_NUM_THREADS", "1")

from bench_gegnn import timed  # noqa: E402  (benchmarks/ is on sys.path when a script there runs)
from machine import cpu_description  # benchmarks/ is on sys.path when a script there runs
from gegnn.fields.cloud_heat import CloudHeatDistance  # noqa: E402
from gegnn.fields.landmarks import farthest_point_fields  # noqa: E402


def lower_bound_quality(fields: np.ndarray, pairs: np.ndarray, dist: np.ndarray) -> tuple[float, float]:
    """Mean of max_k |d_ik - d_jk| / d_ij over pairs with d_ij > 0, and the share with the bound above
    1.01 d_ij (a true lower bound never is; heat distances are approximate)."""
    ok = dist > 0
    i, j, d = pairs[ok, 0], pairs[ok, 1], dist[ok].astype(np.float64)
    bound = np.zeros(len(d))
    for start in range(0, fields.shape[1], 16):                    # (pairs x 16) at a time
        block = fields[:, start:start + 16]
        np.maximum(bound, np.abs(block[i] - block[j]).max(axis=1), out=bound)
    return float((bound / d).mean()), float((bound > 1.01 * d).mean())


def bench_cloud(name, points, args, pairs=None, dist=None, fps=True):
    import potpourri3d as pp3d

    n = len(points)
    rng = np.random.default_rng(0)
    sources = rng.choice(n, size=min(args.sources, n), replace=False)
    row = {"name": name, "n": n}
    row["pp_setup"], theirs = timed(lambda: pp3d.PointCloudHeatSolver(points), args.repeat)
    t = time.perf_counter()
    ref0 = theirs.compute_distance(int(sources[0]))                   # factors both systems
    row["pp_first"] = time.perf_counter() - t
    row["pp_field"], refs = timed(lambda: [theirs.compute_distance(int(s)) for s in sources], args.repeat)
    row["pp_field"] /= len(sources)
    row["setup"], ours = timed(lambda: CloudHeatDistance(points), args.repeat)
    ours.distance(int(sources[0]))
    row["field"], mine = timed(lambda: [ours.distance(int(s)) for s in sources], args.repeat)
    row["field"] /= len(sources)
    batch = rng.choice(n, size=min(128, n), replace=False)
    row["batched"], _ = timed(lambda: ours.distances(batch), args.repeat)
    row["batched"] /= len(batch)
    row["diff"] = max(np.abs(a - b).max() / np.abs(b).max() for a, b in zip(mine, refs))
    del ref0
    if fps:
        k, first = min(args.landmarks, n), int(sources[0])
        row["pp_fps"], (pp_lm, pp_fields) = timed(
            lambda: farthest_point_fields(pp3d.PointCloudHeatSolver(points).compute_distance, n, k, first), 1)
        row["fps"], (lm, fields) = timed(
            lambda: farthest_point_fields(CloudHeatDistance(points).distance, n, k, first), args.repeat)
        row["same_landmarks"] = lm == pp_lm
        row["fps_diff"] = float(np.abs(fields.astype(np.float64) - pp_fields).max() / np.abs(pp_fields).max())
        if pairs is not None:
            row["lb"], row["lb_over"] = lower_bound_quality(fields, pairs, dist)
            row["pp_lb"], row["pp_lb_over"] = lower_bound_quality(pp_fields, pairs, dist)
    return row


def print_rows(rows):
    print(f"{'cloud':<28} {'N':>5} {'setup ms':>14} {'first ms':>8} {'field ms (single | 128)':>28} "
          f"{'max|diff|/max':>13} {'K FPS s':>15}")
    for r in rows:
        fps = (f"{r['fps']:.2f} / {r['pp_fps']:.2f}" if "fps" in r else "")
        print(f"{r['name'][:28]:<28} {r['n']:>5} {r['setup'] * 1e3:>6.0f} / {r['pp_setup'] * 1e3:>5.0f} "
              f"{r['pp_first'] * 1e3:>8.0f} {r['field'] * 1e3:>6.2f} | {r['batched'] * 1e3:>5.2f} / "
              f"{r['pp_field'] * 1e3:>6.2f} ({r['pp_field'] / r['field']:>4.1f}x) {r['diff']:>13.1e} {fps:>15}")


def summary(rows, label):
    med = {key: float(np.median([r[key] for r in rows])) for key in rows[0] if isinstance(rows[0][key], float)}
    print(f"\n{label} (medians): setup {med['setup'] * 1e3:.0f} ms vs potpourri3d {med['pp_setup'] * 1e3:.0f} ms "
          f"+ {med['pp_first'] * 1e3:.0f} ms on its first field "
          f"({(med['pp_setup'] + med['pp_first']) / med['setup']:.2f}x); "
          f"a field {med['field'] * 1e3:.2f} ms one at a time, {med['batched'] * 1e3:.2f} ms in a 128-source solve, "
          f"potpourri3d {med['pp_field'] * 1e3:.2f} ms ({med['pp_field'] / med['field']:.1f}x, "
          f"{med['pp_field'] / med['batched']:.1f}x batched); max |diff| / max field "
          f"{max(r['diff'] for r in rows):.1e} (worst cloud)")
    if "fps" in rows[0]:
        print(f"  {len(rows)} x farthest-point landmark fields, setup included: {med['fps']:.3f} s vs "
              f"{med['pp_fps']:.3f} s ({med['pp_fps'] / med['fps']:.1f}x); same landmarks on "
              f"{sum(r['same_landmarks'] for r in rows)}/{len(rows)}; fields max |diff| / max "
              f"{max(r['fps_diff'] for r in rows):.1e} (float32 storage)")
    if "lb" in rows[0]:
        print(f"  landmark lower bound / geodesic: mean {med['lb']:.4f} (potpourri3d {med['pp_lb']:.4f}); "
              f"pairs over 1.01x: {med['lb_over']:.2e} (potpourri3d {med['pp_lb_over']:.2e})")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--store", default="data/val.zarr")
    ap.add_argument("--sources", type=int, default=16)
    ap.add_argument("--landmarks", type=int, default=128)
    ap.add_argument("--big", type=int, default=8000, help="bumpy_sphere points (0: skip)")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--clouds", type=int, default=None, help="only the first N validation clouds")
    args = ap.parse_args()
    print(f"{cpu_description()}, {os.cpu_count()} cores visible, OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS')}")
    print(f"potpourri3d {version('potpourri3d')}; times: ours / potpourri3d")
    if os.path.isdir(args.store):
        from gegnn.training.data import GeodesicStore

        store = GeodesicStore(args.store)
        rows = []
        for mesh_id in store.mesh_ids[:args.clouds]:
            points = np.asarray(store.geometry(mesh_id).vertices, dtype=np.float64)
            pairs, dist = store.pairs(mesh_id)
            rows.append(bench_cloud(mesh_id, points, args, np.asarray(pairs), np.asarray(dist)))
        print_rows(rows)
        summary(rows, f"{len(rows)} validation clouds")
    if args.big:
        from geodata.examples import bumpy_sphere

        points = np.asarray(bumpy_sphere(args.big).vertices, dtype=np.float64)
        rows = [bench_cloud(f"bumpy_sphere({args.big})", points, args)]
        print()
        print_rows(rows)
        summary(rows, f"bumpy_sphere({args.big})")


if __name__ == "__main__":
    main()
