"""Landmark count K of the landmark-guided GeGnn: accuracy and cost of each model, measured in one run.

    python benchmarks/ablation_k.py VAL_STORE [NAME=CHECKPOINT[@K] ...] [--mesh ID] [--fps-batch B ...]

NAME=CHECKPOINT is a model to compare (``shipped`` for ``GeGnn.pretrained()``); ``@K`` runs it with K
landmark fields at embed time instead of the K it was trained with (the decoder's weights do not
depend on K). Default: the shipped model at K = 128, 256, 512 and 1024. For each model:
  - validation MRE over all stored pairs of every mesh of VAL_STORE (mean over meshes, as
    docs/results.md and `gegnn eval`),
  - on the mesh --mesh (default dragon-4af53808, 5,224 vertices): embed (landmark fields + one forward
    pass, fp32) and 1M random queries, best of 3, and their sum against the heat method for the same
    1M pairs (potpourri3d, one field per distinct source, measured once in this run).
--record writes each NAME=...'s MRE to docs/results.json (mre.NAME). --fps-batch runs every model once per B: landmarks chosen B a round (gegnn.fields.landmarks.FPS_BATCH;
1 is sequential farthest-point sampling).
Prints a markdown table (for docs/results.md) with the CPU.
"""
from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np

from gegnn import GeGnn
from gegnn.fields import landmarks
from gegnn.training.loop import evaluate_store
from geodata import store as geostore

from bench_gegnn import heat_pairs, timed  # benchmarks/ is on sys.path when a script there runs
from machine import cpu_description
from stores import mesh_id


def load_model(spec: str) -> tuple[str, GeGnn]:
    """``NAME=PATH[@K]`` or ``PATH[@K]`` (named so) -> (name, model); PATH ``shipped``: the shipped default."""
    name, _, target = spec.partition("=")
    path, _, k = (target or spec).partition("@")
    model = GeGnn.pretrained() if path == "shipped" else GeGnn.from_checkpoint(path)
    if k and int(k) != model.config.landmarks:
        if not model.config.landmarks:
            raise SystemExit(f"{spec}: @K needs a landmark model")
        other = GeGnn(dataclasses.replace(model.config, landmarks=int(k)))
        other.load_state_dict(model.state_dict())
        model = other.eval()
    return name, model


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("store")
    ap.add_argument("models", nargs="*", default=[f"shipped@{k}" for k in (128, 256, 512, 1024)])
    ap.add_argument("--mesh", default="dragon-4af53808", help="a mesh id of the store, or a unique prefix of one")
    ap.add_argument("--out", help="also write the table to this file (for bench_results.py --landmarks-table)")
    ap.add_argument("--record", action="store_true",
                    help="write each named model's validation MRE to docs/results.json as mre.NAME")
    ap.add_argument("--fps-batch", type=int, nargs="+", default=[landmarks.FPS_BATCH],
                    help="landmarks chosen a round, each a row (default: gegnn.fields.landmarks.FPS_BATCH)")
    args = ap.parse_args()
    print(f"CPU: {cpu_description()}", flush=True)
    args.mesh = mesh_id(args.store, args.mesh)
    with geostore.read_mesh(args.store, args.mesh) as g:
        v, f = g["vertices"][:].astype(np.float64), g["faces"][:].astype(np.int64)
    rng = np.random.default_rng(0)
    i, j = rng.integers(0, len(v), 1_000_000), rng.integers(0, len(v), 1_000_000)
    heat = timed(lambda: heat_pairs(v, f, i, j), repeat=1)[0]
    print(f"heat method, 1M pairs on {args.mesh} ({len(v):,} vertices): {heat:.2f} s", flush=True)
    lines = ["| model | K | landmarks a round | validation MRE | embed (s) | 1M queries (s) | embed + 1M | vs heat method |",
             "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for spec in args.models:
        name, model = load_model(spec)
        for batch in args.fps_batch:
            landmarks.FPS_BATCH = batch
            rows = evaluate_store(model, args.store)
            mre = float(np.mean([r["mre"] for r in rows]))
            embed, emb = timed(lambda: model.embed(v, f))
            query = timed(lambda: emb.distance(i, j))[0]
            lines.append(f"| {name} | {model.config.landmarks} | {batch} | {100 * mre:.3f}% | {embed:.3f} | "
                         f"{query:.3f} | {embed + query:.3f} | {heat / (embed + query):.1f}x |")
            print(lines[-1], flush=True)
            if args.record and "=" in spec:
                from results import record

                record(f"mre.{name}", f"{100 * mre:.2f}%")
    print("\n" + "\n".join(lines))
    if args.out:
        Path(args.out).write_text(f"CPU: {cpu_description()}; heat method for the 1M pairs: {heat:.2f} s.\n\n"
                                  + "\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
