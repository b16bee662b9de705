"""The per-vertex fields a model's decoder reads besides the embeddings, computed from the mesh before the
network runs: landmark distance fields (geodesic, :mod:`gegnn.fields.landmarks`) or truncated spectral codes
(biharmonic, :mod:`gegnn.fields.spectral`); and their cache, shared by every loader worker and every rank.

A landmark-guided model trains on one of a few landmark draws per (epoch, mesh) (an augmentation). The
heat-method fields of one draw cost ~0.29 s at K = 128 on a 5k-vertex mesh (one CPU thread), twice
what the rest of a batch of four meshes costs to build, and each is needed many times; spectral codes
(one draw: they involve no random choice) cost ~0.1 s at m = 32. Kept per loader worker, each worker would
recompute what the others had and hold ~10 MB per mesh in its own memory.

Here they are computed before the first step, every rank its share with local processes, into a folder
of NumPy files, one a (fields, mesh, draw), read back per sample (a few milliseconds):

    CACHE/format.json                          {"gegnn_field_cache": 2}
    CACHE/<spec>/<key[:2]>/<key>-<seed>.npy    float16 (N, K) landmark fields, float32 (N, m + 1) codes

``<spec>`` (:attr:`FieldSpec.name`) is ``k<K>-rounds16`` for a mesh's heat-method landmark fields (``k<K>-rounds16-vsp``
by virtual source propagation), ``k<K>-cloud<k>-surface2``
for a point cloud's and ``spectral<m>`` for spectral codes, then ``-v<n>`` where the values of that kind of
field are in their version n > 1 (:data:`FIELD_VERSIONS`). ``key`` is a hash of
the mesh's vertices and faces, not its id: an id names the raw file, and two stores made from one file
with other settings hold other meshes. So one cache can serve several runs and stores
(``gegnn train --field-cache DIR``), and a killed fill loses only the fields in flight.

Many processes may fill and read one cache at once (ranks, loader workers, concurrent runs): an entry is
written to a temporary file in its folder and published by ``os.link``, which never replaces a name, so
a file that exists is complete and is never rewritten; two writers of one entry (a duplicate mesh, two
runs) publish once and the other drops its copy. Nothing is pickled (``np.load(allow_pickle=False)``).

Landmark fields are stored as float16 (5.1 MB per mesh at K = 128, 4 draws and 5k vertices, half of
float32): a field read back differs from the computed one by at most 2^-11 of its value (2^-25 near 0).
Measured on five classic meshes of 5-7k vertices with the shipped model (K = 256, 2026-11-26,
docs/training.md), that moves the lower bound's mean relative error by at most +0.0024 and the model's by
at most +0.0011 percentage points (1.57% and 1.12% on decimated-max). Spectral codes stay float32 (one
draw of m + 1 columns: a small part of the bytes). A cache of format 1 (one zarr array per entry,
float32, rewritten in place while others could read it) is refused by name: its ``zarr.json`` at the root.
"""
from __future__ import annotations

import io
import json
import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from geodata.store import publish, temporary_name

from .landmarks import FPS_BATCH, landmark_solver
from .spectral import spectral_codes

__all__ = ["FieldSpec", "FieldCache", "estimate_fill", "readable", "LANDMARK_DRAWS", "FIELD_VERSIONS"]

FORMAT = 2  # 1: a zarr group of float32 arrays, each with a "complete" attribute (before 2026-11-26)
LANDMARK_DRAWS = 4  # landmark choices per training mesh (augmentation; each computed once, in the cache)
# The version of each kind of field's values, part of its cache folder's name (FieldSpec.name), so that a cache
# shared with another release never serves fields computed otherwise. Bump a kind's version whenever its values
# change (its solver, the value of a point it leaves unreached, the landmark choice); at 1 the name carries none.
FIELD_VERSIONS = {
    "heat": 1,        # a mesh's landmark fields by the heat method (gegnn.fields.landmarks)
    "vsp": 3,         # ... by virtual sources (geodata.approximate_geodesic); 2 (0.3.3): a gate at every
                      # saddle vertex, fast-marching updates after the propagation, no value below the chord;
                      # 3 (after 0.3.3): vertices at one place (an edge of zero length) take the point's excess
    "exact": 1,       # ... by the exact solver (gegnn.fields.landmarks._exact_field)
    "paths": 1,       # ... by its windows pruned within a tolerance (gegnn.fields.landmarks._paths_field)
    "cloud-heat": 2,  # a point cloud's by the heat method (gegnn.fields.cloud_heat); 2 (after 0.3.3): as cloud-vsp 3
    "cloud-vsp": 4,   # ... by virtual sources on its local triangles (gegnn.fields.cloud_vsp); 2 (0.3.3): a
                      # point they leave apart continued along the graph, where it was inf; no value below the chord;
                      # 3 (after 0.3.3): with a scan's normals, the neighbours on a point's own sheet and a projection
                      # fitted to its side (gegnn.fields.cloud_sides; a cloud without normals, as a cache holds it,
                      # keeps its values); 4: gates at every saddle point, the local triangulations of points
                      # moved 3% of a spacing (a regular grid's were ambiguous)
    "spectral": 1,    # spectral codes (gegnn.fields.spectral)
}


@dataclass(frozen=True)
class FieldSpec:
    """Which fields: ``"landmark"`` (K landmark distance fields per component) or ``"spectral"`` (m spectral
    modes and the tail scale), and K or m; ``cloud``: the k of a point-cloud model's neighbour graph, whose
    landmark fields come from the points alone (:mod:`gegnn.fields.pointcloud`), 0 for a mesh model;
    ``solver``: the landmark fields by the heat method (``"heat"``) or by virtual source propagation
    (``"vsp"``: a mesh's by :func:`gegnn.fields.landmarks.landmark_solver`, a cloud's on its local triangles
    glued in pairs, :mod:`gegnn.fields.cloud_vsp`)."""

    kind: str
    size: int
    cloud: int = 0
    solver: str = "heat"

    @classmethod
    def of(cls, config) -> "FieldSpec | None":
        """The fields a :class:`gegnn.GeGnnConfig` asks for (None for the paper's model)."""
        if config.landmarks:
            return cls("landmark", config.landmarks, config.points, config.landmark_fields)
        return cls("spectral", config.spectral) if config.spectral else None

    @property
    def draws(self) -> int:
        """Distinct seeds a training mesh is drawn with (spectral codes involve no choice)."""
        return LANDMARK_DRAWS if self.kind == "landmark" else 1

    @property
    def columns(self) -> int:
        """Columns of one mesh's fields: K landmark distances, or m spectral codes and the tail scale."""
        return self.size if self.kind == "landmark" else self.size + 1

    @property
    def dtype(self) -> type:
        """As stored: landmark fields float16 (their bytes are the cache's: 4 draws of K columns), spectral
        codes float32 (m + 1 columns, one draw; a biharmonic model's 0.2% error would feel 2^-11)."""
        return np.float16 if self.kind == "landmark" else np.float32

    @property
    def values(self) -> str:
        """The kind of field values, a key of :data:`FIELD_VERSIONS`."""
        if self.kind == "spectral":
            return "spectral"
        return ("cloud-" if self.cloud else "") + self.solver

    @property
    def name(self) -> str:
        """The cache folder of these fields: what they are, then their values' version where it is past 1."""
        version = FIELD_VERSIONS[self.values]
        return self._what() + (f"-v{version}" if version > 1 else "")

    def _what(self) -> str:
        if self.kind == "spectral":
            return f"spectral{self.size}"
        # "-surface2": point-cloud fields on surface_neighbors with twice-fitted cone normals (since
        # 2026-11-23, the second cloud release); "-rounds16": a mesh's landmarks chosen 16 a round (since
        # 2026-11-26, gegnn.fields.landmarks.FPS_BATCH): not those of older caches
        # "-vsp": fields by virtual source propagation (meshes since 2026-11-27, clouds since 2026-11-28); the
        # heat method's names are unchanged
        by = "" if self.solver == "heat" else f"-{self.solver}"  # "-vsp", "-exact", "-paths"
        if self.cloud:
            return f"k{self.size}-cloud{self.cloud}-surface2" + by
        return f"k{self.size}" + (f"-rounds{FPS_BATCH}" if FPS_BATCH > 1 else "") + by

    def compute(self, vertices: np.ndarray, faces: np.ndarray, seed: int = 0) -> np.ndarray:
        """The fields of one mesh, float32 (N, K) or (N, m + 1); for a point-cloud model, of its vertices as
        a point cloud (faces unused), the points of :func:`gegnn.fields.pointcloud.cloud_graph` (projected)."""
        return self.compute_draws(vertices, faces, [seed])[0]

    def compute_draws(self, vertices: np.ndarray, faces: np.ndarray, seeds) -> list[np.ndarray]:
        """:meth:`compute` for each of ``seeds``, the heat method set up once for all of them (at 5k
        vertices ~0.05 s of a mesh's ~0.15 s a draw, ~0.2 s of a cloud's ~0.4 s)."""
        if self.cloud:
            from .pointcloud import cloud_landmark_solver, graph_parts, knn_edges
            part = graph_parts(len(vertices), knn_edges(vertices, self.cloud)[0])
            solver = cloud_landmark_solver(vertices, part, solver=self.solver)
            return [solver(self.size, seed).distances for seed in seeds]
        if self.kind == "landmark":
            solver = landmark_solver(vertices, faces, self.size, fields=self.solver)
            return [solver(seed).distances for seed in seeds]
        codes = spectral_codes(vertices, faces, self.size)  # no choice: the same for every seed
        return [codes for _ in seeds]


class FieldCache:
    """The fields of one :class:`FieldSpec`, by mesh and seed.

    Args:
        path: the cache's folder (made on first use).
        spec: which fields.
    """

    def __init__(self, path, spec: FieldSpec):
        self.path, self.spec = str(path), spec
        self._checked = False

    def create(self) -> "FieldCache":
        """Make the folder and its format mark where they do not exist yet; refuse another format's."""
        root = Path(self.path)
        if (root / "zarr.json").exists():
            raise ValueError(f"{self.path}: a field cache of format 1 (zarr), which this gegnn no longer reads; "
                             "delete it or give another --field-cache (its fields are computed again)")
        mark = root / "format.json"
        if not mark.exists():
            root.mkdir(parents=True, exist_ok=True)
            _publish_bytes(mark, json.dumps({"gegnn_field_cache": FORMAT}).encode())
        found = json.loads(mark.read_text()).get("gegnn_field_cache")
        if found != FORMAT:
            raise ValueError(f"{self.path}: a field cache of format {found}, this gegnn reads format {FORMAT}; "
                             "give another --field-cache")
        self._checked = True
        return self

    def entry(self, key: str, seed: int) -> Path:
        """The file of one mesh's fields of one draw."""
        return Path(self.path, self.spec.name, key[:2], f"{key}-{seed}.npy")

    def has(self, key: str, seed: int) -> bool:
        """Whether the fields were published (a name lookup: no data is read)."""
        if not self._checked:
            self.create()
        return self.entry(key, seed).exists()

    def get(self, key: str, seed: int) -> np.ndarray | None:
        """The fields float32, or None where they were never published (or their name is claimed by a writer
        on a filesystem without hard links: an empty file, :func:`geodata.store.publish`)."""
        if not self._checked:
            self.create()
        try:
            return np.load(self.entry(key, seed), allow_pickle=False).astype(np.float32)
        except FileNotFoundError:
            return None
        except EOFError:
            if self.entry(key, seed).stat().st_size == 0:
                return None
            raise

    def put(self, key: str, seed: int, fields: np.ndarray) -> bool:
        """Publish the fields unless they already are; True when this call published them."""
        if not self._checked:
            self.create()
        path = self.entry(key, seed)
        if path.exists():
            return False
        path.parent.mkdir(parents=True, exist_ok=True)
        out = io.BytesIO()
        np.save(out, np.asarray(fields).astype(self.spec.dtype), allow_pickle=False)
        return _publish_bytes(path, out.getvalue())

    def fill(self, todo: list, jobs: int = 1, progress: bool = True) -> int:
        """Compute and store the fields of every ``(key, vertices, faces, seed)`` in ``todo`` with ``jobs``
        local processes, writing each as it arrives; returns how many this call published (an entry another
        process published meanwhile is not counted).

        The processes are spawned for this call and end with it: joblib's loky workers would idle on for
        5 minutes, and a torchrun or ``mp.spawn`` child cannot exit while they do. Each keeps to one thread;
        with ``jobs`` 1 the fields are computed here, on this process's threads."""
        from geodata.progress import progress_bar

        bar = progress_bar(total=len(todo), desc=f"{self.spec.kind} fields", leave=False, disable=not progress,
                           dynamic_ncols=True)
        meshes = {}  # the draws of one mesh in one task: its heat method set up once
        for key, vertices, faces, seed in todo:
            meshes.setdefault(key, (key, vertices, faces, []))[3].append(seed)
        jobs = min(jobs, len(meshes))
        published = 0
        if jobs <= 1:
            for task in meshes.values():
                for draw in _fields(*task, self.spec):
                    published += self.put(*draw)
                    bar.update()
        else:
            with ProcessPoolExecutor(jobs, mp_context=multiprocessing.get_context("spawn"),
                                     initializer=_one_thread) as pool:
                try:
                    for future in as_completed([pool.submit(_fields, *task, self.spec) for task in meshes.values()]):
                        for draw in future.result():
                            published += self.put(*draw)
                            bar.update()
                except BaseException:  # fail now: leaving the block would first compute every queued item
                    pool.shutdown(wait=False, cancel_futures=True)
                    raise
        bar.close()
        return published


def estimate_fill(todo: list, spec: FieldSpec, seconds_a_draw: float, vertices_measured: int
                  ) -> tuple[int, int, float]:
    """Entries, bytes on disk and CPU seconds of filling ``todo`` (as :meth:`FieldCache.fill` takes it):
    bytes N x columns x the stored item size, and the .npy header's 128, an entry; seconds the measured
    draw's (one of a mesh of ``vertices_measured`` vertices) scaled by N: a draw is a sparse solve per
    landmark, about linear in N at these sizes (its factorization, shared by a mesh's draws, is not)."""
    vertices = sum(len(t[1]) for t in todo)
    nbytes = sum(len(t[1]) * spec.columns * np.dtype(spec.dtype).itemsize + 128 for t in todo)
    return len(todo), nbytes, seconds_a_draw * vertices / max(vertices_measured, 1)


def readable(value: float, unit: str) -> str:
    """Bytes ("B": kB, MB, ... by 1000) or seconds ("s": min, h) in the largest unit that ``value`` reaches."""
    step, units = (1000, ("B", "kB", "MB", "GB", "TB")) if unit == "B" else (60, ("s", "min", "h"))
    k = 0
    while k + 1 < len(units) and value >= step ** (k + 1):
        k += 1
    return f"{value / step ** k:.3g} {units[k]}"


def _one_thread() -> None:
    """A fill process keeps to one core (torch's thread count, which gegnn.threads follows): there are as
    many processes as cores."""
    import torch

    torch.set_num_threads(1)


def _fields(key: str, vertices: np.ndarray, faces: np.ndarray, seeds: list, spec: FieldSpec) -> list[tuple]:
    return [(key, seed, fields) for seed, fields in zip(seeds, spec.compute_draws(vertices, faces, seeds))]


def _publish_bytes(path: Path, data: bytes) -> bool:
    """Write ``data`` to a temporary file beside ``path`` (flushed to disk: a node that fails later leaves no
    named empty file), then give it ``path`` as the store's meshes get theirs (:func:`geodata.store.publish`:
    the first writer wins and the file is never rewritten). True when this call published."""
    tmp = temporary_name(path)  # unique also among containers sharing a hostname and pid numbers
    with open(tmp, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())
    return publish(tmp, path)
