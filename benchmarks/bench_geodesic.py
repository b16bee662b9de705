"""Pairs stage: tvb-gdist against libigl's exact_geodesic (the reference), measured in the same run.

    python benchmarks/bench_geodesic.py [--meshes 3] [--pairs 600000] [--sources N]

Each mesh goes through the pipeline's stages first (so it is what the pairs stage really sees),
then both backends compute the same sources; the distances must agree to within one float32 ulp
(1.2e-7 relative), the precision the store keeps. With --sources the
per-source times are measured on N sources and scaled to the pairs count (libigl is slow).
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from geodata.geodesic import exact_geodesic_distances, sample_sources
from geodata.mesh import vertex_components
from geodata.prepare import PrepareConfig, prepare_mesh

SHARED = Path(__file__).resolve().parents[2] / "shared" / "meshes" / "train"
DEFAULT = ["sweethome3d/armchair.obj", "sweethome3d/lamp.obj", "trimesh-models/featuretype.STL"]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--meshes", nargs="*", default=DEFAULT, help="paths under shared/meshes/train")
    ap.add_argument("--pairs", type=int, default=600_000)
    ap.add_argument("--sources", type=int, default=None, help="time only this many sources and scale up")
    args = ap.parse_args()
    config = PrepareConfig(pairs=1)
    print(f"{'mesh':34s} {'verts':>6s} {'sources':>7s} {'gdist s':>8s} {'libigl s':>9s} {'ratio':>6s} {'max rel diff':>12s}")
    ratios = []
    for name in args.meshes:
        mesh, *_ = prepare_mesh((SHARED / name).read_bytes(), Path(name).suffix, config, np.random.default_rng(0))
        sources = sample_sources(vertex_components(mesh), args.pairs, np.random.default_rng(0))
        timed = sources if args.sources is None else sources[: args.sources]
        seconds, results = {}, {}
        for backend in ("gdist", "libigl"):
            t = time.perf_counter()
            results[backend] = [exact_geodesic_distances(mesh, int(s), backend) for s in timed]
            seconds[backend] = (time.perf_counter() - t) * len(sources) / len(timed)
        # Agreement is ~4e-15 at almost every vertex; one or two vertices of some sources differ by up
        # to ~8e-8 relative (floating-point order of window propagation), under one ulp of the float32
        # the store keeps.
        diff = max((np.abs(a - b) / np.maximum(b, 1e-12)).max() for a, b in zip(results["gdist"], results["libigl"]))
        assert diff < np.finfo(np.float32).eps, f"backends disagree on {name}: {diff}"
        ratios.append(seconds["libigl"] / seconds["gdist"])
        print(f"{name:34s} {mesh.n_vertices:6d} {len(sources):7d} {seconds['gdist']:8.2f} "
              f"{seconds['libigl']:9.2f} {ratios[-1]:5.2f}x {diff:12.1e}")
    print(f"pairs stage speed-up over libigl (geometric mean): {np.exp(np.mean(np.log(ratios))):.2f}x")


if __name__ == "__main__":
    main()
