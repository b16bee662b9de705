"""Geodesic fields by virtual source propagation (geodata.approximate_geodesic) against the exact solver
and the heat method: accuracy and time per field, on one core (issue 55, item 1).

    python benchmarks/bench_field_solver.py [--meshes max homer camel ...] [--levels 0 1] [--sources 8]
        [--sweep] [--ablation]
    python benchmarks/bench_field_solver.py --lower-bound [MESH ...]
    python benchmarks/bench_field_solver.py --cloud-lower-bound [MESH ...]
    python benchmarks/bench_field_solver.py --raw
    python benchmarks/bench_field_solver.py --zoo [--size 1]

Per mesh, a base of ~3-7k vertices and its midpoint subdivisions (``trimesh.remesh.subdivide`` keeps the
base's vertices and the surface, so the exact distances between base vertices stay the truth at every
level): mean and max relative error |d - exact| / exact over sources x base vertices (the source left
out) of the new solver and of the heat method (gegnn.fields.heat.HeatDistance, the landmark fields of
today's models), and milliseconds a field: the new solver one source a call, the heat method all
sources in one batched solve (its cheapest use; factorization not counted) and one source a solve, the
exact solver
(geodata.geodesic, vtp) one source a call; each the least CPU time of the calling thread over --repeat
calls (the machine is shared; wall time counts the others' turns too). Ratios are taken within this run.

Meshes: twelve real ones from ../shared/meshes/dev (``max``: decimated-max, ``homer``, ``camel``,
``cheburashka``, ``scorpion``, ``penguin``, with which the saddle threshold was chosen; ``horse``, ``hand``,
``cat``, ``koala``, ``arm``, ``alligator`` (open), which it was not), ``irregular``: decimated-max with a third of its faces split
at a random interior point (uneven valences, thin triangles), ``slivers``: the same with the split point
near an edge (needle triangles, angles down to ~1 degree).

--sweep: decimated-max at 5k, 20k, 80k, 320k, 1.35M vertices (2 sources; the heat method and the exact solver up to 80k).
--ablation: the solver's design choices on the real meshes (probe point, saddle gates, queue, bucket width).
--zoo: the shapes of geodata.zoo (tori, bent tubes, a coil, a trefoil, a T pipe, a saddle patch, a genus-3 plate, a
filleted part, slivers, noise), the tubes also at 2 and 4 times the vertices, and six classic meshes, 4 sources each:
the mean, signed mean and 99th percentile of the relative error against the exact solver and ms a field, of today's
solver and of 0.3.2's choices (gates only at saddle vertices of excess over 0.05 rad, no relaxation).
--raw: every mesh of ../shared/meshes (both splits) under 10k vertices that is a closed manifold as loaded
(the exact solver's condition), unremeshed: CAD parts with needle triangles, furniture; 3 sources each.
--lower-bound: issue 55's table: the triangle-inequality lower bound LB(i, j) = max_k |d(i, l_k) - d(j, l_k)|
over the first K of 256 farthest-point landmarks (chosen on the heat method's fields in rounds of 16, as
today's models do; "own landmarks": chosen on the new fields), against exact distances from 20 sources to
every vertex, with each kind of field at the same landmarks.
--cloud-lower-bound: the same bound for the point-cloud model's fields (issue 55, item 4), the mesh's vertices
taken as a cloud, 256 landmarks chosen along its neighbour graph as the points model does, each kind of field at
the same landmarks: points-v2's fields (the point-cloud heat method), virtual sources on the cloud's local
Delaunay triangles glued in pairs around each edge (points-v3's, :mod:`gegnn.fields.cloud_vsp`) or as their
tufted cover, the same solver on a manifold copy of those triangles (an edge's two faces kept that the most
points' triangulations agree on, the rest set aside by ``manifold_copy``: holes), and the mesh's exact fields
(the bound a perfect cloud field would give); and each kind's own error, its 256 fields against the exact ones.
"""
from __future__ import annotations

import argparse
import time
import warnings
from pathlib import Path

import numpy as np
import torch

from geodata._virtual_source_geodesic import VirtualSources
from geodata.geodesic import geodesic_solver
from geodata.mesh import Mesh
from geodata.zoo import split_faces
from gegnn.fields.heat import HeatDistance

from machine import cpu_description  # benchmarks/ is on sys.path when a script there runs

DEV = Path(__file__).resolve().parents[1] / ".." / "shared" / "meshes" / "dev"
CLASSIC = ["max", "homer", "camel", "penguin", "horse", "cat"]
REAL = {"max": "libigl-tutorial-data/decimated-max.obj", "homer": "common-3d-test-models/homer.obj",
        "camel": "isoblend/camel.obj", "cheburashka": "common-3d-test-models/cheburashka.obj",
        "scorpion": "odedstein-meshes/scorpion_low_resolution.obj", "penguin": "odedstein-meshes/penguin.obj",
        "horse": "isoblend/horse.obj", "hand": "odedstein-meshes/hand_closed.obj",
        "cat": "odedstein-meshes/cat-low-resolution.obj", "koala": "odedstein-meshes/koala_low_resolution.obj",
        "arm": "libigl-tutorial-data/arm.obj", "alligator": "common-3d-test-models/alligator.obj"}


def load(name: str) -> tuple[np.ndarray, np.ndarray]:
    import trimesh

    m = trimesh.load(DEV / REAL[name], process=True, force="mesh")  # merge coincident vertices
    return np.asarray(m.vertices, dtype=np.float64), np.asarray(m.faces, dtype=np.int64)


def base_mesh(name: str):
    if name in ("irregular", "slivers"):
        return split_faces(*load("max"), share=1 / 3, near_edge=name == "slivers")
    return load(name)


def subdivide(v, f, levels: int):
    import trimesh.remesh

    for _ in range(levels):
        v, f = trimesh.remesh.subdivide(v, f)
    return np.asarray(v, dtype=np.float64), np.asarray(f, dtype=np.int64)


def best_of(fn, repeat: int) -> float:
    """The least CPU time of the calling thread (where all three solvers run with one thread) over
    `repeat` calls: on a shared machine, wall time also counts the other users' turns."""
    times = []
    for _ in range(repeat):
        t = time.thread_time()
        fn()
        times.append(time.thread_time() - t)
    return min(times)


def errors(fields: np.ndarray, exact: np.ndarray, sources) -> np.ndarray:
    """Relative errors (S x base vertices, sources left out) of fields (S, >= base) against exact (S, base)."""
    n = exact.shape[1]
    with np.errstate(invalid="ignore", divide="ignore"):  # inf - inf on other parts: left out as NaN
        e = np.abs(fields[:, :n] - exact) / np.where(exact > 0, exact, np.nan)
    e[np.arange(len(sources)), sources] = np.nan
    return e[np.isfinite(e)]


def row(name, level, v, f, sources, exact, repeat, heat=True, exact_time=True) -> str:
    solver = VirtualSources(v, f)
    fields = solver.distances(np.asarray(sources, dtype=np.int64))
    ours = np.mean([best_of(lambda: solver.distances(np.array([s])), repeat) for s in sources[:4]]) * 1e3
    err = errors(fields, exact, sources)
    cells = [name, str(level), f"{len(v):,}", f"{100 * err.mean():.3f}%", f"{100 * err.max():.2f}%", f"{ours:.2f}"]
    if heat:
        h = HeatDistance(v, f)
        herr = errors(h.distances(sources).T, exact, sources)
        ht = best_of(lambda: h.distances(sources), repeat) / len(sources) * 1e3
        h1 = np.mean([best_of(lambda: h.distance(int(s)), repeat) for s in sources[:2]]) * 1e3
        cells += [f"{100 * herr.mean():.2f}%", f"{ht:.2f}", f"{ht / ours:.2f}x", f"{h1:.2f}", f"{h1 / ours:.1f}x"]
    else:
        cells += ["", "", "", "", ""]
    if exact_time:
        solve = geodesic_solver(Mesh(v, f))
        et = np.mean([best_of(lambda: solve(int(s)), 1) for s in sources[:2]]) * 1e3
        cells += [f"{et:.1f}", f"{et / ours:.0f}x"]
    else:
        cells += ["", ""]
    return "| " + " | ".join(cells) + " |"


HEADER = ("| mesh | level | vertices | mean error | max error | ms/field | heat mean error | heat ms/field, batched "
          "| heat / ours | heat ms/field, one a solve | heat / ours | exact ms/field | exact / ours |\n"
          "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")


def accuracy_table(names, levels, n_sources, repeat):
    print(HEADER)
    for name in names:
        v0, f0 = base_mesh(name)
        sources = np.random.default_rng(0).choice(len(v0), n_sources, replace=False)
        exact = geodesic_solver(Mesh(v0, f0))
        truth = np.stack([exact(int(s)) for s in sources])
        for level in levels:
            v, f = subdivide(v0, f0, level)
            print(row(name, level, v, f, sources, truth, repeat), flush=True)


def sweep(repeat):
    print("\nsize sweep: decimated-max and its subdivisions, 2 sources (truth: the base's exact distances)")
    print(HEADER)
    v0, f0 = load("max")
    sources = np.random.default_rng(0).choice(len(v0), 2, replace=False)
    exact = geodesic_solver(Mesh(v0, f0))
    truth = np.stack([exact(int(s)) for s in sources])
    for level in range(5):  # 5k, 21k, 84k, 337k, 1.35M vertices
        v, f = subdivide(v0, f0, level)
        print(row("max", level, v, f, sources, truth, repeat if level < 3 else 1, heat=level <= 2,
                  exact_time=level <= 2), flush=True)


def ablation(names, n_sources, repeat):
    choices = [dict(), dict(saddle=100.0), dict(saddle=0.01), dict(saddle=0.02), dict(saddle=0.1), dict(saddle=0.2),
               dict(probe=0.95), dict(probe=0.9), dict(probe=0.5), dict(probe=0.0), dict(probe=0.0, saddle=100.0),
               dict(queue="heap"), dict(bucket=0.1), dict(bucket=2.0)]
    print("\nablation: mean relative error (ms/field) on the real meshes' base level; saddle 100: no gates")
    print("| choice | " + " | ".join(names) + " | mean |\n|---|" + "---:|" * (len(names) + 1))
    data = []
    for name in names:
        v, f = base_mesh(name)
        sources = np.random.default_rng(0).choice(len(v), n_sources, replace=False)
        exact = geodesic_solver(Mesh(v, f))
        data.append((VirtualSources(v, f), sources, np.stack([exact(int(s)) for s in sources])))
    for choice in choices:
        cells, means = [], []
        for solver, sources, truth in data:
            err = errors(solver.distances(sources.astype(np.int64), **choice), truth, sources).mean()
            ms = np.mean([best_of(lambda: solver.distances(np.array([s]), **choice), repeat) for s in sources[:2]]) * 1e3
            cells.append(f"{100 * err:.3f}% ({ms:.2f})")
            means.append(err)
        label = ", ".join(f"{k} {v}" for k, v in choice.items()) or "default (probe 1, saddle 0.05, buckets 0.5)"
        print(f"| {label} | " + " | ".join(cells) + f" | {100 * np.mean(means):.3f}% |", flush=True)


def raw_meshes(limit: int = 10000):
    import csv

    import trimesh

    from geodata.mesh import closed_manifold_problem

    root = DEV.parent
    rows = list(csv.DictReader(open(root / "MANIFEST.tsv"), delimiter="\t"))
    results = []
    for r in rows:
        if int(r["n_vertices"]) > limit:
            continue
        m = trimesh.load(root / r["relative_path"], process=True, force="mesh")
        mesh = Mesh(np.asarray(m.vertices), np.asarray(m.faces))
        if mesh.n_faces == 0 or closed_manifold_problem(mesh) is not None:
            continue
        sources = np.array([0, mesh.n_vertices // 3, mesh.n_vertices // 2])
        exact = geodesic_solver(mesh)
        truth = np.stack([exact(int(s)) for s in sources])
        err = errors(VirtualSources(mesh.vertices, mesh.faces).distances(sources), truth, sources)
        results.append((err.mean(), r["relative_path"], mesh.n_vertices))
    results.sort()
    means = np.array([e for e, _, _ in results])
    print(f"\nraw closed manifold meshes of ../shared/meshes under {limit} vertices: {len(results)}; mean error "
          f"a mesh: median {100 * np.median(means):.3f}%, mean {100 * means.mean():.3f}%, "
          f"{int((means > 0.002).sum())} over 0.2%, {int((means > 0.01).sum())} over 1%; the worst:")
    for e, path, n in results[-6:]:
        print(f"| {path} | {n:,} | {100 * e:.2f}% |")


def lower_bound_errors(fields: np.ndarray, truth: np.ndarray, sources, ks) -> list[float]:
    """Mean relative error of LB over sources x vertices (the source left out), for the first K columns
    of ``fields`` (N, 256), each K of ``ks``."""
    out = []
    for k in ks:
        lb = np.stack([np.abs(fields[s, :k] - fields[:, :k]).max(axis=1) for s in sources])
        out.append(errors(lb, truth, sources).mean())
    return out


def exact_truth(name: str, n_sources: int):
    """A bound table's mesh and its truth: vertices, faces, the exact solver, the generator (seed 0) after the
    sources were drawn (the landmarks' first pick comes next), the sources and their exact fields (S, N)."""
    v, f = base_mesh(name)
    exact = geodesic_solver(Mesh(v, f))
    rng = np.random.default_rng(0)
    sources = rng.choice(len(v), n_sources, replace=False)
    return v, f, exact, rng, sources, np.stack([exact(int(s)) for s in sources])


def lower_bound_table(names, ks=(16, 32, 64, 128, 256), n_sources=20):
    from gegnn.fields.landmarks import batched_farthest_point_fields

    print(f"\nlower bound of the first K of 256 landmarks: mean relative error over {n_sources} sources x "
          "every vertex")
    print("| mesh | fields | " + " | ".join(f"K = {k}" for k in ks) + " |\n|---|---|" + "---:|" * len(ks))
    for name in names:
        v, f, exact, rng, sources, truth = exact_truth(name, n_sources)
        heat, ours = HeatDistance(v, f), VirtualSources(v, f)
        first = int(rng.integers(len(v)))
        landmarks, by_heat = batched_farthest_point_fields(heat.distances, v, max(ks), first)
        picks = np.asarray(landmarks, dtype=np.int64)
        rows = {"heat method (today)": by_heat, "virtual sources": ours.distances(picks).T,
                "exact": np.stack([exact(int(l)) for l in picks], axis=1)}
        _, rows["virtual sources, own landmarks"] = batched_farthest_point_fields(
            lambda s: ours.distances(np.asarray(s, dtype=np.int64)).T, v, max(ks), first)
        for label, fields in rows.items():
            cells = lower_bound_errors(np.asarray(fields, dtype=np.float64), truth, sources, ks)
            print(f"| {name} | {label} | " + " | ".join(f"{100 * e:.2f}%" for e in cells) + " |", flush=True)


def cloud_lower_bound_table(names, ks=(64, 128, 256), n_sources=20):
    from gegnn.fields.cloud_heat import local_triangulations
    from gegnn.fields.cloud_vsp import CloudVirtualSources, agreed_soup
    from gegnn.fields.landmarks import _vsp_field, graph_farthest_points
    from gegnn.fields.pointcloud import CLOUD_T_COEF, _cloud_field, cloud_graph, surface_neighbors

    print(f"\ncloud fields: lower bound of the first K of 256 landmarks, mean relative error over {n_sources} "
          "sources x every point; the 256 fields' own mean relative error against the exact ones at the same "
          "landmarks; seconds for the 256 fields")
    print("| mesh | fields | " + " | ".join(f"K = {k}" for k in ks) + " | fields vs exact | s |\n|---|---|"
          + "---:|" * (len(ks) + 2))
    for name in names:
        v, f, exact, rng, sources, truth = exact_truth(name, n_sources)
        landmarks = graph_farthest_points(v, cloud_graph(v).edges, max(ks), int(rng.integers(len(v))))
        t = time.perf_counter()
        rows = {"point-cloud heat method (points-v2's)": _cloud_field(v, CLOUD_T_COEF)[1]()(landmarks)}
        seconds = [time.perf_counter() - t]
        t = time.perf_counter()
        triangles = local_triangulations(v, surface_neighbors(v))[1]
        for gluing, label in (("pairs", "virtual sources, local triangles glued in pairs (points-v3's)"),
                              ("cover", "virtual sources, the local triangles' tufted cover")):
            rows[label] = CloudVirtualSources(v, triangles, gluing).distances(landmarks)
            seconds.append(time.perf_counter() - t)
            t = time.perf_counter()
        soup = agreed_soup(triangles)  # most agreed first: kept on their edges by manifold_copy
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the soup's non-manifold edges, expected
            rows["virtual sources on a manifold copy of the local triangles"] = _vsp_field(v, soup, 0.5, max(ks))(
                landmarks)
        seconds.append(time.perf_counter() - t)
        rows["exact (the mesh's)"] = exact_fields = np.stack([exact(int(l)) for l in landmarks], axis=1)
        seconds.append(float("nan"))
        far = exact_fields > 0
        for (label, fields), sec in zip(rows.items(), seconds):
            fields = np.asarray(fields, dtype=np.float64)
            cells = lower_bound_errors(fields, truth, sources, ks)
            own = np.mean(np.abs(fields[far] - exact_fields[far]) / exact_fields[far])
            print(f"| {name} | {label} | " + " | ".join(f"{100 * e:.2f}%" for e in cells)
                  + f" | {100 * own:.2f}% | {sec:.2f} |", flush=True)


def zoo_truth(name: str, size: float | None):
    """A zoo shape at ``size`` (or a classic mesh, size None), 4 sources (seed 0) and their exact fields (4, N),
    by the exact solver itself (which takes boundaries too: the saddle patch)."""
    from geodata._exact_geodesic import Surface
    from geodata.zoo import zoo_mesh

    v, f = load(name) if name in REAL else zoo_mesh(name, size)
    sources = np.random.default_rng(0).choice(len(v), 4, replace=False).astype(np.int64)
    return v, f, sources, Surface(v, f.astype(np.int32)).distances(sources)


def zoo_table(size: float, repeat: int):
    from geodata.zoo import ZOO

    before = dict(saddle=0.05, convex=False, relax=False)
    print(f"\nthe zoo at size {size}, the tubes finer, and six classic meshes, 4 sources each: mean / signed mean / "
          "99th percentile of the relative error against exact, ms a field (one core)")
    print("| shape | vertices | before: mean | signed | p99 | ms | today: mean | signed | p99 | ms |\n"
          "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    finer = [("trefoil", 2 * size), ("trefoil", 4 * size), ("coil", 2 * size), ("u-bend", 2 * size)]
    for name, at in [*((n, size) for n in ZOO), *finer, *((n, None) for n in CLASSIC)]:
        v, f, sources, exact = zoo_truth(name, at)
        keep = exact > 0
        solver, cells = VirtualSources(v, f), [name if at in (size, None) else f"{name} x{at / size:g}", f"{len(v):,}"]
        for choice in (before, {}):
            r = (solver.distances(sources, **choice)[keep] - exact[keep]) / exact[keep]
            ms = best_of(lambda: solver.distances(sources[:1], **choice), repeat) * 1e3
            cells += [f"{100 * np.abs(r).mean():.3f}%", f"{100 * r.mean():+.3f}%",
                      f"{100 * np.quantile(np.abs(r), 0.99):.2f}%", f"{ms:.2f}"]
        print("| " + " | ".join(cells) + " |", flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--meshes", nargs="+", default=[*REAL, "irregular", "slivers"])
    ap.add_argument("--levels", type=int, nargs="+", default=[0, 1])
    ap.add_argument("--sources", type=int, default=8)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--sweep", action="store_true")
    ap.add_argument("--ablation", action="store_true")
    ap.add_argument("--raw", action="store_true")
    ap.add_argument("--zoo", action="store_true", help="the shape zoo (geodata.zoo), before and today")
    ap.add_argument("--size", type=float, default=1.0, help="the zoo's size (1: 3-10k vertices)")
    ap.add_argument("--lower-bound", nargs="*", metavar="MESH", help="issue 55's LB table on these meshes "
                    "(default: max homer camel)")
    ap.add_argument("--cloud-lower-bound", nargs="*", metavar="MESH", help="the same for the point-cloud "
                    "model's fields (default: max homer camel)")
    args = ap.parse_args()
    torch.set_num_threads(1)  # the heat method's solves run on torch's thread count: one core for all three
    print(f"CPU: {cpu_description()}")
    if args.raw:
        raw_meshes()
        return
    if args.zoo:
        zoo_table(args.size, args.repeat)
        return
    if args.lower_bound is not None:
        lower_bound_table(args.lower_bound or ["max", "homer", "camel"])
        return
    if args.cloud_lower_bound is not None:
        cloud_lower_bound_table(args.cloud_lower_bound or ["max", "homer", "camel"])
        return
    print(f"{args.sources} sources a mesh (seed 0); errors over sources x base vertices; times: the least CPU "
          f"time of {args.repeat} calls, one thread")
    accuracy_table(args.meshes, args.levels, args.sources, args.repeat)
    if args.sweep:
        sweep(args.repeat)
    if args.ablation:
        ablation([m for m in args.meshes if m in REAL], args.sources, args.repeat)


if __name__ == "__main__":
    main()
