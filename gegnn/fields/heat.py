r"""Heat-method distances (Crane, Weischedel, Wardetzky 2013) as potpourri3d's robust solver computes them
(``MeshHeatMethodDistanceSolver(V, F, t_coef, use_robust=True)``, i.e. geometry-central's
``HeatMethodDistanceSolver`` on an intrinsic tufted cover, Sharp and Crane 2020), to solver rounding,
factored once, for one source or many per solve.

The operators live on an intrinsic triangulation of the edge lengths alone:

* **Tufted cover**: every face twice, a front copy and an oppositely oriented back copy. Along an edge
  of two faces the fronts are glued to each other and so are the backs (front to back where the faces
  run the edge the same way); along a boundary edge a face's front is glued to its own back. The cover
  is a closed surface on the same vertices; every operator below is summed over both copies.
* **Mollification**: every length grows by :math:`\epsilon = \max(0, \max_{\text{corners}}
  (l_c - l_a - l_b) + 10^{-5}\,\bar l)` (:math:`\bar l`: mean cover edge length), so every triangle
  satisfies the triangle inequality with a margin.
* **Intrinsic Delaunay flips**: an edge whose cotangent weight :math:`w_{ij} = \tfrac12(\cot\alpha +
  \cot\beta)` is below :math:`-10^{-6}` is flipped (its new length from laying out its two triangles),
  from a FIFO queue that starts with every edge in order and re-queues the four edges around each flip.
  A boundary edge is an ordinary edge of the cover: it flips when its opposite angle is obtuse enough.
  Both copies are flipped, in geometry-central's order: where four vertices are cocircular (CAD meshes)
  the mirrored copies re-queue edges in another order and can keep different diagonals, which the
  fields see (1e-3 relative on a test prism), so nothing is assumed symmetric.

With :math:`L` (the flipped cover's cotangent Laplacian), :math:`M` (a third of each cover triangle's
Heron area to each corner) and :math:`t = t_{coef}\,\bar l^2` (:math:`\bar l`: mean cover edge length
*after* mollification and flips; a boundary edge counts once, any other edge twice):

.. math::
    (M + tL)\,u = e_s, \qquad X_f = \frac{\nabla u}{|\nabla u|}\ (0 \text{ where } \nabla u = 0), \qquad
    (L + 10^{-6} I)\,\phi = \nabla\!\cdot X, \qquad d = \phi - \phi_s ,

:math:`(\nabla\!\cdot X)_i = \sum_{ij} w^f_{ij} \langle e_{ij}, X_f\rangle` over the cover's halfedges
:math:`ij` of face f (:math:`w^f_{ij}`: half the cotangent opposite them; :math:`e_{ij}` in f's layout).
The source's entry is 1, not a mass; the :math:`10^{-6} I` is absolute (not scaled with the mesh) and
meets the cover's doubled :math:`L` (it acts as :math:`5 \cdot 10^{-7} I` on a closed mesh): both shape
the fields and are kept. No clamping: d can be slightly negative near the source.

Here the gradient and divergence are sparse matrices over the cover's distinct faces (a back copy that
is still its front's mirror image is counted twice instead of computed again), both systems are
factored by Eigen's SimplicialLLT (AMD order) and solved by src/heat_ops.cpp, sixteen sources at a time,
the blocks spread over torch's threads, and the flips run in Python. 5,224-vertex closed mesh (2,164
cover flips), one core of a 2-core EPYC (2026-11-24, ``benchmarks/bench_landmark_fields.py``): setup
49 ms (potpourri3d ~40 ms; the flips are half of it), a field 0.5 ms one at a time (potpourri3d ~2 ms,
60% of it its per-face loop).

Supported: edge-manifold meshes (at most two faces an edge; any orientation, boundaries, slivers, zero
lengths) with finite coordinates and no face repeating a vertex. :func:`cover_problem` says why not
(potpourri3d orders the faces around a non-manifold edge by its internal halfedge order).
"""
from __future__ import annotations

import heapq
import math
from collections import deque
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .. import threads

__all__ = ["HeatSolver", "HeatDistance", "cover_problem", "MOLLIFY", "DELAUNAY_EPS", "POISSON_SHIFT"]

MOLLIFY = 1e-5          # mollification margin, relative to the mean cover edge length
DELAUNAY_EPS = 1e-6     # flip an edge whose cotangent weight is below -DELAUNAY_EPS
POISSON_SHIFT = 1e-6    # (L + POISSON_SHIFT I) phi = div X, with L the cover's Laplacian


def cover_problem(vertices, faces) -> str | None:
    """Why :class:`HeatDistance` does not reproduce potpourri3d on this mesh; None when it does."""
    f = np.asarray(faces)
    problem = _input_problem(np.asarray(vertices), f)
    if problem is None and np.bincount(_edge_keys(f, len(vertices))[1]).max() > 2:
        problem = "non-manifold edges"
    return problem


def _input_problem(v: np.ndarray, f: np.ndarray) -> str | None:
    if v.ndim != 2 or v.shape[1] != 3 or f.ndim != 2 or f.shape[1] != 3 or not len(f):
        return "not a triangle mesh"
    if not np.isfinite(v).all():
        return "non-finite vertex coordinates"
    if f.min() < 0 or f.max() >= len(v) or np.bincount(f.ravel(), minlength=len(v)).min() == 0:
        return "face indices out of range or unreferenced vertices"
    if ((f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 2] == f[:, 0])).any():
        return "face with a repeated vertex"
    return None


def _edge_keys(faces: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """For the halfedges 3f + c (corner c to c + 1): each edge's first halfedge, in order of the edge
    keys, and each halfedge's index into it."""
    tail, tip = faces.reshape(-1), faces[:, [1, 2, 0]].reshape(-1)
    _, first, inverse = np.unique(np.minimum(tail, tip) * n + np.maximum(tail, tip), return_index=True,
                                  return_inverse=True)
    return first, inverse


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


def _tufted_cover(vertices: np.ndarray, faces: np.ndarray) -> _Cover:
    """Front halfedge 3f + c runs from corner c to c + 1, its back copy 3F + 3f + c from c + 1 to c.
    Edges: the mesh's in order of first appearance, then a back edge per two-face edge, same order."""
    n_f = len(faces)
    tail = faces.reshape(-1)
    tip = faces[:, [1, 2, 0]].reshape(-1)
    first, inverse = _edge_keys(faces, len(vertices))
    if np.bincount(inverse).max() > 2:
        raise ValueError("heat method: non-manifold edges")
    order = np.argsort(first, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    edge_of = rank[inverse]                                   # mesh edge of each front halfedge
    h1 = first[order]                                         # each mesh edge's first halfedge
    h2 = np.full(len(h1), -1)
    is_second = np.ones(3 * n_f, dtype=bool)
    is_second[h1] = False
    h2[edge_of[is_second]] = np.flatnonzero(is_second)        # its second face's halfedge, if any
    interior = np.flatnonzero(h2 >= 0)
    same = tail[h1[interior]] == tail[h2[interior]]           # both faces run the edge the same way
    back = 3 * n_f
    b2 = h2[interior]
    pair_a = np.concatenate([h1, back + h1[interior]])
    pair_b = back + np.concatenate([h1, b2])                  # boundary edges: front to its own back
    pair_b[interior] = np.where(same, back + b2, b2)
    pair_b[len(h1):] = np.where(same, b2, back + b2)
    step = np.repeat([[1, 2, 0], [2, 0, 1]], n_f, axis=0)    # next corner: c + 1 on fronts, c - 1 on backs
    nxt = (3 * np.arange(2 * n_f)[:, None] + step).ravel()
    vert = np.concatenate([tail, tip])
    sib = np.empty(len(nxt), dtype=np.int64)
    sib[pair_a], sib[pair_b] = pair_b, pair_a
    edge = np.empty(len(nxt), dtype=np.int64)
    edge[pair_a] = edge[pair_b] = np.arange(len(pair_a))
    d = vertices[tail[h1]] - vertices[tip[h1]]
    length = np.sqrt(np.einsum("ij,ij->i", d, d))            # (x^2 + y^2) + z^2, as geometry-central
    length = np.concatenate([length, length[interior]])       # a back edge has its front's length
    return _Cover(nxt, vert, np.repeat(np.arange(2 * n_f), 3), sib, edge, pair_a, 3 * np.arange(2 * n_f), length)


def _mollify(cover: _Cover, relative: float = MOLLIFY) -> None:
    """Add one epsilon to every length so that each corner has l_a + l_b - l_c >= relative x mean."""
    la = cover.length[cover.edge]
    lb = la[cover.nxt]
    lc = lb[cover.nxt]
    delta = cover.length.sum() / len(cover.length) * relative
    cover.length += max(0.0, float(np.max(lc - la - lb + delta)))


def _cotan_halves(cover: _Cover) -> tuple[np.ndarray, np.ndarray]:
    """Face areas (Heron, from each face's first halfedge) and, per halfedge, half the cotangent of the
    angle opposite it: (l_jk^2 + l_ki^2 - l_ij^2) / (8 area)."""
    h0 = cover.f_he
    h1 = cover.nxt[h0]
    a, b, c = (cover.length[cover.edge[h]] for h in (h0, h1, cover.nxt[h1]))
    s = (a + b + c) / 2.0
    arg = s * (s - a) * (s - b) * (s - c)
    area = np.sqrt(np.where(arg > 0, arg, 0.0))
    lij = cover.length[cover.edge]
    ljk = lij[cover.nxt]
    lki = ljk[cover.nxt]
    with np.errstate(divide="ignore", invalid="ignore"):
        half = (-lij * lij + ljk * ljk + lki * lki) / (4.0 * area[cover.face]) / 2
    return area, half


def _flip_to_delaunay(cover: _Cover, eps: float = DELAUNAY_EPS) -> int:
    """geometry-central's flipToDelaunay, in place: the same queue, flips and arithmetic.

    The queue starts with every edge; here that first pass evaluates only the edges that are not
    Delaunay or whose triangles a flip has changed (the others would be popped without effect).
    Half-cotangents are cached per halfedge and recomputed for the two new triangles of each flip.
    ZeroDivisionError where a length or an area is 0 (geometry-central would go on with inf/nan)."""
    _, half = _cotan_halves(cover)
    first_pass = np.flatnonzero(half[cover.e_he] + half[cover.sib[cover.e_he]] < -eps).tolist()
    if not first_pass:
        return 0
    # Memoryviews: element access at list speed, in place, with no conversion of the arrays.
    nxt, vert, face, sib, edge, e_he, f_he, length, hc = (
        memoryview(a) for a in (cover.nxt, cover.vert, cover.face, cover.sib, cover.edge, cover.e_he,
                                cover.f_he, cover.length, half))

    def refresh(h0):
        """Half-cotangents of h0's triangle; h0 is its first halfedge (Heron from there)."""
        h1 = nxt[h0]
        h2 = nxt[h1]
        a, b, c = length[edge[h0]], length[edge[h1]], length[edge[h2]]
        s = (a + b + c) / 2.0
        area4 = 4.0 * math.sqrt(max(0.0, s * (s - a) * (s - b) * (s - c)))
        hc[h0] = (-a * a + b * b + c * c) / area4 / 2
        hc[h1] = (-b * b + c * c + a * a) / area4 / 2
        hc[h2] = (-c * c + a * a + b * b) / area4 / 2

    def flip(e, ha1, hb1):
        """Flip edge e (halfedges ha1, hb1) unless geometry-central would not; its four neighbours."""
        ha2, hb2 = nxt[ha1], nxt[hb1]
        ha3, hb3 = nxt[ha2], nxt[hb2]
        # Lay out the quad (geometry-central's flippedEdgeLen): vertex 3 = (0, 0), 0 = (l30, 0), then
        # 2 from l02, l23 and 1 from l01, l12; the new edge runs from 1 to 3.
        l30 = length[edge[hb3]]
        x2, y2 = _layout_from_origin(l30, length[e], length[edge[hb2]])
        x1, y1 = _layout((x2, y2), (l30, 0.0), length[edge[ha2]], length[edge[ha3]])
        new = math.sqrt(x1 * x1 + y1 * y1)
        if not math.isfinite(new) or ha2 == hb1 or hb2 == ha1:
            return ()
        relink(nxt, vert, face, f_he, face[ha1], face[hb1], (ha1, ha2, ha3), (hb1, hb2, hb3))
        length[e] = new
        refresh(ha1)
        refresh(hb1)
        return edge[hb3], edge[ha2], edge[ha3], edge[hb2]

    # Queue = [rest of the first pass, in edge order] + [FIFO]. A flip's neighbour still ahead in the
    # first pass is queued there already (and must now be evaluated); any other one joins the FIFO
    # unless it is in it.
    heapq.heapify(first_pass)
    ahead = set(first_pass)
    in_fifo = bytearray(len(length))
    fifo = deque()
    n_flips = 0
    while first_pass or fifo:
        in_first = bool(first_pass)
        if in_first:
            e = heapq.heappop(first_pass)
        else:
            e = fifo.popleft()
            in_fifo[e] = 0
        ha1 = e_he[e]
        hb1 = sib[ha1]
        if not hc[ha1] + hc[hb1] < -eps:
            continue
        neighbours = flip(e, ha1, hb1)
        n_flips += bool(neighbours)
        for n in neighbours:
            if in_first and n > e:
                if n not in ahead:
                    ahead.add(n)
                    heapq.heappush(first_pass, n)
            elif not in_fifo[n]:
                in_fifo[n] = 1
                fifo.append(n)
    return n_flips


def relink(nxt, vert, face, f_he, fa, fb, a, b) -> None:
    """The halfedge links after flipping the edge between faces ``fa`` (halfedges ``a`` = (a1, a2, a3),
    a1 on the edge) and ``fb`` (``b``, b1 its twin): one flip (ints) or many disjoint ones (index arrays)."""
    (ha1, ha2, ha3), (hb1, hb2, hb3) = a, b
    f_he[fa], f_he[fb] = ha1, hb1
    nxt[ha1], nxt[hb3], nxt[ha2] = hb3, ha2, ha1
    nxt[hb1], nxt[ha3], nxt[hb2] = ha3, hb2, hb1
    vert[ha1], vert[hb1] = vert[ha3], vert[hb3]
    face[ha3], face[hb3] = fb, fa


def _layout_from_origin(l_ab: float, l_bc: float, l_ca: float) -> tuple[float, float]:
    """:func:`_layout` for A = (0, 0), B = (l_ab, 0) (the same floating-point result)."""
    s = (l_ab + l_bc + l_ca) / 2.0
    area = math.sqrt(max(0.0, s * (s - l_ab) * (s - l_bc) * (s - l_ca)))
    return (l_ab * l_ab - l_bc * l_bc + l_ca * l_ca) / (2.0 * l_ab), 2.0 * area / l_ab


def _layout(pa, pb, l_bc: float, l_ca: float) -> tuple[float, float]:
    """geometry-central's layoutTriangleVertex: C left of A -> B with |BC| = l_bc, |CA| = l_ca."""
    dx, dy = pb[0] - pa[0], pb[1] - pa[1]
    l_ab = math.sqrt(dx * dx + dy * dy)
    s = (l_ab + l_bc + l_ca) / 2.0
    area = math.sqrt(max(0.0, s * (s - l_ab) * (s - l_bc) * (s - l_ca)))
    h = 2.0 * area / l_ab
    w = (l_ab * l_ab - l_bc * l_bc + l_ca * l_ca) / (2.0 * l_ab)
    ux, uy = dx / l_ab, dy / l_ab
    return pa[0] + w * ux + h * -uy, pa[1] + w * uy + h * ux


def _halfedge_vectors(cover: _Cover, area: np.ndarray) -> np.ndarray:
    """(H, 2): each halfedge as a vector in its face's layout (first halfedge along +x, third vertex
    above), as geometry-central's halfedgeVectorsInFace."""
    h0 = cover.f_he
    h1 = cover.nxt[h0]
    h2 = cover.nxt[h1]
    l_ab, l_bc, l_ca = (cover.length[cover.edge[h]] for h in (h0, h1, h2))
    with np.errstate(divide="ignore", invalid="ignore"):
        height = 2.0 * area / l_ab
    w2 = l_ca * l_ca - height * height
    w = np.sqrt(np.where(w2 > 0, w2, 0.0))
    w = np.where(l_bc * l_bc > l_ab * l_ab + l_ca * l_ca, -w, w)
    vec = np.empty((len(cover.nxt), 2))
    vec[h0, 0], vec[h0, 1] = l_ab, 0.0
    vec[h1, 0], vec[h1, 1] = w - l_ab, height
    vec[h2, 0], vec[h2, 1] = -w, -height
    return vec


def _operators(cover: _Cover, n: int):
    """Cotangent Laplacian (CSC) and lumped masses of the cover; gradient (2F' x N: per face the
    unnormalized gradient direction, x components then y) and divergence (N x 2F') over its F' distinct
    faces (:func:`_distinct_faces`)."""
    area, half = _cotan_halves(cover)
    e, s = cover.e_he, cover.sib[cover.e_he]
    lap = laplacian(cover.vert[e], cover.vert[cover.nxt[e]], half[e] + half[s], n)
    mass = np.bincount(cover.vert, weights=(area / 3.0)[cover.face], minlength=n)
    h = np.stack([cover.f_he, cover.nxt[cover.f_he], cover.nxt[cover.nxt[cover.f_he]]], 1)   # (2F, 3)
    keep, weight = _distinct_faces(cover, h)
    h = h[keep]
    return (lap, mass, *gradient_divergence(cover.vert[h], _halfedge_vectors(cover, area)[h],
                                            weight[:, None] * half[h], n))


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


def _distinct_faces(cover: _Cover, h: np.ndarray, rtol: float = 1e-12) -> tuple[np.ndarray, np.ndarray]:
    """Faces to keep and their multiplicity. Two faces on the same three vertices with the same lengths
    opposite them (to rtol) add the same normalized gradient and divergence: one of them counts twice.
    The front and back copy of most faces are such twins (not where a boundary edge flipped)."""
    by_vertex = np.argsort(cover.vert[h], axis=1)
    corners = np.take_along_axis(cover.vert[h], by_vertex, 1)
    opposite = np.take_along_axis(cover.length[cover.edge[cover.nxt[h]]], by_vertex, 1)
    n = int(corners[:, 2].max()) + 1
    key = (corners[:, 0] * n + corners[:, 1]) * n + corners[:, 2] if n < 2 ** 21 else np.arange(len(h))
    order = np.argsort(key, kind="stable")
    a, b = order[:-1], order[1:]
    twin = ((key[a] == key[b]) & (np.abs(opposite[a] - opposite[b]) <= rtol * opposite[a]).all(1)
            & (corners[a, 0] != corners[a, 1]) & (corners[a, 1] != corners[a, 2]))
    twin[1:] &= ~twin[:-1]                                    # pairs only: a face is merged at most once
    weight = np.ones(len(h))
    weight[a[twin]] = 2.0
    keep = np.ones(len(h), dtype=bool)
    keep[b[twin]] = False
    return keep, weight[keep]


class HeatSolver:
    """The heat method's two solves on operators built once (a subclass builds them): :math:`(M + tL)`,
    :math:`(L + 10^{-6} I)` factored (Eigen's SimplicialLLT, AMD order), the per-face gradient and
    divergence; then :meth:`distances` for any sources, in blocks of 16 spread over torch's threads
    (:mod:`gegnn.threads`), or :meth:`distance` for one (src/heat_ops.cpp: without the interpreter; the
    same fields for any thread count).

    Attributes:
        n: vertex count; t: the time step.
    """

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
        poisson.data[diagonal] += POISSON_SHIFT
        try:
            arrays = [np.ascontiguousarray(a, dtype=dt) for m in (heat, poisson, grad.tocsr(), div.tocsr())
                      for a, dt in ((m.indptr, np.int64), (m.indices, np.int64), (m.data, np.float64))]
            self._fields = HeatFields(*arrays, n=self.n)
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
        t_coef: time step over the mean squared cover edge length.

    Attributes:
        n: vertex count; t: the time step; n_flips: intrinsic flips made on the cover (both copies).
    """

    def __init__(self, vertices, faces, t_coef: float = 0.5):
        v = np.ascontiguousarray(vertices, dtype=np.float64)
        f = np.ascontiguousarray(faces, dtype=np.int64)
        problem = _input_problem(v, f)
        if problem:
            raise ValueError(f"heat method: {problem}")
        self.n = len(v)
        cover = _tufted_cover(v, f)
        _mollify(cover)
        try:
            self.n_flips = _flip_to_delaunay(cover)
        except ZeroDivisionError:
            raise ValueError("heat method: zero edge length or area after mollification") from None
        self.t = t_coef * (cover.length.sum() / len(cover.length)) ** 2
        self._factor("heat method", *_operators(cover, self.n))
