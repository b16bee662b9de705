r"""The heat method (Crane, Weischedel, Wardetzky 2013) on an intrinsic tufted cover (Sharp and Crane
2020), as potpourri3d computes it: for meshes its robust solver (``MeshHeatMethodDistanceSolver(V, F,
t_coef, use_robust=True)``, here :class:`HeatDistance`), for point clouds its ``PointCloudHeatSolver``
on the soup of the points' local triangles (:mod:`gegnn.fields.cloud_heat`). One core serves both:

* **Tufted cover** of a triangle soup (a mesh's faces, or a cloud's local triangles with repeats): every
  face twice, a front copy and an oppositely oriented back copy; around an edge of faces
  :math:`h_0, \dots, h_{n-1}` (creation order) the sheets are glued cyclically in the order
  :math:`h_0, h_{n-1}, \dots, h_1`, each face's free sheet to the next face's sheet of the other
  orientation. On a mesh: along an edge of two faces the fronts are glued to each other and so are the
  backs (front to back where the faces run the edge the same way); along a boundary edge a face's front
  is glued to its own back. The cover is a closed surface on the same vertices.
* **Mollification**: every length grows by :math:`\epsilon = \max(0, \max_{\text{corners}}
  (l_c - l_a - l_b) + 10^{-5}\,\bar l)`, so every triangle satisfies the triangle inequality with a
  margin (:math:`\bar l`: the mean cover edge length on meshes, the mean soup edge length on clouds, as
  the library).
* **Intrinsic Delaunay flips**: an edge whose cotangent weight :math:`w_{ij} = \tfrac12(\cot\alpha +
  \cot\beta)` is below :math:`-10^{-6}` is flipped (its new length from laying out its two triangles),
  in rounds of face-disjoint flips (each round every such edge that has the smallest such index on both
  its faces). The library flips from a FIFO queue; where the Delaunay triangulation is unique (generic
  input) both end with the same triangles, where four vertices are cocircular they may keep other
  diagonals, which the fields see (tests: meshes 1.6e-2 of the largest distance at most, clouds as
  their module says).

With :math:`L` (the flipped cover's cotangent Laplacian), :math:`M` (a third of each cover triangle's
Heron area to each corner) and :math:`t = t_{coef}\,\bar l^2` (:math:`\bar l`: mean cover edge length
*after* mollification and flips):

.. math::
    (M + tL)\,u = e_s, \qquad X_f = \frac{\nabla u}{|\nabla u|}\ (0 \text{ where } \nabla u = 0), \qquad
    (L + 10^{-6} I)\,\phi = \nabla\!\cdot X, \qquad d = \phi - \phi_s ,

:math:`(\nabla\!\cdot X)_i = \sum_{ij} w^f_{ij} \langle e_{ij}, X_f\rangle` over the cover's halfedges
:math:`ij` of face f (:math:`w^f_{ij}`: half the cotangent opposite them; :math:`e_{ij}` in f's layout).
The source's entry is 1, not a mass; the :math:`10^{-6} I` is absolute (not scaled with the mesh) and
meets the cover's doubled :math:`L`: both shape the fields and are kept. No clamping: d can be slightly
negative near the source.

The operators are sparse matrices over the cover's distinct faces (identical triangles: same corners,
bitwise equal lengths, such as a front and its back copy, count once with their multiplicity); both
systems are factored by Eigen's SimplicialLLT (AMD order) and solved by src/heat_ops.cpp, sixteen
sources at a time, the blocks spread over torch's threads. 5,224-vertex closed mesh (2,166 cover
flips), one core of a 2-core EPYC (2026-11-26, ``benchmarks/bench_landmark_fields.py``): setup 41 ms
(the library's queue replayed in Python, before: 62-78 ms in the same runs), a field 0.8 ms; 128
farthest-point landmark fields 0.12 s (potpourri3d 0.28 s), the same landmarks and float32 fields. The
fields of the 19 validation meshes are potpourri3d's to 5.2e-14 of their largest value.

Meshes supported: edge-manifold (at most two faces an edge; any orientation, boundaries, slivers, zero
lengths) with finite coordinates and no face repeating a vertex. :func:`cover_problem` says why not
(potpourri3d orders the faces around a non-manifold edge by its internal halfedge order).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from geodata.mesh import edge_face_counts

from .. import threads

__all__ = ["HeatSolver", "HeatDistance", "cover_problem", "tufted_cover", "mollify", "flip_to_delaunay", "operators",
           "MOLLIFY", "DELAUNAY_EPS", "POISSON_SHIFT", "time_step", "poisson_shift", "SAME_UP_TO", "RESOLUTION"]

MOLLIFY = 1e-5          # mollification margin, relative to the mean cover edge length
DELAUNAY_EPS = 1e-6     # flip an edge whose cotangent weight is below -DELAUNAY_EPS
POISSON_SHIFT = 1e-6    # (L + POISSON_SHIFT I) phi = div X, with L the cover's Laplacian
SAME_UP_TO = 10_000     # meshes of at most this many vertices keep t = t_coef hbar^2 and POISSON_SHIFT
RESOLUTION = 90         # beyond: t = t_coef hbar^2 max(1, (D / hbar) / RESOLUTION), D the bounding-box diagonal


def time_step(hbar: float, diagonal: float, n: int, t_coef: float = 0.5, same_up_to: int = SAME_UP_TO) -> float:
    """The heat step t for a mesh of ``n`` vertices, mean cover edge length ``hbar`` and bounding-box
    diagonal ``diagonal``: ``t_coef hbar^2`` up to ``same_up_to`` vertices (the fields the shipped models were
    trained with, at ~5k), beyond ``t_coef hbar^2 max(1, (diagonal / hbar) / RESOLUTION)``, i.e. t grows
    as hbar D instead of hbar^2 once the mesh is fine: a step tied to hbar^2 alone loses the far field
    (bunny at 320k vertices: 11.5% off at t_coef 0.5). docs/benchmarks.md, "The heat method's time step"."""
    t = t_coef * (hbar * hbar)
    return t if n <= same_up_to else t * max(1.0, diagonal / hbar / RESOLUTION)


def poisson_shift(n: int, same_up_to: int = SAME_UP_TO) -> float:
    """The Poisson system's shift for ``n`` vertices: POISSON_SHIFT up to ``same_up_to`` vertices, then
    POISSON_SHIFT same_up_to / n, so that it stays as small against the Laplacian's lowest modes (whose
    eigenvalues fall as 1 / n) as at ``same_up_to``: unscaled it damps them, 3% of distance error at 385k."""
    return POISSON_SHIFT * min(1.0, same_up_to / n)


def cover_problem(vertices, faces) -> str | None:
    """Why :class:`HeatDistance` does not take this mesh (nor reproduce potpourri3d on it); None when it does."""
    v, f = np.asarray(vertices), np.asarray(faces)
    if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3 or not len(f):
        return "not a triangle mesh"
    if not np.isfinite(v).all():
        return "non-finite vertex coordinates"
    if f.min() < 0 or f.max() >= len(v) or np.bincount(f.ravel(), minlength=len(v)).min() == 0:
        return "face indices out of range or unreferenced vertices"
    if ((f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 2] == f[:, 0])).any():
        return "face with a repeated vertex"
    if edge_face_counts(f)[1].max() > 2:
        return "non-manifold edges"
    return None


@dataclass
class _Cover:
    """Halfedge connectivity of the tufted cover in geometry-central's element order: halfedge h runs
    from ``vert[h]`` to ``vert[nxt[h]]`` in face ``face[h]``; ``sib[h]`` is the other halfedge of its
    edge ``edge[h]``; ``e_he``/``f_he``: each edge's and face's first halfedge; ``length`` per edge.
    Faces f < F are the mesh's (fronts), F + f the back copy of f."""

    nxt: np.ndarray
    vert: np.ndarray
    face: np.ndarray
    sib: np.ndarray
    edge: np.ndarray
    e_he: np.ndarray
    f_he: np.ndarray
    length: np.ndarray
    soup_edges: int  # the soup's own edges come first; the rest glue its other sheets


def tufted_cover(points: np.ndarray, faces: np.ndarray) -> _Cover:
    """The tufted cover of a triangle soup in geometry-central's element order (:class:`_Cover`), lengths
    not yet mollified: front halfedge 3f + c runs from corner c to c + 1, its back copy
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
    length = np.sqrt((d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]) + d[:, 2] * d[:, 2])  # Vector3's norm
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
                  3 * np.arange(2 * n_f), np.concatenate([length, length[e_new]]), len(h0))


def mollify(cover: _Cover, mean: float, relative: float = MOLLIFY) -> None:
    """Add one epsilon to every length so that each corner has l_a + l_b - l_c >= relative x mean."""
    la = cover.length[cover.edge]
    lb = la[cover.nxt]
    lc = lb[cover.nxt]
    cover.length += max(0.0, float(np.max(lc - la - lb + mean * relative)))


def _heron_halves(a, b, c):
    """Triangles of side lengths a, b, c (a along the first halfedge, then b, c): their area (Heron, as
    geometry-central from the first halfedge) and half the cotangent of the angle opposite each side,
    (b^2 + c^2 - a^2) / (8 area) for a and so on."""
    s = (a + b + c) / 2.0
    arg = s * (s - a) * (s - b) * (s - c)
    area = np.sqrt(np.where(arg > 0, arg, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        return area, ((-a * a + b * b + c * c) / (4.0 * area) / 2, (-b * b + c * c + a * a) / (4.0 * area) / 2,
                      (-c * c + a * a + b * b) / (4.0 * area) / 2)


def _cotan_halves(cover: _Cover, half: np.ndarray, h0: np.ndarray) -> None:
    """Into ``half``, for the faces of first halfedges ``h0``: per halfedge, half the cotangent of the angle
    opposite it in its face (:func:`_heron_halves`)."""
    h1 = cover.nxt[h0]
    h2 = cover.nxt[h1]
    half[h0], half[h1], half[h2] = _heron_halves(*(cover.length[cover.edge[h]] for h in (h0, h1, h2)))[1]


def flip_to_delaunay(cover: _Cover, eps: float = DELAUNAY_EPS) -> int:
    """Intrinsic Delaunay flips in rounds, in place: each round flips, at once, every edge with cotangent
    weight below -eps that has the smallest such index on both its faces; returns the flips made. Each
    flip is geometry-central's (its layout arithmetic and halfedge updates, refused where the new length
    is not finite or a vertex has degree 1); an edge refused waits until one of its faces changes."""
    nxt, vert, face, sib, edge, e_he, f_he, length = (cover.nxt, cover.vert, cover.face, cover.sib, cover.edge,
                                                      cover.e_he, cover.f_he, cover.length)
    half = np.empty(len(nxt))
    _cotan_halves(cover, half, f_he)
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
        # the halfedge links after the flips: fa's new first halfedge is ha1, fb's hb1
        f_he[fa], f_he[fb] = ha1, hb1
        nxt[ha1], nxt[hb3], nxt[ha2] = hb3, ha2, ha1
        nxt[hb1], nxt[ha3], nxt[hb2] = ha3, hb2, hb1
        vert[ha1], vert[hb1] = vert[ha3], vert[hb3]
        face[ha3], face[hb3] = fb, fa
        length[e] = new
        _cotan_halves(cover, half, np.concatenate([ha1, hb1]))  # the two new faces of every flip
        touched = edge[np.concatenate([ha1, ha2, ha3, hb1, hb2, hb3])]
        weight[touched] = half[e_he[touched]] + half[sib[e_he[touched]]]
        refused[touched] = False


def _layout(pax, pay, pbx, pby, l_bc, l_ca):
    """geometry-central's layoutTriangleVertex: C left of A -> B with |BC| = l_bc, |CA| = l_ca."""
    dx, dy = pbx - pax, pby - pay
    l_ab = np.sqrt(dx * dx + dy * dy)
    s = (l_ab + l_bc + l_ca) / 2.0
    area = np.sqrt(np.maximum(0.0, s * (s - l_ab) * (s - l_bc) * (s - l_ca)))
    h = 2.0 * area / l_ab
    w = (l_ab * l_ab - l_bc * l_bc + l_ca * l_ca) / (2.0 * l_ab)
    ux, uy = dx / l_ab, dy / l_ab
    return pax + w * ux + h * -uy, pay + w * uy + h * ux


def operators(cover: _Cover, n: int):
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
    area, halves = _heron_halves(la, lb, lc)
    half = np.stack(halves, 1)
    with np.errstate(divide="ignore", invalid="ignore"):
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


def laplacian(tail: np.ndarray, tip: np.ndarray, w: np.ndarray, n: int) -> sp.csc_matrix:
    """The symmetric (N, N) matrix with -w on (tail, tip) and (tip, tail) and the row sums on the diagonal,
    repeated entries summed (a cotangent Laplacian from its edge weights)."""
    diagonal = np.bincount(tail, w, minlength=n) + np.bincount(tip, w, minlength=n)
    lap = sp.csr_matrix((np.concatenate([-w, -w, diagonal]), (np.concatenate([tail, tip, np.arange(n)]),
                                                              np.concatenate([tip, tail, np.arange(n)]))),
                        shape=(n, n))
    lap.sum_duplicates()
    return sp.csc_matrix((lap.data, lap.indices, lap.indptr), shape=(n, n))   # symmetric: CSR = CSC


def gradient_divergence(corner: np.ndarray, vec: np.ndarray, whalf: np.ndarray, n: int):
    """Per-face gradient (2F x N: the unnormalized gradient direction, x components then y) and divergence
    (N x 2F) of faces with corner vertices (F, 3), halfedge vectors in their layout (F, 3, 2) and weighted
    half-cotangents (F, 3), halfedge k running from corner k to corner k + 1."""
    cols = np.tile(corner.ravel(), 2)
    rows = np.arange(0, len(cols) + 1, 3)                    # three corners a row
    shape = (2 * len(corner), n)
    nv = np.roll(vec, -1, axis=1)                             # grad u ~ sum_h rot90(vec[next h]) u[tail h]
    grad = sp.csr_matrix((np.concatenate([-nv[..., 1].ravel(), nv[..., 0].ravel()]), cols, rows), shape=shape)
    wv = whalf[..., None] * vec                               # div X: +-w_h <vec h, X> at tail / tip of h
    c = wv - np.roll(wv, 1, axis=1)
    div_t = sp.csr_matrix((np.concatenate([c[..., 0].ravel(), c[..., 1].ravel()]), cols, rows), shape=shape)
    return grad, div_t.T.tocsr()


class HeatSolver:
    """The heat method's two solves (see the module) on operators a subclass builds once: :meth:`distances`
    for any sources, on torch's threads (:mod:`gegnn.threads`; the same fields for any thread count), or
    :meth:`distance` for one.

    Attributes:
        n: vertex count; t: the time step; shift: the Poisson system's shift.
    """

    shift = POISSON_SHIFT

    def _factor(self, what: str, lap: sp.csc_matrix, mass: np.ndarray, grad, div) -> None:
        """Factor (M + tL) and (L + shift I) of ``lap``, ``mass`` and ``self.t`` with ``grad`` and ``div``;
        ValueError where a system is not numerically positive definite (degenerate input)."""
        if not (np.isfinite(lap.data).all() and np.isfinite(mass).all() and np.isfinite(self.t)):
            raise ValueError(f"{what}: non-finite operators (degenerate input)")
        from .._heat_ops import HeatFields

        lap = lap.copy()
        lap.sort_indices()
        diagonal = np.flatnonzero(lap.indices == np.repeat(np.arange(self.n), np.diff(lap.indptr)))
        heat, poisson = lap.copy(), lap                       # (M + tL), (L + shift I): same pattern
        heat.data *= self.t
        heat.data[diagonal] += mass
        poisson.data[diagonal] += self.shift
        try:
            arrays = [np.ascontiguousarray(a, dtype=dt) for m in (heat, poisson, grad.tocsr(), div.tocsr())
                      for a, dt in ((m.indptr, np.int64), (m.indices, np.int64), (m.data, np.float64))]
            self._fields = HeatFields(*arrays, self.n)  # (M + tL), (L + shift I), G, D: CSR arrays
        except RuntimeError as exc:
            raise ValueError(f"{what}: cannot factor ({exc})") from None

    def distances(self, sources) -> np.ndarray:
        """float64 (N, len(sources)): column j is the distance field of ``sources[j]`` alone."""
        sources = np.ascontiguousarray(np.atleast_1d(np.asarray(sources, dtype=np.int64)))
        return self._fields.distances(sources, threads.count())

    def distance(self, source: int) -> np.ndarray:
        """float64 (N,): the field of one source (a column of :meth:`distances`)."""
        return self._fields.distances(np.array([source], dtype=np.int64), 1)[:, 0]

    def _divergence(self, u: np.ndarray) -> np.ndarray:
        """(N, k): the divergence of the normalized gradient of each column of u, (N,) or (N, k), per face
        grad u / |grad u| (0 where it is 0), as SciPy's products would give it (src/heat_ops.cpp)."""
        return self._fields.divergence(np.ascontiguousarray(u.reshape(len(u), -1), dtype=np.float64))


class HeatDistance(HeatSolver):
    """potpourri3d's robust heat-method distance on one mesh: cover, flips and both factorizations
    once; then :meth:`distances` for any sources, many per solve.

    Args:
        vertices: (N, 3) float.
        faces: (F, 3) int; see :func:`cover_problem` for what is supported (ValueError otherwise).
        t_coef: time step over the mean squared cover edge length, on meshes of up to ``same_up_to`` vertices;
            on larger meshes :func:`time_step` scales it up with the resolution.
        same_up_to: where that starts (SAME_UP_TO; a model's landmark fields keep the step it was trained
            with further: :data:`gegnn.fields.landmarks.MODEL_STEP_UP_TO`).

    Attributes:
        n: vertex count; t: the time step; shift: the Poisson shift (:func:`poisson_shift`); hbar: the mean
        cover edge length after mollification and flips; n_flips: intrinsic flips made on the cover.
    """

    def __init__(self, vertices, faces, t_coef: float = 0.5, same_up_to: int = SAME_UP_TO):
        v = np.ascontiguousarray(vertices, dtype=np.float64)
        f = np.ascontiguousarray(faces, dtype=np.int64)
        problem = cover_problem(v, f)
        if problem:
            raise ValueError(f"heat method: {problem}")
        self.n = len(v)
        cover = tufted_cover(v, f)
        mollify(cover, cover.length.sum() / len(cover.length))
        self.n_flips = flip_to_delaunay(cover)
        self.hbar = cover.length.sum() / len(cover.length)
        self.t = time_step(self.hbar, float(np.linalg.norm(np.ptp(v, axis=0))), self.n, t_coef, same_up_to)
        self.shift = poisson_shift(self.n, same_up_to)
        self._factor("heat method", *operators(cover, self.n))
