r"""Point-cloud heat-method distances as potpourri3d computes them (``PointCloudHeatSolver(P, t_coef)``:
geometry-central's ``PointCloudHeatSolver``, the heat method on the tufted triangulation of the points'
local Delaunay triangulations, Sharp and Crane 2020), to solver rounding, factored once, for one source
or many per solve.

The library's discrete choices (which neighbours, each normal's sign, which local triangles, how the
cover is glued) each move the fields by 1e-4 to 5e-2 when made differently, so every step makes them as
the library does (the normals and local triangulations compiled, ``src/local_triangulation.cpp``; the
rest in NumPy). Where rounding alone decides (exactly equal distances, mirror-symmetric neighbourhoods)
the choice may be another; such clouds get other, equally valid fields:

* **Neighbours**: the :math:`k = 30` nearest other points, nearest first: scipy's k-d tree finds them;
  rows with two distances equal up to rounding are re-sorted by
  :math:`((\Delta x^2 + \Delta y^2) + \Delta z^2)`, exact ties by point index (the library's nanoflann
  orders exact ties as its search reaches them).
* **Normals**: :math:`n_i` = the third left singular vector of the :math:`3 \times k` matrix of offsets
  :math:`p_j - p_i` (not centred), sign included, by Eigen's ``JacobiSVD`` (the library's choice; Eigen
  3.4 here, 3.3.9 in potpourri3d 1.4: the same normals to rounding on generic clouds).
  Tangent frame :math:`x = \widehat{t \times n}`, :math:`t = e_x` (:math:`e_y` where
  :math:`|n_x| > 0.9`), :math:`y = \widehat{n \times x}`; neighbour coordinates
  :math:`((q - p_i) - ((q - p_i) \cdot n)\,n) \cdot (x, y)`.
* **Local triangulation** of each point: its neighbours sorted by angle (equal angles in libstdc++'s
  ``std::sort`` order), then sweeps that drop a neighbour when the triangle pair it closes with its two
  current angular neighbours fails the in-circle test (Eigen's 4x4 determinant with the origin first;
  pairs across a gap of :math:`\pi` or more are not tested), of two collinear neighbours the farther
  (angle below :math:`10^{-7}`); neighbours within :math:`10^{-7}` of the neighbourhood radius are pushed
  out first. A point emits the triangles :math:`(i, a, b)` of consecutive kept neighbours with
  :math:`a \times b > 0`.
* **The heat method** on the soup of all points' triangles (in order; a triangle reappears for each
  corner that emits it), by the core the meshes use (:mod:`gegnn.fields.heat`: tufted cover, intrinsic
  flips, operators, both solves), with the library's two differences: the lengths are mollified with
  the mean *soup* edge length, and the time step is :math:`t = t_{coef}\,\bar l^2` with potpourri3d's
  default :math:`t_{coef} = 1`.

Measured against potpourri3d 1.4.0 (``benchmarks/bench_cloud_heat.py``; one core of a 2-core AMD EPYC
shared with other work, medians), 2026-11-26: on 17 of the 19 validation clouds (~5,000 points) the
fields differ by at most 4.5e-14 of their largest value; on homer and spot_low_resolution, where 9 and 2
points have exactly equidistant neighbours and 2 and 1 normals take the other sign, by 4.5e-4 and 5.6e-4.
Exactly symmetric synthetic clouds differ more (a subdivided cube's vertices: 5.6e-2, with a mean error
to the exact surface distances of 2.88% against the library's 2.48%; 800 points on a sphere with 45
duplicates: 1.1e-3, 1.8813% against 1.8797% to the great circles; tests). Setup 126 ms (potpourri3d 109
ms, plus 41 ms factoring on its first field); a field 0.90 ms one source at a time, 0.48 ms in a
128-source solve (potpourri3d 5.8 ms); 128 farthest-point landmark fields, setup included, 0.27 s (1.0
s), the same landmarks. bumpy_sphere(8000): setup 219 ms (377 + 134), a field 1.6 ms, 1.3 ms batched
(15 ms); 128 landmark fields 0.59 s (2.5 s).

Supported: finite points, more than :math:`k` of them, every point in some local triangle (ValueError
otherwise).
"""
from __future__ import annotations

import numpy as np

from .. import threads
from .heat import HeatSolver, flip_to_delaunay, mollify, operators, tufted_cover

__all__ = ["CloudHeatDistance", "local_triangulations", "K_NEIGHBORS"]

K_NEIGHBORS = 30          # geometry-central's PointPositionGeometry::kNeighborSize


def _nearest(points: np.ndarray, k: int = K_NEIGHBORS) -> np.ndarray:
    """(N, k): geometry-central's kNearestNeighbors, the k + 1 nearest without the point itself (without
    the last one if the point is not among them), nearest first. scipy's k-d tree finds them; where two
    of the k + 1 (or the k + 1-th and the next) are equally far to within rounding, the row is re-sorted
    by the squared distance ((dx^2 + dy^2) + dz^2), exact ties by point index (nanoflann, the library's
    k-d tree, orders them as its search reaches them: another order only on exactly symmetric clouds)."""
    from scipy.spatial import cKDTree

    n = len(points)
    want = k + 1
    extra = 2
    tree = cKDTree(points)
    while True:
        m = min(n, want + extra)
        dist, cand = tree.query(points, m)
        dist = dist.reshape(n, m)
        cand = np.asarray(cand, dtype=np.int64).reshape(n, m)
        close = dist[:, 1:] <= dist[:, :-1] * (1 + 1e-12)     # equal but for rounding
        if m == n or not close[:, want - 1:].all(1).any():
            break
        extra *= 4                                            # a tie reaches past the candidates
    rows = np.flatnonzero(close[:, :want].any(1))
    if len(rows):
        # The boundary decides which point is the k-th; the order, the normal's rounding.
        c = cand[rows]
        d = points[rows[:, None]] - points[c]                  # query - point, as nanoflann's L2_Simple_Adaptor
        sq = (d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1]) + d[..., 2] * d[..., 2]
        by_row = np.repeat(np.arange(len(rows)), c.shape[1])
        cand[rows] = c.ravel()[np.lexsort((c.ravel(), sq.ravel(), by_row))].reshape(c.shape)  # per row by sq, c
    cand = cand[:, :want]
    is_self = cand == np.arange(n)[:, None]
    first_self = np.where(is_self.any(1), is_self.argmax(1), want - 1)
    keep = np.ones_like(cand, dtype=bool)
    keep[np.arange(n), first_self] = False
    return cand[keep].reshape(n, k)


def local_triangulations(points, neighbors: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Each point's normal (N, 3) and its local Delaunay triangles, the soup (F, 3) of
    :class:`CloudHeatDistance` (its ``neighbors``: potpourri3d's 30 nearest where None); compiled
    (``src/local_triangulation.cpp``), in blocks of rows on torch's threads (:func:`gegnn.threads.by_rows`).
    ValueError for points the method cannot take."""
    from .._local_triangulation import local_triangulations as triangulate

    p = np.ascontiguousarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or len(p) <= K_NEIGHBORS:
        raise ValueError(f"cloud heat method: need (N, 3) points with N > {K_NEIGHBORS}")
    if not np.isfinite(p).all():
        raise ValueError("cloud heat method: non-finite coordinates")
    neighbors = np.ascontiguousarray(_nearest(p) if neighbors is None else neighbors, dtype=np.int64)
    normals, faces = threads.by_rows(
        lambda rows: triangulate(p, threads.indices(rows), neighbors[rows]), len(p))
    if np.bincount(faces.ravel(), minlength=len(p)).min() == 0:
        raise ValueError("cloud heat method: a point in no local triangle (degenerate neighbourhood)")
    return normals, faces


class CloudHeatDistance(HeatSolver):
    """potpourri3d's point-cloud heat-method distance on one cloud: neighbourhoods, cover, flips and
    both factorizations once; then :meth:`distance` or :meth:`distances` for any sources.

    Args:
        points: (N, 3) float, finite, N > 30.
        t_coef: time step over the mean squared cover edge length (potpourri3d's default 1).
        neighbors: (N, k) int, each point's neighbours nearest first, instead of potpourri3d's 30 nearest
            (then the fields are no longer the library's: :func:`gegnn.fields.pointcloud.surface_neighbors`).
        triangles: ``local_triangulations(points, neighbors)``, where they were made before.

    Attributes:
        n: point count; t: the time step; n_faces: soup triangles; n_flips: intrinsic flips made;
        normals: (N, 3) the library's unit normals (unoriented: signs as its SVD leaves them).
    """

    def __init__(self, points, t_coef: float = 1.0, neighbors: np.ndarray | None = None,
                 triangles: tuple[np.ndarray, np.ndarray] | None = None):
        p = np.ascontiguousarray(points, dtype=np.float64)
        self.normals, faces = local_triangulations(p, neighbors) if triangles is None else triangles
        self.n = len(p)
        self.n_faces = len(faces)
        cover = tufted_cover(p, faces)
        mollify(cover, cover.length[:cover.soup_edges].sum() / cover.soup_edges)  # the soup's mean, as the library
        self.n_flips = flip_to_delaunay(cover)
        self.t = t_coef * (cover.length.sum() / len(cover.length)) ** 2
        self._factor("cloud heat method", *operators(cover, self.n))
