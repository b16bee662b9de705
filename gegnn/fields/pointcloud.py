r"""Point clouds as GeGnn inputs: the graph, the normals and the landmark fields from the points alone.

* **Projection**: every point moved onto a quadric fitted to its neighbourhood (one moving-least-squares
  projection, :func:`mls_project`); the graph, the normals, the landmark fields and the network's positions
  are all of the projected points, while distances stay those between the cloud's own points. It takes
  the scanner noise out of the heat method's paths (their zigzag makes distances too long) and costs
  nothing on clean clouds: on the 19 validation clouds the heat method's mean relative error falls from
  9.07% to 5.12% with noise of 0.5% of the bounding box and from 4.63% to 4.22% without.
* **Graph**: the k nearest neighbours of every point, symmetrized (an edge where either point is among
  the other's k nearest); with a scan's own oriented normals, the k nearest facing the same side (validation
  clouds with the meshes' normals: 3.07% -> 3.02%, the lion 19.5% -> 19.1% and the teapot 10.4% -> 9.7%,
  the other 17 unchanged at 1.67%).
* **Normals**: the direction of least variance of each point's neighbourhood (PCA), oriented
  consistently by propagation along a minimum spanning tree of the graph weighted by
  :math:`1 - |n_i \cdot n_j|` (Hoppe et al. 1992), each part's tree rooted at its point farthest
  from the part's centroid, whose normal points away from it (outwards on a closed surface).
* **Landmark fields**: farthest-point landmarks on every part of the graph, by shortest paths along the
  surface neighbours below (:func:`gegnn.fields.landmarks.graph_farthest_points`), and their distance fields
  from the points' local Delaunay triangulations: by the point-cloud heat method (``solver="heat"``,
  potpourri3d's ``PointCloudHeatSolver``: the heat method on their tufted Laplacian, Sharp and Crane 2020;
  computed by :mod:`gegnn.fields.cloud_heat`), all solved together; or by virtual source propagation on
  the same triangles (``"vsp"``, :mod:`gegnn.fields.cloud_vsp`: the landmark bound at K = 256 a quarter
  lower; its triangulations from points moved a little, :func:`_unlatticed`, as a regular grid's are
  ambiguous), the sources on torch's threads. A model's ``landmark_fields`` says which. (Meshes take each next
  landmark from the heat fields so far, :mod:`gegnn.fields.landmarks`, which keeps the fields one after the
  other; along the graph the validation clouds' errors stay within 0.02 points of that, at 8k points the
  fields take 0.1 s instead of 0.2 s.) Each point's local triangulation from neighbours near its tangent plane (:func:`surface_neighbors`), not across a gap to a nearby part
  (heat-method MRE on the validation clouds 4.22% -> 3.85%), and with a scan's own oriented normals
  only from neighbours on its own sheet (:mod:`gegnn.fields.cloud_sides`: facing the same side, the
  offset along the surface; 3.93% -> 3.32% with the meshes' normals).
* **Close walls**: with a scan's own normals the projection too is fitted to each point's side only, so
  that two sheets closer than the neighbourhood is wide are not fitted as one between them; the points
  where two such sheets are seen and the normals do not tell them apart (or no normals are given) are
  flagged ``ambiguous`` (:func:`gegnn.fields.cloud_sides.close_walls`, on the points as given).

Exact duplicates are merged before any of it and share their point's values.
"""
from __future__ import annotations

from collections.abc import Callable
from functools import cached_property

import numpy as np

from geodata.mesh import label_groups

from .. import threads
from .cloud_sides import Walls, close_walls, facing_neighbors
from .landmarks import LandmarkFields, _along_edges, graph_farthest_points, landmark_columns

__all__ = ["CloudGraph", "cloud_graph", "mls_project", "surface_neighbors", "knn_edges", "graph_parts",
           "pca_normals", "unoriented_normals", "orient_normals", "cloud_landmark_fields", "cloud_landmark_solver",
           "KNN", "CLOUD_T_COEF"]

KNN = 8             # neighbours a point's graph edges and normal come from
CLOUD_T_COEF = 1.0  # potpourri3d's default time step for point clouds (the mesh fields' 0.5: worse on
                    # irregular samples, 8k surface points 3.52% -> 3.75%; docs/pointclouds.md)
MLS_K = 30          # neighbours of each point's quadric fit
HEAT_K = 15         # neighbours of each point's local triangulation in the heat method
CONE_DEG = 30.0     # ... within this angle of its tangent plane
CONE_FIT = 5        # ... fitted to the point and this many neighbours
UNLATTICE = 0.03    # the local triangulations of virtual-source fields from points moved this share of a spacing
MIN_PART = 31       # parts of fewer points get no fields (distance 0): potpourri3d's point-cloud solver
                    # needs more points than its 30 neighbours


class CloudGraph:
    """A point cloud's graph: the projected ``points`` (N, 3) it is made of (:func:`mls_project`),
    undirected ``edges`` (E, 2), the part of every point (``part``, (N,), labels 0, 1, ... of the graph's
    connected components), unit ``normals`` (N, 3): the given ones, or estimated and oriented
    (:func:`pca_normals` of each point's k ``neighbors``, :func:`orient_normals`) when first read, which
    only the network does (:meth:`gegnn.GeGnn.embed` reads them beside the landmark fields); and what
    :func:`gegnn.fields.cloud_sides.close_walls` saw of close sheets (``walls``)."""

    def __init__(self, points: np.ndarray, edges: np.ndarray, part: np.ndarray, neighbors: np.ndarray,
                 walls: Walls, normals: np.ndarray | None = None):
        self.points, self.edges, self.part, self.neighbors, self.walls = points, edges, part, neighbors, walls
        if normals is not None:
            self.normals = np.asarray(normals, dtype=np.float64)

    @cached_property
    def normals(self) -> np.ndarray:
        return orient_normals(self.points, pca_normals(self.points, self.neighbors), self.edges)[0]


def knn_edges(points: np.ndarray, k: int = KNN, normals: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    r"""Undirected edges (E, 2) of the symmetrized k-nearest-neighbour graph (i < j), and the neighbours
    (N, k) of every point, nearest first. With the cloud's own oriented ``normals`` (a scan's), each
    point's k nearest among its 4k nearest that face its side, :math:`n_q \cdot n_p > 0` (the two sides of
    a thin wall face away from each other), rows with fewer filled with the nearest others. Needs more
    than k distinct points."""
    from scipy.spatial import cKDTree

    candidates = k if normals is None else min(4 * k, len(points) - 1)
    _, nbrs = cKDTree(points).query(points, candidates + 1, workers=threads.count())
    nbrs = nbrs[:, 1:]
    if normals is not None:
        away = np.einsum("nkd,nd->nk", normals[nbrs], normals) <= 0
        nbrs = np.take_along_axis(nbrs, np.argsort(away, axis=1, kind="stable")[:, :k], axis=1)
    i = np.repeat(np.arange(len(points)), k)
    j = nbrs.ravel()
    key = np.unique(np.minimum(i, j) * len(points) + np.maximum(i, j))
    return np.stack([key // len(points), key % len(points)], axis=1), nbrs


def mls_project(points: np.ndarray, k: int = MLS_K, normals: np.ndarray | None = None) -> np.ndarray:
    r"""Every point moved onto the quadric fitted to its neighbourhood (one moving-least-squares step).

    With the point :math:`p` and its k nearest neighbours :math:`q_j` at distances :math:`d_j`, weights
    :math:`w_j = \exp(-(2 d_j / d_k)^2)` (the point itself weighs 1), the frame of the weighted
    covariance about the weighted centroid (normal :math:`n`, tangents :math:`t_1, t_2`) and local
    coordinates :math:`(u, v, z)_j = (q_j - p) \cdot (t_1, t_2, n)`, the height field
    :math:`z = c_0 + c_1 u + c_2 v + c_3 u^2 + c_4 uv + c_5 v^2` is fitted by weighted least squares and
    :math:`p' = p + c_0\,n`. A point whose fit would move it by more than half its neighbourhood's radius
    :math:`d_k` (too few or degenerate neighbours) stays where it is. Needs more than k distinct points
    (fewer: all of them are used). With the cloud's own oriented ``normals``, the k nearest on the point's own
    side (:func:`gegnn.fields.cloud_sides.facing_neighbors` among the 4k nearest), so that the two sides of
    a wall thinner than the neighbourhood are not fitted as one surface between them. Compiled
    (``src/cloud_ops.cpp``), in blocks of rows on torch's threads."""
    from scipy.spatial import cKDTree

    from .._cloud_ops import mls_project as project

    points = np.ascontiguousarray(points, dtype=np.float64)
    k = min(k, len(points) - 1)
    if normals is None:
        dist, nbrs = cKDTree(points).query(points, k + 1, workers=threads.count())
        nbrs = nbrs.astype(np.int64, copy=False)
    else:  # the point itself first (distance 0), then its sheet's nearest, nearest first
        nbrs, dist = facing_neighbors(points, normals, k, None, 4 * k)
        by_distance = np.argsort(dist, axis=1, kind="stable")
        nbrs = np.concatenate([np.arange(len(points))[:, None], np.take_along_axis(nbrs, by_distance, axis=1)], 1)
        dist = np.concatenate([np.zeros((len(points), 1)), np.take_along_axis(dist, by_distance, axis=1)], 1)
    return threads.by_rows(lambda rows: project(points, threads.indices(rows), nbrs[rows], dist[rows]), len(points))


def pca_normals(points: np.ndarray, nbrs: np.ndarray) -> np.ndarray:
    """Unit normals (N, 3), unoriented: the least-variance direction of each point with its neighbours (N, k)
    (about their mean; ``src/cloud_ops.cpp``)."""
    from .._cloud_ops import plane_normals

    points = np.ascontiguousarray(points, dtype=np.float64)
    nbrs = np.ascontiguousarray(nbrs, dtype=np.int64)
    return threads.by_rows(lambda rows: plane_normals(points, threads.indices(rows), nbrs[rows]), len(points))


def unoriented_normals(points: np.ndarray, k: int = KNN) -> np.ndarray:
    """:func:`pca_normals` of every point with its k nearest: for light, where a normal's sign does not matter
    (pictures of clouds without normals of their own)."""
    return pca_normals(points, knn_edges(points, k)[1])


def orient_normals(points: np.ndarray, normals: np.ndarray, edges: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Normals flipped to agree along a minimum spanning tree of the graph (weights 1 - |n_i . n_j|), each
    part's root pointing away from the part's centroid; and the part of every point."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import breadth_first_order, connected_components, minimum_spanning_tree

    n = len(points)
    i, j = edges[:, 0], edges[:, 1]
    weight = 1.0 - np.abs(np.einsum("ij,ij->i", normals[i], normals[j])) + 1e-9  # > 0: kept by the tree
    tree = minimum_spanning_tree(sp.coo_matrix((weight, (i, j)), shape=(n, n)).tocsr())
    tree = (tree + tree.T).tocsr()
    n_parts, part = connected_components(tree, directed=False)
    out = normals.copy()
    for members in label_groups(part, n_parts):
        offset = points[members] - points[members].mean(axis=0)
        root = members[np.argmax(np.einsum("ij,ij->i", offset, offset))]
        if out[root] @ (points[root] - points[members].mean(axis=0)) < 0:
            out[root] = -out[root]
        order, parent = breadth_first_order(tree, root, directed=False)
        out[order] *= _tree_signs(order, parent, out)[:, None]
    return out, part


def _tree_signs(order: np.ndarray, parent: np.ndarray, normals: np.ndarray) -> np.ndarray:
    r"""The flips (+-1, in ``order``) that make every normal of a tree agree with its parent's flipped
    one, :math:`n_v \cdot n_{parent(v)} \ge 0` (``order[0]``, the root, stays): the product of the edges'
    signs up to the root, by pointer jumping (log of the depth passes). A normal at right angles to its
    parent's is not flipped, and its subtree follows it."""
    n = len(normals)
    anchor = np.arange(n)
    sign = np.ones(n)
    child = order[1:]
    dot = np.einsum("ij,ij->i", normals[child], normals[parent[child]])
    tied = dot != 0
    anchor[child[tied]] = parent[child[tied]]
    sign[child] = np.where(dot < 0, -1.0, 1.0)
    while True:
        up = anchor[order]
        if (anchor[up] == up).all():  # every anchor a root (sign 1): the products are complete
            return sign[order]
        sign[order] *= sign[up]
        anchor[order] = anchor[up]


def cloud_graph(points: np.ndarray, k: int = KNN, normals: np.ndarray | None = None) -> CloudGraph:
    """The graph of a point cloud of distinct points, made of the points projected by :func:`mls_project`
    (see the module); ``normals``: given ones (used as they are, unit length) instead of estimated. Its
    ``walls`` come from the points as given (the projection would fit two close sheets as one):
    :func:`gegnn.fields.cloud_sides.close_walls`."""
    walls = close_walls(points, normals)
    points = mls_project(points, normals=normals)
    edges, nbrs = knn_edges(points, k, normals)
    return CloudGraph(points, edges, graph_parts(len(points), edges), nbrs, walls, normals)


def graph_parts(n: int, edges: np.ndarray) -> np.ndarray:
    """Connected-component label (N,) of every point of the graph with undirected ``edges``."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    adjacency = sp.coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
    return connected_components(adjacency, directed=False)[1].astype(np.int64)


def cloud_landmark_fields(points: np.ndarray, part: np.ndarray, k: int, seed: int = 0,
                          t_coef: float = CLOUD_T_COEF, normals: np.ndarray | None = None,
                          solver: str = "heat") -> LandmarkFields:
    """K farthest-point landmarks per part of the graph and their distance fields (float32 (N, K)) by the
    point-cloud heat method (``solver`` "heat") or by virtual sources on the same local triangles ("vsp",
    :mod:`gegnn.fields.cloud_vsp`), as :func:`gegnn.fields.landmarks.landmark_fields` on a mesh: deterministic for a given
    cloud, ``k`` and ``seed``; parts of fewer than MIN_PART points, or on a line, get distance 0 (as a
    mesh's parts of fewer than 3 vertices). ``normals``: the cloud's own oriented unit normals, if it has them (see
    :func:`surface_neighbors`). The same as ``cloud_landmark_solver(points, part, t_coef, normals, solver)(k, seed)``."""
    return cloud_landmark_solver(points, part, t_coef, normals, solver)(k, seed)


def cloud_landmark_solver(points: np.ndarray, part: np.ndarray, t_coef: float = CLOUD_T_COEF,
                          normals: np.ndarray | None = None, solver: str = "heat"
                          ) -> Callable[[int, int], LandmarkFields]:
    """The fields' row-by-row set-up on every part of the graph (surface neighbours, local
    triangulations: on all of torch's threads), and a function ``(k, seed) -> LandmarkFields`` giving
    :func:`cloud_landmark_fields` from it: the covers and factorizations (or the glued triangles) on its
    first call (one thread), then farthest-point landmarks along the surface neighbours (:func:`gegnn.fields.landmarks.graph_farthest_points`)
    and their fields all together, on torch's threads."""
    n_parts = int(part.max()) + 1
    groups = label_groups(part, n_parts)
    builds = [_cloud_field(points[idx], t_coef, None if normals is None else normals[idx], solver)
              if len(idx) >= MIN_PART and not collinear(points[idx]) else None for idx in groups]
    solvers = {}

    def fields(k: int, seed: int = 0) -> LandmarkFields:
        out = np.zeros((len(points), k), dtype=np.float32)
        landmarks = np.zeros((n_parts, k), dtype=np.int64)
        for c, (idx, build) in enumerate(zip(groups, builds)):
            rng = np.random.default_rng([seed, c])
            if build is None:
                landmarks[c] = idx[0]
                continue
            edges, make = build
            if c not in solvers:
                solvers[c] = make()
            chosen = graph_farthest_points(points[idx], edges, min(k, len(idx)), int(rng.integers(len(idx))))
            sampled = landmark_columns(solvers[c](chosen), chosen)
            cols = np.arange(k) % len(chosen)
            out[idx] = sampled[:, cols]
            landmarks[c] = idx[chosen[cols]]
        return LandmarkFields(out, landmarks, part)
    return fields


def collinear(points: np.ndarray) -> bool:
    """Whether the points lie on one line (to 1e-9 of their extent): no surface, no local triangles (the
    heat method's solvers fail on them)."""
    s = np.linalg.svd(points - points.mean(axis=0), compute_uv=False)
    return bool(s[1] <= 1e-9 * s[0]) if len(s) > 1 else True


def surface_neighbors(points: np.ndarray, k: int = HEAT_K, cone_deg: float = CONE_DEG,
                      normals: np.ndarray | None = None) -> np.ndarray:
    r"""(N, k): each point's k nearest neighbours :math:`q` within ``cone_deg`` of its tangent plane,
    :math:`|n \cdot (q - p)| < \sin(\text{cone})\,|q - p|`, among its 6k nearest; rows with fewer are filled
    with the nearest of the others. A point across a narrow gap (between two legs, two fingers) lies off
    the tangent plane and is left out, where the plain k nearest would join the two sides in the local
    triangulation. n is fitted twice (:func:`pca_normals`): to the point and its CONE_FIT nearest, then to
    the point and its CONE_FIT nearest within that first cone, so that near a gap the other side, which
    tilts a plain fit, does not set the cone. With the cloud's own oriented ``normals`` (a scan's), the
    k nearest on the point's own sheet instead (:func:`gegnn.fields.cloud_sides.facing_neighbors`: facing
    the same side, :math:`n_q \cdot n_p > 0`, as the two sides of a thin wall do not, and within the cone
    about the plane normal to :math:`n_p + n_q`, which a sheet stacked on the point's does not meet). Needs
    more than 6k points (fewer: all)."""
    from scipy.spatial import cKDTree

    from .._cloud_ops import cone_neighbors

    points = np.ascontiguousarray(points, dtype=np.float64)
    if normals is not None:
        return facing_neighbors(points, normals, k, cone_deg)[0]
    given = np.zeros((0, 3))
    sin_cone = float(np.sin(np.radians(cone_deg)))
    tree = cKDTree(points)
    out = np.empty((len(points), k), dtype=np.int64)
    rows = np.arange(len(points), dtype=np.int64)
    for candidates in (2 * k, 6 * k):  # most rows are settled by their 2k nearest: the 6k only where not
        candidates = min(candidates, len(points) - 1)
        nbrs = tree.query(points[rows], candidates + 1, workers=threads.count())[1][:, 1:].astype(np.int64)

        def cone(block, rows=rows, nbrs=nbrs):
            return cone_neighbors(points, rows[block], nbrs[block], k, sin_cone, min(CONE_FIT, candidates), given)
        out[rows], settled = threads.by_rows(cone, len(rows))
        rows = rows[~settled]
        if not len(rows) or candidates == len(points) - 1:
            break
    return out


def _unlatticed(points: np.ndarray) -> np.ndarray:
    """The points, each moved by a seeded random offset of up to ``UNLATTICE`` of the distance to its nearest,
    for the local triangulations only (their lengths stay the points'): on a regular grid four neighbours lie
    on one circle, the local Delaunay triangulations of two points pick the two diagonals differently, and the
    glued triangles zigzag (virtual-source fields on a 128 x 32 grid torus 4.95% off, 0.58% moved by 3%)."""
    from scipy.spatial import cKDTree

    nearest = cKDTree(points).query(points, 2, workers=threads.count())[0][:, 1]
    return points + np.random.default_rng(0).uniform(-1, 1, points.shape) * (UNLATTICE * nearest)[:, None]


def _cloud_field(points: np.ndarray, t_coef: float, normals: np.ndarray | None = None, solver: str = "heat"):
    """The fields of one part, in two steps: its :func:`surface_neighbors` (potpourri3d's 30 nearest where
    those would split the part) and local triangulations now, row by row on torch's threads; then the edges
    (E, 2) of the landmarks' graph (each point to those neighbours), and a function building
    ``distances(sources) -> (N, len(sources))`` from them: ``solver`` "heat",
    :class:`gegnn.fields.cloud_heat.CloudHeatDistance`'s cover, flips and factorizations (built on one thread);
    "vsp", :class:`gegnn.fields.cloud_vsp.CloudVirtualSources` on the same triangles, the sources on torch's
    threads; either from potpourri3d's heat method on clouds that the local triangulation refuses (a
    degenerate neighbourhood)."""
    from .cloud_heat import CloudHeatDistance, local_triangulations
    from .cloud_vsp import CloudVirtualSources

    points = np.ascontiguousarray(points, dtype=np.float64)
    neighbors = surface_neighbors(points, normals=normals)
    pairs = np.stack([np.repeat(np.arange(len(points)), neighbors.shape[1]), neighbors.ravel()], axis=1)
    if graph_parts(len(points), pairs).max() > 0:  # the cone split the part: the plain nearest keep it whole
        neighbors = None
    try:
        triangles = local_triangulations(_unlatticed(points) if solver == "vsp" else points, neighbors)
    except ValueError:
        triangles = None
    edges = knn_edges(points, HEAT_K)[0] if neighbors is None else pairs

    def build():
        try:
            if triangles is not None and solver == "vsp":  # the sources on all threads (the same fields)
                fields = CloudVirtualSources(points, triangles[1])
                # a point the triangles leave apart from its part (the graph joins it): along the graph
                return lambda sources: _along_edges(fields.distances(sources, threads=threads.count()), points,
                                                    edges)
            if triangles is not None:
                return CloudHeatDistance(points, t_coef, neighbors, triangles).distances
        except ValueError:
            pass
        import potpourri3d as pp3d
        heat = pp3d.PointCloudHeatSolver(points, t_coef=t_coef)
        return lambda sources: np.stack([heat.compute_distance(int(s)) for s in sources], axis=1)
    return edges, build
