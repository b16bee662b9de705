"""A large mesh embedded through a proxy: the same surface with fewer vertices (edge collapse and remesh), embedded
once; every vertex of the large mesh then gets the code of its closest point on the proxy of its own connected
part (a blend of the proxy's vertex codes, :meth:`gegnn.queries.embedding.Embedding.at_points`). Each part is
decimated on its own, and the proxy never has more vertices than asked, however many parts the mesh has
(:func:`part_budget`): each part gets a floor, ``PART_VERTICES`` or all its own up to twice that, and the rest
of the budget is shared by area. A screw, an eye or a bolt beside a large body keeps its own distances
(decimated with the body, a 642-vertex sphere of radius 0.02 beside a unit sphere kept 4 proxy vertices and its
antipodes came out 0 apart). Where the floors would take more than ``FLOORS`` of the budget (a few dozen
parts), they are lowered alike for every part, with a warning: 300 parts of 642 vertices get 66 each at
20,000, and their distances ~4% (MRE) where the mesh itself gives 0.2%; a mesh of more parts than
``PART_FEWEST`` vertices each can hold is refused. The network and the landmark fields run at the resolution
the model was trained at, whatever the user's resolution; what scales with the user's mesh is the decimation
and one closest-point query per vertex (libigl's AABB tree), both near-linear.
A large point cloud likewise: a random subset embedded, every point blended from its 3 nearest subset points.
"""
from __future__ import annotations

import warnings

import numpy as np

from typing import NamedTuple

from geodata.mesh import Mesh, face_areas, label_groups, vertex_components

__all__ = ["PROXY_ABOVE", "PROXY_VERTICES", "PART_VERTICES", "PART_FEWEST", "Proxy", "proxy_size", "part_budget",
           "proxy_of", "decimate", "triangle_quality", "cloud_subset", "cloud_weights"]

PROXY_ABOVE = 40_000  # meshes with more vertices are embedded through a proxy (docs/benchmarks.md)
PROXY_VERTICES = 20_000  # the proxy's vertex count
COARSE = 3  # the edge collapse stops at COARSE x the proxy's vertices, the remesh does the rest
PART_VERTICES = 500  # a connected part's floor of proxy vertices (a part of at most twice this is kept whole)
FLOORS = 0.75  # the floors take at most this share of the proxy's vertices (the area's 5,000 of 20,000 at least)
PART_FEWEST = 4  # the floors lowered for many parts stop here (a tetrahedron): below, the mesh is refused
REMESH_FEWEST = 100  # a part decimated to fewer vertices is edge-collapsed only (the remesh is erratic there)
SLIVERS = 0.05  # a mesh with more faces of quality < 0.1 than this is collapsed by pymeshlab (see decimate)
CREASED = 1.01  # a fast collapse that adds more area than this factor creased the surface (see decimate)
UNLATTICE = 0.01  # fast-simplification's input moved in its tangent planes by up to this share of the shortest edge


def proxy_size(n_vertices: int, proxy) -> int | None:
    """The proxy's vertex count for a mesh of ``n_vertices`` (None: embed the mesh itself). ``proxy``:
    ``"auto"`` (PROXY_VERTICES above PROXY_ABOVE vertices), a vertex count (used when the mesh is larger), or
    None / 0 (never)."""
    if proxy == "auto":
        return PROXY_VERTICES if n_vertices > PROXY_ABOVE else None
    if not proxy:
        return None
    if not isinstance(proxy, (int, np.integer)) or isinstance(proxy, bool) or proxy < 100:
        raise ValueError(f"proxy must be 'auto', None or a vertex count >= 100, got {proxy!r}")
    return int(proxy) if n_vertices > proxy else None


class Proxy(NamedTuple):
    """A mesh's proxy and where each of the mesh's vertices lies on it: on a face of the proxy of its own
    connected part (``face`` (N,) int64, ``bary`` (N, 3) barycentric coordinates)."""
    mesh: Mesh
    face: np.ndarray
    bary: np.ndarray


def part_budget(size: np.ndarray, area: np.ndarray, target_vertices: int) -> np.ndarray:
    r"""Each connected part's proxy vertices (int64) from its vertex count ``size`` and its ``area``: at most
    its own vertices, and :math:`T` = ``target_vertices`` in all, never more. A part's floor is all its
    vertices up to :math:`2P` (``PART_VERTICES``), :math:`P` above; where the floors sum to more than
    ``FLOORS`` :math:`T`, each is cut to a common level :math:`m`, the largest with the floors summing to at
    most ``FLOORS`` :math:`T` but at least ``PART_FEWEST`` (the smallest parts keep all their own few vertices;
    a warning says how many parts get less than their floor). Then part :math:`c` gets
    :math:`\min(n_c, \max(\mathrm{floor}_c, \lfloor\lambda A_c\rfloor))`, :math:`\lambda` the largest with
    the sum at most :math:`T` (about :math:`T / \sum A` for a part much larger than the others). A mesh whose
    parts cannot have ``PART_FEWEST`` vertices each (their own, if fewer) within :math:`T` is refused
    (ValueError)."""
    size, area = np.asarray(size, dtype=np.int64), np.asarray(area, dtype=np.float64)
    target = int(target_vertices)
    if size.sum() <= target:
        return size.copy()
    fewest = np.minimum(size, PART_FEWEST).sum()
    if fewest > target:
        larger = f", a proxy of at least {fewest:,} vertices (proxy=N)," if fewest < size.sum() else ""
        raise ValueError(f"a mesh of {len(size):,} connected parts does not fit a proxy of {target:,} vertices "
                         f"({PART_FEWEST} vertices a part, or its own if fewer, take {fewest:,}): embed the mesh "
                         f"itself (proxy=None){larger} or join its parts (merge coincident vertices, or prepare it)")
    floor = full = np.where(size <= 2 * PART_VERTICES, size, PART_VERTICES)
    if floor.sum() > FLOORS * target:  # the largest common level that fits, by bisection over the level
        lo, hi = 0, int(floor.max())
        while lo < hi:
            mid = (lo + hi + 1) // 2
            lo, hi = (mid, hi) if np.minimum(floor, mid).sum() <= FLOORS * target else (lo, mid - 1)
        floor = np.minimum(floor, max(lo, PART_FEWEST))

    def budget(scale: float) -> np.ndarray:  # clipped before the cast: a part of ~0 area makes scales huge
        return np.minimum(size, np.maximum(floor, np.floor(np.minimum(scale * area, size)).astype(np.int64)))

    grows = (area > 0) & (floor < size)  # the parts whose budget grows with the scale, until it is their size
    out = floor
    if grows.any():  # the largest scale whose budgets fit (their sum grows with the scale), by bisection of its
        # logarithm: the scales span from where no part gets more than its floor to where all have their size,
        # which a part of ~1e-18 area puts 1e18 times higher
        lo, hi = 1.0 / float(area[grows].sum()), float((size[grows] / area[grows]).max())
        for _ in range(200):
            mid = float(np.sqrt(lo * hi))
            lo, hi = (mid, hi) if budget(mid).sum() <= target else (lo, mid)
        out = budget(lo)
    cut = out < full
    if cut.any():
        enough = int(np.ceil(full.sum() / FLOORS))
        instead = (f"a proxy of {enough:,} vertices (proxy=N) or the mesh itself (proxy=None)"
                   if enough < size.sum() else "the mesh itself (proxy=None)")
        warnings.warn(f"{len(size):,} connected parts in a proxy of {target:,} vertices: {int(cut.sum()):,} of them "
                      f"get as few as {int(out[cut].min())} proxy vertices, not the {PART_VERTICES} (or all their "
                      f"own, up to {2 * PART_VERTICES}) a part gets when the budget allows, and their distances are "
                      f"coarser; {instead} keeps them", stacklevel=3)
    return out


def proxy_of(vertices: np.ndarray, faces: np.ndarray, target_vertices: int) -> Proxy:
    r"""The proxy of a mesh with at most ``target_vertices`` vertices, part by part: connected part :math:`c`
    is decimated (:func:`decimate`) to its budget :math:`t_c` (:func:`part_budget`, from its vertex count and
    area), or kept as it is when it has no more than that. A vertex is placed on its own part's proxy (the
    closest point there, libigl's AABB tree), a vertex of a part kept whole at itself; a vertex on no face, on
    the closest point of the whole proxy (a part without faces takes no proxy vertices)."""
    from geodata.surface_points import locate_points

    v, f = np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64)
    labels = vertex_components(Mesh(v, f))
    n_parts = int(labels.max()) + 1
    face_part = labels[f[:, 0]]
    area = np.bincount(face_part, face_areas(v, f), minlength=n_parts)
    size = np.bincount(labels, minlength=n_parts) * (np.bincount(face_part, minlength=n_parts) > 0)  # on faces
    goal = part_budget(size, area, target_vertices)
    whole = (size <= goal) & (size > 0)
    face, bary = np.full(len(v), -1, dtype=np.int64), np.zeros((len(v), 3))
    local = np.empty(len(v), dtype=np.int64)  # a vertex's index in its piece (each vertex in one piece at most)
    pieces, offset = [], [0, 0]  # the proxy's pieces; the vertices and faces before the next one

    def add(piece: Mesh) -> int:
        """Append a piece; the index of its first face in the proxy."""
        first = offset[1]
        pieces.append(Mesh(piece.vertices, piece.faces + offset[0]))
        offset[0], offset[1] = offset[0] + piece.n_vertices, offset[1] + piece.n_faces
        return first

    kept = np.flatnonzero(whole[face_part])
    if len(kept):  # the parts kept whole, in one piece: each vertex at a corner of one of its faces
        idx = np.flatnonzero(whole[labels])
        local[idx] = np.arange(len(idx))
        first = add(Mesh(v[idx], local[f[kept]]))
        for k in range(3):
            face[f[kept, k]] = first + np.arange(len(kept))
            bary[f[kept, k]] = np.eye(3)[k]
    vertex_groups, face_groups = label_groups(labels, n_parts), label_groups(face_part, n_parts)
    for c in np.flatnonzero(~whole & (size > 0)):
        idx = vertex_groups[c]
        local[idx] = np.arange(len(idx))
        coarse = decimate(v[idx], local[f[face_groups[c]]], int(goal[c]))
        places = locate_points(coarse, v[idx])
        face[idx], bary[idx] = add(coarse) + places.face, places.bary
    proxy = Mesh(np.concatenate([p.vertices for p in pieces]), np.concatenate([p.faces for p in pieces]))
    alone = np.flatnonzero(face < 0)
    if len(alone):
        places = locate_points(proxy, v[alone])
        face[alone], bary[alone] = places.face, places.bary
    return Proxy(proxy, face, bary)


def decimate(vertices: np.ndarray, faces: np.ndarray, target_vertices: int) -> Mesh:
    """The surface with about ``target_vertices`` vertices and never more (:func:`at_most`), triangulated as the
    model's training meshes are: a
    quadric edge collapse to ``COARSE`` x the target (fast, close to the surface; its long thin triangles alone
    cost accuracy: 3.7% against 0.64% at 320k vertices, docs/benchmarks.md), then an isotropic remesh to the
    target (:func:`geodata.stages.remesh.isotropic_remesh`). Below ``REMESH_FEWEST`` vertices, the collapse
    alone, to the target: the remesh there misses its target by up to 5x and leaves the surface (a 642-vertex
    unit sphere remeshed to 20 vertices: 4, of radius 0.21).

    The collapse is fast-simplification's, except on a mesh rich in slivers (more than ``SLIVERS`` of its
    faces of quality below 0.1, :func:`triangle_quality`), which it barely reduces, slowly (45k -> 27k
    vertices in 13 s where 15k were asked; scans and modelled meshes have at most 1% such faces): there, and
    wherever fast-simplification stops short of the target, pymeshlab's quadric edge collapse, keeping the
    topology (without, a sliver-rich 135k-vertex spot's proxy had 1,509 edges of three or more faces, which the
    landmark fields' solver can only take through a manifold copy: 0.77% for the shipped model; with, none).
    So too where fast-simplification's own result has more area than its input, by over ``CREASED``: on fine
    thin tubes it creases the surface (a 239k-vertex U-bent tube collapsed to 60k: 19% more area, 34% of the
    faces slivers, geodesics 13% longer than the tube's; a 331k trefoil 3.4%, 2.1% longer; a coil 0.6% and a
    754k spot 0.1%, both fine). pymeshlab's collapse of the U bend: 0.02%, in 4.7 s instead of 0.3 s."""
    from geodata.stages.remesh import isotropic_remesh

    mesh = Mesh(np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64))
    if target_vertices < REMESH_FEWEST:
        return at_most(mesh, target_vertices)
    goal = COARSE * target_vertices
    if mesh.n_vertices > goal:
        mesh = collapse(mesh, max(4, int(round(goal * mesh.n_faces / mesh.n_vertices))))  # boundaries keep their ratio
    return at_most(isotropic_remesh(mesh, target_vertices), target_vertices)


def collapse(mesh: Mesh, target_faces: int) -> Mesh:
    """The quadric edge collapse of :func:`decimate` to about ``target_faces`` faces."""
    import fast_simplification

    from geodata.stages.repair import compact, meshlab_filter

    if target_faces >= mesh.n_faces:
        return mesh
    if np.mean(triangle_quality(mesh) < 0.1) <= SLIVERS:
        v, f = fast_simplification.simplify(unlatticed(mesh), mesh.faces.astype(np.int32), target_count=target_faces)
        fast = compact(np.asarray(v, dtype=np.float64), np.asarray(f, dtype=np.int64))
        if face_areas(fast.vertices, fast.faces).sum() <= CREASED * face_areas(mesh.vertices, mesh.faces).sum():
            mesh = fast  # else it creased the surface (a collapse does not add area): pymeshlab's, below
    if mesh.n_faces > 1.5 * target_faces:
        mesh = meshlab_filter(mesh, "meshing_decimation_quadric_edge_collapse", targetfacenum=target_faces,
                              preservetopology=True, qualitythr=0.3, autoclean=True)
    return mesh


def unlatticed(mesh: Mesh, share: float = UNLATTICE, seed: int = 0) -> np.ndarray:
    r"""The vertices, each moved in its tangent plane (normal to its area-weighted normal) by a seeded random
    offset of up to ``share`` of its shortest edge: the same surface to :math:`O(\text{share}^2)` of an edge
    where it curves, exactly where it is flat. fast-simplification all but stops on a regular lattice in a
    plane (a mesh subdivided by midpoints: every face of the original a plane of 4^k triangles, whose collapses
    tie exactly): a 1.29M-vertex spot subdivided 4 times lost ~0.6% of its faces a round after its first five
    and stopped at 377,646 of the 60,000 vertices asked after its 100 rounds, in 34 s; moved by 1%, 60,002 in
    4.6 s."""
    v, f = mesh.vertices, mesh.faces
    edge = v[np.roll(f, -1, axis=1)] - v[f]  # (M, 3, 3): the edge from each corner to the next
    a, b = edge[:, 0].T, -edge[:, 2].T
    area_normal = (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])
    normal = np.stack([np.bincount(f.ravel(), np.repeat(c, 3), minlength=len(v)) for c in area_normal], 1)
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), np.finfo(float).tiny)
    length = np.sqrt(np.einsum("mkd,mkd->mk", edge, edge))  # (M, 3): the edge leaving each corner
    shortest = np.full(len(v), np.inf)
    np.minimum.at(shortest, f.ravel(), np.minimum(length, np.roll(length, 1, axis=1)).ravel())
    shortest[~np.isfinite(shortest)] = 0.0  # a vertex on no face stays
    step = np.random.default_rng(seed).uniform(-1, 1, v.shape) * (share * shortest)[:, None]
    return v + step - (step * normal).sum(axis=1, keepdims=True) * normal


def at_most(mesh: Mesh, n_vertices: int) -> Mesh:
    """``mesh`` collapsed (:func:`collapse`) until it has at most ``n_vertices`` vertices: first to the faces
    of that many vertices at the mesh's ratio of faces to vertices, then, as an edge collapse takes one vertex
    and two faces (one on a boundary), two faces fewer for each vertex still over. A surface that the collapse
    keeping the topology cannot take so low (a torus below 7 vertices) is collapsed without keeping it."""
    from geodata.stages.repair import meshlab_filter

    if mesh.n_vertices > n_vertices:
        mesh = collapse(mesh, max(1, int(round(n_vertices * mesh.n_faces / mesh.n_vertices))))
    for _ in range(4):
        if mesh.n_vertices <= n_vertices:
            return mesh
        mesh = collapse(mesh, max(1, mesh.n_faces - 2 * (mesh.n_vertices - n_vertices)))
    for _ in range(8):
        if mesh.n_vertices <= n_vertices:
            return mesh
        mesh = meshlab_filter(mesh, "meshing_decimation_quadric_edge_collapse", preservetopology=False,
                              targetfacenum=max(1, mesh.n_faces - 2 * (mesh.n_vertices - n_vertices)))
    if mesh.n_vertices > n_vertices:
        raise RuntimeError(f"the edge collapse stopped at {mesh.n_vertices} vertices, {n_vertices} asked")
    return mesh


def triangle_quality(mesh: Mesh) -> np.ndarray:
    r"""Each face's shape quality :math:`4\sqrt{3}\,A / (a^2 + b^2 + c^2)`: 1 for an equilateral triangle, towards
    0 for a sliver."""
    p = mesh.vertices[mesh.faces]
    edges = p - np.roll(p, 1, axis=1)
    area = 0.5 * np.linalg.norm(np.cross(edges[:, 0], edges[:, 1]), axis=1)
    return 4 * np.sqrt(3) * area / np.maximum((edges ** 2).sum(axis=(1, 2)), np.finfo(float).tiny)


def cloud_subset(points: np.ndarray, target: int, seed: int = 0) -> np.ndarray:
    """``target`` distinct points of a cloud (indices, sorted), drawn uniformly at random with a fixed seed:
    a scan's density carries over, as the area-uniform samples the point model was trained on do."""
    distinct = np.unique(np.asarray(points, dtype=np.float64), axis=0, return_index=True)[1]
    pick = np.random.default_rng(seed).choice(len(distinct), min(target, len(distinct)), replace=False)
    return np.sort(distinct[pick])


def cloud_weights(points: np.ndarray, subset: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For every point, its 3 nearest points of ``subset`` (indices into the subset, (N, 3)) and inverse-distance
    weights summing to 1 ((N, 3)); a point of the subset is its own blend (weight 1)."""
    from scipy.spatial import cKDTree

    points = np.asarray(points, dtype=np.float64)
    dist, idx = cKDTree(points[subset]).query(points, k=3)
    inv = 1.0 / np.maximum(dist, 1e-12 * max(np.ptp(points, axis=0).max(), 1e-300))
    exact = dist[:, 0] <= 0
    inv[exact] = (1.0, 0.0, 0.0)
    return idx, inv / inv.sum(axis=1, keepdims=True)

