"""Exact polyhedral geodesic distances (MMP family) and the pair sampler.

Three backends compute the same exact distances:

- ``vtp`` (default): this package's own window-propagation solver (``src/exact_geodesic.cpp``), the
  fastest; the mesh is prepared once for all sources of a mesh.
- ``gdist``: tvb-gdist, Kirsanov's implementation of Surazhsky et al. (it rebuilds its mesh per call).
- ``libigl``: libigl's ``exact_geodesic``, the same Kirsanov code: the reference the others are tested
  against (to 1e-9 relative).

and two approximate them, for meshes too large for an exact solve of every source:

- ``paths``: vtp with its windows pruned wherever a real path is within PATHS_TOLERANCE (0.03%) of them, so
  every value is still a real path's length, never below exact: 0.005-0.05% above it on average (up to ~0.2%
  at a field's worst vertex; thin tubes the most), 1.2-4.5x faster than vtp (docs/benchmarks.md, the frontier).
- ``vsp``: virtual source propagation (:mod:`geodata.approximate_geodesic`), 0.1-0.3% from exact on
  average over the shape zoo and classic meshes (a few percent at a field's worst vertex, and below exact
  there where a path bends at a boundary or across noise), 6-8x faster than vtp at 5k vertices and linear in
  the mesh.

A store made with either names it in its parameters (``geodesic_backend``), and each of its meshes records its
error measured against vtp (:func:`approximation_error`).

Kirsanov's code segfaults on non-manifold input, so every call first checks the closed-manifold
invariants; the same guard keeps the contract of the ``vtp`` solver, which is only tested on such meshes.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from geodata.exact_memory import require_memory
from geodata.mesh import Mesh, MeshError, require_closed_manifold, vertex_components

__all__ = ["BACKENDS", "APPROXIMATE", "PATHS_TOLERANCE", "geodesic_solver", "exact_geodesic_distances", "sample_sources",
           "exact_geodesic_pairs", "approximation_error", "PROBED_UP_TO", "polyline_length", "edge_flip_paths"]

BACKENDS = ("vtp", "gdist", "libigl", "paths", "vsp")
APPROXIMATE = ("paths", "vsp")  # the approximate backends (their errors: the module docstring, docs/benchmarks.md)
PATHS_TOLERANCE = 3e-4  # the paths backend's window pruning, and the "paths" landmark fields' (gegnn.fields.landmarks)
def geodesic_solver(mesh: Mesh, backend: str = "vtp") -> Callable[[int], np.ndarray]:
    """A function source -> exact geodesic distances (float64, (N,)) from that vertex to every vertex.

    Only distances within the source's connected component are meaningful (vtp and gdist give inf
    elsewhere, libigl 0). Whatever a backend precomputes for the mesh is done once, here. A mesh whose
    one-source vtp solve is estimated to need more memory than is available
    (:func:`geodata.exact_memory.require_memory`) is refused here, before anything is allocated, with MeshError("geodesic").
    """
    if backend in ("vtp", "paths"):
        require_memory(mesh.n_vertices)
        from geodata._exact_geodesic import Surface

        surface = Surface(np.ascontiguousarray(mesh.vertices, dtype=np.float64),
                          np.ascontiguousarray(mesh.faces, dtype=np.int32))
        tolerance = PATHS_TOLERANCE if backend == "paths" else 0.0
        return lambda source: surface.distances(np.array([source], dtype=np.int64), tolerance)[0]
    if backend == "gdist":
        import gdist

        vertices, faces = mesh.vertices.astype(np.float64), mesh.faces.astype(np.int32)
        return lambda source: gdist.compute_gdist(vertices, faces, np.array([source], dtype=np.int32))
    if backend == "vsp":
        from geodata.approximate_geodesic import ApproximateGeodesicSolver

        solver = ApproximateGeodesicSolver(mesh.vertices, mesh.faces)
        return lambda source: solver.distances([source], threads=1)[0]
    if backend == "libigl":
        import igl

        targets = np.arange(mesh.n_vertices, dtype=np.int64)
        # Keywords only: positional slots silently return an empty array (libigl-python-bindings#284).
        return lambda source: igl.exact_geodesic(V=mesh.vertices, F=mesh.faces,
                                                 VS=np.array([source], dtype=np.int64), VT=targets)
    raise ValueError(f"unknown geodesic backend {backend!r}; choose from {BACKENDS}")


def exact_geodesic_distances(mesh: Mesh, source: int, backend: str = "vtp") -> np.ndarray:
    """Exact geodesic distance (float64, (N,)) from vertex `source` to every vertex (see `geodesic_solver`)."""
    return geodesic_solver(mesh, backend)(source)


PROBED_UP_TO = 50_000  # vertices: an exact probe costs ~1 s a source at 50k, ~100 s at 1M (N^1.5)


def approximation_error(mesh: Mesh, pairs: np.ndarray, distances: np.ndarray, probes: int = 2) -> float | None:
    """The mean relative error of approximate pairs (from :func:`exact_geodesic_pairs` with an approximate
    backend) against the exact solver's, over every pair of their first ``probes`` sources: what a store
    made with ``vsp`` records for each mesh (its attribute ``geodesic_error``), measured, not assumed. None
    for a mesh of more than ``PROBED_UP_TO`` vertices, where the probes would cost a hundred times the pairs
    themselves (the backend is for such meshes): its error is the one the store's parameters state."""
    if mesh.n_vertices > PROBED_UP_TO:
        return None
    sources = _first_seen(pairs[:, 0])[:probes]
    exact = geodesic_solver(mesh, "vtp")
    errors = []
    for s in sources:
        rows = pairs[:, 0] == s
        truth = exact(int(s))[pairs[rows, 1].astype(np.int64)]
        errors.append(np.abs(distances[rows] - truth) / truth)
    return float(np.concatenate(errors).mean())


def _first_seen(values: np.ndarray) -> np.ndarray:
    """The distinct values in the order they first appear."""
    _, first = np.unique(values, return_index=True)
    return values[np.sort(first)]


def polyline_length(points: np.ndarray) -> float:
    """Length of the polyline through ``points`` (K, 3)."""
    return float(np.linalg.norm(np.diff(points, axis=0), axis=1).sum())


def edge_flip_paths(mesh: Mesh, pairs, converged: bool = False) -> list[np.ndarray]:
    """Locally shortest surface paths (polylines (K, 3)) between the vertex ``pairs`` (P, 2), by
    potpourri3d's edge flips (FlipOut, Sharp & Crane 2020), one solver for all pairs. They are real
    surface paths, so their lengths bound the geodesic distance from above, and on the meshes here
    they reach it. ``converged``: flip until no flip shortens a path (potpourri3d stops earlier by
    default)."""
    import potpourri3d as pp3d

    solver = pp3d.EdgeFlipGeodesicSolver(mesh.vertices, mesh.faces)
    options = dict(max_iterations=100000, max_relative_length_decrease=0.0) if converged else {}
    return [solver.find_geodesic_path(int(s), int(t), **options) for s, t in pairs]


def sample_sources(labels: np.ndarray, n_pairs: int, rng: np.random.Generator) -> np.ndarray:
    """Distinct random sources, just enough that sources x (other vertices of their component) >= n_pairs."""
    order = rng.permutation(len(labels))
    targets_per_source = np.bincount(labels)[labels[order]] - 1
    n_sources = int(np.searchsorted(np.cumsum(targets_per_source), n_pairs)) + 1
    return order[:n_sources]


def exact_geodesic_pairs(mesh: Mesh, n_pairs: int, rng: np.random.Generator, backend: str = "vtp"
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pairs (P, 2) uint32 and exact distances (P,) float32 (approximate with ``backend`` "paths" or "vsp"): sources x
    every other vertex of their component.

    Sources come in the order of `sample_sources`. Kirsanov's code, rarely, leaves a vertex unreached
    from one particular source of a clean mesh (libigl/libigl#1013; inf from gdist, 0 from libigl); from
    any backend, such a source is skipped for the next one and returned as the third value. A mesh where
    more than a tenth of the sources fail is refused.
    """
    require_closed_manifold(mesh, "geodesic")  # a broken mesh would crash the native code
    solve = geodesic_solver(mesh, backend)
    labels = vertex_components(mesh)
    pairs, dists, skipped, total = [], [], [], 0
    for s in rng.permutation(mesh.n_vertices):
        if total >= n_pairs:
            break
        d = solve(int(s))
        targets = np.flatnonzero((labels == labels[s]) & (np.arange(len(labels)) != s))
        if not (np.isfinite(d[targets]).all() and (d[targets] > 0).all()):
            skipped.append(s)
            if len(skipped) > max(2, len(pairs) // 10):
                raise MeshError("geodesic", f"unreached vertices from {len(skipped)} sources")
            continue
        pairs.append(np.stack([np.full(len(targets), s), targets], axis=1))
        dists.append(d[targets])
        total += len(targets)
    return (np.concatenate(pairs).astype(np.uint32), np.concatenate(dists).astype(np.float32),
            np.array(skipped, dtype=np.int64))
