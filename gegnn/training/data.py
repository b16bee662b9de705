"""Reading a geodata store (zarr v3) and turning meshes into training batches.

Sampling is a pure function of (seed, epoch, mesh id): a batch does not depend on which process or
loader worker makes it, so resumed, multi-worker and multi-process runs see identical data.
"""
from __future__ import annotations

import hashlib
import logging
from collections import OrderedDict
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import torch
from torch import Tensor

from geodata import store as geostore
from geodata.store import geometry_key

from ..fields.cache import FieldCache, FieldSpec
from ..graph import Graph, Tensors, disjoint_union, mesh_graph, random_rotation
from ..nn.geopool import Hierarchy, build_hierarchy

__all__ = ["GeodesicStore", "MeshGeometry", "Batch", "split_meshes", "epoch_batches", "sample_mesh",
           "make_batch", "BatchDataset", "EpochSampler"]

DISTANCES = ("geodesic", "biharmonic")
VAL_EPOCH = -1  # rng stream of the fixed validation sample
GEOMETRY_CACHE = 64  # meshes a dataset keeps per process (every loader worker has its own)
log = logging.getLogger("gegnn")


@dataclass
class MeshGeometry:
    vertices: np.ndarray  # float32 (N, 3), normalized
    normals: np.ndarray   # float32 (N, 3)
    edges: np.ndarray     # int64 (E, 2), undirected
    faces: np.ndarray     # int64 (F, 3)
    derived_from: str | None = None  # a point cloud's: the key of the stored mesh its points were made from

    @cached_property
    def key(self) -> str:
        """The field cache's key: the content hash (:func:`geodata.store.geometry_key`) of the stored mesh,
        for a point cloud the one its points were made from (so that every rank can tell duplicates
        apart from the store alone)."""
        return self.derived_from or geometry_key(self.vertices, self.faces)


class GeodesicStore:
    """Read-only view of a store written by ``geodata prepare``: its published meshes (for biharmonic
    distances, those whose ``biharmonic`` subgroup is published too), but for orphans (meshes no input maps to
    any more: an input edited or removed since, :func:`geodata.accounting.orphans`) unless ``include_orphans``.
    The ids are one listing of meshes/ and the prepare runs' ledgers, read when first asked for; a mesh's
    arrays and attributes are read when asked for."""

    def __init__(self, path, distance: str = "geodesic", include_orphans: bool = False):
        if distance not in DISTANCES:
            raise ValueError(f"distance must be one of {DISTANCES}, got {distance!r}")
        self.path, self.distance, self.include_orphans = str(path), distance, include_orphans
        try:
            self.root = geostore.open_store(self.path)
        except geostore.StoreError as exc:
            raise ValueError(str(exc)) from None

    @cached_property
    def _published(self) -> dict[str, set[str]]:
        return geostore.list_meshes(self.path)

    @cached_property
    def orphans(self) -> list[str]:
        """Published meshes no input maps to any more (left out of ``mesh_ids`` unless ``include_orphans``)."""
        from geodata.accounting import orphans

        unreadable: dict = {}
        ledgers = geostore.read_ledgers(self.path, unreadable)
        return orphans(ledgers, self._published, unreadable)

    @cached_property
    def mesh_ids(self) -> list[str]:
        left_out = set() if self.include_orphans else set(self.orphans)
        if left_out:
            log.warning("%s: %d orphaned meshes left out (no input maps to them any more; `geodata info %s` "
                        "lists them)", self.path, len(left_out), self.path)
        return [m for m, subs in self._published.items()
                if (self.distance == "geodesic" or self.distance in subs) and m not in left_out]

    def attrs(self, mesh_id: str) -> dict:
        """The mesh's attributes (source, sha256, geometry_key, params, timings, ...)."""
        return geostore.mesh_attrs(self.path, mesh_id)

    def key(self, mesh_id: str) -> str:
        """The field cache's key of the mesh: its geometry key recorded at prepare time (no array is read)."""
        return self.attrs(mesh_id)["geometry_key"]

    def geometry(self, mesh_id: str) -> MeshGeometry:
        with geostore.read_mesh(self.path, mesh_id) as g:
            return MeshGeometry(np.asarray(g["vertices"][:], dtype=np.float32),
                                np.asarray(g["normals"][:], dtype=np.float32),
                                np.asarray(g["edges"][:], dtype=np.int64),
                                np.asarray(g["faces"][:], dtype=np.int64))

    def pairs(self, mesh_id: str) -> tuple[np.ndarray, np.ndarray]:
        """All stored pairs (P, 2) int64 and their distances (P,) float32."""
        if self.distance == "geodesic":
            with geostore.read_mesh(self.path, mesh_id) as g:
                return np.asarray(g["geodesic/pairs"][:], dtype=np.int64), np.asarray(g["geodesic/distances"][:],
                                                                                      dtype=np.float32)
        with geostore.read_mesh(self.path, mesh_id, self.distance) as g:
            return np.asarray(g["pairs"][:], dtype=np.int64), np.asarray(g["distances"][:], dtype=np.float32)


def mesh_hash(mesh_id: str) -> int:
    """A stable 63-bit hash of a mesh id (Python's hash() is salted per process)."""
    return int.from_bytes(hashlib.sha256(mesh_id.encode()).digest()[:8], "little") >> 1


def split_meshes(mesh_ids: list[str], val_fraction: float = 0.1) -> tuple[list[str], list[str]]:
    """Deterministic train/validation split by hash of the mesh id; at least one validation mesh
    (and one training mesh) whenever there are two or more meshes and ``val_fraction > 0``."""
    ranked = sorted(mesh_ids, key=mesh_hash)
    val = {m for m in ranked if mesh_hash(m) / 2 ** 63 < val_fraction}
    if len(ranked) >= 2 and val_fraction > 0:
        if not val:
            val = {ranked[0]}
        if len(val) == len(ranked):
            val.discard(ranked[-1])
    return sorted(set(mesh_ids) - val), sorted(val)


def epoch_batches(mesh_ids: list[str], epoch: int, seed: int, batch_size: int, rank: int = 0,
                  world: int = 1) -> list[tuple[str, ...]]:
    """This rank's batches for one epoch: a seeded permutation dealt round-robin to the ranks (sharded
    by mesh). Every rank gets the same number of batches (short shards wrap around) so that
    DistributedDataParallel never waits on a rank that ran out."""
    if not mesh_ids:
        return []
    order = np.random.default_rng([seed, epoch]).permutation(len(mesh_ids))
    per_rank = -(-len(mesh_ids) // world)
    shard = [mesh_ids[order[(rank + k * world) % len(order)]] for k in range(per_rank)]
    return [tuple(shard[s:s + batch_size]) for s in range(0, len(shard), batch_size)]


@dataclass
class Sample:
    graph: Graph
    pairs: Tensor      # long (P, 2), local vertex indices
    distances: Tensor  # float (P,)
    fields: Tensor | None = None  # float (N, C) landmark fields or spectral codes (gegnn.fields.cache)


@dataclass
class Batch(Tensors):
    """A disjoint union of meshes with its GeoPool hierarchy and sampled pairs (global indices)."""

    hierarchy: Hierarchy
    pairs: Tensor
    distances: Tensor
    mesh_ids: tuple[str, ...]
    fields: Tensor | None = None


def sample_mesh(geometry: MeshGeometry, pairs: np.ndarray, distances: np.ndarray,
                rng: np.random.Generator | None, num_pairs: int | None, rotate: bool,
                fields: np.ndarray | None = None) -> Sample:
    """Pick ``num_pairs`` stored pairs (all if None or more than stored) and, with ``rotate``, rotate
    coordinates and normals by one random rotation (distances are invariant, the network is not).
    ``fields``: the mesh's fields (N, C) for a model that reads them (:mod:`gegnn.fields.cache`)."""
    v, n = geometry.vertices, geometry.normals
    if rotate:
        r = random_rotation(rng).astype(np.float32)
        v, n = v @ r.T, n @ r.T
    if num_pairs is not None and num_pairs < len(pairs):
        keep = rng.choice(len(pairs), num_pairs, replace=False)
        pairs, distances = pairs[keep], distances[keep]
    return Sample(mesh_graph(v, n, geometry.edges), torch.from_numpy(pairs), torch.from_numpy(distances),
                  None if fields is None else torch.from_numpy(fields))


def make_batch(samples: list[Sample], mesh_ids, levels: int, sigma_c: float, sigma_n: float) -> Batch:
    union, offsets = disjoint_union([s.graph for s in samples])
    pairs = torch.cat([s.pairs + o for s, o in zip(samples, offsets.tolist())])
    fields = torch.cat([s.fields for s in samples]) if samples[0].fields is not None else None
    return Batch(build_hierarchy(union, levels, sigma_c, sigma_n), pairs,
                 torch.cat([s.distances for s in samples]), tuple(mesh_ids), fields)


class BatchDataset(torch.utils.data.Dataset):
    """Map-style dataset whose keys are ``(epoch, mesh_ids)``: the loader's workers build whole
    batches, hierarchy included, so the training process only runs the network.

    Args:
        store_path, distance: the store to read (opened lazily in each worker process).
        seed: data seed; sampling uses the rng stream (seed, epoch, mesh hash).
        num_pairs: pairs per mesh (None: all stored pairs).
        rotate: random rotation augmentation.
        levels, sigma_c, sigma_n: the model's GeoPool settings.
        fields: the per-vertex fields the model reads (:class:`gegnn.fields.cache.FieldSpec`; None: none).
            Training draws one of ``fields.draws`` choices (seeds: landmark draws) per (epoch, mesh) as
            augmentation; validation uses seed 0, as ``GeGnn.embed`` does.
        field_cache: a :class:`gegnn.fields.cache.FieldCache` path the fields are read from (training fills it
            first); fields missing there, or without a cache, are computed per use.
        cloud: for a point-cloud model, k: each mesh's vertices are read as a point cloud, its projected
            points, graph and normals made from them alone (:func:`gegnn.fields.pointcloud.cloud_graph`); 0: the
            mesh's own.
    """

    def __init__(self, store_path, distance, seed, num_pairs, rotate, levels, sigma_c, sigma_n,
                 fields: FieldSpec | None = None, field_cache: str | None = None, cloud: int = 0):
        self.store_path, self.distance, self.seed = str(store_path), distance, seed
        self.num_pairs, self.rotate, self.fields, self.cloud = num_pairs, rotate, fields, cloud
        self.levels, self.sigma_c, self.sigma_n = levels, sigma_c, sigma_n
        self.field_cache = field_cache
        self._store, self._geometries, self._cache = None, OrderedDict(), None

    @property
    def store(self) -> GeodesicStore:
        if self._store is None:
            self._store = GeodesicStore(self.store_path, self.distance)
        return self._store

    def __getitem__(self, key) -> Batch:
        epoch, mesh_ids = key
        samples = [self.sample(epoch, m) for m in mesh_ids]
        return make_batch(samples, mesh_ids, self.levels, self.sigma_c, self.sigma_n)

    def sample(self, epoch: int, mesh_id: str) -> Sample:
        rng = np.random.default_rng([self.seed, epoch + 1, mesh_hash(mesh_id)])  # epoch -1 -> 0 is val
        pairs, distances = self.store.pairs(mesh_id)
        fields = None
        if self.fields is not None:  # the draw: seed 0 for validation, else one of fields.draws
            fields = self.mesh_fields(mesh_id, 0 if epoch == VAL_EPOCH else int(rng.integers(self.fields.draws)))
        return sample_mesh(self.geometry(mesh_id), pairs, distances, rng, self.num_pairs,
                           self.rotate and epoch != VAL_EPOCH, fields)

    def geometry(self, mesh_id: str) -> MeshGeometry:
        """The mesh's geometry as the model reads it (:meth:`as_input`), the last GEOMETRY_CACHE meshes kept
        (~200 kB per 5k-vertex mesh: the validation meshes, seen every epoch, and small stores stay; a
        worker's memory stays bounded on a large one). Pairs (~7 MB a mesh) are read per use."""
        if mesh_id in self._geometries:
            self._geometries.move_to_end(mesh_id)
        else:
            self._geometries[mesh_id] = self.as_input(self.store.geometry(mesh_id))
            while len(self._geometries) > GEOMETRY_CACHE:
                self._geometries.popitem(last=False)
        return self._geometries[mesh_id]

    def as_input(self, stored: MeshGeometry) -> MeshGeometry:
        """A stored mesh's geometry as the model reads it: itself, or for a point-cloud model the projected
        points, graph and normals of its vertices alone (faces kept; the stored mesh's key)."""
        if not self.cloud:
            return stored
        from ..fields.pointcloud import cloud_graph
        c = cloud_graph(stored.vertices.astype(np.float64), self.cloud)
        return MeshGeometry(c.points.astype(np.float32), c.normals.astype(np.float32), c.edges, stored.faces,
                            stored.key)

    def mesh_fields(self, mesh_id: str, seed: int) -> np.ndarray:
        g = self.geometry(mesh_id)
        if self.field_cache is not None:
            if self._cache is None:
                self._cache = FieldCache(self.field_cache, self.fields)
            cached = self._cache.get(g.key, seed)
            if cached is not None:
                return cached
        return self.fields.compute(g.vertices, g.faces, seed)

    def __getstate__(self):  # worker processes reopen the store themselves
        return {**self.__dict__, "_store": None, "_geometries": OrderedDict(), "_cache": None}


class EpochSampler(torch.utils.data.Sampler):
    """Yields ``(epoch, batch)`` keys of the current epoch; ``set_epoch`` before each pass."""

    def __init__(self, mesh_ids, seed, batch_size, rank=0, world=1):
        self.mesh_ids, self.seed, self.batch_size, self.rank, self.world = mesh_ids, seed, batch_size, rank, world
        self.epoch = 0

    def set_epoch(self, epoch: int) -> None:
        self.epoch = epoch

    def batches(self, epoch: int):
        return epoch_batches(self.mesh_ids, epoch, self.seed, self.batch_size, self.rank, self.world)

    def __iter__(self):
        return iter([(self.epoch, b) for b in self.batches(self.epoch)])

    def __len__(self) -> int:
        return len(self.batches(self.epoch))
