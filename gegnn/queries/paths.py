"""Geodesic paths from a distance field: follow its steepest descent from the target to the source.

The geodesic from t to s runs against the gradient of the distance field d(s, .) (Kimmel & Sethian
1998; the paper's Section 4). The tracer walks face by face, with one descent direction per face:

- towards the face's *virtual source*: the point s' of the face's plane with |s' - p_k| = d_k at its
  three corners (trilateration: s' = p0 + q with q . e_k = (d0^2 - d_k^2 + |e_k|^2) / 2, e_k = p_k - p0).
  Where the field is the distance from a point of the unfolded plane this is the true direction, so a
  path on a flat mesh comes out straight, where the linear interpolant's gradient would zigzag by
  O(h). Where the three values are not consistent with a point (a learned field's noise: s' more than
  45 degrees off the gradient), the direction is -grad d of the linear interpolant instead;
- inside a face, the path is the ray along that direction from where it entered, up to the edge it
  leaves by;
- at a vertex, it takes the incident face whose direction points into that face and descends fastest,
  or, where no face has one (a ridge), the edge to the neighbour with the steepest decrease;
- it ends with a straight segment as soon as it is on a face or edge that touches the source.

Only the field values of the vertices it visits are asked for (a lazy cache), so a path costs
O(k) distance queries for the k faces it crosses. A learned field can have a spurious local minimum;
there the path finishes along the shortest edge path and says so (``Path.traced`` is False).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Path", "SurfaceTopology", "trace_path", "face_gradient", "descent_direction"]

SNAP = 1e-9  # a ray leaving a face this close (in barycentric units) to a corner leaves by the corner


@dataclass
class Path:
    """A polyline on the surface from the source to the target: points (K, 3), in the mesh's units.

    ``traced`` is False where the field had a local minimum away from the source and the path had to
    finish along mesh edges."""

    points: np.ndarray
    traced: bool = True

    @property
    def length(self) -> float:
        from geodata.geodesic import polyline_length
        return polyline_length(self.points)


class SurfaceTopology:
    """Vertex-to-face and edge-to-face adjacency of a triangle mesh (built once, O(F))."""

    def __init__(self, vertices, faces):
        self.vertices = np.asarray(vertices, dtype=np.float64)
        self.faces = np.asarray(faces, dtype=np.int64)
        flat = self.faces.ravel()
        order = np.argsort(flat, kind="stable")
        self._vf = order // 3
        self._vf_ptr = np.searchsorted(flat[order], np.arange(len(self.vertices) + 1))
        self._edge_faces: dict[tuple[int, int], list[int]] = {}
        for fi, (a, b, c) in enumerate(self.faces.tolist()):
            for x, y in ((a, b), (b, c), (c, a)):
                self._edge_faces.setdefault((x, y) if x < y else (y, x), []).append(fi)

    def faces_of(self, v: int) -> np.ndarray:
        return self._vf[self._vf_ptr[v]:self._vf_ptr[v + 1]]

    def across(self, a: int, b: int, face: int) -> int:
        """The other face on edge (a, b), or -1 on a boundary (or a non-manifold edge)."""
        faces = self._edge_faces.get((a, b) if a < b else (b, a), [])
        others = [f for f in faces if f != face]
        return others[0] if len(faces) == 2 and others else -1

    def neighbours(self, v: int) -> np.ndarray:
        return np.setdiff1d(self.faces[self.faces_of(v)].ravel(), [v])


class _LazyField:
    """Field values computed on first use, for the missing vertices of each request in one batch."""

    def __init__(self, fn, n: int):
        self.fn, self.values = fn, np.full(n, np.nan)

    def __getitem__(self, idx):
        idx = np.atleast_1d(np.asarray(idx, dtype=np.int64))
        missing = np.unique(idx[np.isnan(self.values[idx])])
        if len(missing):
            self.values[missing] = self.fn(missing)
        return self.values[idx]


def face_gradient(p: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Gradient of the linear interpolation of values ``d`` (3,) over the triangle ``p`` (3, 3):
    grad = -[(d1 - d0) (n x e2) + (d2 - d0) (e1 x n)] / |n|^2, e1 = p1 - p0, e2 = p2 - p0, n = e1 x e2
    (it satisfies grad . e1 = d1 - d0, grad . e2 = d2 - d0, grad . n = 0)."""
    e1, e2 = p[1] - p[0], p[2] - p[0]
    n = np.cross(e1, e2)
    return -((d[1] - d[0]) * np.cross(n, e2) + (d[2] - d[0]) * np.cross(e1, n)) / max(n @ n, 1e-300)


def descent_direction(p: np.ndarray, d: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Unit direction in which the field ``d`` (3,) decreases on the triangle ``p`` (3, 3) from the point
    ``at``: towards the virtual source where that is consistent with the gradient (module docstring);
    zero on a flat field."""
    g = face_gradient(p, d)
    g_norm = np.linalg.norm(g)
    if g_norm == 0:
        return g
    e1, e2 = p[1] - p[0], p[2] - p[0]
    x, y = _solve_gram(e1, e2, (d[0] ** 2 - d[1] ** 2 + e1 @ e1) / 2, (d[0] ** 2 - d[2] ** 2 + e2 @ e2) / 2)
    return -g / g_norm if x is None else _towards(p[0] + x * e1 + y * e2 - at, -g / g_norm)


def _towards(to_source, fallback):
    """``to_source`` normalized, or ``fallback`` when that is more than 45 degrees off it."""
    norm = np.linalg.norm(to_source)
    if norm == 0 or to_source @ fallback < np.cos(np.pi / 4) * norm:
        return fallback
    return to_source / norm


def _solve_gram(u, w, ru, rw):
    """(x, y) with (x u + y w) . u = ru and (x u + y w) . w = rw; (None, None) for a degenerate pair."""
    uu, uw, ww = u @ u, u @ w, w @ w
    det = uu * ww - uw * uw
    if det <= 1e-30 * uu * ww:
        return None, None
    return (ru * ww - rw * uw) / det, (rw * uu - ru * uw) / det


def _in_basis(direction: np.ndarray, u: np.ndarray, w: np.ndarray) -> tuple[float, float]:
    """Coefficients (x, y) of the in-plane ``direction`` = x u + y w ((0, 0) on a degenerate face)."""
    x, y = _solve_gram(u, w, direction @ u, direction @ w)
    return (0.0, 0.0) if x is None else (x, y)


def trace_path(topology: SurfaceTopology, distance_from_source, source: int, target: int) -> Path:
    """The path from ``source`` to ``target`` along the steepest descent of the field.

    Args:
        topology: the mesh.
        distance_from_source: ``f(vertex indices) -> distances from source`` (vectorized).
        source, target: vertex indices.
    """
    V, F = topology.vertices, topology.faces
    n = len(V)
    for v in (source, target):
        if not 0 <= v < n:
            raise IndexError(f"vertex {v} out of range ({n} vertices)")
    field = _LazyField(distance_from_source, n)
    points = [V[target]]
    vertex, edge = int(target), None  # the walker is at a vertex, or on an edge (e0, e1, t, face)
    for _ in range(4 * len(F) + 16):
        if vertex is not None:
            if vertex == source:
                return Path(np.array(points[::-1]))
            faces = topology.faces_of(vertex)
            if (F[faces] == source).any():
                points.append(V[source])
                return Path(np.array(points[::-1]))
            vertex, edge = _leave_vertex(topology, field, vertex, faces, points)
            if vertex is None and edge is None:  # a local minimum of the field away from the source
                break
        else:
            e0, e1, t, face = edge
            if source in (e0, e1):
                points.append(V[source])
                return Path(np.array(points[::-1]))
            vertex, edge = _cross_face(topology, field, e0, e1, t, face, source, points)
            if vertex == -1:
                return Path(np.array(points[::-1]))
    return _finish_on_edges(topology, points, source)


def _leave_vertex(topology, field, v, faces, points):
    V, F = topology.vertices, topology.faces
    best, best_slope = None, 0.0
    for fi in faces:
        a, b = (int(x) for x in F[fi] if x != v)
        tri = V[[v, a, b]]
        d = field[[v, a, b]]
        direction = descent_direction(tri, d, tri[0])
        x, y = _in_basis(direction, tri[1] - tri[0], tri[2] - tri[0])
        slope = -float(face_gradient(tri, d) @ direction)
        if x >= -SNAP and y >= -SNAP and x + y > 0 and slope > best_slope:
            best, best_slope = (fi, a, b, max(x, 0.0), max(y, 0.0)), slope
    if best is not None:
        fi, a, b, x, y = best
        t = y / (x + y)  # the ray from v meets edge (a, b) at a + t (b - a)
        if t < SNAP or t > 1 - SNAP:
            nxt = a if t < SNAP else b
            points.append(V[nxt])
            return nxt, None
        points.append(V[a] + t * (V[b] - V[a]))
        return None, (a, b, t, int(fi))
    nbrs = topology.neighbours(v)
    slopes = (field[v] - field[nbrs]) / np.linalg.norm(V[nbrs] - V[v], axis=1)
    if slopes.max() <= 0:
        return None, None
    nxt = int(nbrs[np.argmax(slopes)])
    points.append(V[nxt])
    return nxt, None


def _cross_face(topology, field, e0, e1, t, came_from, source, points):
    """From the point e0 + t (e1 - e0) into the face across the edge from ``came_from``."""
    V, F = topology.vertices, topology.faces
    fi = topology.across(e0, e1, came_from)
    if fi < 0:  # boundary: slide along the edge to its lower end
        nxt = e0 if field[e0][0] <= field[e1][0] else e1
        points.append(V[nxt])
        return nxt, None
    c = int(next(x for x in F[fi] if x != e0 and x != e1))
    if c == source:
        points.append(V[source])
        return -1, None
    direction = descent_direction(V[[e0, e1, c]], field[[e0, e1, c]], V[e0] + t * (V[e1] - V[e0]))
    ea, eb = V[e0] - V[c], V[e1] - V[c]
    x, y = _in_basis(direction, ea, eb)
    alpha, beta = 1 - t, t  # p = c + alpha ea + beta eb; edge (e0, e1) is alpha + beta = 1
    if x + y >= 0:  # the descent points back over the edge: follow the edge down
        nxt = e0 if field[e0][0] <= field[e1][0] else e1
        points.append(V[nxt])
        return nxt, None
    s_beta = -beta / y if y < 0 else np.inf   # where beta reaches 0: edge (c, e0)
    s_alpha = -alpha / x if x < 0 else np.inf  # where alpha reaches 0: edge (c, e1)
    if s_beta <= s_alpha:
        end, w = e0, alpha + s_beta * x       # point c + w (V[e0] - c)
    else:
        end, w = e1, beta + s_alpha * y
    w = min(max(w, 0.0), 1.0)
    if w < SNAP:
        points.append(V[c])
        return c, None
    if w > 1 - SNAP:
        points.append(V[end])
        return end, None
    points.append(V[c] + w * (V[end] - V[c]))
    return None, (c, end, w, fi)


def _finish_on_edges(topology, points, source) -> Path:
    """From the last point's nearest vertex to the source along the shortest edge path."""
    import scipy.sparse
    from scipy.sparse.csgraph import dijkstra

    from geodata.mesh import unique_edges

    V, F = topology.vertices, topology.faces
    start = int(np.argmin(np.linalg.norm(V - points[-1], axis=1)))
    e = unique_edges(F)  # each edge once: a face list repeating an edge would otherwise sum its lengths
    w = np.linalg.norm(V[e[:, 0]] - V[e[:, 1]], axis=1)
    graph = scipy.sparse.coo_matrix((w, (e[:, 0], e[:, 1])), shape=(len(V), len(V))).tocsr()
    _, pred = dijkstra(graph, directed=False, indices=start, return_predecessors=True)
    chain, v = [], int(source)
    while v != start and v >= 0:
        chain.append(v)
        v = int(pred[v])
    if v < 0:
        raise ValueError("the source is not on the target's connected part")
    points = points + [V[start]] + [V[u] for u in reversed(chain)]
    return Path(np.array(points[::-1]), traced=False)
