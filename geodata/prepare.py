"""`geodata prepare`: raw mesh files to committed mesh groups with exact geodesic pairs.

The stage functions are pure (Mesh -> Mesh); this module alone wires them, times them, checks the
invariants between them and touches files and the store.
"""
from __future__ import annotations

import contextlib
import hashlib
import importlib.metadata
import json
import os
import re
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np

from geodata import store
from geodata.geodesic import APPROXIMATE, approximation_error, exact_geodesic_pairs
from geodata.mesh import Mesh, MeshError, one_line, require_closed_manifold, unique_edges, vertex_normals
from geodata.parallel import current_stage, in_shard, run_isolated
from geodata.stages.load import MESH_SUFFIXES, load_mesh_bytes
from geodata.stages.normalize import normalization, normalize
from geodata.stages.remesh import remesh, simplify
from geodata.stages.watertight import watertight
from geodata.surface_points import SurfacePoints, locate_points

__all__ = ["PrepareConfig", "MeshTask", "raw_root", "discover", "read_list", "make_tasks", "mesh_rng", "run_stage",
           "prepare_geometry", "Prepared", "prepare_mesh", "input_places", "process_task", "ShardPlan",
           "plan_shard"]

LIBRARIES = ("geogegnn", "trimesh", "manifold3d", "pymeshlab", "fast-simplification", "tvb-gdist", "libigl", "numpy")


@dataclass(frozen=True)
class PrepareConfig:
    pairs: int = 600_000
    target_vertices: int = 5000
    collapse: float = 0.15
    seed: int = 0
    geodesic_backend: str = "vtp"
    timeout: float = 1800.0  # seconds a mesh may take before it is recorded as failed
    max_memory: int | None = None  # bytes one mesh's process may use (None: no limit)

    def store_params(self) -> dict:
        """The parameters that decide the data (a store holds one setting of them), values only: an approximate
        store is told by its ``geodesic_backend`` (one of ``APPROXIMATE``), and each of its meshes records its
        measured error (the attribute ``geodesic_error``)."""
        return {k: v for k, v in asdict(self).items() if k not in ("timeout", "max_memory")}


@dataclass(frozen=True)
class MeshTask:
    path: str      # absolute path of the raw file
    source: str    # path relative to the input root (as recorded in the store)
    mesh_id: str
    sha256: str | None  # None: the file could not be read (``error`` says why)
    error: str | None = None


def raw_root(raw_dir: str | Path) -> Path:
    """The folder that `discover`'s relative paths start from: RAW_DIR, or a single file's folder."""
    root = Path(raw_dir)
    return root.parent if root.is_file() else root


def discover(raw_dir: str | Path, include: set[str] | None = None, exclude: set[str] | None = None) -> list[str]:
    """Mesh files under raw_dir, recursively, as sorted relative POSIX paths, none in ``exclude``; with
    ``include``, the files it lists (the tree is not walked: a shard of a large catalog reads its list only)."""
    root = Path(raw_dir)
    if root.is_file():
        found = [root.name] if root.suffix.lower() in MESH_SUFFIXES else []
    elif include is not None:  # the list is the inputs: no walk of the tree (a listed file that is missing fails)
        found = sorted(include)
    else:  # os.walk: the directory entries' types, no stat of each file (a catalog has 50k of them)
        found = sorted(Path(folder, name).relative_to(root).as_posix()
                       for folder, _, names in os.walk(root, followlinks=True)
                       for name in names if name.lower().endswith(MESH_SUFFIXES))
    return [s for s in found if (include is None or s in include) and s not in (exclude or ())]


def read_list(path: str | Path) -> set[str]:
    """Relative mesh paths, one a line; blank lines and `#` comments are ignored."""
    lines = (line.split("#", 1)[0].strip() for line in Path(path).read_text().splitlines())
    return {line for line in lines if line}


ID_DIGITS = 32  # hex digits of the SHA-256 in a mesh id: 128 bits, no collision among any real catalog


def mesh_id_of(source: str, digest: str) -> str:
    """``<safe stem>-<32 hex digits of the content hash>``: distinct files get distinct ids at any scale
    (ShapeNet names every file model_normalized.obj), byte copies of one file name one id, in every run, shard
    and job count (a byte copy under another name is a mesh of its own)."""
    stem = re.sub(r"[^A-Za-z0-9_.-]+", "_", Path(source).stem).strip("._") or "mesh"
    return f"{stem[:40]}-{digest[:ID_DIGITS]}"


STAT_KEYS = ("size", "mtime_ns", "ctime_ns", "inode")  # a ledger's hash is reused only where all four are unchanged


def file_stat(stat: os.stat_result) -> dict:
    """What a ledger keeps of a file's stat: a rewrite changes its ctime (no tool sets it back: `cp -p`, `touch -r`
    and `rsync -t` keep the size and mtime, never the ctime) and a replacement its inode."""
    return {"size": stat.st_size, "mtime_ns": stat.st_mtime_ns, "ctime_ns": stat.st_ctime_ns, "inode": stat.st_ino}


COARSE_TICK_NS = 2_000_000_000  # the clock of filesystems that keep whole seconds (ext3, FAT, some NFS servers)


def racy(entry: dict) -> bool:
    """Whether a ledger entry's file changed so shortly before it was hashed that a later change could leave its
    ctime the same, on a filesystem whose times are whole seconds: its hash is not reused (git's "racily clean"
    entries). Where times have nanoseconds the tick is the kernel's (a few ms): not guarded (docs/store.md)."""
    coarse = entry["ctime_ns"] % 1_000_000_000 == 0
    return coarse and entry["ctime_ns"] + COARSE_TICK_NS >= entry.get("checked_ns", 0)


def reusable_hash(old: dict | None, stat: dict, lenient: bool = False) -> str | None:
    """An earlier ledger entry's hash where the file is unchanged by every sign its stat gives, else None.
    ``lenient`` (a check's): an entry of a ledger from before ctime and inode were kept (0.3.0) is judged by its
    size and mtime, so that a recovery's first check after an update does not call every finished shard
    pending; a run hashes such a file again."""
    if not old or not old.get("sha256"):
        return None
    if lenient and "ctime_ns" not in old:
        return old["sha256"] if (old.get("size"), old.get("mtime_ns")) == (stat["size"], stat["mtime_ns"]) else None
    if any(old.get(k) != stat[k] for k in STAT_KEYS) or racy(old):
        return None
    return old["sha256"]


def make_tasks(raw_dir: str | Path, sources: list[str], known: dict | None = None,
               legacy: dict | None = None, unread: list | None = None) -> tuple[list[MeshTask], dict]:
    """One task per distinct mesh id among ``sources`` (byte copies of one file name are one task, under the first
    path), and the ledger entry of every source: {sha256, mesh_id, size, mtime_ns, ctime_ns, inode, checked_ns}.
    ``known``: an earlier ledger's entries, whose hash is reused where a file's size, times and inode are
    unchanged (a rerun reads no such file again: :func:`reusable_hash`). ``legacy``: (source, sha256) -> the id
    an upgraded store kept for that file (:func:`geodata.store.legacy_ids`). ``unread``: no file is read; the
    sources whose hash ``known`` does not give are appended to it instead (no task, no entry). A file that cannot
    be read is a task with its reason in ``error``."""
    base = raw_root(raw_dir)
    tasks: dict[str, MeshTask] = {}
    entries = {}
    for source in sources:
        path = base / source
        try:
            checked = time.time_ns()
            stat = file_stat(path.stat())
            digest = reusable_hash((known or {}).get(source), stat, lenient=unread is not None)
            if digest is None and unread is not None:
                unread.append(source)
                continue
            if digest is None:
                digest = hashlib.sha256(path.read_bytes()).hexdigest()
            mesh_id = (legacy or {}).get((source, digest)) or mesh_id_of(source, digest)
            task = MeshTask(str(path.resolve()), source, mesh_id, digest)
            entries[source] = {"sha256": digest, "mesh_id": task.mesh_id, **stat, "checked_ns": checked}
        except OSError as exc:  # permissions, a broken link, a file removed since the listing
            unreadable = mesh_id_of(source, hashlib.sha256(f"unreadable:{source}".encode()).hexdigest())
            task = MeshTask(str(path), source, unreadable, None, f"cannot read the file: {exc.strerror or exc}")
            entries[source] = {"sha256": None, "mesh_id": unreadable, "size": None, "mtime_ns": None}
        tasks.setdefault(task.mesh_id, task)
    return list(tasks.values()), entries


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
    except (MeshError, MemoryError):  # out of memory: worded by run_isolated (with its --max-memory)
        raise
    except Exception as exc:  # a library error is this stage's failure, in one line
        raise MeshError(stage, one_line(exc)) from None
    if check:
        require_closed_manifold(result, stage, zero_area_ok=zero_area_ok)
    timings[stage] = round(time.perf_counter() - t, 4)
    return result


def prepare_geometry(mesh: Mesh, config: PrepareConfig, timings: dict | None = None,
                     transform: list | None = None) -> Mesh:
    """The geometry stages on a loaded mesh: watertight, remesh, simplify, normalize; ``transform`` gets the
    normalization's (center, scale): a point p of the input lies at (p - center) / scale in the result's units."""
    timings = {} if timings is None else timings
    mesh = run_stage(timings, "watertight", watertight, mesh, zero_area_ok=True)  # remesh rebuilds triangles
    mesh = run_stage(timings, "remesh", lambda m: remesh(m, config.target_vertices, collapse=config.collapse), mesh)
    mesh = run_stage(timings, "simplify", simplify, mesh, config.collapse)
    if transform is not None:
        transform.extend(normalization(mesh.vertices))
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


class Prepared(NamedTuple):
    """One file through every stage: the stored mesh, its geodesic pairs and distances, the sources the solver
    skipped, where each of the file's vertices lies on the mesh (:func:`input_places`), and the normalization
    (a point p of the input is at (p - center) / scale on the mesh: distances in input units are the stored
    ones times ``scale``)."""

    mesh: Mesh
    pairs: np.ndarray
    distances: np.ndarray
    skipped: np.ndarray
    places: SurfacePoints
    center: np.ndarray
    scale: float


def prepare_mesh(data: bytes, suffix: str, config: PrepareConfig, rng: np.random.Generator,
                 timings: dict | None = None, notes: list | None = None) -> Prepared:
    """All stages on one file's bytes; ``notes`` gets :func:`input_notes` of the loaded input."""
    timings = {} if timings is None else timings
    mesh, index_map = run_stage(timings, "load", load_mesh_bytes, data, suffix, True, check=False)
    if notes is not None:
        notes.extend(input_notes(mesh))
    transform: list = []
    stored = prepare_geometry(mesh, config, timings, transform)
    pairs, distances, skipped = run_stage(timings, "geodesic", exact_geodesic_pairs, stored, config.pairs, rng,
                                          config.geodesic_backend, check=False)
    return Prepared(stored, pairs, distances, skipped, input_places(mesh.vertices, index_map, stored, *transform),
                    *transform)


def input_places(loaded: np.ndarray, index_map: np.ndarray, stored: Mesh, center: np.ndarray,
                 scale: float) -> SurfacePoints:
    """Where each vertex of the input file lies on the stored surface: the closest point to its position
    mapped by the normalization, (p - center) / scale, as a face and barycentric coordinates, and its offset
    (the distance to the surface, in the stored units: what watertight, remesh and simplify moved).

    Args:
        loaded: the loaded mesh's vertices (M, 3), input units.
        index_map: (V,) for each vertex of the file its row in ``loaded``, -1 where the load stage dropped it
            (no face uses it): such a vertex gets face -1, barycentric (0, 0, 0) and offset NaN.
    """
    places = locate_points(stored, (loaded - center) / scale)
    used = index_map >= 0
    face = np.full(len(index_map), -1, dtype=np.int64)
    bary = np.zeros((len(index_map), 3))
    offset = np.full(len(index_map), np.nan)
    face[used], bary[used], offset[used] = (a[index_map[used]] for a in places)
    return SurfacePoints(face, bary, offset)


def _compute(task: MeshTask, config: PrepareConfig) -> tuple[dict, dict]:
    """Runs in the isolated child: arrays to store and attributes (timings, skipped sources)."""
    current_stage("load")
    data = Path(task.path).read_bytes()
    timings: dict = {}
    notes: list = []
    done = prepare_mesh(data, Path(task.path).suffix, config, mesh_rng(config.seed, task.mesh_id), timings, notes)
    arrays = {
        "vertices": done.mesh.vertices.astype(np.float32),
        "faces": done.mesh.faces.astype(np.int32),
        "normals": vertex_normals(done.mesh).astype(np.float32),
        "edges": unique_edges(done.mesh.faces).astype(np.int32),
        "geodesic/pairs": done.pairs,
        "geodesic/distances": done.distances,
        "input/face": done.places.face.astype(np.int32),
        "input/bary": done.places.bary.astype(np.float32),
        "input/offset": done.places.offset.astype(np.float32),
    }
    attrs = {"timings": timings, "skipped_sources": done.skipped.tolist(), "warnings": notes,
             "geometry_key": store.geometry_key(arrays["vertices"], done.mesh.faces),
             "normalization": {"center": done.center.tolist(), "scale": done.scale}}
    if config.geodesic_backend in APPROXIMATE:  # measured against exact fields of two of its sources
        attrs["geodesic_error"] = run_stage(timings, "geodesic check", approximation_error, done.mesh, done.pairs,
                                            done.distances, check=False)
    return arrays, attrs


def library_versions() -> dict:
    versions = {}
    for name in LIBRARIES:
        try:
            versions[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            versions[name] = None
    return versions


def process_task(task: MeshTask, out: str, config: PrepareConfig) -> dict:
    """Prepare one mesh and publish it (or record its failure). Returns a summary row; never raises MeshError."""
    start = time.perf_counter()
    row = {"mesh_id": task.mesh_id, "source": task.source, "warnings": []}
    try:
        if task.error:
            raise MeshError("load", task.error)
        arrays, computed = run_isolated(_compute, task, config, timeout=config.timeout,
                                        warnings_out=row["warnings"], max_memory=config.max_memory)
    except MeshError as exc:
        store.record_failure(out, task.mesh_id, task.source, exc.stage, exc.reason)
        return {**row, "status": "failed", "stage": exc.stage, "error": exc.reason,
                "seconds": time.perf_counter() - start}
    attrs = {"source": task.source, "sha256": task.sha256, "params": config.store_params(), **computed,
             "n_vertices": len(arrays["vertices"]), "n_faces": len(arrays["faces"]),
             "n_pairs": len(arrays["geodesic/pairs"]), "versions": library_versions()}
    if not store.write_mesh(out, task.mesh_id, arrays, attrs):  # a byte copy in another shard was first
        computed["warnings"] = [*computed["warnings"], "already published by another run (a byte copy of this file)"]
    store.clear_failure(out, task.mesh_id)
    return {**row, "status": "ok", "timings": computed["timings"], "n_vertices": attrs["n_vertices"],
            "notes": computed["warnings"], "seconds": time.perf_counter() - start}


@dataclass
class ShardPlan:
    """What one shard of a prepare run finds: its distinct inputs and their state in the store."""

    tasks: list[MeshTask]      # one per distinct content among the shard's files
    ledger: dict               # sources/<ledger_name>.json: every file of the shard -> sha256, mesh id
    ledger_name: str
    published: set[str]        # ids among ``tasks`` already in the store, whole
    failed: set[str]           # ids among ``tasks`` with a failure record
    damaged: dict[str, str] = field(default_factory=dict)  # ids among ``tasks`` whose zip is damaged: the reason
    unread: list[str] = field(default_factory=list)  # a check's: files its ledger does not vouch for (pending)

    def pending(self, retry_failed: bool = False) -> list[MeshTask]:
        """The tasks still to do (with ``retry_failed``, the failed ones too); a damaged mesh is to do again."""
        return [t for t in self.tasks if t.mesh_id not in self.published
                and (retry_failed or t.mesh_id not in self.failed or t.mesh_id in self.damaged)]


def ledger_name(raw_dir: str | Path, shard: tuple[int, int], include: set[str] | None,
                exclude: set[str] | None) -> str:
    """The name of a run's ledger: the same for a rerun of one shard of one input selection."""
    key = json.dumps([str(raw_root(raw_dir).resolve()), list(shard), sorted(include) if include is not None
                      else None, sorted(exclude or ())])
    return f"shard{shard[0]}of{shard[1]}-{hashlib.sha256(key.encode()).hexdigest()[:16]}"


def plan_shard(raw_dir: str | Path, out: str, shard: tuple[int, int], include: set[str] | None = None,
               exclude: set[str] | None = None, rehash: bool = False, read: bool = True) -> ShardPlan:
    """This shard's files (hashed, or their hash taken from the shard's last ledger where unchanged; with
    ``rehash`` every file is hashed) and the state of their meshes, from the shard's own files and records
    alone: its cost does not grow with the store. ``read=False`` (a check): no file is read, those the ledger
    does not vouch for are ``unread``."""
    name, known = ledger_name(raw_dir, shard, include, exclude), None
    with contextlib.suppress(FileNotFoundError, json.JSONDecodeError, KeyError):
        known = None if rehash else json.loads((Path(out) / "sources" / f"{name}.json").read_text())["inputs"]
    unread = None if read else []
    tasks, entries = make_tasks(raw_dir, [s for s in discover(raw_dir, include, exclude) if in_shard(s, shard)],
                                known, store.legacy_ids(out), unread)
    ids = {t.mesh_id for t in tasks}
    found = {m for m in ids if store.mesh_file(out, m).is_file()}
    damaged = {m: reason for m in found if (reason := store.damage(out, m))}  # one small read of each: its end
    ledger = {"root": str(raw_root(raw_dir).resolve()), "shard": f"{shard[0]}/{shard[1]}", "written": time.time(),
              "inputs": entries}
    return ShardPlan(tasks, ledger, name, found - set(damaged), set(store.list_failures(out, ids)), damaged,
                     unread or [])
