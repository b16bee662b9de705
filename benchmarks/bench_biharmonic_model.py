"""Accuracy and cost of biharmonic distance estimates on a validation store with exact biharmonic pairs
(`geodata biharmonic`): the table of docs/results.md, "Biharmonic distances".

    python benchmarks/bench_biharmonic_model.py data/val.zarr [--checkpoint CKPT] [--pure CKPT]
        [--modes 16 32 64 128 256] [--out table.md]

For every mesh, over all its stored pairs (sources x every vertex), the mean relative error
|d - d*| / (d* + 1e-3) (the training metric, normalized units) of:
  - the biharmonic GeGnn (`GeGnn.pretrained("biharmonic")`, or --checkpoint),
  - the pure learned model (--pure: no eigen-solve), when given,
  - the Weyl estimate alone: the model's m modes and their Weyl-law tail, no learning,
  - the truncated spectral sum for each m of --modes, with the time of its eigen-solve,
and the exact solver's time for the stored pairs (`geodata.biharmonic`, the same sources x all vertices). Then, on the largest
mesh: the model's precomputation (eigen-solve, one forward pass) and 1M random queries.
"""
from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from geodata.biharmonic import biharmonic_distances
from geodata.mesh import Mesh
from gegnn import GeGnn
from gegnn.training.data import GeodesicStore
from gegnn.decoders import SpectralDecoder
from gegnn.fields.spectral import spectral_codes
from gegnn.metrics import METRIC_EPS

from bench_results import timed  # benchmarks/ is on sys.path when a script there runs
from machine import cpu_description  # benchmarks/ is on sys.path when a script there runs


def mre(pred, exact) -> float:
    return float(np.mean(np.abs(pred - exact) / (exact + METRIC_EPS)))


@torch.no_grad()
def weyl_estimate(codes, v, pairs, m):
    """d_m and the Weyl-tail estimate for ``pairs`` from spectral codes (N, m + 1): a fresh
    SpectralDecoder without embeddings, whose correction starts at zero."""
    decoder = SpectralDecoder(0, m, 1, embedding=False)
    z = SpectralDecoder.codes(torch.empty(len(v), 0), torch.as_tensor(codes), torch.as_tensor(v))
    a, b = z[torch.as_tensor(pairs[:, 0])], z[torch.as_tensor(pairs[:, 1])]
    _, (bound, _) = decoder.inputs(a, b)
    return bound.sqrt().numpy(), decoder(a, b).numpy()


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("store")
    ap.add_argument("--checkpoint", help="biharmonic GeGnn (default: the shipped one)")
    ap.add_argument("--pure", help="a pure learned biharmonic GeGnn (no spectral codes)")
    ap.add_argument("--modes", type=int, nargs="+", default=[16, 32, 64, 128, 256])
    ap.add_argument("--out", help="also write the markdown table here")
    args = ap.parse_args()

    torch.set_num_threads(2)
    model = GeGnn.from_checkpoint(args.checkpoint) if args.checkpoint else GeGnn.pretrained("biharmonic")
    pure = GeGnn.from_checkpoint(args.pure) if args.pure else None
    m = model.config.spectral
    store = GeodesicStore(args.store, "biharmonic")
    header = ["mesh", "vertices", "GeGnn", *(["pure learned"] if pure else []), f"Weyl estimate (m = {m})",
              *[f"m = {k}" for k in args.modes], "exact (s)"]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    cols, solve_times, largest = [], {k: [] for k in args.modes}, None
    for mesh_id in store.mesh_ids:
        g = store.geometry(mesh_id)
        v, f = g.vertices.astype(np.float64), g.faces
        pairs, exact = store.pairs(mesh_id)
        emb = model.embed(v, f, precision="fp32")
        row = [mre(emb.distance(pairs[:, 0], pairs[:, 1]), exact)]
        if pure:
            row.append(mre(pure.embed(v, f, precision="fp32").distance(pairs[:, 0], pairs[:, 1]), exact))
        row.append(mre(weyl_estimate(spectral_codes(v, f, m), v, pairs, m)[1], exact))
        for k in args.modes:
            t = time.perf_counter()
            codes = spectral_codes(v, f, k)
            solve_times[k].append(time.perf_counter() - t)
            row.append(mre(weyl_estimate(codes, v, pairs, k)[0], exact))
        t = time.perf_counter()
        biharmonic_distances(Mesh(v, f), np.unique(pairs[:, 0]))
        seconds = time.perf_counter() - t
        cols.append(row + [seconds])
        largest = max(largest or (0, None), (len(v), mesh_id))
        cells = [f"{100 * x:.2f}%" for x in row] + [f"{seconds:.2f}"]
        lines.append(f"| {mesh_id} | {len(v)} | " + " | ".join(cells) + " |")
        print(lines[-1], flush=True)
    mean = np.mean(cols, axis=0)
    lines.append("| **mean** | | " + " | ".join(f"**{100 * x:.2f}%**" for x in mean[:-1]) + f" | {mean[-1]:.2f} |")
    lines.append("| eigen-solve (s, mean) | | | " + ("| " if pure else "") + "| "
                 + " | ".join(f"{np.mean(solve_times[k]):.3f}" for k in args.modes) + " | |")

    g = store.geometry(largest[1])
    v, f = g.vertices.astype(np.float64), g.faces
    rng = np.random.default_rng(0)
    i, j = rng.integers(len(v), size=(2, 1_000_000))
    t_codes = timed(lambda: spectral_codes(v, f, m))
    t_embed = timed(lambda: model.embed(v, f))
    emb = model.embed(v, f)
    t_query = timed(lambda: emb.distance(i, j))
    lines += ["", f"Largest mesh {largest[1]} ({len(v)} vertices): spectral codes (m = {m}) {t_codes:.3f} s; "
              f"precomputation (codes + one forward pass) {t_embed:.3f} s; 1M random queries {t_query:.3f} s "
              f"({emb.dtype}); in all {t_embed + t_query:.3f} s.",
              "", f"CPU: {cpu_description()}, torch {torch.__version__}, {torch.get_num_threads()} threads."]
    print("\n".join(lines[-3:]))
    if args.out:
        with open(args.out, "w") as fh:
            fh.write("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
