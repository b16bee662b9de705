r"""Point-cloud distance fields by virtual source propagation on the tufted cover of the points' local
Delaunay triangulations: the mesh solver's accuracy where the triangles close into a surface, and no holes
where they do not.

The soup is every point's local triangles (:func:`gegnn.fields.cloud_heat.local_triangulations`, the
point-cloud heat method's), each distinct triangle once. It is no mesh: an edge may have one face or
five. Its tufted cover (Sharp and Crane 2020, :func:`gegnn.fields.heat.tufted_cover`) is: every triangle
twice, a front and a back, glued so that each edge joins exactly two faces (around an edge of n
triangles, each one's back to the next one's front). Its intrinsic geometry is the soup's: a path on the
cover is a path over the triangles, and between two triangles of one edge it may pass either way. The
virtual-source solver (:mod:`geodata.approximate_geodesic`) lays faces out from their edges alone, so it
runs on the cover as given, its half-edges glued explicitly (``twins``).

The gates of the solver (saddle vertices, angle excess over 0.05 rad) take each point's excess from its
own local triangles, :math:`\sum_{(i, a, b)} \angle a i b - 2\pi` over the triangles point i emitted:
the cover counts every corner twice and the soup a point's corners of every triangulation it is in.

Measured (``benchmarks/bench_field_solver.py --cloud-lower-bound``, six meshes' vertices as clouds, the
landmark bound at K = 256, mean relative error): 2.56% against the point-cloud heat method's 3.67%; the
same solver on a manifold copy of the soup (its non-manifold triangles set aside) left holes: 4.35%.
Where two parts lie within a spacing (thin parts, a flipper on a body) the local triangles bridge them
and the fields take the bridge at full length: too short there, as the heat method is.
"""
from __future__ import annotations

import numpy as np

from geodata.mesh import unique_edges

from .heat import tufted_cover

__all__ = ["CloudVirtualSources", "cover_mesh", "own_excess", "relax_along_edges"]


def cover_mesh(points: np.ndarray, soup: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The tufted cover of a triangle soup (F, 3) as faces (2F, 3) and twins (6F,): fronts are the soup's
    triangles, back f is front f reversed, ``(a, c, b)``; ``twins[h]`` is the half-edge glued to half-edge
    h = 3 f + k (from corner k to corner k + 1), as :func:`gegnn.fields.heat.tufted_cover` glues them."""
    n_f = len(soup)
    cover = tufted_cover(points, soup)
    # the cover's back half-edge 3F + 3f + c runs from corner c + 1 to c of front f; in the back face
    # (a, c, b) that is half-edge 2 - c
    h = np.arange(6 * n_f)
    ours = h.copy()
    back = h >= 3 * n_f
    ours[back] += 2 - 2 * ((h[back] - 3 * n_f) % 3)
    twins = np.empty(6 * n_f, dtype=np.int64)
    twins[ours] = ours[cover.sib]
    return np.concatenate([soup, soup[:, [0, 2, 1]]]).astype(np.int64), twins


def own_excess(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Each point's angle excess (N,) over the triangles it emitted (their first corner): the sum of their
    angles at it, less 2 pi."""
    a, b, c = points[triangles[:, 0]], points[triangles[:, 1]], points[triangles[:, 2]]
    u, w = b - a, c - a
    angle = np.arctan2(np.linalg.norm(np.cross(u, w), axis=1), np.einsum("ij,ij->i", u, w))
    return np.bincount(triangles[:, 0], angle, minlength=len(points)) - 2.0 * np.pi


class CloudVirtualSources:
    """Distance fields on one point cloud from its local triangles (N, 3 points; the (F, 3) soup of
    :func:`gegnn.fields.cloud_heat.local_triangulations`, each triangle emitted by its first corner).

    ValueError where the points or triangles are not a cloud's (shapes, non-finite coordinates, indices
    out of range)."""

    def __init__(self, points: np.ndarray, triangles: np.ndarray):
        from geodata.approximate_geodesic import ApproximateGeodesicSolver

        points = np.ascontiguousarray(points, dtype=np.float64)
        triangles = np.asarray(triangles, dtype=np.int64)
        soup = triangles[np.unique(np.sort(triangles, axis=1), axis=0, return_index=True)[1]]
        faces, twins = cover_mesh(points, soup)
        self.n_points = len(points)
        self._points = points
        self._edges = unique_edges(soup)
        self._solver = ApproximateGeodesicSolver(points, faces, twins=twins, excess=own_excess(points, triangles))

    def distances(self, sources, threads: int = 1) -> np.ndarray:
        """Distances (N, len(sources)) from each source point to every point (``inf`` on other parts),
        each at most a soup edge's length beyond its neighbour's (:func:`relax_along_edges`)."""
        d = self._solver.distances(np.asarray(sources, dtype=np.int64), threads=threads).T
        return relax_along_edges(d, self._points, self._edges)


def relax_along_edges(fields: np.ndarray, points: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """``fields`` (N, S) with every value at most its neighbour's plus their edge's length,
    :math:`d_i \le d_j + |p_i - p_j|` over ``edges`` (E, 2) (Bellman-Ford rounds on the edges of the
    points that moved, until none does). A distance field obeys it; a point that the cover reaches only
    by a detour (folds around it) does not, and gets its neighbours' value plus the step."""
    a, b = edges.T
    w = np.linalg.norm(points[a] - points[b], axis=1)[:, None]
    active = np.ones(len(edges), dtype=bool)
    while active.any():
        ea, eb, ew = a[active], b[active], w[active]
        before = fields.copy()
        np.minimum.at(fields, ea, fields[eb] + ew)
        np.minimum.at(fields, eb, fields[ea] + ew)
        moved = (fields < before).any(axis=1)
        active = moved[a] | moved[b]
    return fields
