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
* **Tufted cover** of the soup of all points' triangles (in order; a triangle reappears for each corner
  that emits it): lengths :math:`|p_a - p_b|` mollified over the soup's edges *before* the cover,
  :math:`\epsilon = \max(0, \max_{\text{corners}} (l_c - l_a - l_b) + 10^{-5}\,\bar l)`; every face
  gets an oppositely oriented back copy; around a soup edge of faces :math:`h_0, \dots, h_{n-1}`
  (creation order) the sheets are glued cyclically in the order :math:`h_0, h_{n-1}, \dots, h_1`, each
  face's free sheet to the next face's sheet of the other orientation. Then intrinsic Delaunay flips
  (cotangent weight below :math:`-10^{-6}`), here in rounds of face-disjoint flips with
  geometry-central's arithmetic: the same triangles as its queue wherever the Delaunay triangulation is
  unique, lengths equal to rounding.

With the flipped cover's cotangent Laplacian :math:`L`, lumped masses :math:`M` (a third of each cover
triangle's Heron area to each corner) and :math:`t = t_{coef}\,\bar l^2` (:math:`\bar l`: mean cover edge
length after the flips), as geometry-central's mesh method on the cover (no second mollification):

.. math::
    (M + tL)\,u = e_s, \qquad X_f = \frac{\nabla u}{|\nabla u|}, \qquad
    (L + 10^{-6} I)\,\phi = \nabla\!\cdot X, \qquad d = \phi - \phi_s .

Identical cover triangles (same corners, bitwise equal lengths; a local triangle and its copies often
appear six times) count once with their multiplicity; both systems are factored and solved as on
meshes (:class:`gegnn.fields.heat.HeatSolver`).

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
from .heat import DELAUNAY_EPS, HeatSolver, _Cover, _cotan_halves, gradient_divergence, laplacian, relink

__all__ = ["CloudHeatDistance", "local_triangulations", "K_NEIGHBORS"]

K_NEIGHBORS = 30          # geometry-central's PointPositionGeometry::kNeighborSize
MOLLIFY = 1e-5            # mollification margin, relative to the mean soup edge length


# ---------------------------------------------------------------------------------------------------
# Neighbours: the k nearest, ties by index
# ---------------------------------------------------------------------------------------------------

def _sq_dist(points: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """Squared distances ((dx^2) + dy^2) + dz^2, d = query - point (as nanoflann's L2_Simple_Adaptor)."""
    d = points[rows] - points[cols]
    return (d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1]) + d[..., 2] * d[..., 2]


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
        cand[rows] = np.take_along_axis(c, _rowwise_lexsort(_sq_dist(points, rows[:, None], c), c), 1)
    cand = cand[:, :want]
    is_self = cand == np.arange(n)[:, None]
    first_self = np.where(is_self.any(1), is_self.argmax(1), want - 1)
    keep = np.ones_like(cand, dtype=bool)
    keep[np.arange(n), first_self] = False
    return cand[keep].reshape(n, k)


def _rowwise_lexsort(primary: np.ndarray, secondary: np.ndarray) -> np.ndarray:
    """Per row, the order sorting by primary then secondary."""
    rows = np.repeat(np.arange(len(primary)), primary.shape[1])
    order = np.lexsort((secondary.ravel(), primary.ravel(), rows))
    return (order - rows * primary.shape[1]).reshape(primary.shape)


# ---------------------------------------------------------------------------------------------------
# Tufted cover of the triangle soup, operators
# ---------------------------------------------------------------------------------------------------

def _soup_cover(points: np.ndarray, faces: np.ndarray) -> _Cover:
    """The mollified tufted cover of the soup in geometry-central's element order (see
    :class:`gegnn.fields.heat._Cover`): front halfedge 3f + c runs from corner c to c + 1, its back copy
    3F + 3f + c the other way. Edges: the soup's (in order of first appearance) keep the pair
    (h_0, h_1's back-or-front); then, edge by edge, the new edges glue h_0's other sheet to h_{n-1},
    h_{n-1}'s to h_{n-2}, ..., h_2's to h_1 (each halfedge pair oppositely oriented)."""
    n_f = len(faces)
    n_h = 3 * n_f
    tail = faces.reshape(-1)
    tip = faces[:, [1, 2, 0]].reshape(-1)
    n = len(points)
    key = np.minimum(tail, tip) * n + np.maximum(tail, tip)
    by_key = np.argsort(key * n_h + np.arange(n_h))           # halfedges by edge, creation order within
    k_sorted = key[by_key]
    new_group = np.concatenate([[True], k_sorted[1:] != k_sorted[:-1]])
    group_start = np.flatnonzero(new_group)
    count = np.diff(np.append(group_start, n_h))
    first = by_key[group_start]                               # each edge's first halfedge
    edge_order = np.argsort(first, kind="stable")             # edges in order of first appearance
    start = group_start[edge_order]
    count = count[edge_order]
    h0 = first[edge_order]
    group_rank = np.empty(len(group_start), dtype=np.int64)
    group_rank[edge_order] = np.arange(len(group_start))
    soup_edge = np.empty(n_h, dtype=np.int64)
    soup_edge[by_key] = group_rank[np.cumsum(new_group) - 1]
    d = points[tail[h0]] - points[tip[h0]]
    length = np.sqrt((d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]) + d[:, 2] * d[:, 2])  # Vector3's norm, in its order
    # mollify the soup: one epsilon for all lengths
    la = length[soup_edge]
    nxt3 = (3 * np.arange(n_f)[:, None] + np.array([1, 2, 0])).ravel()
    lb = la[nxt3]
    lc = lb[nxt3]
    delta = length.sum() / len(length) * MOLLIFY
    length = length + max(0.0, float(np.max(lc - la - lb + delta)))
    # orientation relative to the edge's first halfedge; its true (T) and false (F) sheet
    ids = np.arange(n_h)
    positive = tail == tail[h0[soup_edge]]
    sheet_t = np.where(positive, ids, n_h + ids)
    sheet_f = np.where(positive, n_h + ids, ids)
    # creation order h_0..h_{n-1} of each edge's halfedges: by_key[start + i]
    h1 = by_key[np.where(count > 1, start + 1, start)]
    extra = count - 1
    e_new = np.repeat(np.arange(len(count)), extra)
    i_new = np.arange(extra.sum()) - np.repeat(np.cumsum(extra) - extra, extra)
    c_new = count[e_new]
    f_i = by_key[start[e_new] + (c_new - i_new) % c_new]      # the i-th face around the edge: h_{(n-i) mod n}
    f_next = by_key[start[e_new] + (c_new - i_new - 1) % c_new]
    pair_a = np.concatenate([h0, sheet_f[f_i]])
    pair_b = np.concatenate([sheet_f[h1], sheet_t[f_next]])
    sib = np.empty(2 * n_h, dtype=np.int64)
    sib[pair_a], sib[pair_b] = pair_b, pair_a
    edge = np.empty(2 * n_h, dtype=np.int64)
    edge[pair_a] = edge[pair_b] = np.arange(len(pair_a))
    step = np.repeat([[1, 2, 0], [2, 0, 1]], n_f, axis=0)    # next corner: c + 1 on fronts, c - 1 on backs
    nxt = (3 * np.arange(2 * n_f)[:, None] + step).ravel()
    return _Cover(nxt, np.concatenate([tail, tip]), np.repeat(np.arange(2 * n_f), 3), sib, edge, pair_a.copy(),
                  3 * np.arange(2 * n_f), np.concatenate([length, length[e_new]]))


def _layout(pax, pay, pbx, pby, l_bc, l_ca):
    """geometry-central's layoutTriangleVertex, vectorized (as :func:`gegnn.fields.heat._layout`)."""
    dx, dy = pbx - pax, pby - pay
    l_ab = np.sqrt(dx * dx + dy * dy)
    s = (l_ab + l_bc + l_ca) / 2.0
    area = np.sqrt(np.maximum(0.0, s * (s - l_ab) * (s - l_bc) * (s - l_ca)))
    h = 2.0 * area / l_ab
    w = (l_ab * l_ab - l_bc * l_bc + l_ca * l_ca) / (2.0 * l_ab)
    ux, uy = dx / l_ab, dy / l_ab
    return pax + w * ux + h * -uy, pay + w * uy + h * ux


def _flip_rounds(cover: _Cover, eps: float = DELAUNAY_EPS) -> int:
    """Intrinsic Delaunay flips in rounds, in place: each round flips, at once, every edge with cotangent
    weight below -eps that has the smallest such index on both its faces. Each flip is
    geometry-central's (as :func:`gegnn.fields.heat._flip_to_delaunay`: same layout arithmetic, same halfedge
    updates, refused where the new length is not finite or a vertex has degree 1); an edge refused
    waits until one of its faces changes. Ends where geometry-central's queue ends wherever the
    Delaunay triangulation is unique (generic input): the same triangles, lengths equal to rounding."""
    nxt, vert, face, sib, edge, e_he, f_he, length = (cover.nxt, cover.vert, cover.face, cover.sib, cover.edge,
                                                      cover.e_he, cover.f_he, cover.length)
    _, half = _cotan_halves(cover)
    weight = half[e_he] + half[sib[e_he]]
    refused = np.zeros(len(length), dtype=bool)
    owner = np.empty(len(f_he), dtype=np.int64)
    n_flips = 0
    while True:
        e = np.flatnonzero((weight < -eps) & ~refused)
        if not len(e):
            return n_flips
        ha1 = e_he[e]
        hb1 = sib[ha1]
        fa, fb = face[ha1], face[hb1]
        owner[fa] = owner[fb] = len(length)
        np.minimum.at(owner, fa, e)
        np.minimum.at(owner, fb, e)
        pick = (owner[fa] == e) & (owner[fb] == e)
        e, ha1, hb1, fa, fb = e[pick], ha1[pick], hb1[pick], fa[pick], fb[pick]
        ha2, hb2 = nxt[ha1], nxt[hb1]
        ha3, hb3 = nxt[ha2], nxt[hb2]
        # flippedEdgeLen: vertex 3 = (0, 0), 0 = (l30, 0); 2 from l02, l23; 1 from l01, l12; new = |1 - 3|
        l30, l02, l23 = length[edge[hb3]], length[e], length[edge[hb2]]
        s = (l30 + l02 + l23) / 2.0
        area = np.sqrt(np.maximum(0.0, s * (s - l30) * (s - l02) * (s - l23)))
        with np.errstate(divide="ignore", invalid="ignore"):
            x2 = (l30 * l30 - l02 * l02 + l23 * l23) / (2.0 * l30)
            y2 = 2.0 * area / l30
            x1, y1 = _layout(x2, y2, l30, np.zeros_like(l30), length[edge[ha2]], length[edge[ha3]])
        new = np.sqrt(x1 * x1 + y1 * y1)
        ok = np.isfinite(new) & (ha2 != hb1) & (hb2 != ha1)
        refused[e[~ok]] = True
        e, ha1, hb1, fa, fb, ha2, hb2, ha3, hb3, new = (a[ok] for a in (e, ha1, hb1, fa, fb, ha2, hb2, ha3, hb3,
                                                                        new))
        n_flips += len(e)
        relink(nxt, vert, face, f_he, fa, fb, (ha1, ha2, ha3), (hb1, hb2, hb3))
        length[e] = new
        for h0 in (ha1, hb1):                                 # the two new faces, from their first halfedge
            h1 = nxt[h0]
            h2 = nxt[h1]
            a, b, c = length[edge[h0]], length[edge[h1]], length[edge[h2]]
            s = (a + b + c) / 2.0
            area4 = 4.0 * np.sqrt(np.maximum(0.0, s * (s - a) * (s - b) * (s - c)))
            with np.errstate(divide="ignore", invalid="ignore"):
                half[h0] = (-a * a + b * b + c * c) / area4 / 2
                half[h1] = (-b * b + c * c + a * a) / area4 / 2
                half[h2] = (-c * c + a * a + b * b) / area4 / 2
        touched = edge[np.concatenate([ha1, ha2, ha3, hb1, hb2, hb3])]
        weight[touched] = half[e_he[touched]] + half[sib[e_he[touched]]]
        refused[touched] = False


def _operators(cover: _Cover, n: int):
    """Over the cover's distinct faces (:func:`_distinct_faces`), each counted with its multiplicity:
    the cotangent Laplacian (CSC), lumped masses, gradient (2F' x N: per face the unnormalized gradient
    direction, x components then y) and divergence (N x 2F'), with geometry-central's per-face formulas
    (Heron from the face's first halfedge, half-cotangents, halfedge vectors in the face's layout)."""
    h0 = cover.f_he
    h = np.stack([h0, cover.nxt[h0], cover.nxt[cover.nxt[h0]]], 1)   # (2F, 3)
    keep, weight = _distinct_faces(cover, h, n)
    h = h[keep]
    corner = cover.vert[h]
    la, lb, lc = (cover.length[cover.edge[h[:, c]]] for c in range(3))
    s = (la + lb + lc) / 2.0
    arg = s * (s - la) * (s - lb) * (s - lc)
    area = np.sqrt(np.where(arg > 0, arg, 0.0))
    sa, sb, sc = la * la, lb * lb, lc * lc
    with np.errstate(divide="ignore", invalid="ignore"):
        half = np.stack([(-sa + sb + sc) / (4.0 * area) / 2, (-sb + sc + sa) / (4.0 * area) / 2,
                         (-sc + sa + sb) / (4.0 * area) / 2], 1)
        height = 2.0 * area / la
    wide = lc * lc - height * height                          # halfedgeVectorsInFace
    wide = np.sqrt(np.where(wide > 0, wide, 0.0))
    wide = np.where(lb * lb > la * la + lc * lc, -wide, wide)
    vec = np.empty((len(h), 3, 2))
    vec[:, 0, 0], vec[:, 0, 1] = la, 0.0
    vec[:, 1, 0], vec[:, 1, 1] = wide - la, height
    vec[:, 2, 0], vec[:, 2, 1] = -wide, -height
    whalf = weight[:, None] * half
    lap = laplacian(corner.ravel(), corner[:, [1, 2, 0]].ravel(), whalf.ravel(), n)
    mass = np.bincount(corner.ravel(), np.repeat(weight * (area / 3.0), 3), minlength=n)
    return (lap, mass, *gradient_divergence(corner, vec, whalf, n))


def _distinct_faces(cover: _Cover, h: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Faces to keep (ascending) and their multiplicities: faces on the same three corners with bitwise
    equal lengths opposite each corner add the same normalized gradient and divergence (up to
    rounding). Grouped by a hash of corners and lengths; only exact equals are merged."""
    v = [cover.vert[h[:, c]] for c in range(3)]
    o = [cover.length[cover.edge[cover.nxt[h[:, c]]]].view(np.uint64) for c in range(3)]
    for i, j in ((0, 1), (1, 2), (0, 1)):                    # sort the corners, lengths alongside
        swap = v[j] < v[i]
        v[i], v[j] = np.where(swap, v[j], v[i]), np.where(swap, v[i], v[j])
        o[i], o[j] = np.where(swap, o[j], o[i]), np.where(swap, o[i], o[j])
    columns = [(v[0] * n + v[1]) * n + v[2] if n < 2 ** 21 else v[0], *o] + ([] if n < 2 ** 21 else v[1:])
    with np.errstate(over="ignore"):
        code = columns[0].astype(np.uint64)
        for col in columns[1:]:
            code = (code ^ (code >> np.uint64(31))) * np.uint64(0x9E3779B97F4A7C15) + col.astype(np.uint64)
    order = np.argsort(code)
    a, b = order[:-1], order[1:]
    same = code[a] == code[b]
    for col in columns:
        same &= col[a] == col[b]
    new = np.concatenate([[True], ~same])                     # first of each run of equal faces
    first = order[new]
    weight = np.zeros(len(h))
    weight[first] = np.diff(np.append(np.flatnonzero(new), len(order)))
    keep = weight > 0
    return keep, weight[keep]


def local_triangulations(points, neighbors: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Each point's normal (N, 3) and its local Delaunay triangles, the soup (F, 3) of
    :class:`CloudHeatDistance` (its ``neighbors``: potpourri3d's 30 nearest where None); compiled
    (``src/local_triangulation.cpp``: the module's normals and local triangulations, the library's arithmetic
    in its order), in blocks of rows on torch's threads (:func:`gegnn.threads.by_rows`). ValueError for
    points the method cannot take."""
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
        cover = _soup_cover(p, faces)
        self.n_flips = _flip_rounds(cover)
        self.t = t_coef * (cover.length.sum() / len(cover.length)) ** 2
        self._factor("cloud heat method", *_operators(cover, self.n))
