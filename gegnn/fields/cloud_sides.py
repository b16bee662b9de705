r"""The sides of a point cloud's surface where two sheets come closer than the points' spacing (a thin
slab, a shell, a folded sheet): which neighbours of a point lie on its own sheet.

With the cloud's own oriented normals (a scan's), a neighbour :math:`q` of :math:`p` is on its sheet where
the two face the same side, :math:`n_p \cdot n_q > 0` (the two sides of a thin wall face away from each
other), and the offset between them runs along the surface: within a cone about the plane normal to their
mean normal :math:`m = n_p + n_q`, :math:`|m \cdot (q - p)| < \sin(\text{cone})\,|m|\,|q - p|`. On one
smooth sheet the chord between two points makes equal angles with their tangent planes, so
:math:`m \cdot (q - p)` vanishes to third order however the sheet curves; a sheet stacked above another
that faces the same way (the first and third layers of a sheet folded twice) has :math:`n_q = n_p` and
lies off that plane by the stack's height. Rows with fewer such neighbours are filled with the nearest
facing the same side, then with the nearest others.

Without normals the sides cannot be told apart from a point's neighbourhood once the sheets are closer
than it is wide, but that they are there can be seen (:func:`close_walls`): the offsets of a point's
``LAYER_K`` nearest from the quadric fitted to them all fall into groups, one sheet's above the fitted
surface and the other's below it, where those of one sheet (curved, or noisy) spread about it in one. Two
sheets: the best split of the sorted offsets into two groups (Otsu's, three or more points in each) puts
their means apart by over ``LAYER_RATIO`` (4.5) times their pooled spread, and by over ``LAYER_GAP``
(0.1) spacings; three (a sheet folded twice): the best split into three holds over ``LAYER_THREE`` (95%) of
their variance, the outer means 0.2 spacings apart. (One sheet's offsets, Gaussian noise or curvature the
quadric leaves, split about 2.5-4 spreads apart and three groups of them hold up to about 94%; on the 19
validation clouds, clean and noisy, 0-0.3% of the points are flagged but for the thin shells, lion 68% and
teapot 49% clean: ``benchmarks/bench_close_walls.py --store``.)
A point is *ambiguous* where at least ``AMBIGUOUS_SHARE`` (three in ten) of it and its nearest are such
points whose other sheet the normals do not tell apart: no normals given, or over ``FACING_SHARE`` (a quarter)
of the other group facing the point's side (:math:`n_p \cdot n_q > 0`), where a wall's other side faces away.
Noise as large as the gap between two sheets hides them (their offsets then spread as one sheet's do): a cloud's ``scatter``, the median RMS
offset in spacings, says how much there is.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .. import threads

__all__ = ["facing_neighbors", "facing_ranks", "two_sheets", "close_walls", "Walls", "LAYER_K", "LAYER_RATIO"]

BLOCK = 4096          # rows ranked at once (bounded temporaries)
LAYER_K = 20          # neighbours of each point's two-sheet test
LAYER_RATIO = 4.5     # gap between the two groups of offsets over their pooled spread, from which they are two sheets
LAYER_GAP = 0.1       # ... and the gap at least this share of the point's spacing
LAYER_THREE = 0.95    # the share of the offsets' variance between three groups from which they are three sheets
FACING_SHARE = 0.25   # with normals: a second sheet not told apart where over this share of its points face our side
AMBIGUOUS_SHARE = 0.3  # a point is ambiguous where this share of its LAYER_K nearest (and itself) are two sheets
                       # not told apart


def facing_ranks(points: np.ndarray, normals: np.ndarray, rows: np.ndarray, nbrs: np.ndarray,
                 sin_cone: float, dist: np.ndarray | None = None) -> np.ndarray:
    """Each candidate's rank (R, m) as a neighbour of its row's point ``rows`` (R,): 0 on its sheet (facing
    the same side, within the cone about the plane normal to their mean normal), 1 facing the same side
    only, 2 else. ``dist``: the candidates' distances (R, m), where known."""
    theirs = normals[nbrs]
    facing = np.einsum("nkd,nd->nk", theirs, normals[rows]) > 0
    if sin_cone >= 1:  # every offset within the cone
        return np.where(facing, 0, 2).astype(np.int8)
    offset = points[nbrs] - points[rows, None]
    length = np.linalg.norm(offset, axis=2) if dist is None else dist
    mean = theirs + normals[rows, None]
    along = np.abs(np.einsum("nkd,nkd->nk", mean, offset)) < sin_cone * np.linalg.norm(mean, axis=2) * length
    return np.where(facing, np.where(along, 0, 1), 2).astype(np.int8)


def facing_neighbors(points: np.ndarray, normals: np.ndarray, k: int, cone_deg: float | None,
                     candidates: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(N, k): each point's k nearest on its own sheet (module docstring) among its ``candidates`` (6k)
    nearest, the rows with fewer filled with the nearest facing its side, then the nearest others; nearest
    first within each rank; and their distances (N, k). ``cone_deg`` None: the nearest facing its side
    (no cone). Most rows are settled by their 2k nearest (k on their sheet among them): the rest only
    look further."""
    from scipy.spatial import cKDTree

    points = np.ascontiguousarray(points, dtype=np.float64)
    normals = np.ascontiguousarray(normals, dtype=np.float64)
    most = min(6 * k if candidates is None else candidates, len(points) - 1)
    k = min(k, most)
    sin_cone = 1.0 if cone_deg is None else float(np.sin(np.radians(cone_deg)))
    tree = cKDTree(points)
    out_nbrs, out_dist = np.empty((len(points), k), dtype=np.int64), np.empty((len(points), k))
    rows = np.arange(len(points))
    for m in sorted({min(2 * k, most), most}):
        dist, nbrs = tree.query(points[rows], m + 1, workers=threads.count())
        dist, nbrs = dist[:, 1:], nbrs[:, 1:].astype(np.int64)
        settled = np.zeros(len(rows), dtype=bool)
        for s in range(0, len(rows), BLOCK):
            block = slice(s, s + BLOCK)
            rank = facing_ranks(points, normals, rows[block], nbrs[block], sin_cone, dist[block])
            order = np.argsort(rank, axis=1, kind="stable")[:, :k]
            out_nbrs[rows[block]] = np.take_along_axis(nbrs[block], order, axis=1)
            out_dist[rows[block]] = np.take_along_axis(dist[block], order, axis=1)
            settled[block] = (rank == 0).sum(axis=1) >= k
        rows = rows[~settled]
        if not len(rows):
            break
    return out_nbrs, out_dist


def two_sheets(points: np.ndarray, k: int = LAYER_K) -> dict:
    """Each point's two-sheet test (module docstring): ``nbrs`` (N, k + 1) the point and its k nearest;
    ``other`` (N, k + 1) those in the other group of offsets than the point's; ``ratio`` (N,) the groups'
    gap over their pooled spread; ``gap`` (N,) and ``rms`` (N,) the gap and the RMS offset from the fitted
    quadric, over the point's spacing (the mean distance of its 6 nearest); ``three`` (N,) the share of the
    offsets' variance between the best three groups, ``gap3`` (N,) the gap between the outer two over the
    spacing. Fewer than k + 1 points: all. A neighbourhood of fewer than 6 points has no two groups of three
    (``ratio`` and ``gap`` 0, no ``other``), of fewer than 9 no three (``three`` and ``gap3`` 0): nothing is
    seen in a cloud that small."""
    from scipy.spatial import cKDTree

    points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    k = max(0, min(k, len(points) - 1))
    if not len(points):
        return {"nbrs": np.zeros((0, 1), dtype=np.int64),
                **{key: np.zeros((0, 1), dtype=bool) if key == "other" else np.zeros(0) for key in _KEYS}}
    dist, nbrs = cKDTree(points).query(points, list(range(1, k + 2)), workers=threads.count())  # (N, k + 1)
    out = {key: [] for key in _KEYS}
    for s in range(0, len(points), BLOCK):
        part = _split(points, nbrs[s:s + BLOCK], dist[s:s + BLOCK])
        for key in out:
            out[key].append(part[key])
    return {"nbrs": nbrs.astype(np.int64), **{key: np.concatenate(v) for key, v in out.items()}}


_KEYS = ("other", "ratio", "gap", "three", "gap3", "rms")


def _split(points: np.ndarray, nbrs: np.ndarray, dist: np.ndarray) -> dict:
    n, m = nbrs.shape
    hood = points[nbrs]
    centered = hood - hood.mean(axis=1, keepdims=True)
    frame = np.linalg.eigh(np.einsum("nki,nkj->nij", centered, centered))[1]  # columns: normal, tangents
    local = np.einsum("nkd,ndj->nkj", hood - points[nbrs[:, :1]], frame)
    radius = np.maximum(dist[:, -1:], 1e-300)
    u, v, z = local[..., 2] / radius, local[..., 1] / radius, local[..., 0]
    a = np.stack([np.ones_like(u), u, v, u * u, u * v, v * v], axis=-1)
    gram = np.einsum("nki,nkj->nij", a, a) + 1e-10 * np.eye(6)
    offset = z - np.einsum("nki,ni->nk", a, np.linalg.solve(gram, np.einsum("nki,nk->ni", a, z)[..., None])[..., 0])
    ordered = np.sort(offset, axis=1)
    c1 = np.concatenate([np.zeros((n, 1)), np.cumsum(ordered, axis=1)], axis=1)
    c2 = np.concatenate([np.zeros((n, 1)), np.cumsum(ordered ** 2, axis=1)], axis=1)

    def group(i, j):  # the sums of the sorted offsets i..j-1 of every row (i, j: vectors of splits)
        count = j - i
        total = c1[:, j] - c1[:, i]
        return total / count, (c2[:, j] - c2[:, i]) - total ** 2 / count

    rows = np.arange(n)
    spacing = np.maximum(dist[:, 1:7].mean(axis=1), 1e-300) if m > 1 else np.ones(n)
    out = {"other": np.zeros((n, m), dtype=bool), "ratio": np.zeros(n), "gap": np.zeros(n), "three": np.zeros(n),
           "gap3": np.zeros(n), "rms": np.sqrt((offset ** 2).mean(axis=1)) / spacing}
    if m >= 6:
        cut = np.arange(3, m - 2)                        # two groups: [0, cut), [cut, m), three or more each
        (lo, lo_ss), (hi, hi_ss) = group(np.zeros_like(cut), cut), group(cut, np.full_like(cut, m))
        within = (lo_ss + hi_ss) / m
        best = ((hi - lo) ** 2 / np.maximum(within, 1e-300)).argmax(axis=1)
        gap = (hi - lo)[rows, best]
        spread = np.sqrt(np.maximum(within[rows, best], 0.0))
        upper = offset > 0.5 * (ordered[rows, cut[best] - 1] + ordered[rows, cut[best]])[:, None]
        out.update(other=upper != upper[:, :1], ratio=gap / np.maximum(spread, 1e-300), gap=gap / spacing)
    if m >= 9:
        a3, b3 = np.meshgrid(np.arange(m + 1), np.arange(m + 1), indexing="ij")  # three: [0, a), [a, b), [b, m)
        ok = (a3 >= 3) & (b3 - a3 >= 3) & (m - b3 >= 3)
        a3, b3 = a3[ok], b3[ok]
        (lo3, ss1), (_, ss2), (hi3, ss3) = group(np.zeros_like(a3), a3), group(a3, b3), group(b3, np.full_like(b3, m))
        best3 = (ss1 + ss2 + ss3).argmin(axis=1)
        total_ss = np.maximum(group(np.zeros(1, dtype=int), np.full(1, m))[1][:, 0], 1e-300)
        out.update(three=1 - (ss1 + ss2 + ss3)[rows, best3] / total_ss, gap3=(hi3 - lo3)[rows, best3] / spacing)
    return out


class Walls(NamedTuple):
    """What :func:`close_walls` sees in a cloud: ``walls`` (N,), the points where two sheets of surface come
    closer than the neighbourhood is wide; ``ambiguous`` (N,), those of them whose sides the normals do not
    tell apart (all of them without normals); ``scatter``, the median RMS offset of a neighbourhood from its
    fitted quadric, in spacings (noise, or a second sheet everywhere)."""
    ambiguous: np.ndarray
    walls: np.ndarray
    scatter: float


def close_walls(points: np.ndarray, normals: np.ndarray | None = None) -> Walls:
    """Which points lie where two sheets of surface come closer than the neighbourhood is wide, and which of
    them cannot be told apart (module docstring): without ``normals`` all of them; with the cloud's own
    oriented normals, those where the normals of the other sheet do not face away. And the cloud's scatter."""
    test = two_sheets(points)
    nbrs, other = test["nbrs"], test["other"]
    seen = (((test["ratio"] > LAYER_RATIO) & (test["gap"] > LAYER_GAP))
            | ((test["three"] > LAYER_THREE) & (test["gap3"] > 2 * LAYER_GAP)))
    walls = seen[nbrs].mean(axis=1) >= AMBIGUOUS_SHARE
    if normals is not None:  # told apart where (nearly) all of the other group face away
        facing = np.einsum("nkd,nd->nk", normals[nbrs], normals) > 0
        seen &= (other & facing).sum(axis=1) > FACING_SHARE * other.sum(axis=1)
    scatter = float(np.median(test["rms"])) if len(points) else 0.0
    return Walls(seen[nbrs].mean(axis=1) >= AMBIGUOUS_SHARE, walls, scatter)
