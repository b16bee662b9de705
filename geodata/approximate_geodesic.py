"""Approximate geodesic distance fields by virtual source propagation: 0.1-0.3% from the exact solver's, at
a few percent of its cost.

Each face carries one virtual source, a point S_f of its own plane and a distance sigma_f, so that a
point X of the face is at ``sigma_f + |S_f - X|`` from the source vertex along a path straight in the
unfolding. A face hands its source to each neighbour g, unfolded across the shared edge ab; where the ray
from S to g's centroid crosses ab, g takes it, else g's source becomes the endpoint e of ab the ray
passes, at distance d(e) (the path bends around e). g's third vertex c gets ``sigma + |S - c|`` where c
itself is seen through ab, else ``sigma + |S - e| + |e - c|``; every vertex keeps its least value, and a
face that improves (nearer at its centroid) is queued to hand its source on again. Where g keeps S
although the ray to c passes a vertex that is not a plane's (saddle or convex), that vertex becomes a gate:
points beyond it are reached around it, never straight through an excess angle the surface lacks (GSP:
Trettner, Bommes, Kobbelt, "Geodesic Distance Computation via Virtual Source Propagation", CGF 40(5) 2021;
details in ``src/virtual_source_geodesic.cpp``). One source a face leaves a vertex reached around a gate a
little long where paths that passed the gate's other side reach it straight: fast marching's triangle update
over the faces takes most of the surplus back. No value is taken below the straight segment from the source
(less 0.1%). On a flat mesh the fields are exact.

Measured against the exact solver (benchmarks/bench_field_solver.py --zoo, docs/benchmarks.md "The shape
zoo"): mean relative error 0.07-0.33% on every shape of :mod:`geodata.zoo` (tori, bent tubes, a coil, a
trefoil knot, a T pipe, a saddle patch, a genus-3 plate, a filleted part, slivers, noise; 0.30-0.48% on the
trefoil at 22-64k vertices), where gates only at saddles of excess over 0.05 rad cut corners by 1.5-10% on
the tori and tubes; 0.11-0.22% on six classic meshes. The fields come out a little long rather than short
(signed mean -0.09 to +0.30%); the worst vertex of a field, beside its source, is a few percent off. Cost on
one core: 1.8 ms a field at 5.3k vertices, linear in the mesh from 84k on (880 ms at 1.35M); memory ~0.9 kB a
vertex. Several sources run on threads, with the same fields for any thread count. A value is not always the
length of a path on the surface: where a path bends at a boundary vertex or across strong noise, a source
can light faces it does not see, and the vertex comes out short (an icosphere(3) with radii jittered by up to
8%: a field's worst vertex 12% short, 130 of its 642 fields with a vertex over 5% short; 5%: 6%, 2 fields).
No check catches that short of an exact solve: the segment from the source, the one bound at hand, is itself
that shortcut.

Unlike the exact solver it needs no closed surface: boundaries are fine, vertices of other connected parts
get ``inf``, faces may be oriented against each other; edges shared by three or more faces and vertices
whose faces form two or more fans (pinched) are refused. :func:`manifold_copy` makes a copy of such a mesh
that it takes (the landmark fields of a model's own proxy or a user's non-manifold mesh use it).
"""
from __future__ import annotations

import os

import numpy as np

__all__ = ["ApproximateGeodesicSolver", "approximate_geodesic_distances", "manifold_copy"]


class ApproximateGeodesicSolver:
    """A mesh prepared once for approximate geodesic fields from any of its vertices.

    Args:
        vertices: (N, 3) float coordinates, all finite.
        faces: (M, 3) integer vertex indices in [0, N); no edge in three or more faces, no vertex whose
            faces form two or more fans.
        twins: (3M,) optional: the half-edge 3 g + j glued to each half-edge 3 f + k (from corner k to
            k + 1), -1 for none, each glued back; for a surface whose edges its two vertices do not tell
            (a point cloud's triangle soup: :mod:`gegnn.fields.cloud_vsp`). Pinched vertices are then taken (a
            path bends there at the vertex's distance), and each field ends with d_i <= d_j + |ij| over the edges
            (a shortest-path queue: a fold can leave a vertex reached only the long way round).
        excess: (N,) optional: each vertex's angle excess for the gates, where its faces' corner angles
            (less 2 pi, the default) do not give it: a cloud's local triangulations overlap, a tufted cover
            counts each corner twice.
        saddle: the angle excess (radians) from which a saddle vertex is a gate (default: any, above
            rounding).
        convex: convex vertices are gates too (the default: every vertex but a plane's is one). A cloud's
            soup, whose excess comes from overlapping fans, is solved without convex gates.

    Raises:
        ValueError: naming what is wrong with the mesh (shapes, non-finite coordinates, indices out of
            range, non-manifold edges or vertices, twins not glued back or joining other vertices).
    """

    def __init__(self, vertices, faces, twins=None, excess=None, saddle: float = 1e-6, convex: bool = True):
        from geodata._virtual_source_geodesic import VirtualSources

        vertices, faces = _checked_mesh(vertices, faces)
        self.n_vertices = len(vertices)
        twins = None if twins is None else np.ascontiguousarray(twins, dtype=np.int64)
        excess = None if excess is None else np.ascontiguousarray(excess, dtype=np.float64)
        self._native = VirtualSources(vertices, faces, twins, excess)  # counts non-manifold edges and vertices
        self.gates = dict(saddle=float(saddle), convex=bool(convex))

    def distances(self, sources, threads: int | None = None) -> np.ndarray:
        """Distances from each source vertex to every vertex.

        Args:
            sources: vertex indices (S,) (or one int).
            threads: how many sources run at once (default: the CPUs this process may use); the
                result is the same for any count.

        Shapes:
            returns (S, N) float64, ``inf`` on vertices of other connected parts.
        """
        sources = np.atleast_1d(np.asarray(sources))
        if sources.ndim != 1 or (len(sources) and not np.issubdtype(sources.dtype, np.integer)):
            raise ValueError(f"sources must be a 1-D array of vertex indices, got {sources.dtype} {sources.shape}")
        bad = (sources < 0) | (sources >= self.n_vertices)
        if bad.any():
            raise ValueError(f"{int(bad.sum())} source vertices out of range (e.g. {int(sources[bad][0])}); "
                             f"the mesh has {self.n_vertices} vertices")
        if threads is None:
            threads = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
        sources = np.ascontiguousarray(sources, dtype=np.int64)
        try:
            fields = self._native.distances(sources, threads=max(1, int(threads)), **self.gates)
        except MemoryError:  # on any thread: each needs ~100 bytes a face
            raise MemoryError(f"approximate geodesic fields of {len(sources)} sources on {self.n_vertices:,} "
                              f"vertices: out of memory (~{100 * self.n_vertices * 2 / 2 ** 20:.0f} MiB a thread, "
                              f"{threads} threads, and the fields' {8 * len(sources) * self.n_vertices / 2 ** 20:.0f} "
                              f"MiB)") from None
        return fields


def approximate_geodesic_distances(vertices, faces, sources, threads: int | None = None) -> np.ndarray:
    """Approximate geodesic distances (S, N) float64 from each of ``sources`` to every vertex, by
    :class:`ApproximateGeodesicSolver` (prepare a solver once where a mesh serves several calls)."""
    return ApproximateGeodesicSolver(vertices, faces).distances(sources, threads)


def manifold_copy(vertices, faces) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """A copy of a mesh that :class:`ApproximateGeodesicSolver` takes, for fields on one it refuses:

    - faces with an edge of zero length (a repeated or coincident corner) are set aside: no path crosses them;
    - on an edge of three or more faces, all but its first two (in face order) are set aside;
    - a vertex whose remaining faces form two or more fans (joined by no edge through the vertex) becomes one
      vertex a fan: the first fan keeps the index, the others get copies appended after the N vertices.

    Returns vertices (N', 3), faces (M', 3), ``origin`` (N',) the input vertex of each, and the number of faces
    set aside. A vertex's distance is the least of its copies' (``origin[N:]`` lists the copies). Paths that
    crossed a set-aside face go around it, and paths through a split vertex another way, where there is one
    (two squares joined at one corner become two parts): distances only grow, and only near the defects. A
    vertex left in no face, or only reached through a split vertex, gets ``inf``."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    vertices, faces = _checked_mesh(vertices, faces)
    n = len(vertices)
    nxt = np.roll(faces, -1, axis=1)
    keep = (np.linalg.norm(vertices[faces] - vertices[nxt], axis=2) > 0).all(axis=1)
    edge = np.sort(np.stack([faces, nxt], axis=2), axis=2).reshape(-1, 2)  # face i's edges at rows 3i..3i+2
    key = edge[:, 0] * n + edge[:, 1]
    order = np.lexsort((np.repeat(np.arange(len(faces)), 3), key))  # by edge, then face
    order = order[np.repeat(keep, 3)[order]]
    sorted_key = key[order]
    start = np.r_[True, sorted_key[1:] != sorted_key[:-1]]
    rank = np.arange(len(order)) - np.maximum.accumulate(np.where(start, np.arange(len(order)), 0))
    keep[order[rank >= 2] // 3] = False  # the third and later faces of an edge
    kept = faces[keep]
    # corners (3M') joined through the edges at their vertex: corner c of vertex v meets edges (v, next) and
    # (v, previous); corners of one vertex sharing such an edge are in one fan
    corner = kept.ravel()
    ends = np.concatenate([np.roll(kept, -1, axis=1).ravel(), np.roll(kept, 1, axis=1).ravel()])
    link_key, link = np.unique(np.tile(corner, 2) * n + ends, return_inverse=True)
    nc = len(corner)
    graph = sp.coo_matrix((np.ones(2 * nc), (np.tile(np.arange(nc), 2), nc + link.ravel())),
                          shape=(nc + len(link_key),) * 2)
    fan = connected_components(graph, directed=False)[1][:nc]
    pairs, which = np.unique(np.stack([corner, fan], axis=1), axis=0, return_inverse=True)
    first = np.r_[True, pairs[1:, 0] != pairs[:-1, 0]]  # sorted by vertex: its first fan keeps the index
    ids = pairs[:, 0].copy()
    ids[~first] = n + np.arange(int((~first).sum()))
    origin = np.concatenate([np.arange(n), pairs[~first, 0]])
    return vertices[origin], ids[which.ravel()].reshape(-1, 3), origin, int(len(faces) - len(kept))


def _checked_mesh(vertices, faces) -> tuple[np.ndarray, np.ndarray]:
    """Contiguous float64 (N, 3) vertices and int64 (M, 3) faces, or ValueError in the mesh's terms."""
    vertices, faces = np.asarray(vertices), np.asarray(faces)
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise ValueError(f"vertices must be (N, 3), got {vertices.shape}")
    if faces.ndim != 2 or faces.shape[1] != 3 or (faces.size and not np.issubdtype(faces.dtype, np.integer)):
        raise ValueError(f"faces must be (M, 3) vertex indices, got {faces.dtype} {faces.shape}")
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    bad = ~np.isfinite(vertices).all(axis=1)
    if bad.any():
        raise ValueError(f"{int(bad.sum())} vertices with non-finite coordinates (e.g. vertex {int(np.argmax(bad))})")
    out = (faces < 0) | (faces >= len(vertices))
    if out.any():
        raise ValueError(f"{int(out.any(axis=1).sum())} faces index vertices out of range "
                         f"(e.g. face {int(np.argmax(out.any(axis=1)))}); the mesh has {len(vertices)} vertices")
    return vertices, np.ascontiguousarray(faces, dtype=np.int64)
