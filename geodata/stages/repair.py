"""Small repairs shared by the stages: unreferenced vertices, pymeshlab round trips, zero-area faces."""
from __future__ import annotations

import numpy as np

from geodata.mesh import Mesh, degenerate_faces

__all__ = ["compact", "meshlab_filter", "remove_degenerate_faces"]


def compact(v: np.ndarray, f: np.ndarray) -> Mesh:
    """Drop unreferenced vertices, keep the order of the others."""
    used = np.zeros(len(v), dtype=bool)
    used[f.ravel()] = True
    if used.all():
        return Mesh(v, f)
    remap = np.cumsum(used) - 1
    return Mesh(v[used], remap[f])


def meshlab_filter(mesh: Mesh, name: str, **params) -> Mesh:
    """`mesh` after the pymeshlab filter `name` (a MeshSet method's name), without unreferenced vertices."""
    import pymeshlab

    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=mesh.vertices, face_matrix=mesh.faces))
    ms.apply_filter(name, **params)
    m = ms.current_mesh()
    return compact(np.asarray(m.vertex_matrix(), dtype=np.float64), np.asarray(m.face_matrix(), dtype=np.int64))


def remove_degenerate_faces(mesh: Mesh) -> Mesh:
    """Collapse away zero-area (collinear) triangles with pymeshlab's T-vertex removal by edge collapse.

    Marching cubes, isotropic remeshing and QEM collapses occasionally leave them (60 on one door here).
    """
    if not degenerate_faces(mesh).any():
        return mesh
    return meshlab_filter(mesh, "meshing_remove_t_vertices", method=0, threshold=40, repeat=True)
