"""The close-walls shapes (geodata.walls): closed and outward where they should be, their normals on the side
the faces face, the sides the thickness asked apart, and the way round a slab's rim what its profile says."""
import numpy as np
import pytest
import trimesh

from geodata.walls import WALLS, wall_mesh


@pytest.mark.parametrize("name", list(WALLS))
def test_each_shape_is_a_manifold_with_its_normals_on_the_faces_side(name):
    v, f, normals = wall_mesh(name, 0.5 * 0.08, 0.08)
    mesh = trimesh.Trimesh(v, f, process=False)
    assert mesh.is_winding_consistent
    assert mesh.is_watertight == (name in ("slab", "bowl"))
    if mesh.is_watertight:
        assert mesh.volume > 0  # outwards
    face_side = np.zeros_like(v)
    np.add.at(face_side, f.ravel(), np.repeat(mesh.face_normals, 3, axis=0))
    assert (np.einsum("ij,ij->i", face_side, normals) > 0).all()
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0)


def test_a_slabs_sides_are_the_thickness_apart_and_the_way_round_is_its_rim():
    from geodata._exact_geodesic import Surface

    h, t = 0.06, 0.03
    v, f, _ = wall_mesh("slab", t, h)
    flat = np.hypot(v[:, 0], v[:, 1]) < 1 - 1e-9
    np.testing.assert_allclose(np.abs(v[flat, 2]), t / 2)
    assert len(np.unique(np.round(v[~flat, 2] / t, 6))) > 2  # a ring of points on the rim, not only its edges
    top, bottom = np.argmax(v[:, 2] - np.hypot(v[:, 0], v[:, 1])), np.argmin(v[:, 2] + np.hypot(v[:, 0], v[:, 1]))
    d = Surface(np.ascontiguousarray(v), f.astype(np.int32)).distances(np.array([top]))[0, bottom]
    assert abs(d - (2 + np.pi * t / 2)) < 0.01 * d  # face, half round, face (the polyhedron a little off)
