"""The shipped default reading its own landmark fields, the real paths' (``embed(V, F, fields="paths")``) and the
exact solver's (``fields="exact"``): mean relative error of 10 fields to every vertex against exact, its worst
vertex, and the embed's time, one torch thread.

    python benchmarks/bench_exact_fields.py [SHAPE ...] [--write] [--tolerance T]  # geodata.zoo shapes (default: eight)
    python benchmarks/bench_exact_fields.py --store data/val.zarr [--write]  # a store's meshes and stored pairs

With --store, the error is the validation MRE over each mesh's stored pairs (as training reports it), a mean row
last. --write puts the table into docs/queries.md (benchmarks/results.py's write_table); --tolerance T: the paths
fields' window pruning at T instead of gegnn.fields.landmarks.PATHS_TOLERANCE (the ablation).
"""
import sys
import time

import numpy as np
import torch

from gegnn import GeGnn
from geodata._exact_geodesic import Surface
from gegnn.fields import landmarks
from geodata.zoo import zoo_mesh


def main(shapes, write: bool):
    torch.set_num_threads(1)
    model = GeGnn.pretrained()
    lines = ["| shape | vertices | its own fields: mean, worst, embed | paths fields: mean, worst, embed "
             "| exact fields: mean, worst, embed |", "|---|---:|---:|---:|---:|"]
    print("\n".join(lines))
    for name in shapes:
        v, f = zoo_mesh(name)
        sources = np.linspace(0, len(v) - 1, 10).astype(np.int64)
        truth = Surface(v.astype(np.float64), f.astype(np.int32)).distances(sources)
        keep = truth > 1e-9
        cells = []
        for fields in (None, "paths", "exact"):
            start = time.perf_counter()
            emb = model.embed(v, f, fields=fields)
            seconds = time.perf_counter() - start
            d = np.stack([emb.field(int(s)) for s in sources])
            error = np.abs(d - truth)[keep] / truth[keep]
            cells.append(f"{100 * error.mean():.3f}%, {100 * error.max():.1f}%, {seconds:.2f} s")
        lines.append(f"| {name} | {len(v):,} | {' | '.join(cells)} |")
        print(lines[-1])
    if write:
        from results import write_table  # benchmarks/ is on sys.path when this script runs

        write_table("docs/queries.md", lines)


def main_store(store: str, write: bool):
    from geodata import store as geostore
    from gegnn.metrics import METRIC_EPS

    torch.set_num_threads(1)
    model = GeGnn.pretrained()
    lines = ["| mesh | vertices | its own fields: MRE, embed | paths fields: MRE, embed | exact fields: MRE, embed |",
             "|---|---:|---:|---:|---:|"]
    print("\n".join(lines))
    rows = []
    for mesh_id in sorted(geostore.list_meshes(store)):
        with geostore.read_mesh(store, mesh_id) as g:
            v, f = g["vertices"][:].astype(np.float64), g["faces"][:].astype(np.int64)
            pairs, truth = g["geodesic/pairs"][:], g["geodesic/distances"][:].astype(np.float64)
        row = []
        for fields in (None, "paths", "exact"):
            start = time.perf_counter()
            emb = model.embed(v, f, fields=fields)
            seconds = time.perf_counter() - start
            d = emb.distance(pairs[:, 0], pairs[:, 1])
            row.append((float(np.mean(np.abs(d - truth) / (truth + METRIC_EPS))), seconds))
        rows.append(row)
        cells = " | ".join(f"{100 * e:.3f}%, {t:.2f} s" for e, t in row)
        stem, digest = mesh_id.rsplit("-", 1)
        lines.append(f"| {stem}-{digest[:8]} | {len(v):,} | {cells} |")  # the id as the docs name meshes
        print(lines[-1], flush=True)
    mean = np.mean(rows, axis=0)
    lines.append(f"| mean of {len(rows)} | | " + " | ".join(f"**{100 * e:.3f}%**, {t:.2f} s" for e, t in mean) + " |")
    print(lines[-1])
    if write:
        from results import write_table

        write_table("docs/queries.md", lines)


if __name__ == "__main__":
    if "--store" in sys.argv:
        main_store(sys.argv[sys.argv.index("--store") + 1], "--write" in sys.argv)
        sys.exit()
    args = [a for a in sys.argv[1:] if a != "--write"]
    if "--tolerance" in args:
        if "--write" in sys.argv:
            sys.exit("--tolerance is an ablation: it writes no table")
        at = args.index("--tolerance")
        landmarks.PATHS_TOLERANCE = float(args[at + 1])
        del args[at:at + 2]
    main(args or ["torus-r0.3", "u-bend", "coil", "trefoil", "genus-3-plate", "t-pipe", "slivers", "noisy"],
         "--write" in sys.argv)
