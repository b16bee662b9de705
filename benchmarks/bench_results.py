"""Accuracy report of the landmark-guided and the paper GeGnn on a validation store: writes
docs/results.md and its pictures.

    python benchmarks/bench_results.py data/val.zarr [--checkpoint CKPT] [--out docs]

For every mesh of the store, over all its stored pairs (sources x every vertex), the mean relative
error |d - d*| / (d* + 1e-3) (the training metric, normalized units) of:
  - GeGnn (the shipped default, landmark-guided, unless --checkpoint),
  - the shipped paper model (`GeGnn.pretrained("paper")`),
  - the landmark lower bound max_k |d_ik - d_jk| alone (the same K fields the model reads),
  - the heat method (potpourri3d, t = mean edge length squared, one factorization per mesh),
  - plain Euclidean distance,
  - both models and the heat method on a damaged copy: 15% of the triangles removed at random and
    Gaussian noise (sigma = 0.1 x mean edge length) on every vertex, against the clean mesh's exact
    distances.
Timings (CPU, this machine; GPU too when one is visible): precomputation (landmark fields, one forward
pass) and 1M queries on the largest mesh, against the heat method for the same pairs, measured in the
same run.
"""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np
import torch

from gegnn import Embedding, GeGnn
from gegnn.training.data import GeodesicStore
from gegnn.fields.landmarks import landmark_fields
from gegnn.pictures.render import Panel, Row, save_panels
from gegnn.metrics import METRIC_EPS
from geodata.mesh import unique_edges

import bench_gegnn  # benchmarks/ is on sys.path when a script there runs
from machine import cpu_description
from stores import mesh_id as find_mesh


LANDMARKS = 64  # K of the bound-alone column when the model has no landmarks


def mre(pred, exact) -> float:
    return float(np.mean(np.abs(pred - exact) / (exact + METRIC_EPS)))


def heat_fields(v, f, sources):
    import potpourri3d as pp3d

    solver = pp3d.MeshHeatMethodDistanceSolver(v, f)
    return {int(s): solver.compute_distance(int(s)) for s in sources}


def damage(v, f, rng, drop=0.15, noise=0.1):
    """Remove `drop` of the triangles at random, jitter every vertex by N(0, (noise x mean edge)^2)."""
    edges = unique_edges(f)
    sigma = noise * np.linalg.norm(v[edges[:, 0]] - v[edges[:, 1]], axis=1).mean()
    keep = rng.random(len(f)) >= drop
    return v + rng.normal(scale=sigma, size=v.shape), f[keep]


def compact(v, f):
    """Drop unused vertices; returns the mesh and old -> new indices (-1 where dropped)."""
    used = np.unique(f)
    remap = np.full(len(v), -1)
    remap[used] = np.arange(len(used))
    return v[used], remap[f], remap


def evaluate_mesh(model, paper, store, mesh_id, rng):
    g = store.geometry(mesh_id)
    faces = g.faces
    v = g.vertices.astype(np.float64)
    pairs, exact = store.pairs(mesh_id)
    exact = exact.astype(np.float64)
    i, j = pairs[:, 0], pairs[:, 1]
    row = dict(mesh=mesh_id, vertices=len(v), pairs=len(pairs))
    emb = model.embed(v, faces)
    row["gegnn"] = mre(emb.distance(i, j), exact)
    paper_emb = paper.embed(v, faces)
    row["paper"] = mre(paper_emb.distance(i, j), exact)
    fields = landmark_fields(v, faces, model.config.landmarks or LANDMARKS).distances
    row["bound"] = mre(np.abs(fields[i] - fields[j]).max(axis=1), exact)
    sources = np.unique(i)
    heat = heat_fields(v, faces, sources)
    row["heat"] = mre(np.concatenate([heat[s][j[i == s]] for s in sources]),
                      np.concatenate([exact[i == s] for s in sources]))
    row["euclid"] = mre(np.linalg.norm(v[i] - v[j], axis=1), exact)

    dv, df = damage(v, faces, rng)
    cv, cf, remap = compact(dv, df)
    ok = (remap[i] >= 0) & (remap[j] >= 0)
    ci, cj = remap[i[ok]], remap[j[ok]]
    row["gegnn_damaged"] = mre(model.embed(cv, cf).distance(ci, cj), exact[ok])
    row["paper_damaged"] = mre(paper.embed(cv, cf).distance(ci, cj), exact[ok])
    src = np.unique(ci)
    heat_d = heat_fields(cv, cf, src)
    row["heat_damaged"] = mre(np.concatenate([heat_d[s][cj[ci == s]] for s in src]),
                              np.concatenate([exact[ok][ci == s] for s in src]))
    s = int(i[0])  # the first stored source, for the picture grid: its exact field over all vertices
    exact_field = np.zeros(len(v))
    exact_field[j[i == s]] = exact[i == s]
    row["_picture"] = (v, faces, s, emb.field(s), paper_emb.field(s), exact_field)
    return row


def timed(fn, repeat=3) -> float:
    return bench_gegnn.timed(fn, repeat)[0]


def timings(model, paper, v, f, queries=1_000_000) -> tuple[list[tuple[str, float]], float]:
    """(what, seconds) rows, and how many times faster GeGnn answers 1M random pairs than the heat
    method, precomputation included."""
    import potpourri3d as pp3d

    rng = np.random.default_rng(0)
    qi, qj = rng.integers(0, len(v), queries), rng.integers(0, len(v), queries)
    out = []
    if model.config.landmarks:
        k = model.config.landmarks
        out.append((f"landmark fields ({k} heat-method solves, part of embed)",
                    timed(lambda: landmark_fields(v, f, k))))
    devices = ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])
    for name, net in (("GeGnn", model), ("paper GeGnn", paper)):
        for dev in devices:
            m = net.to(dev)
            for precision in ("fp32", "bf16"):
                out.append((f"{name}, {dev}: embed, {precision} network",
                            timed(lambda: m.embed(v, f, precision=precision))))
            features = m.embed(v, f).features
            for precision in ("fp32", "bf16"):
                emb = Embedding(features, m.distance, precision=precision)
                out.append((f"{name}, {dev}: 1M queries, {precision} decoder", timed(lambda: emb.distance(qi, qj))))
        net.to("cpu")
    embed, query = dict(out)["GeGnn, cpu: embed, fp32 network"], dict(out)["GeGnn, cpu: 1M queries, fp32 decoder"]
    solver_time = timed(lambda: pp3d.MeshHeatMethodDistanceSolver(v, f), repeat=1)
    solver = pp3d.MeshHeatMethodDistanceSolver(v, f)
    out.append(("heat method: factorization (once per mesh)", solver_time))
    one_field = timed(lambda: solver.compute_distance(0))
    out.append(("heat method: one source's field", one_field))
    sources = len(np.unique(qi))  # 1M random pairs need a field from every distinct first vertex
    heat = solver_time + sources * one_field
    out.append((f"heat method: 1M random pairs ({sources} fields, estimated)", heat))
    out.append(("GeGnn: 1M random pairs (fp32 embed + fp32 queries)", embed + query))
    return out, heat / (embed + query)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("store")
    ap.add_argument("--checkpoint", help="default: the model shipped in the package")
    ap.add_argument("--out", default="docs")
    ap.add_argument("--grid", default="cow-69afce54,hand_closed-cb2fb353,dragon-4af53808,teapot-1b5396fe",
                    help="meshes of the picture grid (comma-separated ids, or unique prefixes of ids)")
    ap.add_argument("--meshes", help="only these meshes (comma-separated ids, or unique prefixes of ids; "
                                     "default: all)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--ablation", help="markdown table of benchmarks/ablation_landmarks.py to include")
    ap.add_argument("--landmarks-table", help="markdown of benchmarks/ablation_k.py --out FILE to include")
    ap.add_argument("--biharmonic", help="markdown table of benchmarks/bench_biharmonic_model.py --out FILE to "
                                         "include")
    ap.add_argument("--triangle", help="markdown table of benchmarks/bench_applications.py --only triangle "
                                       "--triangle-md FILE to include")
    args = ap.parse_args()
    torch.set_num_threads(os.cpu_count() or 1)

    model = GeGnn.pretrained() if not args.checkpoint else GeGnn.from_checkpoint(args.checkpoint)
    model.eval()
    paper = GeGnn.pretrained("paper").eval()
    store = GeodesicStore(args.store)
    mesh_ids = ([find_mesh(args.store, m, store.mesh_ids) for m in args.meshes.split(",")] if args.meshes
                else store.mesh_ids)
    rows = []
    for k, mesh_id in enumerate(mesh_ids):
        rng = np.random.default_rng([args.seed, store.mesh_ids.index(mesh_id)])
        rows.append(evaluate_mesh(model, paper, store, mesh_id, rng))
        print(f"{mesh_id:40s} " + "  ".join(f"{c} {100 * rows[-1][c]:6.2f}%" for c in COLUMNS), flush=True)

    out = Path(args.out)
    (out / "img").mkdir(parents=True, exist_ok=True)
    grid_ids = [find_mesh(args.store, p, mesh_ids) for p in args.grid.split(",")
                if any(m.startswith(p) for m in mesh_ids)]  # a grid mesh not evaluated is left out
    grid_rows = []
    for mesh_id in grid_ids:
        v, f, s, pred, paper_pred, exact = next(r for r in rows if r["mesh"] == mesh_id)["_picture"]
        top = float(exact.max())
        panels = [Panel(exact, f"{mesh_id}: exact", vmin=0, vmax=top)]
        for name, field in (("GeGnn", pred), ("paper GeGnn", paper_pred)):
            err = np.abs(field - exact) / (exact + METRIC_EPS)
            err[s] = 0
            panels += [Panel(field, name, vmin=0, vmax=top),
                       Panel(err, f"{name} error (mean {100 * err.mean():.1f}%)", "magma", "relative error", 0, 0.1,
                             isolines=0)]
        grid_rows.append(Row(v, f, s, panels))
    if grid_rows:
        save_panels(out / "img" / "results-grid.png", grid_rows, size=360)
    largest = max(rows, key=lambda r: r["vertices"])
    lv, lf = largest["_picture"][:2]
    times, speedup = timings(model, paper, lv, lf)
    for name, t in times:
        print(f"{name}: {t:.4g} s")
    print(f"speed-up over the heat method for 1M random pairs: {speedup:.1f}x")
    write_report(out / "results.md", args, rows, times, speedup, largest, grid_ids)


COLUMNS = ["gegnn", "paper", "bound", "heat", "euclid", "gegnn_damaged", "paper_damaged", "heat_damaged"]
HEADERS = ["GeGnn", "paper GeGnn", "landmark bound", "heat method", "Euclidean", "GeGnn, damaged",
           "paper, damaged", "heat, damaged"]


LANDMARKS_INTRO = (
    "The landmark models at K landmark fields (`python benchmarks/ablation_k.py data/val.zarr NAME=CKPT[@K]... "
    "--out FILE`): `vN@K` runs the weights of `gegnn-landmark-vN` with K fields at embed time (the decoder's "
    "weights do not depend on K); `v2 recipe, K` is `pipelines/landmark/more_landmarks.sh data/ runs/ K`, "
    "v1's weights trained on at K (K = 128: the same training without more landmarks, the control). "
    "Validation MRE over all stored pairs, mean over meshes; embed (landmark fields + one forward pass, fp32) "
    "and 1M random queries on the largest mesh, best of 3, against the heat method for the same pairs, all "
    "in one run.")


BIHARMONIC_INTRO = (
    "`GeGnn.pretrained(\"biharmonic\")` (32 spectral modes, their Weyl-law tail and a learned correction; "
    "[model card](model-card.md#gegnn-biharmonic-v1-biharmonic-distances-biharmonic)) against the exact "
    "biharmonic distances of the same validation meshes (`geodata biharmonic data/val.zarr --pairs 200000`), "
    "all stored pairs, same metric; the pure learned model (the paper's network with a Euclidean decoder, no "
    "eigen-solve: `pipelines/biharmonic/train.sh`); the Weyl estimate alone; and the classical truncated "
    "spectral sum over the first m modes, a lower bound, with the mean time of its eigen-solve. `exact (s)`: "
    "the exact solver for the stored pairs (their ~40 sources x every vertex). Made by `python "
    "benchmarks/bench_biharmonic_model.py data/val.zarr --pure runs/bih-pure/best.safetensors --out FILE`.")


def write_report(path, args, rows, times, speedup, largest, grid_ids):
    mean = {c: float(np.mean([r[c] for r in rows])) for c in COLUMNS}
    ckpt = args.checkpoint or "the shipped default model (`GeGnn.pretrained()`, landmark-guided)"
    lines = [
        "# Results: accuracy of the pretrained GeGnn models on held-out classic meshes",
        "",
        "Produced by",
        "",
        "```",
        f"python benchmarks/bench_results.py {args.store}"
        + (f" --checkpoint {args.checkpoint}" if args.checkpoint else "")
        + (f" --ablation {args.ablation}" if args.ablation else "")
        + (f" --landmarks-table {args.landmarks_table}" if args.landmarks_table else "")
        + (f" --triangle {args.triangle}" if args.triangle else "")
        + (f" --biharmonic {args.biharmonic}" if args.biharmonic else ""),
        "```",
        "",
        f"with {ckpt} and the shipped paper model (`GeGnn.pretrained(\"paper\")`), on the validation store "
        f"made by `pipelines/pretrained/data.sh` (the {len(rows)} meshes of `pipelines/pretrained/val.txt`, "
        "never trained on, prepared by the geodata pipeline: watertight, ~5k vertices, normalized to "
        f"[-1, 1]). Every stored pair counts: {sum(r['pairs'] for r in rows):,} pairs in all. Metric: mean of "
        "|d - d*| / (d* + 1e-3), d* the exact polyhedral geodesic distance (the paper's metric). The "
        "landmark bound is max_k |d(i, l_k) - d(j, l_k)| over the same heat-method landmark fields the "
        "GeGnn reads, with no learning.",
        "",
        "Damaged: 15% of the triangles removed at random and Gaussian noise (sigma = 0.1 mean edge length) "
        "on every vertex, compared with the clean mesh's exact distances (the paper's robustness test).",
        "",
        "| mesh | vertices | " + " | ".join(HEADERS) + " |",
        "|---|---:|" + "---:|" * len(COLUMNS),
    ]
    for r in rows:
        lines.append(f"| {r['mesh']} | {r['vertices']} | " + " | ".join(f"{100 * r[c]:.2f}%" for c in COLUMNS) + " |")
    lines.append("| **mean** | | " + " | ".join(f"**{100 * mean[c]:.2f}%**" for c in COLUMNS) + " |")
    lines += [
        "",
        f"## Timings ({largest['mesh']}, {largest['vertices']} vertices)",
        "",
        f"Best of 3, {os.cpu_count()} CPU threads ({cpu_description()}); torch {torch.__version__}; Python "
        f"{sys.version.split()[0]}. The landmark model's embed includes its landmark fields.",
        "",
        "| what | seconds |",
        "|---|---:|",
    ]
    lines += [f"| {name} | {t:.4g} |" for name, t in times]
    lines += ["", f"Precomputation plus 1M random-pair queries: **{speedup:.1f}x** faster than the heat "
                  "method for the same pairs, its time estimated as one factorization plus one source's field "
                  "per distinct source (`benchmarks/bench_queries.py --only queries` times the heat method's "
                  "actual loop over the same pairs: see the README's figure)."]
    if args.ablation:
        lines += ["", "## Ablation of the landmark-guided model", "",
                  "`bash pipelines/landmark/ablation.sh data/ runs/ablation`: every variant trains the same "
                  "steps on one thread, a 3,000-step decoder warm-up where it has one, then one epoch of 91 "
                  "network steps at lr 1e-3; all stored pairs of the validation meshes, mean over meshes. "
                  "CPU min counts the warm-up.", "", Path(args.ablation).read_text().strip()]
    if args.landmarks_table:
        lines += ["", "## Landmark count K", "", LANDMARKS_INTRO, "", Path(args.landmarks_table).read_text().strip()]
    if args.triangle:
        lines += ["", "## Triangle inequality", "",
                  "A learned distance is not a metric by construction (the paper's limitations). Per mesh, 64 "
                  "random vertices and all their triples (400k samples); a triple violates the inequality when "
                  "d(p, q) > d(p, x) + d(x, q) by more than 1e-6 relative (`gegnn.queries.statistics.triangle_violations`"
                  "; `python benchmarks/bench_applications.py data/val.zarr --only triangle --triangle-md FILE`).",
                  "", Path(args.triangle).read_text().strip()]
    if args.biharmonic:
        lines += ["", "## Biharmonic distances", "", BIHARMONIC_INTRO, "", Path(args.biharmonic).read_text().strip()]
    if grid_ids:
        lines += ["", "## Predicted vs exact", "",
                  "One stored source per mesh (red dot); the error panels' scale stops at 10%.", "",
                  "![exact, landmark GeGnn, paper GeGnn and their relative errors](img/results-grid.png)"]
    Path(path).write_text("\n".join(lines) + "\n")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
