"""A worker's start at catalog scale: seconds of each step before a worker's first mesh, at several store sizes.

    python benchmarks/bench_store_scale.py [--sizes 2000 20000] [--shards 200]

Builds synthetic catalogs (tests/storetools.py synthetic_catalog: SYNSET/MODEL/models/model_normalized.obj
inputs, each published as a small mesh zip, and the prepare run's ledger) and times, in one run: a prepare
shard's plan over the input tree (first run of that shard count, its rerun, and its rerun given its own
--include list), a biharmonic shard's
selection, a training rank's store listing and split, one mesh's key, and `geodata info` over the whole store
(which reads every mesh's attributes: it grows with the store by design). The per-worker steps should stay
flat from the smallest size to the largest but for the listings (one readdir of meshes/, one walk of the
input tree).
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

from click.testing import CliRunner
from machine import cpu_description  # benchmarks/ is on sys.path when a script there runs

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from storetools import synthetic_catalog  # noqa: E402


def timed(fn, repeat: int = 3) -> tuple[float, object]:
    best, result = float("inf"), None
    for _ in range(repeat):
        t = time.perf_counter()
        result = fn()
        best = min(best, time.perf_counter() - t)
    return best, result


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", type=int, nargs="+", default=[2000, 20000])
    ap.add_argument("--shards", type=int, default=200)
    args = ap.parse_args()
    from gegnn.training.data import GeodesicStore, split_meshes
    from geodata import store
    from geodata.cli import main as geodata_cli
    from geodata.parallel import in_shard
    from geodata.prepare import plan_shard
    from geodata.subgroup import pending

    print(f"{cpu_description()}; best of 3 each; shard 7/{args.shards}")
    rows = []
    for n in args.sizes:
        with tempfile.TemporaryDirectory() as tmp:
            raw, out = Path(tmp) / "raw", Path(tmp) / "out.zarr"
            build, ids = timed(lambda: synthetic_catalog(raw, out, n), repeat=1)
            shard = (7, args.shards)
            first, plan = timed(lambda: plan_shard(raw, str(out), shard), repeat=1)
            store.write_ledger(out, plan.ledger_name, plan.ledger)
            rerun, _ = timed(lambda: plan_shard(raw, str(out), shard))
            listed = {s for s in plan.ledger["inputs"]}  # the shard's own --include list: no walk of the tree
            listing, _ = timed(lambda: plan_shard(raw, str(out), shard, include=listed))
            bh, _ = timed(lambda: pending(str(out), "biharmonic", lambda m: in_shard(m, shard)))
            rank, _ = timed(lambda: split_meshes(GeodesicStore(out).mesh_ids))
            opened = GeodesicStore(out)
            key, _ = timed(lambda: opened.key(ids[0]))
            info, _ = timed(lambda: CliRunner().invoke(geodata_cli, ["info", str(out)]), repeat=1)
            files = sum(1 for p in (out / "meshes").iterdir())
            rows.append((n, files / n, len(plan.tasks), first, rerun, listing, bh, rank, key, info))
    print("| meshes | files per mesh | shard's own | prepare shard, 1st run | its rerun | rerun with --include | "
          "biharmonic shard | training rank's list | one mesh's key | geodata info |")
    print("|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    for n, fpm, own, first, rerun, listing, bh, rank, key, info in rows:
        print(f"| {n:,} | {fpm:.2f} | {own} | {first:.3f} s | {rerun:.3f} s | {listing * 1e3:.1f} ms | "
              f"{bh * 1e3:.0f} ms | {rank * 1e3:.0f} ms | {key * 1e3:.1f} ms | {info:.1f} s |")


if __name__ == "__main__":
    main()
