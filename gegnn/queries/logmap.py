"""The discrete logarithmic map (geodesic polar coordinates) from constant-time distance queries.

Around a center c, a vertex v at geodesic distance r = d(c, v) has log-map coordinates w = r (cos t, sin t)
in the tangent plane at c, t the direction in which the geodesic leaves c. Distance queries give t
without tracing anything (after Xin et al. 2012 and Panozzo et al. 2013, who did it with all-pairs
distances): for stencil vertices q_k near c (their tangent-plane positions known from the local
geometry), the law of cosines in the tangent plane reads

    d(q_k, v)^2 = |w - q_k|^2 = r^2 + |q_k|^2 - 2 q_k . w,   so   q_k . w = (r^2 + |q_k|^2 - d(q_k, v)^2) / 2,

which is linear in w: one least-squares solve with the same 2 x K matrix for every v, then w is
scaled to length r (the most accurate number there is). On a plane with exact distances it is exact.
The stencil is the ``rings``-ring of c projected onto the tangent plane (area-weighted normal), each
point at its true distance |q_k - c| from c; a wider stencil averages out a learned field's noise.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["LogMap", "log_map", "stencil", "tangent_frame", "vector_heat_log_map"]


@dataclass
class LogMap:
    """Log-map coordinates ``uv`` (M, 2) of mesh ``vertices`` (M,) within ``radius`` of ``center``, in
    the mesh's units, in the tangent ``frame`` (2, 3) at the center (rows: the u and v axes)."""

    center: int
    vertices: np.ndarray
    uv: np.ndarray
    frame: np.ndarray
    radius: float


def tangent_frame(topology, center: int) -> np.ndarray:
    """Orthonormal (u, v) axes (2, 3) of the tangent plane at ``center``: the normal is the area-weighted
    mean of the incident face normals, u the projected direction to the lowest-numbered neighbour, and
    v = n x u (counter-clockwise seen from outside)."""
    V, F = topology.vertices, topology.faces
    tri = V[F[topology.faces_of(center)]]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]).sum(axis=0)
    n /= np.linalg.norm(n)
    first = V[topology.neighbours(center)[0]] - V[center]
    u = first - (first @ n) * n
    u /= np.linalg.norm(u)
    return np.stack([u, np.cross(n, u)])


def stencil(topology, center: int, rings: int) -> np.ndarray:
    """The vertices within ``rings`` edge rings of ``center``, without it, ascending."""
    ring, seen = np.array([center]), {center}
    for _ in range(rings):
        nxt = np.unique(np.concatenate([topology.neighbours(v) for v in ring]))
        ring = np.array([v for v in nxt if v not in seen])
        seen.update(ring.tolist())
    return np.array(sorted(seen - {center}))


def log_map(topology, distance, center: int, radius: float | None = None, rings: int = 2) -> LogMap:
    """Log-map coordinates around ``center`` of the vertices of its connected part with
    d(center, v) <= ``radius``.

    Args:
        topology: :class:`gegnn.queries.paths.SurfaceTopology` of the mesh.
        distance: ``f(i, j) -> distances`` for index arrays (e.g. :meth:`gegnn.Embedding.distance`).
        center: vertex index.
        radius: in the mesh's units; None: every vertex of the center's part.
        rings: stencil width in edge rings (1 for exact distances; 2, the default, for learned ones).
    """
    V = topology.vertices
    if not 0 <= center < len(V):
        raise IndexError(f"vertex {center} out of range ({len(V)} vertices)")
    frame = tangent_frame(topology, center)
    near = stencil(topology, center, rings)
    offsets = V[near] - V[center]
    planar = offsets @ frame.T
    # each stencil point at its true distance from the center, in its projected direction
    q = planar * (np.linalg.norm(offsets, axis=1) / np.maximum(np.linalg.norm(planar, axis=1), 1e-300))[:, None]
    from geodata.mesh import Mesh, vertex_components

    labels = vertex_components(Mesh(V, topology.faces))
    r_all = distance(np.full(len(V), center), np.arange(len(V)))
    inside = np.isfinite(r_all) & (r_all <= (np.inf if radius is None else radius)) & (labels == labels[center])
    inside[center] = True
    vertices = np.flatnonzero(inside)
    r = r_all[vertices]
    d = distance(np.repeat(near[None], len(vertices), 0), np.repeat(vertices[:, None], len(near), 1))
    rhs = (r[:, None] ** 2 + (q ** 2).sum(axis=1)[None] - d ** 2) / 2      # (M, K) = q_k . w
    w = rhs @ np.linalg.pinv(q).T                                          # (M, 2)
    norm = np.linalg.norm(w, axis=1)
    uv = np.where(norm[:, None] > 0, w * (r / np.maximum(norm, 1e-300))[:, None], 0.0)
    uv[vertices == center] = 0.0
    return LogMap(center, vertices, uv, frame, float(np.max(r)) if radius is None else float(radius))


def vector_heat_log_map(vertices, faces, reference: LogMap) -> tuple[np.ndarray, float]:
    """potpourri3d's vector-heat log map (Sharp et al. 2019) at ``reference``'s center and vertices,
    rotated onto ``reference``'s tangent frame (the rotation that fits best: the two methods pick
    their u axes differently), and the mean |difference| of the two over the radius, where both are
    defined (the vector heat method gives NaN on meshes it cannot handle, e.g. non-manifold ones: a
    ValueError when that is everywhere)."""
    import potpourri3d as pp

    solver = pp.MeshVectorHeatSolver(np.asarray(vertices, dtype=np.float64), np.asarray(faces))
    theirs = solver.compute_log_map(reference.center)[reference.vertices]
    ok = np.isfinite(theirs).all(axis=1)
    if ok.sum() < 2:
        raise ValueError("the vector heat method gives no log map on this mesh")
    u, _, vt = np.linalg.svd(theirs[ok].T @ reference.uv[ok])  # orthogonal Procrustes
    rotation = u @ np.diag([1.0, np.sign(np.linalg.det(u @ vt))]) @ vt
    aligned = theirs @ rotation
    return aligned, float(np.linalg.norm(aligned[ok] - reference.uv[ok], axis=1).mean() / reference.radius)
