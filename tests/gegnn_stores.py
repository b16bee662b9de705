"""Test helpers for gegnn: small meshes, and geodata stores written with plain zarr in the contract layout
(exact geodesics from tvb-gdist)."""
from __future__ import annotations

import gdist
import numpy as np
import trimesh

from geodata import store
from geodata.biharmonic import biharmonic_distances
from geodata.mesh import Mesh, unique_edges, vertex_normals
from geodata.stages.normalize import normalize


def ellipsoid(axes=(1.0, 0.7, 0.5), subdivisions=2) -> tuple[np.ndarray, np.ndarray]:
    m = trimesh.creation.icosphere(subdivisions)
    return np.asarray(m.vertices) * np.asarray(axes), np.asarray(m.faces)


def fibonacci_sphere(n: int, center=(0.0, 0.0, 0.0), radius: float = 1.0) -> np.ndarray:
    """n near-uniform points of a sphere (a Fibonacci lattice), as a point cloud (N, 3)."""
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    r, phi = np.sqrt(1 - z * z), np.pi * (1 + 5 ** 0.5) * i
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1) * radius + np.asarray(center)


def flat_grid(n=12) -> tuple[np.ndarray, np.ndarray]:
    """A triangulated square: geodesic distance equals Euclidean distance."""
    x, y = np.meshgrid(np.linspace(-1, 1, n), np.linspace(-1, 1, n), indexing="ij")
    v = np.stack([x.ravel(), y.ravel(), np.zeros(n * n)], axis=1)
    k = np.arange(n * n).reshape(n, n)
    a, b, c, d = k[:-1, :-1].ravel(), k[1:, :-1].ravel(), k[1:, 1:].ravel(), k[:-1, 1:].ravel()
    return v, np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])


def exact_pairs(v: np.ndarray, f: np.ndarray, sources: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sources x all other vertices, exact polyhedral geodesics (tvb-gdist)."""
    pairs, dists = [], []
    targets = np.arange(len(v), dtype=np.int32)
    for s in sources:
        d = gdist.compute_gdist(v.astype(np.float64), f.astype(np.int32), np.array([s], np.int32), targets)
        keep = targets != s
        pairs.append(np.stack([np.full(keep.sum(), s), targets[keep]], 1))
        dists.append(d[keep])
    return np.concatenate(pairs).astype(np.uint32), np.concatenate(dists).astype(np.float32)


def write_store(path, meshes: dict, num_sources: int = 8, biharmonic: bool = False, seed: int = 0) -> str:
    """A store in the geodata layout (geodata.store's writer), with exact biharmonic distances of the same
    pairs in biharmonic/; a failure record and a writer's leftover temporary file besides, which readers skip."""
    rng = np.random.default_rng(seed)
    store.create_store(path, {"pairs": num_sources})
    for mesh_id, (v, f) in meshes.items():
        v = normalize(Mesh(v, f)).vertices
        arrays = {"vertices": v.astype(np.float32), "faces": f.astype(np.int32),
                  "normals": vertex_normals(Mesh(v, f)).astype(np.float32),
                  "edges": unique_edges(f).astype(np.int32)}
        sources = rng.choice(len(v), min(num_sources, len(v)), replace=False)
        pairs, dists = exact_pairs(v, f, sources)
        arrays.update({"geodesic/pairs": pairs, "geodesic/distances": dists})
        store.write_mesh(path, mesh_id, arrays, {"source": f"{mesh_id}.obj",
                                                 "geometry_key": store.geometry_key(v, f)})
        if biharmonic:
            row = {int(src): k for k, src in enumerate(sources)}
            rows = np.array([row[int(src)] for src in pairs[:, 0]])
            bh = biharmonic_distances(Mesh(v, f), sources)[rows, pairs[:, 1]].astype(np.float32)
            store.write_mesh(path, mesh_id, {"pairs": pairs, "distances": bh}, {}, "biharmonic")
    store.record_failure(path, "broken_mesh", "broken.obj", "load", "no faces")
    (store.mesh_file(path, "unfinished").parent / ".unfinished.zip.host.1.tmp").write_bytes(b"PK")  # a killed writer's
    return str(path)


FOUR_MESHES = {
    "ellipsoid_a": ellipsoid((1.0, 0.7, 0.5)),
    "ellipsoid_b": ellipsoid((0.6, 1.0, 0.8)),
    "sphere": ellipsoid((1.0, 1.0, 1.0)),
    "grid": flat_grid(12),
}


def small_config(channels=16, blocks=1, **kw):
    from gegnn import GeGnnConfig
    return GeGnnConfig(channels=channels, embed_dim=channels, decoder_hidden=channels,
                       encoder_blocks=(blocks,) * 5, decoder_blocks=(blocks,) * 5, **kw)


def overfit(store, steps, channels=64, distance="geodesic", **options):
    """MRE on the mesh "ellipsoid" of ``store`` before the first step and after ``steps`` steps of a small
    model with ``options`` (GeGnnConfig fields)."""
    import torch

    from gegnn import GeGnn
    from gegnn.training.data import BatchDataset
    from gegnn.fields.cache import FieldSpec
    from gegnn.training.loop import lr_at, train_step
    from gegnn.metrics import relative_error

    torch.manual_seed(0)
    model = GeGnn(small_config(channels, **options))
    batch = BatchDataset(store, distance, 0, None, False, 5, 1 / 16, 3 / 16,
                         FieldSpec.of(model.config))[(0, ("ellipsoid",))]
    opt = torch.optim.AdamW(model.parameters(), lr=3e-3, weight_decay=0.01)
    first = train_step(model, batch, opt, 3e-3, 0.0, torch.device("cpu")).item()
    for s in range(1, steps):
        train_step(model, batch, opt, lr_at(s, steps, 3e-3, 0), 0.0, torch.device("cpu"))
    with torch.no_grad():
        return first, relative_error(model(batch.hierarchy, batch.pairs, batch.fields), batch.distances).mean().item()
