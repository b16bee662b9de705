"""Surfaces whose two sides lie a chosen distance apart, sampled at a chosen spacing: the close-walls
benchmark's shapes (benchmarks/bench_close_walls.py) and the tests' thin slab.

Every shape is a mesh whose vertices are the cloud: vertices ``spacing`` apart along each side (rings or
rows of points that step, and points on them, every ``spacing``, each point then moved along the surface
by up to a quarter step at random, so that the two sides' points do not face each other in a pattern),
the two sides ``thickness`` apart and joined by a half-round rim of that diameter. A rim shorter than two
spacings gets one ring or row of points round its middle all the same (a scan of it samples it by area:
a rim of 0.5 spacings' thickness, 0.8 spacings round, has about 0.8 of a ring's points).

- ``slab``: a disc of radius 1 with a thickness, a closed surface of revolution (the way from the
  centre of one face to the other's is round the rim, 2 + pi t / 2, the way through the wall t);
- ``bowl``: a hemispherical shell of outer radius 1, open at the top with a rounded lip (a cup's or a
  mask's wall; closed, of revolution);
- ``fold``: a 2 x 1 sheet folded in two about a line (a hairpin), sides ``thickness`` apart; open (its
  boundary is the sheet's edge);
- ``zfold``: the same sheet folded twice (three layers, a Z).

``wall_mesh(name, thickness, spacing, seed)`` returns float64 vertices (N, 3), int64 faces (M, 3)
oriented outwards (the closed shapes) and the exact unit normals of the surface at the vertices (N, 3),
on the side the faces face.
"""
from __future__ import annotations

import numpy as np

__all__ = ["WALLS", "wall_mesh", "slab_profile", "bowl_profile", "fold_profile"]

JITTER = 0.25  # of a spacing: how far a point moves along the surface from its ring or row


def _arc(center, radius, start, stop, n=64) -> np.ndarray:
    t = np.linspace(start, stop, n)
    return np.stack([center[0] + radius * np.cos(t), center[1] + radius * np.sin(t)], axis=1)


def slab_profile(thickness: float) -> list[np.ndarray]:
    """The slab's profile (r, z) in pieces: the top face from its centre out to the rim, the rim, the
    bottom face back to the axis."""
    h = thickness / 2
    return [np.array([[0.0, h], [1.0, h]]), _arc((1.0, 0.0), h, np.pi / 2, -np.pi / 2),
            np.array([[1.0, -h], [0.0, -h]])]


def bowl_profile(thickness: float, opening_deg: float = 90.0) -> list[np.ndarray]:
    """The bowl's profile (r, z) in pieces: up the outside from the bottom to the lip at ``opening_deg`` from
    the bottom, round the lip, and down the inside."""
    a = np.radians(opening_deg)
    phi = np.linspace(0.0, a, 256)
    outer = np.stack([np.sin(phi), -np.cos(phi)], axis=1)
    mid = (1 - thickness / 2) * np.array([np.sin(a), -np.cos(a)])
    return [outer, _arc(mid, thickness / 2, a - np.pi / 2, a + np.pi / 2), (1 - thickness) * outer[::-1]]


def fold_profile(thickness: float, layers: int = 2, length: float = 1.0) -> list[np.ndarray]:
    """The folded sheet's profile (x, z) in pieces: ``layers`` straight runs of ``length``, ``thickness``
    apart, each joined to the next by a half round."""
    out = []
    for k in range(layers):
        z = -k * thickness
        run = np.array([[0.0, z], [length, z]])
        out.append(run if k % 2 == 0 else run[::-1])
        if k < layers - 1:
            right = k % 2 == 0
            c = (length if right else 0.0, z - thickness / 2)
            out.append(_arc(c, thickness / 2, np.pi / 2, -np.pi / 2 if right else 3 * np.pi / 2))
    return out


def _stations(pieces: list[np.ndarray], spacing: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The profile joined (P, 2), the arc lengths of its rows or rings (every ``spacing`` along each piece,
    at least one inside each: a round thinner than the spacing still carries points) and the step about
    each."""
    lengths = [np.linalg.norm(np.diff(p, axis=0), axis=1).sum() for p in pieces]
    stations, start = [0.0], 0.0
    for length in lengths:
        n = max(2, int(round(length / spacing)))
        stations.extend(start + length * np.arange(1, n + 1) / n)
        start += length
    s = np.asarray(stations)
    gaps = np.diff(s)
    step = np.minimum(np.r_[gaps[0], gaps], np.r_[gaps, gaps[-1]])
    return np.concatenate([pieces[0]] + [p[1:] for p in pieces[1:]]), s, step


def _along(profile: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Points (len(s), 2) of the polyline at arc lengths s, and its unit tangents there."""
    seg = np.diff(profile, axis=0)
    length = np.linalg.norm(seg, axis=1)
    cum = np.concatenate([[0.0], np.cumsum(length)])
    k = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(seg) - 1)
    t = ((s - cum[k]) / length[k])[:, None]
    return profile[k] + t * seg[k], seg[k] / length[k, None]


def _strip(a: np.ndarray, ta: np.ndarray, b: np.ndarray, tb: np.ndarray, period: float | None) -> list:
    """Triangles between two rows of vertex ids ``a`` and ``b`` at sorted positions ``ta``, ``tb`` along
    them (angles with ``period`` 2 pi, closed rows; or plain coordinates), each step taking the row whose
    next point comes first, oriented as (a_i, a_i+1, b_j) and (a_i, b_j+1, b_j)."""
    if period is not None:
        a, b = np.r_[a, a[0]], np.r_[b, b[0]]
        ta, tb = np.r_[ta, ta[0] + period], np.r_[tb, tb[0] + period]
    out, i, j = [], 0, 0
    if len(a) == 2 and period is not None:      # a pole (one vertex): a fan
        return [(a[0], b[k + 1], b[k]) for k in range(len(b) - 1)]
    if len(b) == 2 and period is not None:
        return [(a[k], a[k + 1], b[0]) for k in range(len(a) - 1)]
    while i < len(a) - 1 or j < len(b) - 1:
        if j == len(b) - 1 or (i < len(a) - 1 and ta[i + 1] < tb[j + 1]):
            out.append((a[i], a[i + 1], b[j]))
            i += 1
        else:
            out.append((a[i], b[j + 1], b[j]))
            j += 1
    return out


def _revolve(pieces: list[np.ndarray], spacing: float, rng: np.random.Generator):
    """A closed surface of revolution about z of a profile (r, z) from the axis to the axis."""
    profile, stations, step = _stations(pieces, spacing)
    n = len(stations) - 1
    ids, angles, parts, count = [], [], [], 0
    for k, s0 in enumerate(stations):
        pole = k in (0, n)
        r = _along(profile, np.array([s0]))[0][0, 0]
        m = 1 if pole else max(3, int(round(2 * np.pi * r / spacing)))
        theta = np.sort((np.arange(m) + rng.random()) * 2 * np.pi / m
                        + (0 if pole else rng.uniform(-JITTER, JITTER, m) * 2 * np.pi / m))
        s = np.full(m, s0) if pole else s0 + rng.uniform(-JITTER, JITTER, m) * step[k]
        (rz, tangent) = _along(profile, s)
        if pole:
            rz[:, 0] = 0.0
        # the normal of the surface: the profile's tangent (dr, dz) turned to (dz, -dr), revolved
        nr, nz = tangent[:, 1], -tangent[:, 0]
        if pole:
            nr, nz = np.zeros(1), np.sign(nz)
        c, sn = np.cos(theta), np.sin(theta)
        parts.append((np.stack([rz[:, 0] * c, rz[:, 0] * sn, rz[:, 1]], 1), np.stack([nr * c, nr * sn, nz], 1)))
        ids.append(np.arange(count, count + m))
        angles.append(theta)
        count += m
    faces = [f for k in range(n) for f in _strip(ids[k], angles[k], ids[k + 1], angles[k + 1], 2 * np.pi)]
    return np.concatenate([p for p, _ in parts]), np.asarray(faces, dtype=np.int64), \
        np.concatenate([q for _, q in parts])


def _extrude(pieces: list[np.ndarray], width: float, spacing: float, rng: np.random.Generator):
    """An open sheet: a profile (x, z) swept along y over ``width``."""
    profile, stations, step = _stations(pieces, spacing)
    n = len(stations) - 1
    m = max(2, int(round(width / spacing)) + 1)
    rows, ids, ys, count = [], [], [], 0
    for k, s0 in enumerate(stations):
        edge = k in (0, n)
        y = np.sort(np.clip((np.arange(m) + (0.5 if k % 2 else 0.0)
                             + rng.uniform(-JITTER, JITTER, m)) * width / (m - 1 + 0.5), 0, width))
        s = np.full(m, s0) if edge else s0 + rng.uniform(-JITTER, JITTER, m) * step[k]
        xz, tangent = _along(profile, s)
        normal = np.stack([tangent[:, 1], np.zeros(m), -tangent[:, 0]], 1)
        rows.append((np.stack([xz[:, 0], y, xz[:, 1]], 1), normal))
        ids.append(np.arange(count, count + m))
        ys.append(y)
        count += m
    faces = [f for k in range(n) for f in _strip(ids[k], ys[k], ids[k + 1], ys[k + 1], None)]
    return np.concatenate([p for p, _ in rows]), np.asarray(faces, dtype=np.int64), \
        np.concatenate([q for _, q in rows])


def _oriented(v, f, normals, closed: bool):
    """A closed shape's faces turned outwards (positive volume), an open one's to the normals' side; the
    normals (all on one side: each the profile's tangent turned the same way) to the faces' side."""
    fn = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    agree = np.einsum("ij,ij->i", fn, normals[f].sum(axis=1)) > 0
    if closed and np.einsum("ij,ij->", v[f[:, 0]], fn) < 0:
        f, agree = f[:, [0, 2, 1]], ~agree
    if agree.sum() < len(f) / 2:
        if closed:
            normals = -normals
        else:
            f = f[:, [0, 2, 1]]
    return v, f, normals


WALLS = {
    "slab": lambda t, h, rng: _revolve(slab_profile(t), h, rng),
    "bowl": lambda t, h, rng: _revolve(bowl_profile(t), h, rng),
    "fold": lambda t, h, rng: _extrude(fold_profile(t, 2, 2.0), 1.0, h, rng),
    "zfold": lambda t, h, rng: _extrude(fold_profile(t, 3, 2.0), 1.0, h, rng),
}


def wall_mesh(name: str, thickness: float, spacing: float, seed: int = 0):
    """The shape ``name`` of :data:`WALLS` with its sides ``thickness`` apart, vertices ``spacing`` apart:
    vertices, faces and the surface's unit normals at the vertices (module docstring)."""
    if name not in WALLS:
        raise ValueError(f"unknown shape {name!r}: one of {', '.join(WALLS)}")
    v, f, normals = WALLS[name](thickness, spacing, np.random.default_rng(seed))
    return _oriented(v, f, normals, closed=name in ("slab", "bowl"))
