r"""Point-cloud distance fields by virtual source propagation on the points' local Delaunay triangles,
glued in pairs around each edge: the mesh solver's accuracy where the triangles close into a surface.

The soup is every point's local triangles (:func:`gegnn.fields.cloud_heat.local_triangulations`, the
point-cloud heat method's), each distinct triangle once, those more points' triangulations agree on first.
It is no mesh: an edge may have one face or five. The virtual-source solver
(:mod:`geodata.approximate_geodesic`) lays each face out from its own edges and hands a source across a
glued pair of half-edges, so it runs on the soup as given with the gluing explicit (``twins``):

* **pairs** (the default, :func:`paired_mesh`): around each edge its faces in soup order, the first glued
  to the second, the third to the fourth; an odd one out is a boundary there. Every triangle is kept, once.
* **cover** (:func:`cover_mesh`): the soup's tufted cover (Sharp and Crane 2020,
  :func:`gegnn.fields.heat.tufted_cover`, as the cloud heat method's Laplacian): every triangle twice, a
  front and a back, each edge's n triangles glued in a ring (each one's back to the next one's front).

Measured, the landmark bound at K = 256 over 20 sources x every point of six meshes' vertices taken as clouds
(``benchmarks/bench_field_solver.py --cloud-lower-bound``, docs/notes/pointclouds-lab.md): pairs 2.65%, cover
2.59%, the cloud heat method 3.68% (exact fields 0.40%); the fields themselves against the exact ones at the
same 256 landmarks: pairs 2.39% (0.26% on horse, 0.27% on max, 5.98% on penguin), cover 2.48%, the heat
method 3.55%; landmark-v3's weights on the 19 validation clouds (``gegnn eval``, all stored pairs): pairs
2.98%, cover 3.09% (pairs better on 17 of 19; landmark-v2's weights on the cloud heat method's fields: 3.47%); 256 fields at 5k points 0.36 s (pairs), 1.03 s (cover), 0.23 s
(the heat method), one core beside a training run. Setting the soup's non-manifold triangles aside instead
(a manifold copy) leaves holes that paths go around: 4.35%.

Cut edges can leave a point reached only the long way round while its straight neighbours are near (a
2,000-point cloud of the dragon had one, 7x too far from a landmark, and the network's answers over the
whole cloud were 160% off): with twins the solver ends each field with :math:`d_i \le d_j + |p_i - p_j|`
over the edges (a shortest-path queue from every point; it lowers 8-17% of the values, by 0.06% at the
median, and moves the fields' mean error by under 0.01 points).

The solver's gates (every saddle point, as a mesh's, but no convex ones: a point's convex excess comes from
overlapping fans; gates only from 0.05 rad, up to 0.3.3, let tubes' saddle regions be cut across: points-v3
on the zoo's trefoil cloud 3.6%, 0.45% at every saddle, the 19 validation clouds 2.18% / 2.17% with
normals) take each point's excess from its own local triangles, :math:`\sum_{(i, a, b)} \angle a i b - 2\pi`
over the triangles point i emitted: the soup holds a point's corners of every triangulation it is in (and a
cover each twice).

Where two parts lie within a spacing (thin parts, a flipper on a body) the local triangles bridge them and
the fields take the bridge at full length: too short there, as the heat method's are.
"""
from __future__ import annotations

import numpy as np

from .heat import tufted_cover

__all__ = ["CloudVirtualSources", "agreed_soup", "paired_mesh", "cover_mesh", "own_excess", "GLUINGS"]

GLUINGS = ("pairs", "cover")


def agreed_soup(triangles: np.ndarray) -> np.ndarray:
    """Each distinct triangle of the points' local triangulations once (F, 3), those that more points'
    triangulations emit first (a stable order among equals)."""
    triangles = np.asarray(triangles, dtype=np.int64)
    _, first, agree = np.unique(np.sort(triangles, axis=1), axis=0, return_index=True, return_counts=True)
    return triangles[first[np.argsort(-agree, kind="stable")]]


def paired_mesh(points: np.ndarray, soup: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The soup (F, 3) itself with twins (3F,): around each edge its half-edges in face order, glued in
    pairs (first to second, third to fourth, ...), an odd one out left a boundary there."""
    n = len(points)
    tail, tip = soup.ravel(), soup[:, [1, 2, 0]].ravel()
    key = np.minimum(tail, tip) * n + np.maximum(tail, tip)
    order = np.lexsort((np.arange(len(key)), key))
    k = key[order]
    starts = np.flatnonzero(np.r_[True, k[1:] != k[:-1]])
    sizes = np.diff(np.r_[starts, len(k)])
    rank = np.arange(len(k)) - np.repeat(starts, sizes)     # place around its edge
    first = np.flatnonzero((rank % 2 == 0) & (rank + 1 < np.repeat(sizes, sizes)))
    twins = np.full(len(key), -1, dtype=np.int64)
    twins[order[first]], twins[order[first + 1]] = order[first + 1], order[first]
    return soup.astype(np.int64), twins


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
    :func:`gegnn.fields.cloud_heat.local_triangulations`, each triangle emitted by its first corner), glued
    in ``pairs`` or as their ``cover`` (module docstring).

    ValueError where the points or triangles are not a cloud's (shapes, non-finite coordinates, indices
    out of range)."""

    def __init__(self, points: np.ndarray, triangles: np.ndarray, gluing: str = "pairs"):
        from geodata.approximate_geodesic import ApproximateGeodesicSolver

        if gluing not in GLUINGS:
            raise ValueError(f"gluing must be one of {', '.join(GLUINGS)}, got {gluing!r}")
        points = np.ascontiguousarray(points, dtype=np.float64)
        triangles = np.asarray(triangles, dtype=np.int64)
        faces, twins = (paired_mesh if gluing == "pairs" else cover_mesh)(points, agreed_soup(triangles))
        self.n_points = len(points)
        self._solver = ApproximateGeodesicSolver(points, faces, twins=twins, excess=own_excess(points, triangles),
                                                 convex=False)

    def distances(self, sources, threads: int = 1) -> np.ndarray:
        """Distances (N, len(sources)) from each source point to every point (``inf`` on other parts)."""
        return self._solver.distances(np.asarray(sources, dtype=np.int64), threads=threads).T
