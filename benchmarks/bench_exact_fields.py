"""The shipped default reading its own landmark fields, the real paths' (``embed(V, F, fields="paths")``) and the
exact solver's (``fields="exact"``): mean relative error of 10 fields to every vertex against exact, its worst
vertex, and the embed's time, one torch thread.

    python benchmarks/bench_exact_fields.py [SHAPE ...] [--write]  # geodata.zoo shapes (default: six)

--write puts the table into docs/queries.md (benchmarks/results.py's write_table).
"""
import sys
import time

import numpy as np
import torch

from gegnn import GeGnn
from geodata._exact_geodesic import Surface
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


if __name__ == "__main__":
    args = [a for a in sys.argv[1:] if a != "--write"]
    main(args or ["torus-r0.3", "u-bend", "genus-3-plate", "t-pipe", "slivers", "noisy"], "--write" in sys.argv)
