"""Watertight stage: a closed, manifold, outward-oriented surface around a triangle soup.

Method (all on a regular grid with cubic cells, distances measured in cell units):

1. Mark the grid nodes near the input surface (dense barycentric samples of every triangle, dilated
   by a few cells) and compute their exact unsigned distance to the soup (libigl AABB tree).
   Nodes outside this narrow band get a large constant distance.
2. The outside is the part of ``{d > offset}`` reachable from the grid border (6-connected flood
   fill); everything else (the surface shell and enclosed cavities) is inside. Cavities are
   therefore filled, which removes nested / inner shells.
3. Lewiner marching cubes extracts the ``offset`` level set between outside and inside. Every part
   of the input, however thin (zero-thickness sheets included), becomes a solid at least
   ``2 * offset`` cells thick, so thin parts survive.
4. manifold3d validates the result (status NoError, not empty), components smaller than a few
   cells are dropped, and the grid transform is undone so the output keeps the input units.

The result is deterministic: no randomness anywhere.
"""
from __future__ import annotations

import numpy as np

from geodata.mesh import Mesh, MeshError, closed_manifold_problem, component_volumes, face_areas

__all__ = ["watertight"]

_STAGE = "watertight"


# Every point of a triangle is within this many `spacing`s of a sample from _surface_samples.
_COVER = np.sqrt(1.25)


def _surface_samples(p: np.ndarray, f: np.ndarray, spacing: float) -> np.ndarray:
    """Points on every triangle of the soup (vertex coords `p` in cell units) such that each point
    of a triangle is within _COVER * spacing of one of them.

    Per triangle: rows parallel to the longest edge, at most `spacing` apart, each row with the
    same number of evenly spaced points (at most `spacing` apart on the longest, widest row).
    About 2 * area / spacing^2 points; slivers get a single row, not a quadratic number.
    """
    tri = p[f]                                                   # (T, 3, 3)
    edge_len = np.linalg.norm(tri[:, [1, 2, 0]] - tri, axis=2)   # edge k: corner k -> k+1
    k = np.argmax(edge_len, axis=1)
    rows = np.arange(len(f))
    a, b, c = (tri[rows, (k + i) % 3] for i in range(3))          # c: apex opposite the longest edge
    length = edge_len[rows, k]
    cross = np.linalg.norm(np.cross(b - a, c - a), axis=1)
    height = np.where(length > 0, cross / np.maximum(length, 1e-300), 0.0)
    n_u = np.maximum(1, np.ceil(length / spacing)).astype(np.int64)
    n_v = np.maximum(1, np.ceil(height / spacing)).astype(np.int64)
    count = (n_u + 1) * (n_v + 1)
    tid = np.repeat(rows, count)
    local = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
    i = local % (n_u + 1)[tid]
    j = local // (n_u + 1)[tid]
    t = (j / n_v[tid])[:, None]
    u = (i / n_u[tid])[:, None]
    left = a[tid] + t * (c[tid] - a[tid])
    right = b[tid] + t * (c[tid] - b[tid])
    return left + u * (right - left)


def _unsigned_distance_band(p: np.ndarray, f: np.ndarray, shape: tuple[int, int, int],
                            band: float, far: float) -> np.ndarray:
    """Unsigned distance (cell units) from every grid node to the soup, exact within `band` cells
    and `far` (a constant >= band) elsewhere."""
    import igl
    from scipy import ndimage

    spacing = 0.5
    samples = _surface_samples(p, f, spacing)
    idx = np.rint(samples).astype(np.int64)
    marked = np.ones(shape, dtype=bool)
    marked[idx[:, 0], idx[:, 1], idx[:, 2]] = False
    # A node within `band` of the surface is within band + _COVER * spacing + sqrt(3)/2 of a marked
    # node (the nearest sample, then the node that sample was rounded to).
    reach = band + _COVER * spacing + np.sqrt(3.0) / 2.0 + 1e-6
    r = int(np.ceil(reach))
    # Cheap prefilter (separable cube max filter), then the exact Euclidean distance to marked nodes
    # inside it.
    box = ndimage.minimum_filter(marked, size=2 * r + 1, mode="constant", cval=True)
    sub = np.argwhere(~box)
    lo, hi = sub.min(axis=0), sub.max(axis=0) + 1
    crop = marked[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]]
    nodes = np.argwhere(ndimage.distance_transform_edt(crop) <= reach) + lo
    d2, _, _ = igl.point_mesh_squared_distance(nodes.astype(np.float64), p, f)
    d = np.full(shape, far, dtype=np.float64)
    d[nodes[:, 0], nodes[:, 1], nodes[:, 2]] = np.minimum(np.sqrt(np.maximum(d2, 0.0)), far)
    return d


def watertight(mesh: Mesh, *, resolution: int = 128, offset: float = 0.75,
               max_surface_cells: float = 60000.0, min_component_cells: float = 3.0,
               tolerance: float = 0.1) -> Mesh:
    """A watertight, edge- and vertex-manifold, outward-oriented surface around `mesh`.

    resolution: grid cells along the longest side of the bounding box (at most).
    max_surface_cells: the cell is enlarged, when needed, so that the input's surface area is at
        most this many cell faces; bounds the work for meshes with a large surface (gears, plants)
        while keeping the cell a fixed fraction of the final edge length.
    offset: level of the unsigned distance field that is extracted, in cells (the surface lies
        about this far outside the input; thin and zero-thickness parts become >= 2*offset thick).
    min_component_cells: closed components whose bounding box is smaller than this many cells
        along every axis (spurious specks) are dropped.
    tolerance: the marching-cubes surface is simplified by manifold3d (manifold-preserving edge
        collapses) within this distance, in cells; far fewer triangles, same shape. 0 disables.
    Keeps the input units. Raises MeshError("watertight", reason) when no valid surface results.
    """
    from scipy import ndimage
    from skimage.measure import marching_cubes
    import manifold3d
    import trimesh

    v, f = mesh.vertices, mesh.faces
    if len(f) == 0 or len(v) == 0:
        raise MeshError(_STAGE, "no faces")
    if not np.isfinite(v).all():
        raise MeshError(_STAGE, "non-finite vertex coordinates")
    if f.min() < 0 or f.max() >= len(v):
        raise MeshError(_STAGE, "face index out of range")
    if resolution < 8:
        raise MeshError(_STAGE, f"resolution {resolution} too small")
    if not offset > 0:
        raise MeshError(_STAGE, f"offset must be positive, got {offset}")

    used = np.unique(f)
    lo, hi = v[used].min(axis=0), v[used].max(axis=0)
    extent = float((hi - lo).max())
    if not extent > 0:
        raise MeshError(_STAGE, "degenerate bounding box")
    area = float(face_areas(v, f).sum())
    h = max(extent / resolution, np.sqrt(area / max_surface_cells))   # cell size in input units
    pad = int(np.ceil(offset)) + 3               # empty layers around the shape
    origin = lo - pad * h
    shape = tuple(int(s) for s in np.ceil((hi - lo) / h).astype(np.int64) + 2 * pad + 1)
    p = (v - origin) / h                          # vertices in cell units; nodes at integers

    # Marching cubes reads the exact field only at nodes next to the level set: d <= offset + 1.
    band = offset + 1.0
    far = band + 1.0
    d = _unsigned_distance_band(p, f, shape, band, far)

    # Outside: the part of {d > offset} connected to the grid border.
    free = d > offset
    labels, _ = ndimage.label(free)
    border = np.ones(shape, dtype=bool)
    border[1:-1, 1:-1, 1:-1] = False
    outside = free & np.isin(labels, labels[border])
    if outside.all():
        raise MeshError(_STAGE, "no solid found on the grid")
    # Inside nodes (shell and filled cavities) below the level, outside above, each at least `gap`
    # away from it: a node value at (or within round-off of) the level puts the surface vertices of
    # all its grid edges on the node, coincident but distinct, which later tools merge into
    # non-manifold edges.
    gap = 0.05 * min(offset, 1.0)
    field = np.where(outside, np.maximum(d, offset + gap), np.minimum(d, offset - gap))

    try:
        mv, mf, _, _ = marching_cubes(field, level=offset, method="lewiner", allow_degenerate=False)
    except (ValueError, RuntimeError) as exc:
        raise MeshError(_STAGE, f"marching cubes failed: {exc}".splitlines()[0]) from None
    mv = mv.astype(np.float64)
    mf = mf.astype(np.int64)
    if len(mf) == 0:
        raise MeshError(_STAGE, "empty level set")
    if component_volumes(Mesh(mv, mf)).sum() < 0:
        mf = mf[:, ::-1]

    man = manifold3d.Manifold(manifold3d.Mesh64(vert_properties=mv, tri_verts=mf.astype(np.uint64)))
    status = man.status()
    if status != manifold3d.Error.NoError or man.is_empty():
        raise MeshError(_STAGE, f"level set is not a valid manifold ({status.name})")
    # manifold3d's simplify can leave two distinct vertices at one position (where it pinches a
    # thin wall); later tools (pymeshlab) merge those into non-manifold edges. Retry finer if so.
    for tol in (tolerance, tolerance / 4.0):
        if not tol > 0:
            break
        simple = man.simplify(tol)
        if simple.status() != manifold3d.Error.NoError or simple.is_empty():
            continue
        sv = np.asarray(simple.to_mesh64().vert_properties)[:, :3]
        if len(np.unique(sv, axis=0)) == len(sv):
            man = simple
            break

    parts = []
    for comp in man.decompose():
        m64 = comp.to_mesh64()
        cv = np.asarray(m64.vert_properties)[:, :3].astype(np.float64)
        cf = np.asarray(m64.tri_verts).astype(np.int64)
        if len(cf) == 0 or (np.ptp(cv, axis=0) < min_component_cells).all():
            continue
        if comp.volume() <= 0:
            cf = cf[:, ::-1]
        parts.append((cv, cf))
    if not parts:
        raise MeshError(_STAGE, "only tiny components")
    # Deterministic order: by the lexicographically smallest vertex of each part.
    parts.sort(key=lambda vf: tuple(vf[0].min(axis=0)))
    out_v, out_f = trimesh.util.append_faces([cv for cv, _ in parts], [cf for _, cf in parts])
    out = Mesh(out_v * h + origin, out_f)
    # Slivers from manifold3d's simplification are left to the remesh stage, which rebuilds the triangles.
    problem = closed_manifold_problem(out, zero_area_ok=True)
    if problem is not None:
        raise MeshError(_STAGE, f"result invalid: {problem}")
    return out
