"""Exact distance fields of a mesh (geodata's solvers, in a forked child) and its connected parts: the
reference the learned fields are measured against and finetuned on."""
from __future__ import annotations

import numpy as np

from geodata.mesh import Mesh, MeshError, edge_face_counts, vertex_components

__all__ = ["exact_field", "exact_fields", "exact_at_points", "require_edge_manifold", "source_part", "largest_part"]


def exact_field(mesh: Mesh, source: int, distance: str = "geodesic") -> np.ndarray:
    """Exact distances from ``source`` (NaN off its connected part); see :func:`exact_fields`."""
    return exact_fields(mesh, np.array([source]), distance)[0]


def exact_fields(mesh: Mesh, sources: np.ndarray, distance: str = "geodesic") -> np.ndarray:
    """Exact geodesic (the default geodata backend) or biharmonic (:mod:`geodata.biharmonic`) distances
    (S, N) from each of ``sources``, NaN off the source's part, in a forked child: native code that
    crashes on some input then fails with a MeshError instead of killing the caller."""
    from geodata.parallel import run_isolated

    if distance == "geodesic":
        require_edge_manifold(mesh)
    d = run_isolated(_solve_all, mesh, [int(s) for s in sources], distance)
    return np.where(np.isfinite(d), d, np.nan)


def exact_at_points(mesh: Mesh, points: np.ndarray, source: int, distance: str = "geodesic"):
    """Exact distances from ``points[source]`` to every point of a cloud taken from ``mesh``: every point
    moved to its closest surface point, the source's inserted as a vertex, the exact field from it read at
    each point by barycentric interpolation (exact at the mesh's vertices, linear between them). Returns
    the distances (P,) (NaN off the source's part) and each point's distance to the surface (P,)."""
    from geodata.surface_points import insert_points, locate_points

    located = locate_points(mesh, points)
    refined, vertex = insert_points(mesh, located.face[[source]], located.bary[[source]])
    field = exact_field(refined, int(vertex[0]), distance)
    again = locate_points(refined, points)
    values = np.einsum("pk,pk->p", again.bary, field[refined.faces[again.face]])
    values[source] = 0.0
    return values, located.offset


def require_edge_manifold(mesh: Mesh) -> None:
    """MeshError unless every edge has at most two faces (the exact geodesic solver needs it)."""
    _, counts = edge_face_counts(mesh.faces)
    if (counts > 2).any():
        raise MeshError("exact", f"{int((counts > 2).sum())} non-manifold edges (exact geodesics need a "
                                 "manifold mesh; --prepare makes one)")


def _solve_all(mesh: Mesh, sources: list[int], distance: str) -> np.ndarray:
    if distance == "biharmonic":
        from geodata.biharmonic import biharmonic_distances
        return biharmonic_distances(mesh, np.asarray(sources))

    from geodata.geodesic import geodesic_solver

    solve = geodesic_solver(mesh)
    return np.stack([solve(s) for s in sources])


def source_part(mesh: Mesh, source: int) -> tuple[np.ndarray, int]:
    """Vertices on the source's connected part (bool (N,)) and how many parts the mesh has."""
    labels = vertex_components(mesh)
    return labels == labels[source], int(labels.max()) + 1


def largest_part(mesh: Mesh) -> np.ndarray:
    """Vertices on the mesh's largest connected part (most vertices), bool (N,)."""
    labels = vertex_components(mesh)
    return labels == np.bincount(labels).argmax()
