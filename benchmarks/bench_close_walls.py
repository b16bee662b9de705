"""Point clouds whose two sides come close: the error as a function of the wall distance / the point spacing,
against exact geodesics on the surface the points were taken from.

    python benchmarks/bench_close_walls.py [--shapes slab bowl fold zfold] [--ratios 0.25 0.5 1 2 4]
        [--points 5000] [--sources 16] [--noise 0.005] [--store data/val.zarr --meshes lion teapot ...]
        [--csv out.csv] [--write]

Shapes (:mod:`geodata.walls`): a slab (a disc with a thickness), a bowl (a hemispherical shell with a
rounded lip), a sheet folded in two (a hairpin, open) and one folded twice (three layers); the sides
``ratio`` spacings apart, about ``--points`` points in all (the mesh's vertices, each moved along the surface
by up to a quarter spacing from a regular pattern). Each shape is a cloud four ways: ``clean`` or ``noisy``
(Gaussian noise of ``--noise`` of the longest bounding-box side on every coordinate: 0.28 spacings at 5,000
points), without normals or with the surface's own (as a scan's: ``embed(P, normals=N)``). The truth is the
exact polyhedral geodesic on the generating mesh (``geodata._exact_geodesic.Surface``, boundaries
included) between the original vertices, ``--sources`` random sources x every point; noise moves the points,
not the answer. MRE: |d - exact| / (exact + 1e-3), the shapes about 2 units across.

Columns: ``heat`` potpourri3d's point-cloud heat method (it takes no normals); ``fields`` the shipped model's
own landmark fields (virtual sources on the cloud's local triangles, ``gegnn.fields.pointcloud``) from the
same sources, alone; ``model``: ``GeGnn.pretrained(--model)``'s answers (its embed as a user calls it);
``apart``: the share of pairs on two parts of the cloud's neighbour graph, which get no answer (NaN from
``gegnn query``; the MRE columns are over the pairs answered); ``flagged``: the share of points the
embedding marks ambiguous (``Embedding.ambiguous``, where the model has
one) and ``model ok`` its MRE over the pairs of unflagged points.

``--store`` adds the validation store's meshes named by ``--meshes`` (id prefixes, "" for all; their stored
exact pairs, ``--pairs`` of them), their vertices as clouds, clean and noisy, without and with the mesh's
vertex normals. One torch thread. ``--write`` (with the default shapes and ratios) writes the summary table
of docs/pointclouds.md and its figures into docs/results.json (``walls.*``).
"""
from __future__ import annotations

import argparse
import csv
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import torch  # noqa: E402

from machine import cpu_description  # noqa: E402  (benchmarks/ is on sys.path when a script there runs)
from gegnn import GeGnn  # noqa: E402
from geodata.walls import WALLS, wall_mesh  # noqa: E402
from results import record, write_table  # noqa: E402

EPS = 1e-3
WARN_SHARE = 0.005  # gegnn query's warning: from this share of the points flagged (gegnn.cli.inputs)


def mre(pred, exact) -> float:
    """Over the pairs answered (a finite ``pred``: pairs across the cloud's parts have none)."""
    ok = np.isfinite(pred)
    return float(np.mean(np.abs(pred[ok] - exact[ok]) / (exact[ok] + EPS))) if ok.any() else float("nan")


def spacing_for(name: str, ratio: float, points: int) -> float:
    """The spacing that gives the shape about ``points`` vertices (one calibration build)."""
    h0 = 0.05
    n0 = len(wall_mesh(name, ratio * h0, h0)[0])
    return h0 * np.sqrt(n0 / points)


def heat_fields(points: np.ndarray, sources: np.ndarray) -> np.ndarray:
    import potpourri3d as pp3d

    solver = pp3d.PointCloudHeatSolver(points)
    return np.stack([solver.compute_distance(int(s)) for s in sources])


def model_fields(model, points: np.ndarray, sources: np.ndarray, normals) -> np.ndarray:
    """The model's own landmark fields from ``sources`` (S, N), as its embed computes them (projection,
    graph, surface neighbours, local triangles, its solver), in the points' units; inf across parts."""
    from gegnn.fields.cache import FieldSpec
    from gegnn.fields.pointcloud import CLOUD_T_COEF, _cloud_field, cloud_graph
    from gegnn.model import normalization

    center, scale = normalization(points)
    g = cloud_graph((points - center) / scale, model.config.points, normals)
    solver = FieldSpec.of(model.config).solver
    out = np.full((len(sources), len(points)), np.inf)
    for part in np.unique(g.part[sources]):
        idx = np.flatnonzero(g.part == part)
        local = np.searchsorted(idx, sources[g.part[sources] == part])
        fields = _cloud_field(g.points[idx], CLOUD_T_COEF, None if normals is None else normals[idx], solver)[1]()
        out[np.ix_(np.flatnonzero(g.part[sources] == part), idx)] = fields(local).T * scale
    return out


def model_answers(model, points, sources, normals):
    """The model's distances (S, N) from ``sources``, its ambiguous flags (N,) (all False where it has none),
    the share of the points it sees on close walls, and the embed's seconds."""
    t = time.perf_counter()
    emb = model.embed(points, normals=normals)
    seconds = time.perf_counter() - t
    d = np.stack([emb.field(int(s)) for s in sources])
    d[emb.part[sources][:, None] != emb.part[None, :]] = np.inf  # across parts: no answer (gegnn query: NaN)
    flags = getattr(emb, "ambiguous", None)
    flags = np.zeros(len(points), bool) if flags is None else np.asarray(flags, bool)
    return d, flags, float(np.mean(emb.walls)), seconds


def evaluate(model, points, normals, sources, truth, with_heat: bool) -> dict:
    """One cloud's row: each method's MRE over sources x other points."""
    mask = np.ones_like(truth, dtype=bool)
    mask[np.arange(len(sources)), sources] = False
    row = {}
    if with_heat:
        row["heat"] = mre(heat_fields(points, sources)[mask], truth[mask])
    row["fields"] = mre(model_fields(model, points, sources, normals)[mask], truth[mask])
    pred, flags, walls, seconds = model_answers(model, points, sources, normals)
    row["model"] = mre(pred[mask], truth[mask])
    row["apart"] = float(np.mean(~np.isfinite(pred[mask])))
    ok = mask & ~flags[None, :] & ~flags[sources][:, None]
    row["flagged"] = float(flags.mean())
    row["walls"] = walls
    row["model_ok"] = mre(pred[ok], truth[ok]) if ok.any() else float("nan")
    row["embed_s"] = seconds
    return row


def shape_rows(model, args):
    from geodata._exact_geodesic import Surface

    for name in args.shapes:
        for ratio in args.ratios:
            h = spacing_for(name, ratio, args.points)
            v, f, normals = wall_mesh(name, ratio * h, h, seed=args.seed)
            rng = np.random.default_rng([args.seed, len(v)])
            sources = np.sort(rng.choice(len(v), args.sources, replace=False))
            truth = Surface(np.ascontiguousarray(v), f.astype(np.int32)).distances(sources)
            for noisy in (False, True):
                points = v + (rng.normal(scale=args.noise * np.ptp(v, axis=0).max(), size=v.shape) if noisy else 0)
                heat = None
                for given in (False, True):
                    row = evaluate(model, points, normals if given else None, sources, truth, with_heat=not given)
                    heat = row.get("heat", heat)
                    row["heat"] = heat
                    yield dict(cloud=name, ratio=ratio, noisy=noisy, normals=given, points=len(v), **row)


def store_rows(model, args):
    from gegnn.training.data import GeodesicStore

    store = GeodesicStore(args.store)
    stems = [mesh_id.rsplit("-", 1)[0] for mesh_id in store.mesh_ids]
    for mesh_id, stem in zip(store.mesh_ids, stems):
        if not any(mesh_id.startswith(m) for m in args.meshes):
            continue
        name = stem if stems.count(stem) == 1 else mesh_id[:len(stem) + 5]  # dragon-4af5, dragon-fd96
        g = store.geometry(mesh_id)
        pairs, exact = store.pairs(mesh_id)
        pick = np.random.default_rng(0).permutation(len(pairs))[:args.pairs]
        pairs, exact = pairs[pick].astype(np.int64), exact[pick]
        keep = pairs[:, 0] != pairs[:, 1]
        pairs, exact = pairs[keep], exact[keep]
        vertices = np.asarray(g.vertices, dtype=np.float64)
        noise = np.random.default_rng([args.seed, len(vertices)]).normal(
            scale=args.noise * np.ptp(vertices, axis=0).max(), size=vertices.shape)
        for noisy, given in ((False, False), (False, True), (True, False), (True, True)):
            points = vertices + noise if noisy else vertices
            emb = model.embed(points, normals=np.asarray(g.normals, dtype=np.float64) if given else None)
            d = emb.distance(pairs[:, 0], pairs[:, 1])
            flags = getattr(emb, "ambiguous", None)
            flags = np.zeros(len(points), bool) if flags is None else np.asarray(flags, bool)
            ok = ~flags[pairs].any(axis=1)
            d[emb.part[pairs[:, 0]] != emb.part[pairs[:, 1]]] = np.inf
            yield dict(cloud=name, ratio=None, noisy=noisy, normals=given,
                       points=len(points), heat=float("nan"), fields=float("nan"), model=mre(d, exact),
                       apart=float(np.mean(~np.isfinite(d))),
                       flagged=float(flags.mean()), walls=float(np.mean(emb.walls)),
                       model_ok=mre(d[ok], exact[ok]) if ok.any() else float("nan"), embed_s=float("nan"))


def pct(x) -> str:
    return "-" if x is None or x != x else f"{100 * x:.2f}%"


def share(x: float) -> str:
    """A percentage as the page states it: two decimals under 1%, one under 10%, none above."""
    x = 100 * x
    return f"{x:.2f}" if x < 1 else f"{x:.1f}" if x < 10 else f"{x:.0f}"


def span(values) -> str:
    """The range of ``values`` as the page states it, ``lo-hi%`` (one figure where they round alike)."""
    lo, hi = share(min(values)), share(max(values))
    return f"{lo}%" if lo == hi else f"{lo}-{hi}%"


PARTED = ("slab", "bowl", "fold")  # the shapes whose two sides face away: the normals part them


def lead_table(rows: list[dict], ratios) -> list[str]:
    """docs/pointclouds.md's summary: by walls / spacing, the heat method's mean over all shapes (clean), and
    over the slab, bowl and fold the model's range without normals, the share flagged, with normals, and
    noisy with normals; the sheet folded twice with normals."""
    lines = ["| walls / spacing | heat method | points-v3, no normals | flagged | points-v3, normals "
             "| folded twice, normals | noisy, normals |", "|---:|---:|---:|---:|---:|---:|---:|"]
    for ratio in ratios:
        def pick(shapes, noisy, given):
            return [r for r in rows if r["ratio"] == ratio and r["cloud"] in shapes and r["noisy"] == noisy
                    and r["normals"] == given]
        plain, given = pick(PARTED, False, False), pick(PARTED, False, True)
        lines.append(f"| {ratio:g} | {share(np.mean([r['heat'] for r in pick(WALLS, False, False)]))}% | "
                     f"{span([r['model'] for r in plain])} | {span([r['flagged'] for r in plain])} | "
                     f"{span([r['model'] for r in given])} | "
                     f"{span([r['model'] for r in pick(('zfold',), False, True)])} | "
                     f"{span([r['model'] for r in pick(PARTED, True, True)])} |")
    return lines


def write_results(rows: list[dict], ratios) -> None:
    """The summary table into docs/pointclouds.md and its headline figures into docs/results.json."""
    write_table("docs/pointclouds.md", lead_table(rows, ratios))
    shapes = [r for r in rows if r["ratio"] is not None and r["cloud"] in PARTED and not r["noisy"]]
    source = "docs/pointclouds.md#geodesics-on-point-clouds"
    record("walls.normals", span([r["model"] for r in shapes if r["normals"]]),
           "GeGnn.pretrained(\"points\") with the surface's normals on a slab, a bowl and a sheet folded in two, "
           f"{min(ratios):g}-{max(ratios):g} spacings thick, ~5,000 clean points: the range of the MRE", source)
    thin = [r for r in shapes if not r["normals"] and r["ratio"] <= 1]
    record("walls.no-normals", span([r["model"] for r in thin]),
           "the same without normals, the walls 1 spacing thick or less: the range of the MRE", source)
    record("walls.flagged", span([r["flagged"] for r in thin]),
           "the same clouds: the share of their points flagged ambiguous", source)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--model", default="points", help="a pretrained name or a point-cloud checkpoint")
    ap.add_argument("--shapes", nargs="*", default=list(WALLS), choices=list(WALLS))
    ap.add_argument("--ratios", nargs="+", type=float, default=[0.25, 0.5, 1.0, 2.0, 4.0])
    ap.add_argument("--points", type=int, default=5000)
    ap.add_argument("--sources", type=int, default=16)
    ap.add_argument("--noise", type=float, default=0.005, help="of the longest bounding-box side")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--store", help="a validation store: its --meshes as clouds too")
    ap.add_argument("--meshes", nargs="+", default=["lion", "teapot", "penguin", "dragon-fd96"])
    ap.add_argument("--pairs", type=int, default=20000)
    ap.add_argument("--csv")
    ap.add_argument("--write", action="store_true", help="write docs/pointclouds.md's summary table and its "
                                                         "figures in docs/results.json")
    args = ap.parse_args()
    torch.set_num_threads(1)
    model = GeGnn.from_checkpoint(args.model) if args.model.endswith(".safetensors") else GeGnn.pretrained(args.model)
    rows = []
    for row in [*shape_rows(model, args), *(store_rows(model, args) if args.store else [])]:
        rows.append(row)
        print(" ".join(f"{k}={v:.4f}" if isinstance(v, float) else f"{k}={v}" for k, v in row.items()), flush=True)
    print(f"\n{cpu_description()}, one torch thread; model {args.model}\n")
    print("MRE over the pairs answered; apart: pairs on two parts of the cloud's graph (no answer)\n")
    print("| cloud | walls / spacing | noise | heat | fields | model | fields, normals | model, normals "
          "| apart, normals | flagged (no normals) | model on unflagged |\n"
          "|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for key in dict.fromkeys((r["cloud"], r["ratio"], r["noisy"]) for r in rows):
        plain, given = ([r for r in rows if (r["cloud"], r["ratio"], r["noisy"]) == key and r["normals"] == n]
                        or [None] for n in (False, True))
        plain, given = plain[0], given[0]
        print(f"| {key[0]} | {'-' if key[1] is None else f'{key[1]:g}'} | {'yes' if key[2] else 'no'} | "
              f"{pct(plain['heat'])} | {pct(plain['fields'])} | {pct(plain['model'])} | {pct(given['fields'])} | "
              f"{pct(given['model'])} | {pct(given['apart'])} | {pct(plain['flagged'])} | {pct(plain['model_ok'])} |")
    shapes = [r for r in rows if r["ratio"] is not None]
    if shapes:
        print(f"\nby walls / spacing, over the shapes ({', '.join(args.shapes)}): the mean, and the worst of the "
              f"clouds without a warning (under {100 * WARN_SHARE:g}% of the points flagged, as gegnn query has it)\n\n"
              "| walls / spacing | noise | heat | model | flagged | worst unwarned | model, normals | worst, normals |"
              "\n|---:|---|---:|---:|---:|---:|---:|---:|")
        for ratio in args.ratios:
            for noisy in (False, True):
                sel = [r for r in shapes if r["ratio"] == ratio and r["noisy"] == noisy]
                plain, given = ([r for r in sel if r["normals"] == n] for n in (False, True))
                unwarned = [r["model"] for r in plain if r["flagged"] < WARN_SHARE]
                print(f"| {ratio:g} | {'yes' if noisy else 'no'} | {pct(np.mean([r['heat'] for r in plain]))} | "
                      f"{pct(np.mean([r['model'] for r in plain]))} | {pct(np.mean([r['flagged'] for r in plain]))} | "
                      f"{pct(max(unwarned)) if unwarned else 'none'} | {pct(np.mean([r['model'] for r in given]))} | "
                      f"{pct(max(r['model'] for r in given))} |")
    if args.write:
        write_results(rows, args.ratios)
    if args.csv:
        with open(args.csv, "w", newline="") as out:
            w = csv.DictWriter(out, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)


if __name__ == "__main__":
    main()
