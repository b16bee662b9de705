"""Surface points with exact distances (`geodata points`): Euclidean on a plane, great circles on a
sphere, the solver's own distances at vertices, area-uniform sampling, and the store command."""
import shutil

import numpy as np
import trimesh
from click.testing import CliRunner

from geodata import store
from geodata.cli import main
from geodata.geodesic import geodesic_solver
from geodata.mesh import Mesh
from geodata.point_samples import SurfaceSamples, point_pairs, sample_points


def grid(n=12) -> Mesh:
    x, y = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))
    v = np.stack([x.ravel(), y.ravel(), np.zeros(n * n)], axis=1)
    i = np.arange(n * n).reshape(n, n)[:-1, :-1].ravel()
    f = np.concatenate([np.stack([i, i + 1, i + n + 1], 1), np.stack([i, i + n + 1, i + n], 1)])
    return Mesh(v, f)


def test_on_a_plane_the_distances_are_straight_lines():
    mesh = grid()
    rng = np.random.default_rng(0)
    samples = sample_points(mesh, 300, rng)
    pairs, d = point_pairs(mesh, samples, 1000, rng)
    assert len(pairs) == 4 * 299 and len(np.unique(pairs[:, 0])) == 4
    straight = np.linalg.norm(samples.xyz[pairs[:, 0]] - samples.xyz[pairs[:, 1]], axis=1)
    np.testing.assert_allclose(d, straight, rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(samples.normals, np.tile([0, 0, 1.0], (300, 1)) * np.sign(samples.normals[:, 2:]))


def test_on_a_sphere_the_distances_are_near_great_circles():
    m = trimesh.creation.icosphere(4)
    mesh = Mesh(np.asarray(m.vertices), np.asarray(m.faces))
    rng = np.random.default_rng(1)
    samples = sample_points(mesh, 500, rng)
    pairs, d = point_pairs(mesh, samples, 1500, rng)
    unit = samples.xyz / np.linalg.norm(samples.xyz, axis=1, keepdims=True)
    great = np.arccos(np.clip(np.einsum("ij,ij->i", unit[pairs[:, 0]], unit[pairs[:, 1]]), -1, 1))
    far = great > 0.2
    assert np.mean(np.abs(d[far] - great[far]) / great[far]) < 0.01
    assert np.einsum("ij,ij->i", samples.normals, unit).min() > 0.99  # smooth outward normals


def test_a_point_on_a_vertex_has_the_solvers_own_distances():
    m = trimesh.creation.icosphere(2)
    mesh = Mesh(np.asarray(m.vertices), np.asarray(m.faces))
    corners = np.array([3, 17, 40])
    bary = np.eye(3)[[0, 1, 2]]
    samples = SurfaceSamples(corners, bary, mesh.vertices[mesh.faces[corners, [0, 1, 2]]], np.zeros((3, 3)))
    pairs, d = point_pairs(mesh, samples, 6, np.random.default_rng(0))
    solve = geodesic_solver(mesh)
    vertex = mesh.faces[corners, [0, 1, 2]]
    truth = np.array([solve(int(vertex[s]))[vertex[t]] for s, t in pairs])
    np.testing.assert_array_equal(d, truth.astype(np.float32))  # stored as float32


def test_faces_are_drawn_by_area():
    mesh = Mesh(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [3, 0, 0], [0, 3, 0.0]]), np.array([[0, 1, 2], [0, 3, 4]]))
    samples = sample_points(mesh, 20000, np.random.default_rng(2))
    assert abs(np.mean(samples.face == 0) - 1 / 9) < 0.01  # areas 1/2 and 9/2 (the big one holds the small)
    inside = samples.xyz[samples.face == 0]
    assert (inside[:, :2] >= -1e-12).all() and (inside[:, :2].sum(axis=1) <= 1 + 1e-12).all()


def test_geodata_points_adds_a_committed_subgroup_and_resumes(reference, tmp_path):
    out = tmp_path / "out.zarr"
    shutil.copytree(reference[0], out)
    result = CliRunner().invoke(main, ["points", str(out), "--points", "200", "--pairs", "800"])
    assert result.exit_code == 0, result.output
    assert "3 to do" in result.output
    assert list(store.list_meshes(out).values()) == [{"points"}] * 3
    for mesh_id in store.list_meshes(out):
        with store.read_mesh(out, mesh_id, "points") as p:
            assert p.attrs["status"] == "ok" and p["xyz"].shape == (200, 3) and p["pairs"].shape[1] == 2
            assert len(np.unique(p["pairs"][:, 0])) == 4 and np.isfinite(p["distances"][:]).all()
    again = CliRunner().invoke(main, ["points", str(out), "--points", "200", "--pairs", "800"])
    assert "0 to do, 3 already done" in again.output



def test_prepare_with_points_writes_what_geodata_points_adds_afterwards(raw, reference, tmp_path):
    from storetools import prepare

    out = tmp_path / "with_points.zarr"
    result = prepare(raw, out, "--points", "200")  # its --pairs (3000) for the points' pairs too
    assert "points" in result.output and "3 to do" in result.output
    after = tmp_path / "after.zarr"
    shutil.copytree(reference[0], after)
    assert CliRunner().invoke(main, ["points", str(after), "--points", "200", "--pairs", "3000"]).exit_code == 0
    ids = sorted(store.list_meshes(out))
    assert len(ids) == 3 and ids == sorted(store.list_meshes(after))
    for mesh_id in ids:
        with store.read_mesh(out, mesh_id, "points") as a, store.read_mesh(after, mesh_id, "points") as b:
            assert a.attrs["status"] == b.attrs["status"] == "ok"
            for name in ("xyz", "normals", "face", "bary", "pairs", "distances"):
                np.testing.assert_array_equal(a[name][:], b[name][:], err_msg=f"{mesh_id}/{name}")
