"""Seconds per geometry stage (load, watertight, remesh, simplify) per mesh, and the invariants.

    python benchmarks/bench_stages.py              # a few shared meshes
    python benchmarks/bench_stages.py --all        # every mesh in ../shared/meshes/train
    python benchmarks/bench_stages.py PATH [PATH ...] [--target-vertices N] [--collapse C]

Reads meshes from ../shared/meshes next to the checkout (not part of the repository). Each mesh runs
in this one process, one core; "valid" means closed_manifold_problem is None, every closed
component has positive signed volume, and the vertex count is within +-20% of the target.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from geodata.mesh import Mesh, MeshError, closed_manifold_problem, component_volumes  # noqa: E402
from geodata.stages.remesh import remesh, simplify  # noqa: E402
from geodata.stages.watertight import watertight  # noqa: E402
from machine import cpu_description  # benchmarks/ is on sys.path when a script there runs

MESHES = ROOT.parent / "shared" / "meshes"
DEFAULT = ["sweethome3d/chair.obj", "sweethome3d/floorUplight.obj", "sweethome3d/table.obj",
           "sweethome3d/door.obj", "sweethome3d/bookcase.obj", "trimesh-models/featuretype.STL"]


def load(path: Path) -> Mesh:
    import trimesh

    tm = trimesh.load(str(path), force="mesh", process=False)
    tm.merge_vertices()
    return Mesh(tm.vertices, tm.faces)


def check(mesh: Mesh, target: int) -> str | None:
    problem = closed_manifold_problem(mesh)
    if problem is not None:
        return problem
    vols = component_volumes(mesh)
    if (vols <= 0).any():
        return f"{int((vols <= 0).sum())} components with non-positive volume"
    if abs(mesh.n_vertices / target - 1) > 0.2:
        return f"{mesh.n_vertices} vertices, target {target}"
    return None


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("paths", nargs="*", help="mesh files (default: a few shared meshes)")
    ap.add_argument("--all", action="store_true", help="every mesh under shared/meshes/train")
    ap.add_argument("--target-vertices", type=int, default=5000)
    ap.add_argument("--collapse", type=float, default=0.15)
    args = ap.parse_args(argv)
    print(f"CPU: {cpu_description()}", flush=True)

    if args.paths:
        paths = [Path(p) for p in args.paths]
    else:
        train = MESHES / "train"
        if not train.is_dir():
            print(f"no shared meshes at {train}", file=sys.stderr)
            return 1
        if args.all:
            paths = sorted(p for p in train.rglob("*") if p.is_file()
                           and p.suffix.lower() in {".obj", ".off", ".ply", ".stl", ".glb"})
        else:
            paths = [train / p for p in DEFAULT if (train / p).exists()]

    stages = ["load", "watertight", "remesh", "simplify"]
    header = f"{'mesh':44s} " + " ".join(f"{s:>10s}" for s in stages) + f" {'total':>7s} {'V_in':>7s} {'V_wt':>7s} {'V_out':>6s}  result"
    print(header)
    times, valid, failures = [], 0, []
    for path in paths:
        name = str(path.relative_to(MESHES / "train")) if MESHES in path.parents else str(path)
        t = [time.perf_counter()]
        counts = ["", "", ""]
        result = None
        try:
            m = load(path)
            counts[0] = str(m.n_vertices)
            t.append(time.perf_counter())
            m = watertight(m)
            counts[1] = str(m.n_vertices)
            t.append(time.perf_counter())
            m = remesh(m, args.target_vertices, collapse=args.collapse)
            t.append(time.perf_counter())
            m = simplify(m, args.collapse)
            t.append(time.perf_counter())
            counts[2] = str(m.n_vertices)
            result = check(m, args.target_vertices)
        except MeshError as exc:
            result = f"MeshError {exc}"
        except Exception as exc:  # noqa: BLE001 - a benchmark reports and goes on
            result = f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"
        dt = list(np.diff(t)) + [np.nan] * (4 - (len(t) - 1))
        if len(t) == 5:
            times.append(dt)
        ok = result is None
        valid += ok
        if not ok:
            failures.append((name, result))
        cells = " ".join(f"{x:10.2f}" if np.isfinite(x) else f"{'-':>10s}" for x in dt)
        print(f"{name:44s} {cells} {np.nansum(dt):7.2f} {counts[0]:>7s} {counts[1]:>7s} {counts[2]:>6s}  "
              f"{'ok' if ok else 'FAIL: ' + result}", flush=True)

    print()
    if times:
        a = np.array(times)
        print(f"{'stage':12s} {'mean s':>8s} {'max s':>8s}")
        for i, s in enumerate(stages + ["total"]):
            col = a[:, i] if i < 4 else a.sum(axis=1)
            print(f"{s:12s} {col.mean():8.2f} {col.max():8.2f}")
    print(f"valid: {valid}/{len(paths)}")
    for name, why in failures:
        print(f"  FAIL {name}: {why}")
    return 0 if valid == len(paths) else 1


if __name__ == "__main__":
    sys.exit(main())
