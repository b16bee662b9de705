r"""Landmark distance fields: farthest-point landmarks on every connected component and their distance
fields by the heat method (Crane, Weischedel, Wardetzky 2013; potpourri3d's solver in its robust mode,
Sharp and Crane 2020), the global structure the landmark-guided GeGnn decodes from.

For landmarks :math:`l_k` on the component of vertices :math:`i, j`, the triangle inequality bounds
their geodesic distance:

.. math::
    \max_k |d(i, l_k) - d(j, l_k)| \;\le\; d(i, j) \;\le\; \min_k \, d(i, l_k) + d(l_k, j).

Landmarks are chosen by geodesic farthest-point sampling, which costs nothing beyond the fields
themselves: each new landmark is the vertex farthest from all fields computed so far (the lowest index
among vertices within TIE of the farthest, so that symmetric meshes, where solver rounding alone tells
equally far vertices apart, give the same landmarks on every solver). Point clouds choose them along
their neighbour graph instead (:func:`graph_farthest_points`, shortest paths), so that all fields are
then solved together, on all threads.

The fields are potpourri3d's robust heat method, computed by :mod:`gegnn.fields.heat` (the same fields to
solver rounding, ~1e-14 relative; on the 19 validation meshes the same landmarks and float32 fields bit
for bit) on parts of at least HEAT_MIN_VERTICES vertices when at least HEAT_MIN_FIELDS fields are
asked for, by potpourri3d's solver elsewhere (there its smaller setup wins). Sampling is sequential
(field k picks landmark k + 1): one heat solve, gradient, divergence and Poisson solve a field. K = 128
on the 5,224-vertex validation dragon, one core of a 2-core EPYC: 0.12 s (setup 0.05 s, a field 0.5
ms), against 0.26 s (2.0 ms a field) with potpourri3d's solver in the same run, the same landmarks and
float32 fields (benchmarks/bench_landmark_fields.py, 2026-11-24). Landmarks along the mesh's edges
instead, with all fields in one call, would take 0.11 s on one core and cover the mesh less evenly
(covering radius 1.12x): meshes keep the sequential choice, which the shipped models were trained and
measured with.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from geodata.geodesic import PATHS_TOLERANCE
from geodata.mesh import Mesh, label_groups, unique_edges, vertex_components

from .. import threads
from .heat import HeatDistance

__all__ = ["LandmarkFields", "landmark_fields", "landmark_solver", "farthest_point_fields",
           "batched_farthest_point_fields", "graph_farthest_points",
           "landmark_columns", "T_COEF", "MODEL_STEP_UP_TO"]

# Landmark fields keep the heat step the models were trained with (t_coef hbar^2) up to here: the model reads
# them as it learned them. On spot / bumpy at 20k-80k vertices the dense-mesh step of gegnn.fields.heat made
# the shipped model worse (0.70/0.67/0.44% -> 0.81/0.81/0.61%); meshes above 40,000 vertices meet the model as
# a 20,000-vertex proxy anyway (gegnn.queries.proxy). Beyond (a proxy turned off), the far field needs the
# dense-mesh step.
MODEL_STEP_UP_TO = 100_000

T_COEF = 0.5
FPS_BATCH = 16  # landmarks chosen a round, their fields in one solve (module docstring: the ablation)
TIE = 1e-9  # farthest-point ties: relative to the largest distance
HEAT_MIN_VERTICES = 500  # below, or for fewer fields, potpourri3d's own solver is faster (its setup is)
HEAT_MIN_FIELDS = 32
SPLIT_PATHS_UP_TO = 256  # pinched vertices a part's fields pass through (_SplitVertexPaths: memory 8 N B each)
SPLIT_CHUNK = 16  # copy fields _SplitVertexPaths solves at once
SPLIT_BLOCK = 8192  # vertices it closes at once (temporaries of P x this floats)


@dataclass
class LandmarkFields:
    """Distance fields of ``K`` landmarks per connected component.

    Attributes:
        distances: float32 (N, K); column k of vertex i is its distance to the k-th landmark *of its own
            component* (never another one's), so every bound above is taken within one component.
        landmarks: int64 (C, K): the landmark vertices of each component; a component with fewer
            than K vertices repeats its landmarks (duplicates change no max or min).
        component: int64 (N,): component label of each vertex.
    """

    distances: np.ndarray
    landmarks: np.ndarray
    component: np.ndarray

    @property
    def k(self) -> int:
        return self.distances.shape[1]


def landmark_fields(vertices, faces, k: int, seed: int = 0, t_coef: float = T_COEF, batch: int | None = None,
                    fields: str = "heat") -> LandmarkFields:
    """K geodesic farthest-point landmarks per component and their distance fields (heat method, or
    virtual source propagation: ``fields="vsp"``).

    Deterministic for a given mesh, ``k`` and ``seed`` (the seed picks each component's first
    landmark). Components of fewer than 3 vertices or without faces (unused vertices) get distance 0
    to themselves. Non-finite solver output (possible on badly broken meshes) is replaced by the
    field's largest finite value, so the result is always finite and non-negative. The same as
    ``landmark_solver(vertices, faces, k, t_coef, batch, fields)(seed)``.

    Args:
        vertices: (N, 3) float.
        faces: (F, 3) int.
        k: landmarks per component (>= 1).
        seed: choice of the first landmark of every component.
        t_coef: heat-method time step (potpourri3d ``t_coef``).
        batch: landmarks chosen a round (:func:`batched_farthest_point_fields`; 1: sequential sampling;
            default FPS_BATCH).
        fields: ``"heat"`` (the shipped models' up to v2), ``"vsp"`` (0.1-0.3% from exact, ~2 ms a field
            at 5k vertices: :mod:`geodata.approximate_geodesic`), ``"exact"`` (the exact solver's, 4-15x a vsp
            field's time: :func:`_exact_field`) or ``"paths"`` (real paths' lengths within 0.05% of exact, 3-5x a
            vsp field's time: :func:`_paths_field`).
    """
    return landmark_solver(vertices, faces, k, t_coef, batch, fields)(seed)


def landmark_solver(vertices, faces, k: int, t_coef: float = T_COEF, batch: int | None = None,
                    fields: str = "heat") -> Callable[[int], LandmarkFields]:
    """``seed -> LandmarkFields``: :func:`landmark_fields` of one mesh for any seed, each component's solver
    set up once (on the first call) and sampled for every seed. ``fields``: ``"heat"`` (the heat method),
    ``"vsp"`` (virtual source propagation, :func:`_vsp_field`), ``"exact"`` (:func:`_exact_field`) or ``"paths"``
    (:func:`_paths_field`)."""
    if fields not in FIELD_SOLVERS:
        raise ValueError(f"fields must be one of {', '.join(FIELD_SOLVERS)}, got {fields!r}")
    if k < 1:
        raise ValueError(f"k must be >= 1, got {k}")
    mesh = Mesh(vertices, faces)
    labels = vertex_components(mesh).astype(np.int64)
    n_comp = int(labels.max()) + 1 if len(labels) else 0
    # Vertices and faces grouped by component once (stable: each group keeps the mesh's order), so a
    # mesh of many parts costs O(N + F), not O((N + F) x parts).
    vertex_groups = label_groups(labels, n_comp)
    face_groups = label_groups(labels[mesh.faces[:, 0]], n_comp)
    local = np.empty(mesh.n_vertices, dtype=np.int64)  # index within the vertex's own component
    parts = []
    for c in range(n_comp):
        idx = vertex_groups[c]
        local[idx] = np.arange(len(idx))
        parts.append((idx, local[mesh.faces[face_groups[c]]]))
    solvers = {}

    def draw(seed: int = 0) -> LandmarkFields:
        out = np.zeros((mesh.n_vertices, k), dtype=np.float32)
        landmarks = np.zeros((n_comp, k), dtype=np.int64)
        for c, (idx, sub_faces) in enumerate(parts):
            rng = np.random.default_rng([seed, c])
            if len(idx) < 3 or not len(sub_faces):
                landmarks[c] = idx[0]
                continue
            n_fields = min(k, len(idx))
            if c not in solvers:
                solvers[c] = FIELD_SOLVERS[fields](mesh.vertices[idx], sub_faces, t_coef, n_fields)
            chosen, sampled = batched_farthest_point_fields(solvers[c], mesh.vertices[idx], n_fields,
                                                            int(rng.integers(len(idx))), batch or FPS_BATCH)
            cols = np.arange(k) % len(chosen)  # fewer vertices than K: repeat
            out[idx] = sampled[:, cols]
            landmarks[c] = idx[np.asarray(chosen)[cols]]
        return LandmarkFields(out, landmarks, labels)
    return draw


def _vsp_field(vertices, faces, t_coef: float, fields: int):
    """``fields(sources) -> (N, len(sources))`` by virtual source propagation
    (:class:`geodata.approximate_geodesic.ApproximateGeodesicSolver`, 0.1-0.3% from exact), the sources on
    torch's threads (the embedding's network, beside them, on one fewer: :mod:`gegnn.threads`). A part it
    refuses (an edge of three or more faces, a pinched vertex: a proxy's decimation of a 1M-vertex mesh can
    make a few) is solved on its
    :func:`geodata.approximate_geodesic.manifold_copy`, each vertex at the least of its copies' distances
    and paths through a split vertex taken from fan to fan (:class:`_SplitVertexPaths`), with a warning
    naming the defects; the heat method's fields only where even that copy is refused."""
    import warnings

    from geodata.approximate_geodesic import ApproximateGeodesicSolver, manifold_copy

    try:
        solver = ApproximateGeodesicSolver(vertices, faces)
        return lambda sources: solver.distances(np.asarray(sources, dtype=np.int64), threads=threads.count()).T
    except ValueError as exc:
        reason = str(exc)
    v, f, origin, set_aside = manifold_copy(vertices, faces)
    try:
        solver = ApproximateGeodesicSolver(v, f)
    except ValueError as exc:
        warnings.warn(f"landmark fields by the heat method on a part of {len(vertices)} vertices: {reason}; "
                      f"its manifold copy: {exc}", stacklevel=2)
        return _heat_field(vertices, faces, t_coef, fields)
    n = len(vertices)
    warnings.warn(f"landmark fields on a part of {n} vertices: {reason}: solved on a copy with {set_aside} "
                  f"face(s) set aside and {len(v) - n} vertex copies", stacklevel=2)

    through = _SplitVertexPaths(solver, origin, n)

    def solve(sources):
        field = through.closed(through.fold(solver.distances(np.asarray(sources, dtype=np.int64),
                                                             threads=threads.count())))
        return _along_edges(field, vertices, unique_edges(faces))
    return solve


class _SplitVertexPaths:
    r"""Paths through the split vertices of a :func:`geodata.approximate_geodesic.manifold_copy`, which the
    copy itself cuts: each fan of a pinched vertex :math:`p` is reached only through its own copy. With
    :math:`D(p, x)` the least copy field of :math:`p`'s copies at :math:`x` (each copy a source), closed over
    the split vertices (Floyd-Warshall on their :math:`P \times P` block), a field :math:`d_s` becomes

    .. math:: d_s(x) \leftarrow \min\big(d_s(x),\ \min_p\, d_s(p) + D(p, x)\big),

    which takes every path that passes split vertices, in any order, and makes a source at a split vertex the
    source on every fan. Costs one field a copy, once a part (a proxy's decimation makes a few), and
    :math:`P` minima a field. Memory: :math:`P N` floats (8 N bytes a split vertex, ``SPLIT_PATHS_UP_TO`` at
    most: 2 GiB at 1M vertices), and while they are made, ``SPLIT_CHUNK`` copy fields at a time (twice: the
    solver's and their fold, 16 B N' each) and :math:`P` x ``SPLIT_BLOCK`` floats of the closure."""

    def __init__(self, solver, origin: np.ndarray, n: int):
        self.origin, self.n = origin, n
        split = np.unique(origin[n:])  # input vertices with two or more fans
        if len(split) > SPLIT_PATHS_UP_TO:
            import warnings
            warnings.warn(f"paths through {len(split)} pinched vertices: taken through the first "
                          f"{SPLIT_PATHS_UP_TO} only, the others' fans reached around them or along edges",
                          stacklevel=3)
            split = split[:SPLIT_PATHS_UP_TO]
        self.split = split
        through = np.full((len(split), n), np.inf)
        copies = np.concatenate([split, n + np.flatnonzero(np.isin(origin[n:], split))])
        for s in range(0, len(copies), SPLIT_CHUNK):
            chunk = copies[s:s + SPLIT_CHUNK]
            d = self.fold(solver.distances(chunk, threads=threads.count()))  # (n, chunk)
            np.minimum.at(through, np.searchsorted(split, origin[chunk]), d.T)
        hops = through[:, split]  # (P, P): split vertex to split vertex, one fan crossing
        for k in range(len(split)):
            hops = np.minimum(hops, hops[:, k, None] + hops[None, k, :])
        for s in range(0, n, SPLIT_BLOCK):  # closed in place, a block of vertices at a time: a row already
            block = through[:, s:s + SPLIT_BLOCK]  # closed through some q is no shorter than its closure (hops
            for q in range(len(split)):            # are closed), so the result is that of the unclosed rows
                np.minimum(block, hops[:, q, None] + block[q], out=block)
        self.through = through

    def fold(self, d: np.ndarray) -> np.ndarray:
        """Copy fields (S, N') -> (N, S), each input vertex at the least of its copies' values."""
        out = d.T[:self.n].copy()
        np.minimum.at(out, self.origin[self.n:], d.T[self.n:])
        return out

    def closed(self, field: np.ndarray) -> np.ndarray:
        """``field`` (N, S) with the paths through split vertices taken (the class docstring)."""
        for p, row in zip(self.split, self.through):
            field = np.minimum(field, field[p][None, :] + row[:, None])
        return field


def _along_edges(fields: np.ndarray, vertices: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """``fields`` (N, S) where its solver left a vertex unreached (``inf``: cut off by a manifold copy's
    set-aside faces or split vertices, or a cloud's local triangles; a connected part's vertices are all
    reachable along its ``edges`` (E, 2)) given the shortest continuation along the edges from the reached
    ones (Bellman-Ford on the edges that touch them, until nothing changes: a few rounds, as such islands
    are small); reached values stay. Left at the largest finite value instead, such vertices would be the
    next landmarks of farthest-point sampling."""
    todo = ~np.isfinite(fields)
    rows = todo.any(axis=1)
    if not rows.any():
        return fields
    a, b = edges[rows[edges].any(axis=1)].T
    w = np.linalg.norm(vertices[a] - vertices[b], axis=1)[:, None]
    for _ in range(len(fields)):
        step = fields.copy()
        np.minimum.at(step, a, fields[b] + w)
        np.minimum.at(step, b, fields[a] + w)
        step = np.where(todo, step, fields)
        if np.array_equal(step, fields):
            break
        fields = step
    return fields


def _exact_field(vertices, faces, t_coef: float, fields: int, tolerance: float = 0.0):
    """``fields(sources) -> (N, len(sources))``: exact polyhedral geodesics, geodata's window-propagation solver
    (``vtp``), every value a shortest path's length; 4-15x a vsp field's time (docs/benchmarks.md), the sources
    on torch's threads (:mod:`gegnn.threads`), each with its own wavefront. ``tolerance`` > 0: windows pruned
    within that relative factor of a real path (:func:`_paths_field`). A part it is not made for (an edge of
    three or more faces, a pinched vertex) or too large for the memory available gets the vsp fields of
    :func:`_vsp_field` instead, with a warning saying why."""
    import warnings

    from geodata._exact_geodesic import Surface
    from geodata.exact_memory import require_memory
    from geodata.mesh import MeshError, has_pinched_vertices

    from .exact import require_edge_manifold

    team = threads.count()
    try:
        require_edge_manifold(Mesh(vertices, faces))
        if has_pinched_vertices(faces, len(vertices)):
            raise MeshError("exact", "pinched vertices (two or more fans)")
        team = require_memory(len(vertices), team)
    except MeshError as exc:
        warnings.warn(f"{'paths' if tolerance else 'exact'} landmark fields on a part of {len(vertices)} vertices: "
                      f"{exc.reason}: virtual-source fields instead", stacklevel=3)
        return _vsp_field(vertices, faces, t_coef, fields)
    surface = Surface(np.ascontiguousarray(vertices, dtype=np.float64), np.ascontiguousarray(faces, dtype=np.int32))
    return lambda sources: surface.distances(np.asarray(sources, dtype=np.int64), tolerance, team).T


def _paths_field(vertices, faces, t_coef: float, fields: int):
    """``fields(sources) -> (N, len(sources))``: :func:`_exact_field` with its windows pruned within
    PATHS_TOLERANCE of a real path: every value still a real path's length (never below exact), 0.005-0.05% above
    exact on the zoo at 0.22-0.86x the exact solver's time; the shipped default reads them as well as exact
    fields (docs/queries.md). Looser tolerances cost the model more than they save: the error grows with the
    relays along a path, and at 1e-3 the model on a thin coil was at 0.28% (0.14% with exact fields or at 3e-4),
    at 3e-3 on a bent tube at 1.2% (0.10%)."""
    return _exact_field(vertices, faces, t_coef, fields, PATHS_TOLERANCE)


def _heat_field(vertices, faces, t_coef: float, fields: int):
    """``fields(sources) -> (N, len(sources))``: potpourri3d's robust heat method, by :class:`gegnn.fields.heat.HeatDistance`
    where that pays (see the module), by potpourri3d itself elsewhere and on meshes that HeatDistance does
    not cover (:func:`gegnn.fields.heat.cover_problem`). Beyond MODEL_STEP_UP_TO vertices always HeatDistance,
    whose time step then grows with the resolution (:func:`gegnn.fields.heat.time_step`); up to there the
    step the shipped models were trained with."""
    if len(vertices) > MODEL_STEP_UP_TO or (len(vertices) >= HEAT_MIN_VERTICES and fields >= HEAT_MIN_FIELDS):
        try:
            return HeatDistance(vertices, faces, t_coef, same_up_to=MODEL_STEP_UP_TO).distances
        except ValueError:
            pass
    import potpourri3d as pp3d

    solver = pp3d.MeshHeatMethodDistanceSolver(vertices, faces, t_coef=t_coef, use_robust=True)
    return lambda sources: np.stack([solver.compute_distance(int(s)) for s in sources], axis=1)


def farthest_point_fields(field, n: int, k: int, first: int) -> tuple[list[int], np.ndarray]:
    """Sequential geodesic farthest-point sampling: ``field(source) -> (n,)``; each next landmark the vertex
    farthest from all fields so far. Returns the landmarks and their fields, float32 (n, k). The same as
    :func:`batched_farthest_point_fields` with batches of 1."""
    return batched_farthest_point_fields(lambda sources: np.stack([field(s) for s in sources], axis=1),
                                         np.zeros((n, 3)), k, first, 1)


def batched_farthest_point_fields(fields, positions: np.ndarray, k: int, first: int, batch: int = FPS_BATCH
                                  ) -> tuple[list[int], np.ndarray]:
    """Geodesic farthest-point sampling in rounds of ``batch`` landmarks, one multi-source solve a round
    (``fields(sources) -> (n, len(sources))``): a round's first landmark is the vertex farthest from every
    field so far, each next one the farthest once the straight-line distance (``positions`` (n, 3)) to the
    round's earlier picks also counts, a stand-in for their fields that never exceeds them. With batches
    of 1, sequential sampling. Returns the landmarks and their fields, float32 (n, k)."""
    from .._farthest_points import round_picks

    n = len(positions)
    positions = np.ascontiguousarray(positions, dtype=np.float64)
    out = np.empty((k, n), dtype=np.float32)  # a row a field: contiguous writes
    nearest = np.full(n, np.inf)
    chosen, picks = [], [first]
    while True:
        block = np.asarray(fields(picks), dtype=np.float64)
        if not np.isfinite(block.sum()):  # one pass when all is finite (nearly always)
            block = np.stack([_finite(column) for column in block.T], axis=1)
        block = np.maximum(block, 0.0)
        out[len(chosen):len(chosen) + len(picks)] = block.T
        np.minimum(nearest, block.min(axis=1), out=nearest)
        # Never pick a landmark twice, even if the solver is off near it (the earlier ones stay at -1:
        # fields are >= 0); a landmark's own distance is 0.
        nearest[picks] = -1.0
        out[np.arange(len(chosen), len(chosen) + len(picks)), picks] = 0.0
        chosen += picks
        if len(chosen) == k:
            return chosen, out.T
        picks = round_picks(nearest, positions, min(batch, k - len(chosen)), TIE).tolist()


def graph_farthest_points(points: np.ndarray, edges: np.ndarray, k: int, first: int) -> np.ndarray:
    """K farthest-point landmarks (int64 (K,), ``first`` first) by shortest paths along the graph of
    ``edges`` (E, 2) between the points (N, 3), each as long as its segment: each next landmark the point
    farthest from all before it (ties as in :func:`farthest_point_fields`; src/farthest_points.cpp).
    Unlike :func:`farthest_point_fields` it needs no field to choose the next, so all K fields can then be
    computed together (:meth:`gegnn.fields.heat.HeatSolver.distances`)."""
    from .._farthest_points import farthest_points

    return farthest_points(np.ascontiguousarray(points, dtype=np.float64),
                           np.ascontiguousarray(edges, dtype=np.int64).reshape(-1, 2), k, first, TIE)


def landmark_columns(distances: np.ndarray, chosen: np.ndarray) -> np.ndarray:
    """float32 (N, K) landmark fields from a solver's distances (N, K) of the landmarks ``chosen``: each
    column's non-finite values replaced by its largest finite one, negatives by 0, the landmark's own 0."""
    out = np.asarray(distances, dtype=np.float64)
    if not np.isfinite(out.sum()):
        out = np.stack([_finite(column) for column in out.T], axis=1)
    out = np.maximum(out, 0.0).astype(np.float32)
    out[np.asarray(chosen), np.arange(len(chosen))] = 0.0
    return out


def _farthest(nearest: np.ndarray) -> int:
    """The lowest-index vertex within TIE of the largest value: on a symmetric mesh, vertices equally
    far in exact arithmetic differ by solver rounding (~1e-14 relative), which would otherwise pick
    among them differently on every solver and platform."""
    top = nearest.max()
    return int(np.argmax(nearest >= top - TIE * abs(top)))


def _finite(field: np.ndarray) -> np.ndarray:
    field = np.asarray(field, dtype=np.float64)
    if not np.isfinite(field.sum()):  # one pass when all is finite (nearly always)
        ok = np.isfinite(field)
        field = np.where(ok, field, field[ok].max() if ok.any() else 0.0)
    return np.maximum(field, 0.0)


FIELD_SOLVERS = {"heat": _heat_field, "vsp": _vsp_field, "exact": _exact_field,  # landmark_solver's ``fields``
                 "paths": _paths_field}
