"""GeGnn speed on CPU: training step, loader vs model, one embed, 1M queries, and the heat method.

    python benchmarks/bench_gegnn.py [--channels 256] [--queries 1000000] [--steps 3]

Runs on a synthetic 5,000-vertex torus (no shared data needed). Reference timings (fp32 decoder, heat
method) are measured in the same run; ratios are against them.
"""
from __future__ import annotations

import argparse
import os
import tempfile
import time

import numpy as np
import torch
import trimesh

from gegnn import GeGnn, GeGnnConfig
from gegnn.training.data import BatchDataset
from gegnn.queries.embedding import Embedding
from geodata.mesh import Mesh, unique_edges, vertex_normals
from geodata.stages.normalize import normalize
from gegnn.training.loop import lr_at, train_step
from machine import cpu_description  # benchmarks/ is on sys.path when a script there runs


def torus_mesh():
    m = trimesh.creation.torus(major_radius=1.0, minor_radius=0.35, major_sections=100, minor_sections=50)
    return np.asarray(m.vertices), np.asarray(m.faces)


def timed(fn, repeat=3):
    fn()  # warm-up: kernel selection, allocator
    best = float("inf")
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return best, out


def write_store(path, meshes: dict, pairs=600_000, seed=0):
    """Meshes {id: (V, F)} in a new store at `path` (geodata.store's layout); distances are Euclidean
    stand-ins (only throughput matters here)."""
    from geodata import store as geostore

    rng = np.random.default_rng(seed)
    geostore.create_store(path, {"benchmark": "bench_gegnn.write_store", "pairs": pairs, "seed": seed})
    for mesh_id, (v, f) in meshes.items():
        v = normalize(Mesh(v, f)).vertices
        p = rng.integers(0, len(v), (pairs, 2)).astype(np.uint32)
        arrays = {"vertices": v.astype(np.float32), "faces": f.astype(np.int32),
                  "normals": vertex_normals(Mesh(v, f)).astype(np.float32),
                  "edges": unique_edges(f).astype(np.int32), "geodesic/pairs": p,
                  "geodesic/distances": np.linalg.norm(v[p[:, 0]] - v[p[:, 1]], axis=1).astype(np.float32)}
        geostore.write_mesh(path, mesh_id, arrays, {
            "source": mesh_id, "geometry_key": geostore.geometry_key(arrays["vertices"], f),
            "n_vertices": len(v), "n_faces": len(f), "n_pairs": pairs})


def bench_training(v, f, channels, steps, pairs_per_mesh):
    with tempfile.TemporaryDirectory() as d:
        write_store(d + "/s.zarr", {"torus": (v, f)})
        torch.manual_seed(0)
        model = GeGnn(GeGnnConfig(channels=channels, embed_dim=channels, decoder_hidden=channels))
        ds = BatchDataset(d + "/s.zarr", "geodesic", 0, pairs_per_mesh, True, 5, 1 / 16, 3 / 16)
        load, batch = timed(lambda: ds[(0, ("torus",))], repeat=steps)
        opt = torch.optim.AdamW(model.parameters(), lr=1e-4, weight_decay=0.01)
        step, _ = timed(lambda: train_step(model, batch, opt, lr_at(0, 10, 1e-4, 0), 1.0, torch.device("cpu")),
                        repeat=steps)
    return step, load, [g.num_nodes for g in batch.hierarchy.graphs]


def bench_queries(v, f, channels, queries):
    torch.manual_seed(0)
    model = GeGnn(GeGnnConfig(channels=channels, embed_dim=channels, decoder_hidden=channels)).eval()
    embed_s, emb = timed(lambda: model.embed(v, f))
    bf16_s, emb16 = timed(lambda: model.embed(v, f, precision="bf16"))
    rng = np.random.default_rng(0)
    i, j = rng.integers(0, len(v), queries), rng.integers(0, len(v), queries)
    fast_s, fast = timed(lambda: emb.distance(i, j), repeat=2)
    fp32 = Embedding(emb.features, model.distance, emb.scale, precision="fp32")
    ref_s, ref = timed(lambda: fp32.distance(i, j), repeat=1)
    deviation = np.median(np.abs(fast - ref) / (np.abs(ref) + 1e-3))
    dev16 = np.median(np.abs(emb16.distance(i[:100_000], j[:100_000]) - ref[:100_000]) / (np.abs(ref[:100_000]) + 1e-3))
    return embed_s, bf16_s, dev16, fast_s, ref_s, deviation, emb.dtype, (i, j)


def heat_pairs(v, f, i, j) -> np.ndarray:
    """potpourri3d's heat method for the pairs (i, j): one field per distinct i (factorization included)."""
    import potpourri3d as pp3d

    solver = pp3d.MeshHeatMethodDistanceSolver(v, f)
    out = np.empty(len(i))
    order = np.argsort(i, kind="stable")
    sources, starts = np.unique(i[order], return_index=True)
    for s, lo, hi in zip(sources, starts, np.append(starts[1:], len(i))):
        out[order[lo:hi]] = solver.compute_distance(int(s))[j[order[lo:hi]]]
    return out


def bench_heat(v, f, pairs):
    i, j = pairs
    t = time.perf_counter()
    heat_pairs(v, f, i, j)
    return time.perf_counter() - t, len(np.unique(i))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--channels", type=int, default=256)
    ap.add_argument("--queries", type=int, default=1_000_000)
    ap.add_argument("--steps", type=int, default=3)
    ap.add_argument("--pairs-per-mesh", type=int, default=100_000)
    ap.add_argument("--skip-train", action="store_true")
    ap.add_argument("--threads", type=int, default=0, help="torch threads (0: torch's default)")
    args = ap.parse_args()
    print(f"CPU: {cpu_description()}", flush=True)
    if args.threads:
        torch.set_num_threads(args.threads)  # on a shared machine, 1 thread avoids oversubscription stalls
    v, f = torus_mesh()
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads, load average "
          f"{os.getloadavg()[0]:.1f}; mesh {len(v)} vertices, {len(f)} faces; {args.channels} channels")
    rows = []
    if not args.skip_train:
        step, load, sizes = bench_training(v, f, args.channels, args.steps, args.pairs_per_mesh)
        rows += [("train step (fwd+bwd+AdamW, 1 mesh, %d pairs)" % args.pairs_per_mesh, step, ""),
                 ("loader: one batch (read 600k pairs, sample, rotate, hierarchy)", load,
                  f"{step / load:.1f}x model consumption per worker")]
        print("hierarchy sizes", sizes)
    embed_s, bf16_s, dev16, fast_s, ref_s, dev, dtype, pairs = bench_queries(v, f, args.channels, args.queries)
    heat_s, n_sources = bench_heat(v, f, pairs)
    ours = embed_s + fast_s
    rows += [("embed (one forward pass), fp32", embed_s, "target <= 0.25 s"),
             ("embed, bf16 autocast", bf16_s, f"{embed_s / bf16_s:.2f}x vs fp32; median rel. distance "
                                              f"deviation {dev16:.2e} (untrained weights)"),
             (f"{args.queries:,} queries, {str(dtype).split('.')[-1]} decoder", fast_s,
              f"{ref_s / fast_s:.2f}x vs fp32 reference; median rel. deviation {dev:.2e}; target <= 1.5 s"),
             (f"{args.queries:,} queries, fp32 reference MLP", ref_s, ""),
             (f"heat method (potpourri3d), {n_sources} sources", heat_s, ""),
             ("embed + queries vs heat method", ours, f"{heat_s / ours:.1f}x faster (target >= 3x)")]
    width = max(len(r[0]) for r in rows)
    print(f"{'measurement':<{width}}  {'seconds':>9}  note")
    for name, seconds, note in rows:
        print(f"{name:<{width}}  {seconds:>9.3f}  {note}")


if __name__ == "__main__":
    main()
