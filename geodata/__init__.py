"""geodata: raw triangle meshes to exact geodesic (and biharmonic) training data in zarr stores."""
from __future__ import annotations

from geodata.mesh import Mesh, MeshError

__all__ = ["Mesh", "MeshError", "load_mesh"]
__version__ = "0.3.3"


def load_mesh(path, *, return_map: bool = False):
    """Read one's own mesh file into a validated, cleaned :class:`Mesh` (the pipeline's first stage).

    The file is read as `geodata prepare` and `gegnn query` read it: OBJ, OFF, PLY, STL or GLB (polygons
    triangulated), coincident vertices merged, degenerate faces and vertices no face uses dropped, and
    checked (finite coordinates, face indices in range, at least one face). Nothing is remeshed or
    normalized: coordinates stay in the file's units.

        mesh = geodata.load_mesh("bunny.obj")
        emb = gegnn.GeGnn.pretrained().embed(mesh.vertices, mesh.faces)

    Args:
        path: the mesh file (str or path-like); its suffix picks the format.
        return_map: also return, for every vertex of the file, its index in the cleaned mesh (-1 for a
            vertex no face uses), to carry results back to the file's own vertex numbering.

    Returns:
        The :class:`Mesh` (vertices float64 (N, 3), faces int64 (F, 3)), or `(mesh, file_to_mesh)` with
        `return_map=True`.

    Raises:
        MeshError: the file is empty, unreadable, holds no triangle mesh (e.g. a point cloud) or fails a
            check; its message says why (stage "load").
        FileNotFoundError: there is no such file.
    """
    from geodata.stages.load import load_mesh_file  # trimesh is imported on first use, not by `import geodata`

    mesh, file_to_mesh = load_mesh_file(path)
    return (mesh, file_to_mesh) if return_map else mesh
