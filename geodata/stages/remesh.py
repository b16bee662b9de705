"""Remesh and simplify stages.

remesh: pymeshlab isotropic explicit remeshing of a closed manifold surface to a uniform edge length
chosen so that the mesh left after `simplify` has about `target_vertices` vertices.

simplify: QEM edge collapse that removes the fraction `collapse` of the edges (default 15%), which
diversifies edge lengths. On a closed surface every edge collapse removes 1 vertex, 3 edges and
2 faces, so removing 15% of the edges is removing 15% of the faces (and about 15% of the vertices,
since F ~ 2V): we ask for ``round(F * (1 - collapse))`` faces. fast-simplification first; when its
result is not a closed manifold (it can pinch thin parts or open holes in flat regions), pymeshlab's
quadric edge collapse with topology preservation; when that fails too, MeshError("simplify", ...).

Both are deterministic (no randomness; the same input gives byte-identical output).
"""
from __future__ import annotations

import numpy as np

from geodata.mesh import Mesh, MeshError, closed_manifold_problem, face_areas
from geodata.stages.repair import compact, meshlab_filter, remove_degenerate_faces

__all__ = ["remesh", "simplify", "isotropic_remesh"]

# An isotropic remesh with target length L of a surface of area A has about
# 2A / (sqrt(3) (L / _LENGTH_FACTOR)^2) vertices (vcg splits edges longer than 4/3 L and collapses
# those shorter than 4/5 L, and keeps vertices on feature creases). Measured on the 114 shared
# train meshes after `watertight`: the count ratio is 1.0 +- 0.15 at this factor; meshes with many
# creases get more vertices, which the correction loop in `remesh` fixes.
_LENGTH_FACTOR = 1.08
# Creases sharper than this stay sharp (pymeshlab's default). 60 degrees gives steadier vertex
# counts, but lets the remesher shave thin slabs and the rims of panels (input surface points up
# to 3 cells outside the result); 30 keeps them all inside.
_FEATURE_DEG = 30.0
_TOLERANCE = 0.06          # accept a remesh whose vertex count is within 6% of what we asked for
_MAX_TRIES = 3


def _isotropic(mesh: Mesh, length: float, iterations: int, checksurfdist: bool) -> Mesh:
    import pymeshlab

    return remove_degenerate_faces(meshlab_filter(
        mesh, "meshing_isotropic_explicit_remeshing", iterations=iterations, targetlen=pymeshlab.PureValue(length),
        featuredeg=_FEATURE_DEG, checksurfdist=checksurfdist))


def isotropic_remesh(mesh: Mesh, target_vertices: int, iterations: int = 5) -> Mesh:
    """One isotropic remesh towards ``target_vertices`` vertices (the edge length from the surface area, as in
    :func:`remesh`), of any surface (boundaries allowed, no closed-manifold check, no retries): for a coarse
    stand-in of a surface, where :func:`remesh` makes training data."""
    area = float(face_areas(mesh.vertices, mesh.faces).sum())
    if not area > 0:
        raise MeshError("remesh", "zero surface area")
    return _isotropic(mesh, _LENGTH_FACTOR * np.sqrt(2.0 * area / (np.sqrt(3.0) * target_vertices)), iterations, False)


def _presimplify(mesh: Mesh, tolerance: float) -> Mesh:
    """Manifold-preserving collapse of a dense input (marching cubes) within `tolerance`."""
    import manifold3d

    man = manifold3d.Manifold(manifold3d.Mesh64(vert_properties=mesh.vertices,
                                                tri_verts=mesh.faces.astype(np.uint64))).simplify(tolerance)
    if man.status() != manifold3d.Error.NoError or man.is_empty():  # an invalid input stays invalid
        return mesh
    m = man.to_mesh64()
    return Mesh(np.asarray(m.vert_properties)[:, :3], np.asarray(m.tri_verts).astype(np.int64))


def remesh(mesh: Mesh, target_vertices: int = 5000, *, collapse: float = 0.15,
           iterations: int = 10) -> Mesh:
    """Isotropic remesh (see the module) with ~target / (1 - collapse) vertices. The edge length is
    estimated from the surface area, then corrected (from the input again) while the vertex count is
    more than 6% off; where remeshing breaks the closed manifold, a more conservative remesh
    (surface-distance checks on) is tried."""
    stage = "remesh"
    problem = closed_manifold_problem(mesh, zero_area_ok=True)
    if problem is not None:
        raise MeshError(stage, f"input is not a closed manifold: {problem}")
    if target_vertices < 4:
        raise MeshError(stage, f"target_vertices {target_vertices} too small")
    if not 0 <= collapse < 1:
        raise MeshError(stage, f"collapse must be in [0, 1), got {collapse}")
    goal = target_vertices / (1.0 - collapse)
    area = float(face_areas(mesh.vertices, mesh.faces).sum())
    if not area > 0:
        raise MeshError(stage, "zero surface area")
    length = _LENGTH_FACTOR * np.sqrt(2.0 * area / (np.sqrt(3.0) * goal))

    source = _presimplify(mesh, 0.05 * length) if mesh.n_vertices > 4 * goal else mesh

    best, best_err, last_problem = None, np.inf, None
    for checksurfdist in (False, True):
        tried = []                                  # (log length, log vertex count)
        cur = length
        for _ in range(_MAX_TRIES):
            out = _isotropic(source, cur, iterations, checksurfdist)
            problem = closed_manifold_problem(out)
            if problem is not None:
                last_problem = problem
                break
            err = abs(out.n_vertices / goal - 1.0)
            if err < best_err:
                best, best_err = out, err
            if err <= _TOLERANCE:
                break
            tried.append((np.log(cur), np.log(out.n_vertices)))
            # V ~ L^-alpha: alpha is 2 for a smooth surface, less where creases pin vertices;
            # estimated from the last two tries (secant in log-log), clamped.
            alpha = 2.0
            if len(tried) >= 2 and tried[-1][0] != tried[-2][0]:
                alpha = float(np.clip(-(tried[-1][1] - tried[-2][1]) / (tried[-1][0] - tried[-2][0]), 0.7, 3.0))
            cur = float(np.exp(tried[-1][0] + (tried[-1][1] - np.log(goal)) / alpha))
        if best is not None:
            break
    if best is None:
        raise MeshError(stage, f"remeshing broke the surface: {last_problem}")
    return best


def simplify(mesh: Mesh, collapse: float = 0.15) -> Mesh:
    """QEM edge collapse of the fraction `collapse` of a closed manifold's edges (see the module)."""
    stage = "simplify"
    problem = closed_manifold_problem(mesh)
    if problem is not None:
        raise MeshError(stage, f"input is not a closed manifold: {problem}")
    if not 0 <= collapse < 1:
        raise MeshError(stage, f"collapse must be in [0, 1), got {collapse}")
    if collapse == 0:
        return mesh
    target_faces = int(round(mesh.n_faces * (1.0 - collapse)))
    target_faces -= target_faces % 2          # closed triangle meshes have an even face count

    import fast_simplification

    problems = []
    try:
        v, f = fast_simplification.simplify(mesh.vertices, mesh.faces.astype(np.int32),
                                            target_count=target_faces)
        out = remove_degenerate_faces(compact(np.asarray(v, dtype=np.float64), np.asarray(f, dtype=np.int64)))
        problem = closed_manifold_problem(out)  # includes outward orientation of every component
        if problem is None:
            return out
        problems.append(f"fast-simplification: {problem}")
    except Exception as exc:  # noqa: BLE001 - native library; any failure means: use the fallback
        problems.append(f"fast-simplification: {type(exc).__name__}")

    out = remove_degenerate_faces(meshlab_filter(
        mesh, "meshing_decimation_quadric_edge_collapse", targetfacenum=target_faces, preservetopology=True,
        preservenormal=True, planarquadric=True, qualitythr=0.3, autoclean=True))
    problem = closed_manifold_problem(out)
    if problem is None:
        return out
    problems.append(f"pymeshlab: {problem}")
    raise MeshError(stage, "; ".join(problems))
