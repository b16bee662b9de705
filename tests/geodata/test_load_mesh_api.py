"""geodata.load_mesh: the documented loader of one's own mesh file (README, docs/api/geodata.md)."""
import numpy as np
import pytest

import geodata

# A tetrahedron whose first vertex is written twice (vertex 5 = vertex 1) and one vertex no face uses.
TETRA_OBJ = """v 0 0 0
v 2 0 0
v 0 3 0
v 0 0 4
v 0 0 0
v 9 9 9
f 1 2 3
f 1 2 4
f 2 3 4
f 5 3 4
"""


def test_load_mesh_reads_cleans_and_keeps_units(tmp_path):
    path = tmp_path / "tetra.obj"
    path.write_text(TETRA_OBJ)
    mesh = geodata.load_mesh(path)
    assert isinstance(mesh, geodata.Mesh)
    assert (mesh.n_vertices, mesh.n_faces) == (4, 4)  # the duplicate merged, the unused vertex dropped
    assert mesh.vertices.dtype == np.float64 and mesh.faces.dtype == np.int64
    # not normalized: the file's own coordinates
    assert sorted(map(tuple, mesh.vertices.tolist())) == [(0, 0, 0), (0, 0, 4), (0, 3, 0), (2, 0, 0)]


def test_load_mesh_map_carries_file_vertices(tmp_path):
    path = tmp_path / "tetra.obj"
    path.write_text(TETRA_OBJ)
    mesh, file_to_mesh = geodata.load_mesh(str(path), return_map=True)
    file_vertices = np.loadtxt(path, comments="f", usecols=(1, 2, 3))
    assert file_to_mesh.shape == (6,)
    assert file_to_mesh[0] == file_to_mesh[4]  # the two copies of vertex 1
    assert file_to_mesh[5] == -1  # used by no face
    used = file_to_mesh >= 0
    np.testing.assert_array_equal(mesh.vertices[file_to_mesh[used]], file_vertices[used])


def test_load_mesh_refuses_with_a_reason(tmp_path):
    cloud = tmp_path / "cloud.obj"
    cloud.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
    with pytest.raises(geodata.MeshError, match="no faces|no triangle"):
        geodata.load_mesh(cloud)
    empty = tmp_path / "empty.ply"
    empty.write_bytes(b"")
    with pytest.raises(geodata.MeshError, match="empty"):
        geodata.load_mesh(empty)


def test_load_mesh_is_exported():
    assert "load_mesh" in geodata.__all__ and geodata.load_mesh.__doc__
