"""`geodata prepare`: raw mesh files to committed mesh groups with exact geodesic pairs.

The stage functions are pure (Mesh -> Mesh); this module alone wires them, times them, checks the
invariants between them and touches files and the store.
"""
from __future__ import annotations

import hashlib
import importlib.metadata
import re
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from geodata import store
from geodata.geodesic import exact_geodesic_pairs
from geodata.mesh import Mesh, MeshError, one_line, require_closed_manifold, unique_edges, vertex_normals
from geodata.parallel import current_stage, in_shard, run_isolated
from geodata.stages.load import MESH_SUFFIXES, load_mesh_bytes
from geodata.stages.normalize import normalize
from geodata.stages.remesh import remesh, simplify
from geodata.stages.watertight import watertight

__all__ = ["PrepareConfig", "MeshTask", "raw_root", "discover", "read_list", "make_tasks", "mesh_rng", "run_stage",
           "prepare_geometry", "prepare_mesh", "process_task"]

LIBRARIES = ("geogegnn", "trimesh", "manifold3d", "pymeshlab", "fast-simplification", "tvb-gdist", "libigl", "numpy")


@dataclass(frozen=True)
class PrepareConfig:
    pairs: int = 600_000
    target_vertices: int = 5000
    collapse: float = 0.15
    seed: int = 0
    geodesic_backend: str = "vtp"
    timeout: float = 1800.0  # seconds a mesh may take before it is recorded as failed

    def store_params(self) -> dict:
        """The parameters that decide the data (a store holds one setting of them)."""
        return {k: v for k, v in asdict(self).items() if k != "timeout"}


@dataclass(frozen=True)
class MeshTask:
    path: str      # absolute path of the raw file
    source: str    # path relative to the input root (as recorded in the store)
    mesh_id: str
    sha256: str


def raw_root(raw_dir: str | Path) -> Path:
    """The folder that `discover`'s relative paths start from: RAW_DIR, or a single file's folder."""
    root = Path(raw_dir)
    return root.parent if root.is_file() else root


def discover(raw_dir: str | Path, include: set[str] | None = None, exclude: set[str] | None = None) -> list[str]:
    """Mesh files under raw_dir, recursively, as sorted relative POSIX paths; only those in
    ``include`` (when given) and none in ``exclude``."""
    root = Path(raw_dir)
    if root.is_file():
        found = [root.name] if root.suffix.lower() in MESH_SUFFIXES else []
    else:
        found = sorted(p.relative_to(root).as_posix() for p in root.rglob("*")
                       if p.is_file() and p.suffix.lower() in MESH_SUFFIXES)
    return [s for s in found if (include is None or s in include) and s not in (exclude or ())]


def read_list(path: str | Path) -> set[str]:
    """Relative mesh paths, one a line; blank lines and `#` comments are ignored."""
    lines = (line.split("#", 1)[0].strip() for line in Path(path).read_text().splitlines())
    return {line for line in lines if line}


def make_tasks(raw_dir: str | Path, sources: list[str]) -> list[MeshTask]:
    """Tasks with ids `<safe stem>-<8 hex of the content hash>`; identical files collapse to one task."""
    base = raw_root(raw_dir)
    tasks: dict[str, MeshTask] = {}
    for source in sources:
        path = base / source
        digest = hashlib.sha256(path.read_bytes()).hexdigest()
        stem = re.sub(r"[^A-Za-z0-9_.-]+", "_", Path(source).stem).strip("._") or "mesh"
        mesh_id = f"{stem[:64]}-{digest[:8]}"
        tasks.setdefault(mesh_id, MeshTask(str(path.resolve()), source, mesh_id, digest))
    return list(tasks.values())


def mesh_rng(seed: int, mesh_id: str) -> np.random.Generator:
    """A mesh's own random stream: the same for a mesh whatever the job count, shard or order."""
    key = int.from_bytes(hashlib.sha256(mesh_id.encode()).digest()[:8], "big")
    return np.random.default_rng([seed, key])


def run_stage(timings: dict, stage: str, fn, *args, check: bool = True, zero_area_ok: bool = False):
    """One stage: a library error becomes MeshError(stage, one line); the result's invariants are
    checked (native code downstream segfaults on broken meshes); the seconds go to ``timings``."""
    current_stage(stage)
    t = time.perf_counter()
    try:
        result = fn(*args)
    except MeshError:
        raise
    except Exception as exc:  # a library error is this stage's failure, in one line
        raise MeshError(stage, one_line(exc)) from None
    if check:
        require_closed_manifold(result, stage, zero_area_ok=zero_area_ok)
    timings[stage] = round(time.perf_counter() - t, 4)
    return result


def prepare_geometry(mesh: Mesh, config: PrepareConfig, timings: dict | None = None) -> Mesh:
    """The geometry stages on a loaded mesh: watertight, remesh, simplify, normalize."""
    timings = {} if timings is None else timings
    mesh = run_stage(timings, "watertight", watertight, mesh, zero_area_ok=True)  # remesh rebuilds triangles
    mesh = run_stage(timings, "remesh", lambda m: remesh(m, config.target_vertices, collapse=config.collapse), mesh)
    mesh = run_stage(timings, "simplify", simplify, mesh, config.collapse)
    return run_stage(timings, "normalize", normalize, mesh)


FLAT = 1e-6  # thickness / extent below which an input is flat


def input_notes(mesh: Mesh) -> list[str]:
    """What the pipeline will do to this input that its author may not expect (kept in the mesh's
    attrs as "warnings" and shown by `geodata info`)."""
    centered = mesh.vertices - mesh.vertices.mean(axis=0)
    extents = np.linalg.svd(centered, compute_uv=False) if len(centered) > 1 else np.zeros(1)
    if extents[0] > 0 and (len(extents) < 3 or extents[-1] <= FLAT * extents[0]):
        return [f"flat input thickened: all {mesh.n_vertices} vertices lie in one plane "
                f"({mesh.n_faces} faces); the watertight stage made a thin closed slab of it"]
    return []


def prepare_mesh(data: bytes, suffix: str, config: PrepareConfig, rng: np.random.Generator,
                 timings: dict | None = None, notes: list | None = None
                 ) -> tuple[Mesh, np.ndarray, np.ndarray, np.ndarray]:
    """All stages on one file's bytes: the normalized mesh, its geodesic pairs, distances, skipped
    sources; ``notes`` gets :func:`input_notes` of the loaded input."""
    timings = {} if timings is None else timings
    mesh = run_stage(timings, "load", load_mesh_bytes, data, suffix, check=False)
    if notes is not None:
        notes.extend(input_notes(mesh))
    mesh = prepare_geometry(mesh, config, timings)
    pairs, distances, skipped = run_stage(timings, "geodesic", exact_geodesic_pairs, mesh, config.pairs, rng,
                                          config.geodesic_backend, check=False)
    return mesh, pairs, distances, skipped


def _compute(task: MeshTask, config: PrepareConfig) -> tuple[dict, dict]:
    """Runs in the isolated child: arrays to store and attributes (timings, skipped sources)."""
    current_stage("load")
    data = Path(task.path).read_bytes()
    timings: dict = {}
    notes: list = []
    mesh, pairs, distances, skipped = prepare_mesh(data, Path(task.path).suffix, config,
                                                   mesh_rng(config.seed, task.mesh_id), timings, notes)
    arrays = {
        "vertices": mesh.vertices.astype(np.float32),
        "faces": mesh.faces.astype(np.int32),
        "normals": vertex_normals(mesh).astype(np.float32),
        "edges": unique_edges(mesh.faces).astype(np.int32),
        "geodesic/pairs": pairs,
        "geodesic/distances": distances,
    }
    return arrays, {"timings": timings, "skipped_sources": skipped.tolist(), "warnings": notes}


def library_versions() -> dict:
    versions = {}
    for name in LIBRARIES:
        try:
            versions[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            versions[name] = None
    return versions


def process_task(task: MeshTask, out: str, config: PrepareConfig) -> dict:
    """Prepare one mesh and commit it (or record its failure). Returns a summary row; never raises MeshError."""
    start = time.perf_counter()
    row = {"mesh_id": task.mesh_id, "source": task.source, "warnings": []}
    try:
        arrays, computed = run_isolated(_compute, task, config, timeout=config.timeout,
                                        warnings_out=row["warnings"])
    except MeshError as exc:
        store.record_failure(out, task.mesh_id, task.source, exc.stage, exc.reason)
        store.remove_mesh(out, task.mesh_id)
        return {**row, "status": "failed", "stage": exc.stage, "error": exc.reason,
                "seconds": time.perf_counter() - start}
    attrs = {"source": task.source, "sha256": task.sha256, "params": config.store_params(), **computed,
             "n_vertices": len(arrays["vertices"]), "n_faces": len(arrays["faces"]),
             "n_pairs": len(arrays["geodesic/pairs"]), "versions": library_versions()}
    store.write_group(out, f"meshes/{task.mesh_id}", arrays, attrs)
    store.commit(out, f"meshes/{task.mesh_id}")
    store.clear_failure(out, task.mesh_id)
    return {**row, "status": "ok", "timings": computed["timings"], "n_vertices": attrs["n_vertices"],
            "notes": computed["warnings"], "seconds": time.perf_counter() - start}


def select_tasks(raw_dir: str | Path, out: str, shard: tuple[int, int], retry_failed: bool,
                 include: set[str] | None = None, exclude: set[str] | None = None
                 ) -> tuple[list[MeshTask], int, int]:
    """This shard's tasks that still need work, and how many were already committed or failed."""
    tasks = make_tasks(raw_dir, [s for s in discover(raw_dir, include, exclude) if in_shard(s, shard)])
    failed = set() if retry_failed else set(store.list_failures(out))
    done = {t.mesh_id for t in tasks if store.mesh_status(out, t.mesh_id) == "ok"}
    pending = [t for t in tasks if t.mesh_id not in done and t.mesh_id not in failed]
    return pending, len(done), sum(t.mesh_id in failed for t in tasks)
