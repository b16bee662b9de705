"""Where the time of 1M landmark queries goes (Embedding.distance on a CPU), against what the CPU allows.

    python benchmarks/profile_decode.py [STORE] [--mesh ID] [--model NAME]

STORE/--mesh as bench_queries.py (default data/val.zarr's 5,224-vertex dragon; without it, a synthetic
5,000-vertex torus). Every part is timed on the same 1M random pairs, best of 5, on torch's threads (and on
one thread):
  - the whole query (Embedding.distance: index checks, the compiled decode, the decoder's output),
  - the compiled decode alone (src/pair_features.cpp decode_pairs), per instruction set this CPU runs,
  - its two halves apart: the features alone (gathers of both codes, landmark reductions: landmark_features)
    and the MLP alone (the same layers on rows of the first layer's width, gathered from a small table),
  - the torch path it replaced (fused features, then torch's MLP in cache-sized chunks).
The limit: the MLP's multiply-adds at the FMA rate torch's own matrix product reaches here on a large
product (the machine's practical peak), and the gathers' bytes.
"""
from __future__ import annotations

import argparse
import os
import time

import numpy as np
import torch

from gegnn import GeGnn, decoders
from gegnn._pair_features import decode_pairs, landmark_features
from gegnn.decoders import compiled_isa
from geodata import store as geostore

from bench_gegnn import torus_mesh  # benchmarks/ is on sys.path when a script there runs
from bench_queries import torch_path
from machine import cpu_description
from stores import mesh_id


def best(fn, repeat=5) -> float:
    fn()
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def peak_gflops(threads: int) -> float:
    """torch's fp32 matrix product on a large square product: the FMA rate this CPU reaches in practice."""
    torch.set_num_threads(threads)
    a, b = torch.randn(2048, 2048), torch.randn(2048, 2048)
    return 2 * 2048 ** 3 / best(lambda: a @ b, 3) / 1e9


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("store", nargs="?", default="data/val.zarr")
    ap.add_argument("--mesh", default="dragon-4af53808")
    ap.add_argument("--model", default="landmark", help="a shipped landmark model's name")
    args = ap.parse_args()
    if os.path.isdir(args.store):
        name = mesh_id(args.store, args.mesh)
        with geostore.read_mesh(args.store, name) as g:
            v, f = g["vertices"][:].astype(np.float64), g["faces"][:].astype(np.int64)
    else:
        name, (v, f) = "torus", torus_mesh()
    threads = torch.get_num_threads()
    print(f"{name}: {len(v)} vertices; CPU: {cpu_description()}, {threads} threads; torch {torch.__version__}")
    model = GeGnn.pretrained(args.model).eval()
    emb = model.embed(v, f)
    dec = emb.decoder
    n = 1_000_000
    rng = np.random.default_rng(0)
    i, j = torch.as_tensor(rng.integers(0, len(v), n)), torch.as_tensor(rng.integers(0, len(v), n))
    weights, biases = [w for w, _ in emb._layers], [b for _, b in emb._layers]
    n_in, hidden = weights[0].shape
    t, lower, upper, x = torch.empty(n), torch.empty(n), torch.empty(n), torch.empty(n, n_in)
    codes = emb.features
    table = torch.randn(len(v), n_in)  # rows of the first layer's width: the MLP with small gathers

    def decode(isa, th):
        return lambda: decode_pairs(codes, i, j, 1, dec.embed_dim, dec.k, dec.embedding, dec.euclidean, weights,
                                    biases, t, lower, upper, th, isa)

    isas = ["avx512", "avx2"] if compiled_isa() == "avx512" else [compiled_isa()]
    rows = []
    for th in sorted({threads, 1}, reverse=True):
        torch.set_num_threads(th)
        rows.append((f"Embedding.distance, {th} thread(s)", best(lambda: emb.distance(i, j))))
        for isa in isas:
            rows.append((f"  compiled decode alone ({isa})", best(decode(isa, th))))
        rows.append(("    features alone (gathers + landmark reductions)", best(
            lambda: landmark_features(codes, i, j, dec.embed_dim, dec.k, dec.embedding, dec.euclidean, x, lower,
                                      upper, th))))
        rows.append((f"    MLP alone ({n_in} -> {hidden} -> {hidden} -> 1, {n_in}-wide rows)", best(
            lambda: decode_pairs(table, i, j, 0, 0, 0, False, False, weights, biases, t, lower, upper, th,
                                 compiled_isa()))))
        reference = torch_path(emb)
        rows.append(("  torch path (fused features, torch's MLP)", best(lambda: reference.distance(i, j), 2)))
    torch.set_num_threads(threads)
    macs = sum(w.shape[0] * w.shape[1] for w in weights)
    gathered = 2 * codes.shape[1] * 4
    peak = peak_gflops(threads)
    limit = 2 * macs * n / (peak * 1e9)
    print("\n| what (1M pairs) | seconds |\n|---|---:|")
    for what, seconds in rows:
        print(f"| {what} | {seconds:.3f} |")
    print(f"\nMLP: {macs:,} multiply-adds a pair, {2 * macs * n / 1e9:.1f} GFLOP for 1M pairs; torch's 2048^3 product "
          f"here: {peak:.0f} GFLOP/s on {threads} threads, so the MLP alone needs >= {limit:.3f} s. Gathers: "
          f"{gathered:,} bytes a pair ({gathered * n / 1e9:.1f} GB, from a {codes.numel() * 4 / 2**20:.1f} MiB table). "
          f"Compiled decode here: {compiled_isa()}; decoders.ISA = {decoders.ISA!r}.")


if __name__ == "__main__":
    main()
