"""Queries of the shipped model against the heat method and the exact solver, measured in the same run:
random pairs, the whole distance matrix, and points inside faces.

    python benchmarks/bench_queries.py [STORE] [--mesh ID] [--only queries,matrix,surface]

STORE is a validation store of `pipelines/pretrained/data.sh` (default data/val.zarr); --mesh picks the
mesh (an id or a unique prefix of one; default dragon-4af53808, 5,224 vertices, the largest held-back one).
Sections:
  - queries: precomputation (landmark fields, network) and 1M random pairs, in fp32, with precision "auto"
    and with the paths landmark fields (the model's error with them too), against the heat method for the same
    pairs (potpourri3d, one field per distinct source,
    factorization included), against the torch path the compiled decode replaced, and on an AVX512 CPU
    against the compiled decode forced to AVX2; the model's error on the mesh's stored pairs.
  - matrix: the N x N matrix by the model (precomputation included), by the heat method's loop over
    sources, and by the exact solver (window propagation on every core; timed on 256 rows and scaled
    to N: rows are independent).
  - surface: over every mesh of the store, distances between random points inside faces against
    exact distances to the points inserted as vertices, next to the model's error between the
    corners of the same faces; and the cost of 1M surface-point queries.
Prints markdown tables (for docs/results.md) with the CPU.
"""
from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import numpy as np
import torch

from gegnn import GeGnn
from gegnn.model import PRETRAINED
from gegnn import decoders
from gegnn.decoders import compiled_isa
from gegnn.queries.embedding import CHUNK_VALUES, Embedding
from gegnn.fields.landmarks import landmark_fields
from gegnn.metrics import METRIC_EPS
from geodata import store as geostore
from geodata.geodesic import geodesic_solver
from geodata.mesh import Mesh
from geodata.surface_points import insert_points

from bench_gegnn import heat_pairs, timed
from machine import cpu_description  # benchmarks/ is on sys.path when a script there runs
from stores import mesh_id as find_mesh


def load(store, mesh_id, pairs=False):
    """The mesh's vertices, faces and (with ``pairs``) its stored geodesic arrays by name, read into memory."""
    with geostore.read_mesh(store, mesh_id) as g:
        stored = {name: g[name][:] for name in ("geodesic/pairs", "geodesic/distances")} if pairs else None
        return g["vertices"][:].astype(np.float64), g["faces"][:].astype(np.int64), stored


def mre(pred, exact):
    return float(np.mean(np.abs(pred - exact) / (exact + METRIC_EPS)))


def section_queries(model, v, f, g, rows):
    rng = np.random.default_rng(0)
    i, j = rng.integers(0, len(v), 1_000_000), rng.integers(0, len(v), 1_000_000)
    k = model.config.landmarks
    solver = model.config.landmark_fields
    fields = timed(lambda: landmark_fields(v, f, k, fields=solver))[0]
    embed, emb = timed(lambda: model.embed(v, f))
    query = timed(lambda: emb.distance(i, j))[0]
    isa = compiled_isa()
    forced = {}  # each narrower instruction set this CPU runs, forced: the same run's ratio between them
    for other in [name for name in ("avx2",) if isa == "avx512"]:
        decoders.ISA = other
        forced[other] = timed(lambda: Embedding(emb.features, emb.decoder, emb.scale).distance(i, j))[0]
        decoders.ISA = "auto"
    reference = timed(lambda: torch_path(emb).distance(i, j), repeat=1)[0]
    auto_embed, auto_emb = timed(lambda: model.embed(v, f, precision="auto"))
    auto_query = timed(lambda: auto_emb.distance(i, j))[0]
    heat = timed(lambda: heat_pairs(v, f, i, j), repeat=1)[0]
    pairs, dist = g["geodesic/pairs"][:].astype(np.int64), g["geodesic/distances"][:]
    error = mre(emb.distance(pairs[:, 0], pairs[:, 1]), dist)
    ours = embed + query
    paths_embed, paths_emb = timed(lambda: model.embed(v, f, fields="paths"), repeat=1)
    paths_error = mre(paths_emb.distance(pairs[:, 0], pairs[:, 1]), dist)
    rows += [
        (f"landmark fields ({k} fields, {solver}), part of the precomputation", fields, ""),
        ("precomputation: landmark fields + one forward pass (fp32)", embed, ""),
        (f"1M random queries, compiled decode ({isa}, fp32)", query,
         f"{reference / query:.2f}x the torch path; target <= 0.15 s"),
        *[(f"1M random queries, compiled decode forced to {name} (fp32)", seconds, f"{seconds / query:.2f}x {isa}'s time")
          for name, seconds in forced.items()],
        ("1M random queries, torch path (reference: fused features, torch's MLP)", reference, ""),
        ("heat method, the same 1M pairs (one field per distinct source)", heat, ""),
        ("precomputation + 1M queries (fp32)", ours, f"**{heat / ours:.1f}x** faster than the heat method"),
        (f"precomputation + 1M queries, precision auto (network {auto_emb_network(model)}, decoder "
         f"{auto_emb.precision})", auto_embed + auto_query, f"**{heat / (auto_embed + auto_query):.1f}x** the heat method"),
        (f"model error on this mesh's {len(pairs):,} stored pairs", None, f"{100 * error:.2f}%"),
        ("precomputation with the paths landmark fields (embed fields=\"paths\") + 1M queries (fp32)",
         paths_embed + query, f"**{heat / (paths_embed + query):.1f}x** the heat method; model error "
         f"{100 * paths_error:.2f}%"),
    ]
    return heat / ours


def torch_path(emb):
    """The embedding's decode as it ran before the compiled decode: fused features, then torch's MLP in chunks
    that keep its intermediates in cache."""
    ref = Embedding(emb.features, emb.decoder, emb.scale, precision="fp32")
    ref._fused = False
    ref.chunk = max(1024, CHUNK_VALUES // emb.decoder.pair_width(emb.features))
    return ref


def auto_emb_network(model):
    from gegnn.precision import resolve

    return resolve("auto", next(model.parameters()).device)


def section_matrix(model, v, f, rows, exact_rows=256):
    import potpourri3d as pp3d

    n = len(v)
    start = time.perf_counter()
    d = model.embed(v, f).matrix()
    ours = time.perf_counter() - start
    start = time.perf_counter()
    solver = pp3d.MeshHeatMethodDistanceSolver(v, f)
    heat = np.stack([solver.compute_distance(s) for s in range(n)])
    heat_s = time.perf_counter() - start
    from concurrent.futures import ThreadPoolExecutor
    jobs = os.cpu_count() or 1
    sample = np.linspace(0, n - 1, exact_rows).astype(int)
    start = time.perf_counter()
    with ThreadPoolExecutor(jobs) as pool:
        blocks = list(pool.map(lambda part: np.stack([geodesic_solver(Mesh(v, f))(int(s)) for s in part]),
                               np.array_split(sample, jobs)))
    exact = np.concatenate(blocks)
    exact_s = (time.perf_counter() - start) * n / exact_rows
    off = exact > 0
    rows += [
        (f"{n} x {n} matrix, model (precomputation included)", ours,
         f"{heat_s / ours:.1f}x faster than the heat loop, {exact_s / ours:.0f}x than exact; "
         f"MRE {100 * mre(d[sample][off], exact[off]):.2f}% on {exact_rows} rows"),
        (f"{n} x {n} matrix, heat method's loop over sources", heat_s,
         f"MRE {100 * mre(heat[sample][off], exact[off]):.2f}%"),
        (f"{n} x {n} matrix, exact solver, {jobs} threads (from {exact_rows} rows)", exact_s, ""),
    ]


def section_surface(model, store, rows, sources=8, targets=200):
    ids = sorted(geostore.list_meshes(store))
    table = []
    for mesh_id in ids:
        v, f, _ = load(store, mesh_id)
        emb = model.embed(v, f)
        rng = np.random.default_rng(0)
        face = rng.choice(len(f), targets, replace=False)
        bary = rng.dirichlet([1, 1, 1], targets)
        refined, vertex = insert_points(Mesh(v, f), face, bary)
        solve = geodesic_solver(refined)
        exact = np.stack([solve(int(vertex[s]))[vertex] for s in range(sources)])
        pred = emb.surface_distance(face[:sources, None], bary[:sources, None], face[None], bary[None])
        corner = f[face, 0]
        solve = geodesic_solver(Mesh(v, f))
        exact_v = np.stack([solve(int(corner[s]))[corner] for s in range(sources)])
        pred_v = emb.distance(corner[:sources, None], corner[None])
        on, on_v = exact > 0, exact_v > 0
        table.append((mesh_id, mre(pred[on], exact[on]), mre(pred_v[on_v], exact_v[on_v])))
        print(f"{mesh_id}: surface points {100 * table[-1][1]:.2f}%, vertices {100 * table[-1][2]:.2f}%", flush=True)
    v, f, _ = load(store, ids[0])
    emb = model.embed(v, f)
    rng = np.random.default_rng(1)
    fa, fb = rng.integers(0, len(f), 1_000_000), rng.integers(0, len(f), 1_000_000)
    ba, bb = rng.dirichlet([1, 1, 1], 1_000_000), rng.dirichlet([1, 1, 1], 1_000_000)
    i, j = rng.integers(0, len(v), 1_000_000), rng.integers(0, len(v), 1_000_000)
    surface_s, vertex_s = timed(lambda: emb.surface_distance(fa, ba, fb, bb), 1)[0], timed(lambda: emb.distance(i, j))[0]
    print("\n| mesh | between surface points (vs inserted vertices) | between the faces' corners |\n|---|---:|---:|")
    for mesh_id, s, c in table:
        print(f"| {mesh_id} | {100 * s:.2f}% | {100 * c:.2f}% |")
    print(f"| **mean** | **{100 * np.mean([t[1] for t in table]):.2f}%** | "
          f"**{100 * np.mean([t[2] for t in table]):.2f}%** |")
    rows += [("1M surface-point queries (blend + decode)", surface_s, f"{surface_s / vertex_s:.1f}x vertex queries"),
             ("1M vertex queries, same mesh", vertex_s, "")]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("store", nargs="?", default="data/val.zarr")
    ap.add_argument("--mesh", default="dragon-4af53808", help="a mesh id of the store, or a unique prefix of one")
    ap.add_argument("--only", default="queries,matrix,surface")
    ap.add_argument("--record", action="store_true",
                    help="write the default model's speed-up over the heat method to docs/results.json")
    args = ap.parse_args()
    model = GeGnn.pretrained().eval()
    args.mesh = find_mesh(args.store, args.mesh)
    v, f, g = load(args.store, args.mesh, pairs=True)
    print(f"{args.mesh}: {len(v)} vertices; CPU: {cpu_description()}, {torch.get_num_threads()} threads, "
          f"load average {os.getloadavg()[0]:.1f}; torch {torch.__version__}")
    rows = []
    only = args.only.split(",")
    if "queries" in only:
        speedup = section_queries(model, v, f, g, rows)
        if args.record:
            from results import record

            record(f"speedup.{Path(PRETRAINED['landmark']).stem.removeprefix('gegnn-')}", f"{speedup:.1f}x")
    if "matrix" in only:
        section_matrix(model, v, f, rows)
    if "surface" in only:
        section_surface(model, args.store, rows)
    print("\n| what | seconds | note |\n|---|---:|---|")
    for name, seconds, note in rows:
        print(f"| {name} | {'' if seconds is None else f'{seconds:.3f}'} | {note} |")


if __name__ == "__main__":
    main()
