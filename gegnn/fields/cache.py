"""The per-vertex fields a model's decoder reads besides the embeddings, computed from the mesh before the
network runs: landmark distance fields (geodesic, :mod:`gegnn.fields.landmarks`) or truncated spectral codes
(biharmonic, :mod:`gegnn.fields.spectral`); and their cache, shared by every loader worker and every rank.

A landmark-guided model trains on one of a few landmark draws per (epoch, mesh) (an augmentation). The
heat-method fields of one draw cost ~0.29 s at K = 128 on a 5k-vertex mesh (one CPU thread), twice
what the rest of a batch of four meshes costs to build, and each is needed many times; spectral codes
(one draw: they involve no random choice) cost ~0.1 s at m = 32. Kept per loader worker, each worker would
recompute what the others had and hold ~10 MB per mesh in its own memory.

Here they are computed before the first step, every rank its share with local processes, into a zarr
group that is read back per sample (2.5 MB per draw at K = 128, a few milliseconds):

    CACHE/                    attrs: {"gegnn_landmark_cache": 1}
      <spec>/<key>/<seed>     float32 (N, columns), attrs {"complete": true} written last

``<spec>`` is ``k<K>`` for landmark fields and ``spectral<m>`` for spectral codes. ``key`` is a hash of
the mesh's vertices and faces, not its id: an id names the raw file, and two stores made from one file
with other settings hold other meshes. So one cache can serve several runs and stores
(``gegnn train --field-cache DIR``), and a killed fill loses only the fields in flight.
"""
from __future__ import annotations

import hashlib
import multiprocessing
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass

import numpy as np

from .landmarks import landmark_solver
from .spectral import spectral_codes

__all__ = ["FieldSpec", "FieldCache", "geometry_key", "LANDMARK_DRAWS"]

FORMAT = 1
LANDMARK_DRAWS = 4  # landmark choices per training mesh (augmentation; each computed once, in the cache)


@dataclass(frozen=True)
class FieldSpec:
    """Which fields: ``"landmark"`` (K heat-method landmark distance fields per component) or
    ``"spectral"`` (m spectral modes and the tail scale), and K or m; ``cloud``: the k of a point-cloud
    model's neighbour graph, whose landmark fields come from the points alone (:mod:`gegnn.fields.pointcloud`),
    0 for a mesh model."""

    kind: str
    size: int
    cloud: int = 0

    @classmethod
    def of(cls, config) -> "FieldSpec | None":
        """The fields a :class:`gegnn.GeGnnConfig` asks for (None for the paper's model)."""
        if config.landmarks:
            return cls("landmark", config.landmarks, config.points)
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
    def name(self) -> str:
        if self.kind == "spectral":
            return f"spectral{self.size}"
        # "-surface2": point-cloud fields on surface_neighbors with twice-fitted cone normals (since
        # 2026-11-23, the second cloud release): not those of older caches
        return f"k{self.size}" + (f"-cloud{self.cloud}-surface2" if self.cloud else "")

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
            solver = cloud_landmark_solver(vertices, part)
            return [solver(self.size, seed).distances for seed in seeds]
        if self.kind == "landmark":
            solver = landmark_solver(vertices, faces, self.size)
            return [solver(seed).distances for seed in seeds]
        codes = spectral_codes(vertices, faces, self.size)  # no choice: the same for every seed
        return [codes for _ in seeds]


def geometry_key(vertices: np.ndarray, faces: np.ndarray) -> str:
    """A content hash of a mesh (24 hex digits of the SHA-256 of its float32 vertices and int64 faces)."""
    h = hashlib.sha256(np.ascontiguousarray(vertices, dtype=np.float32).tobytes())
    h.update(np.ascontiguousarray(faces, dtype=np.int64).tobytes())
    return h.hexdigest()[:24]


class FieldCache:
    """The fields of one :class:`FieldSpec`, by mesh and seed.

    Args:
        path: the cache's zarr group (made on first use).
        spec: which fields.
    """

    def __init__(self, path, spec: FieldSpec):
        self.path, self.spec = str(path), spec
        self._root = None

    @property
    def root(self):
        if self._root is None:
            self.create()
        return self._root

    def create(self) -> "FieldCache":
        """Open the group, making it where it does not exist yet."""
        import zarr

        self._root = zarr.open_group(self.path, mode="a")
        if self._root.attrs.get("gegnn_landmark_cache") is None:
            self._root.attrs["gegnn_landmark_cache"] = FORMAT
        return self

    def _name(self, key: str, seed: int) -> str:
        return f"{self.spec.name}/{key}/{seed}"

    def has(self, key: str, seed: int) -> bool:
        """Whether the fields were completed (their attributes only: no array data is read)."""
        name = self._name(key, seed)
        return name in self.root and bool(self.root[name].attrs.get("complete"))

    def get(self, key: str, seed: int) -> np.ndarray | None:
        """The fields float32, or None where they were never completed."""
        return np.asarray(self.root[self._name(key, seed)][:]) if self.has(key, seed) else None

    def put(self, key: str, seed: int, fields: np.ndarray) -> None:
        array = self.root.create_array(self._name(key, seed), shape=fields.shape, dtype=np.float32,
                                       chunks=fields.shape, overwrite=True)
        array[:] = fields
        array.attrs["complete"] = True

    def fill(self, todo: list, jobs: int = 1, progress: bool = True) -> None:
        """Compute and store the fields of every ``(key, vertices, faces, seed)`` in ``todo`` with ``jobs``
        local processes, writing each as it arrives.

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
        if jobs <= 1:
            for task in meshes.values():
                for draw in _fields(*task, self.spec):
                    self.put(*draw)
                    bar.update()
        else:
            with ProcessPoolExecutor(jobs, mp_context=multiprocessing.get_context("spawn"),
                                     initializer=_one_thread) as pool:
                try:
                    for future in as_completed([pool.submit(_fields, *task, self.spec) for task in meshes.values()]):
                        for draw in future.result():
                            self.put(*draw)
                            bar.update()
                except BaseException:  # fail now: leaving the block would first compute every queued item
                    pool.shutdown(wait=False, cancel_futures=True)
                    raise
        bar.close()


def _one_thread() -> None:
    """A fill process keeps to one core (torch's thread count, which gegnn.threads follows): there are as
    many processes as cores."""
    import torch

    torch.set_num_threads(1)


def _fields(key: str, vertices: np.ndarray, faces: np.ndarray, seeds: list, spec: FieldSpec) -> list[tuple]:
    return [(key, seed, fields) for seed, fields in zip(seeds, spec.compute_draws(vertices, faces, seeds))]
