"""Scaling of `geodata prepare` with worker count (and backend), measured in one run.

    python benchmarks/bench_scaling.py [--meshes 8] [--pairs 600000] [--jobs 1 2] [--backend loky]

Prepares the same meshes from shared/meshes/train into fresh stores with each worker count and
prints wall seconds, meshes per hour and the speed-up over the first count. The stores must come out
identical (checked), so the comparison is of the same work.
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from geodata import store as geostore
from machine import cpu_description  # benchmarks/ is on sys.path when a script there runs

SHARED = Path(__file__).resolve().parents[2] / "shared" / "meshes" / "train"


def store_digest(out: Path) -> dict:
    """Every published mesh's id and the sum of its geodesic distances."""
    digest = {}
    for mesh_id in geostore.list_meshes(out):
        with geostore.read_mesh(out, mesh_id) as g:
            digest[mesh_id] = float(g["geodesic/distances"][:].astype(np.float64).sum())
    return digest


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--meshes", type=int, default=8)
    ap.add_argument("--pairs", type=int, default=600_000)
    ap.add_argument("--jobs", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--backend", default="loky")
    args = ap.parse_args()
    print(f"CPU: {cpu_description()}", flush=True)
    files = sorted((SHARED / "sweethome3d").glob("*.obj"))[:: max(1, 89 // args.meshes)][: args.meshes]
    with tempfile.TemporaryDirectory() as tmp:
        raw = Path(tmp) / "raw"
        raw.mkdir()
        for f in files:
            (raw / f.name).symlink_to(f)
        print(f"{len(files)} meshes, {args.pairs} pairs each, backend {args.backend}")
        print(f"{'jobs':>4s} {'seconds':>8s} {'meshes/h':>9s} {'speed-up':>8s}")
        base, digest = None, None
        for jobs in args.jobs:
            out = Path(tmp) / f"out{jobs}.zarr"
            t = time.perf_counter()
            subprocess.run([sys.executable, "-m", "geodata.cli", "prepare", str(raw), str(out), "--pairs",
                            str(args.pairs), "--jobs", str(jobs), "--backend", args.backend],
                           check=True, capture_output=True)
            seconds = time.perf_counter() - t
            base = base or seconds
            d = store_digest(out)
            assert digest is None or d == digest, "stores differ between worker counts"
            digest = d
            print(f"{jobs:4d} {seconds:8.1f} {len(files) * 3600 / seconds:9.0f} {base / seconds:7.2f}x")


if __name__ == "__main__":
    main()
