"""The paper's applications measured on the validation meshes (docs/applications.md).

    python benchmarks/bench_applications.py data/val.zarr [--only paths logmap triangle finetune d2]
        [--meshes 19] [--finetune-meshes 5] [--out /tmp] [--triangle-md runs/triangle.md]

- paths: predicted path length / potpourri3d's exact edge-flip path length, and / the exact distance,
  over 8 random pairs per mesh (shipped landmark model);
- logmap: mean |log map - vector-heat log map| / radius (radius 0.3 in normalized units, 4 centers per
  mesh), from the model's distances and from exact distances (the method's own error);
- triangle: fraction of violating triples among 64 random vertices per mesh (all 64^3 triples) for
  both shipped models and the heat method (potpourri3d, d(a, b) read from a's field);
- finetune: held-out MRE before and after `finetune` with the command's defaults, and CPU seconds;
- d2: shape distributions of each validation mesh and a copy bent by 180 degrees (geodata augment's
  bend), predicted geodesic against Euclidean; the camel pair is written to --out as OBJ;
- biharmonic: exact | predicted | error from one source on three meshes, with the shipped biharmonic
  model (or --biharmonic CKPT).
One torch thread (the development CPU has 2 cores). The pictures of docs/applications.md come from
the commands written there.
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import torch

from geodata.geodesic import edge_flip_paths, polyline_length
from geodata.mesh import Mesh
from gegnn import GeGnn
from gegnn.training.data import GeodesicStore
from gegnn.finetune import finetune
from gegnn.queries.logmap import log_map, stencil, vector_heat_log_map
from gegnn.fields.exact import exact_fields
from gegnn.queries.statistics import geodesic_and_euclidean_d2, histogram_l1, triangle_violations
from machine import cpu_description  # benchmarks/ is on sys.path when a script there runs

NORMALIZED_RADIUS = 0.3


def meshes(store, n):
    """(mesh id, vertices float64, faces) of the first ``n`` committed meshes of ``store``, by id."""
    view = GeodesicStore(store)
    for mesh_id in view.mesh_ids[:n]:
        g = view.geometry(mesh_id)
        yield mesh_id, g.vertices.astype(np.float64), g.faces


def bench_paths(store, n, out):
    model = GeGnn.pretrained()
    ratios, errors = [], []
    for k, (mesh_id, v, f) in enumerate(meshes(store, n)):
        emb = model.embed(v, f)
        rng = np.random.default_rng(k)
        pairs = rng.choice(len(v), (8, 2), replace=False)
        exact = exact_fields(Mesh(v, f), pairs[:, 0])
        for (s, t), d, flip in zip(pairs, exact, edge_flip_paths(Mesh(v, f), pairs)):
            path = emb.path(int(s), int(t))
            ratios.append(path.length / polyline_length(flip))
            errors.append(abs(path.length - d[t]) / d[t])
        print(f"paths {mesh_id}: length / edge-flip {np.mean(ratios[-8:]):.4f}", flush=True)
    ratios = np.array(ratios)
    print(f"paths: {len(ratios)} paths, predicted length / edge-flip length mean {ratios.mean():.4f} "
          f"(|ratio - 1| mean {np.abs(ratios - 1).mean():.4f}, max {np.abs(ratios - 1).max():.4f}); "
          f"|length - exact distance| / exact mean {np.mean(errors):.4f}")


def bench_logmap(store, n, out):
    model = GeGnn.pretrained()
    learned, exact_diffs = [], []
    for k, (mesh_id, v, f) in enumerate(meshes(store, n)):
        emb = model.embed(v, f)
        for c in np.random.default_rng(k).choice(len(v), 4, replace=False):
            lm = emb.log_map(int(c), NORMALIZED_RADIUS)
            learned.append(vector_heat_log_map(v, f, lm)[1])
            ring = np.append(stencil(emb.topology, int(c), 2), c)  # the exact fields the log map asks for
            fields = dict(zip(ring.tolist(), exact_fields(Mesh(v, f), ring)))
            exact_lm = log_map(emb.topology, lambda i, j: np.array([fields[a][b] for a, b in
                                                                      zip(np.ravel(i), np.ravel(j))]).reshape(np.shape(i)),
                               int(c), NORMALIZED_RADIUS)
            exact_diffs.append(vector_heat_log_map(v, f, exact_lm)[1])
        print(f"logmap {mesh_id}: model {np.mean(learned[-4:]):.4f} exact {np.mean(exact_diffs[-4:]):.4f}", flush=True)
    print(f"logmap: {len(learned)} centers, mean |ours - vector heat| / radius: model distances "
          f"{np.mean(learned):.4f} (median {np.median(learned):.4f}), exact distances {np.mean(exact_diffs):.4f} "
          f"(median {np.median(exact_diffs):.4f})")


def bench_triangle(store, n, out, markdown=None):
    import potpourri3d as pp

    models = {name: GeGnn.pretrained(name) for name in ("landmark", "paper")}
    rows = {name: [] for name in (*models, "heat method")}
    for k, (mesh_id, v, f) in enumerate(meshes(store, n)):
        pool = np.zeros(len(v), dtype=bool)
        pool[np.random.default_rng(k).choice(len(v), 64, replace=False)] = True
        for name, model in models.items():
            rows[name].append(triangle_violations(model.embed(v, f).distance, len(v), 400_000, k, pool))
        solver = pp.MeshHeatMethodDistanceSolver(v, f)
        ids = np.flatnonzero(pool)
        row = np.full(len(v), -1)
        row[ids] = np.arange(len(ids))
        heat = np.stack([solver.compute_distance(int(s)) for s in ids])  # d(a, b) = heat[row[a], b]
        rows["heat method"].append(triangle_violations(lambda i, j: heat[row[i], j], len(v), 400_000, k, pool))
        print(f"triangle {mesh_id}: " + ", ".join(f"{m} {100 * r[-1].fraction:.2f}%" for m, r in rows.items()),
              flush=True)
    table = ["| distance | violating triples (mean over meshes) | mean excess of those | max excess |",
             "|---|---:|---:|---:|"]
    for name, reports in rows.items():
        table.append(f"| {name} | {100 * np.mean([r.fraction for r in reports]):.2f}% | "
                     f"{100 * np.mean([r.mean_excess for r in reports if r.fraction]):.2f}% | "
                     f"{100 * max(r.max_excess for r in reports):.1f}% |")
    print("triangle inequality, random triples of 64 vertices per mesh:\n" + "\n".join(table))
    if markdown:
        Path(markdown).write_text("\n".join(table) + "\n")


def bench_finetune(store, n, out, names=("paper", "landmark")):
    for name in names:
        rows = []
        for mesh_id, v, f in meshes(store, n):
            model = GeGnn.pretrained(name)
            t0 = time.process_time()
            r = finetune(model, v, f)
            cpu = time.process_time() - t0
            rows.append((r.mre_before, r.mre_after, cpu))
            print(f"finetune {name} {mesh_id}: {100 * r.mre_before:.2f}% -> {100 * r.mre_after:.2f}%, "
                  f"{cpu:.0f} CPU s (exact {r.exact_seconds:.1f} s wall)", flush=True)
        b, a, c = np.array(rows).T
        print(f"finetune {name}: held-out MRE {100 * b.mean():.2f}% -> {100 * a.mean():.2f}% "
              f"(ratio {np.mean(a / b):.2f}), {c.mean():.0f} CPU s per mesh")


def bench_d2(store, n, out, angle=np.pi):
    """D2 of every mesh and of its copy bent by ``angle`` (geodata augment's bend in the plane of the
    longest and middle principal axes: the thinnest axis is the one stretched by (R - y) / R, so the
    bend is as close to an isometry as a solid allows)."""
    from geodata.augment import bend

    model = GeGnn.pretrained()
    rows = []
    for mesh_id, v, f in meshes(store, n):
        frame = np.linalg.eigh(np.cov(v.T))[1][:, [2, 0, 1]]  # longest, thinnest, middle
        bent = bend(v, frame, angle)
        hists = [geodesic_and_euclidean_d2(model.embed(verts, f).distance, verts, f, 1_000_000)
                 for verts in (v, bent)]
        rows.append((histogram_l1(hists[0][0], hists[1][0]), histogram_l1(hists[0][1], hists[1][1])))
        print(f"d2 {mesh_id} vs bent by {np.degrees(angle):.0f} degrees: L1 geodesic {rows[-1][0]:.3f}, "
              f"Euclidean {rows[-1][1]:.3f}", flush=True)
        if mesh_id.startswith("camel-"):
            import trimesh
            for name, verts in (("camel.obj", v), ("camel-bent.obj", bent)):
                trimesh.Trimesh(verts, f, process=False).export(Path(out) / name)
    geo, euc = np.array(rows).T
    print(f"d2: {len(rows)} meshes, L1 to the bent copy: geodesic mean {geo.mean():.3f} (median "
          f"{np.median(geo):.3f}), Euclidean mean {euc.mean():.3f} (median {np.median(euc):.3f}); geodesic "
          f"closer on {(geo < euc).sum()} of {len(rows)}")


def bench_biharmonic(store, n, out, checkpoint=None, picture=None):
    """Exact | predicted | relative error of the biharmonic distance from one source on three meshes."""
    from geodata.biharmonic import biharmonic_distances
    from gegnn.pictures.render import Panel, Row, save_panels

    model = GeGnn.from_checkpoint(checkpoint) if checkpoint else GeGnn.pretrained("biharmonic")
    rows = []
    for mesh_id, v, f in meshes(store, 100):
        if not mesh_id.startswith(("cow-8834713b", "hand_closed", "dragon-4af53808")):
            continue
        exact = biharmonic_distances(Mesh(v, f), np.array([0]))[0]
        pred = model.embed(v, f).field(0)
        err = np.abs(pred - exact) / (exact + 1e-3)
        err[0] = 0
        top = float(exact.max())
        print(f"biharmonic {mesh_id}: MRE from vertex 0 {100 * err[1:].mean():.2f}%")
        rows.append(Row(v, f, 0, [Panel(exact, "exact biharmonic", vmin=0, vmax=top),
                                  Panel(pred, "predicted", vmin=0, vmax=top),
                                  Panel(err, "relative error", "magma", "|pred - exact| / exact", 0, 0.02,
                                        isolines=0)]))
    if picture:
        save_panels(picture, rows, suptitle="biharmonic GeGnn")


BENCHES = {"paths": bench_paths, "logmap": bench_logmap, "triangle": bench_triangle, "finetune": bench_finetune,
           "d2": bench_d2, "biharmonic": bench_biharmonic}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("store")
    ap.add_argument("--only", nargs="+", choices=list(BENCHES), default=list(BENCHES))
    ap.add_argument("--meshes", type=int, default=19)
    ap.add_argument("--finetune-meshes", type=int, default=5)
    ap.add_argument("--out", default="/tmp", help="where the D2 meshes (camel and bent camel OBJ) go")
    ap.add_argument("--triangle-md", help="also write the triangle-inequality table here (markdown), for "
                                          "bench_results.py --triangle")
    ap.add_argument("--biharmonic", help="checkpoint of a biharmonic model (default: the shipped one)")
    ap.add_argument("--biharmonic-png", help="its exact | predicted | error picture")
    args = ap.parse_args()
    print(f"CPU: {cpu_description()}", flush=True)
    torch.set_num_threads(1)
    for name in args.only:
        t0 = time.perf_counter()
        extra = {"triangle": {"markdown": args.triangle_md},
                 "biharmonic": {"checkpoint": args.biharmonic, "picture": args.biharmonic_png}}.get(name, {})
        BENCHES[name](args.store, args.finetune_meshes if name == "finetune" else args.meshes, args.out, **extra)
        print(f"[{name}: {time.perf_counter() - t0:.0f} s]", flush=True)


if __name__ == "__main__":
    main()
