"""insert_points: surface points (face, barycentrics) become vertices of the same surface, so exact geodesics
between them are vertex-to-vertex distances (flat grid: straight lines; sphere: original distances unchanged)."""
import time
from pathlib import Path

import numpy as np
import pytest
import trimesh

from geodata.geodesic import geodesic_solver
from geodata.mesh import Mesh, closed_manifold_problem, degenerate_faces, edge_face_counts
from geodata.surface_points import insert_points

SHARED = Path(__file__).resolve().parents[3] / "shared" / "meshes"


def icosphere(level: int) -> Mesh:
    s = trimesh.creation.icosphere(level)
    return Mesh(s.vertices, s.faces)


def unit_square(n: int = 21) -> Mesh:
    """The unit square, (n - 1) x (n - 1) cells of two triangles each, normals +z."""
    x, y = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n), indexing="ij")
    v = np.stack([x.ravel(), y.ravel(), np.zeros(n * n)], axis=1)
    i = (np.arange(n - 1)[:, None] * n + np.arange(n - 1)[None, :]).ravel()
    return Mesh(v, np.concatenate([np.stack([i, i + n, i + 1], 1), np.stack([i + 1, i + n, i + n + 1], 1)]))


def points_of(mesh: Mesh, face, bary) -> np.ndarray:
    return np.einsum("pk,pkd->pd", np.asarray(bary, float), mesh.vertices[mesh.faces[face]])


def normals(mesh: Mesh) -> np.ndarray:
    v, f = mesh.vertices, mesh.faces
    return np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])


def in_faces(mesh: Mesh, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Barycentric coordinates (M, F, 3) of points x (M, 3) projected on every face's plane, and their
    distances to those planes (M, F)."""
    a = mesh.vertices[mesh.faces[:, 0]]
    e1, e2 = mesh.vertices[mesh.faces[:, 1]] - a, mesh.vertices[mesh.faces[:, 2]] - a
    d = x[:, None] - a[None]
    d11, d12, d22 = (e1 * e1).sum(1), (e1 * e2).sum(1), (e2 * e2).sum(1)
    d1, d2 = (d * e1).sum(2), (d * e2).sum(2)
    den = d11 * d22 - d12 ** 2
    v, w = (d22 * d1 - d12 * d2) / den, (d11 * d2 - d12 * d1) / den
    n = normals(mesh)
    return np.stack([1 - v - w, v, w], axis=2), (d * n).sum(2) / np.linalg.norm(n, axis=1)


def assert_same_surface(mesh: Mesh, new: Mesh, face, bary, vertex, atol=1e-12):
    """New vertices at the points, old ones unchanged; every new face non-degenerate, inside one original face
    (its parent: the one holding its centroid) with the parent's orientation, and the new faces of each
    parent covering exactly its area."""
    n = mesh.n_vertices
    assert vertex.dtype == np.int64 and vertex.shape == (len(face),)
    assert np.array_equal(new.vertices[:n], mesh.vertices)
    np.testing.assert_allclose(new.vertices[vertex], points_of(mesh, face, bary), rtol=0, atol=atol)
    assert not degenerate_faces(new).any()
    assert (np.bincount(new.faces.ravel(), minlength=new.n_vertices) > 0).all()  # every new vertex is used

    centroid_bary, centroid_height = in_faces(mesh, new.vertices[new.faces].mean(axis=1))
    inside = np.where(np.abs(centroid_height) < 1e-12, centroid_bary.min(axis=2), -np.inf)
    parent = inside.argmax(axis=1)
    rows = np.arange(new.n_faces)
    assert (inside[rows, parent] > 1e-9).all()  # centroid strictly inside its parent face
    for k in range(3):  # ... and so are (up to rounding) all three corners
        corner_bary, corner_height = in_faces(mesh, new.vertices[new.faces[:, k]])
        assert (corner_bary[rows, parent].min(axis=1) > -1e-12).all()
        assert (np.abs(corner_height[rows, parent]) < 1e-12).all()
    assert (np.einsum("ij,ij->i", normals(new), normals(mesh)[parent]) > 0).all()
    area, new_area = np.linalg.norm(normals(mesh), axis=1) / 2, np.linalg.norm(normals(new), axis=1) / 2
    np.testing.assert_allclose(np.bincount(parent, new_area, minlength=mesh.n_faces), area, rtol=1e-12, atol=0)
    assert new_area.sum() == pytest.approx(area.sum(), rel=1e-12)


def test_points_inside_faces_split_them_and_keep_the_closed_surface():
    mesh = icosphere(2)
    rng = np.random.default_rng(0)
    face = rng.choice(mesh.n_faces, 60, replace=False)
    bary = rng.dirichlet([2, 2, 2], 60)
    new, vertex = insert_points(mesh, face, bary)
    assert np.array_equal(vertex, mesh.n_vertices + np.arange(60))
    assert new.n_faces == mesh.n_faces + 2 * 60
    assert_same_surface(mesh, new, face, bary, vertex)
    assert closed_manifold_problem(mesh) is None and closed_manifold_problem(new) is None


def test_corner_edge_and_coinciding_points():
    mesh = icosphere(2)
    n, f = mesh.n_vertices, mesh.faces
    # The face across the edge (f[0, 0], f[0, 1]) of face 0, and where those two corners sit in it.
    other = next(g for g in range(1, mesh.n_faces) if {f[0, 0], f[0, 1]} <= set(f[g]))
    i0, i1 = list(f[other]).index(f[0, 0]), list(f[other]).index(f[0, 1])
    across = np.zeros(3)
    across[i0], across[i1] = 0.3, 0.7
    face = np.array([3, 3, 3, 0, other, 5, 5, 5, 7])
    bary = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1],              # the corners of face 3
                     [0.3, 0.7, 0], across,                        # one edge point, given from both sides
                     [0.2, 0.3, 0.5], [0.2, 0.3, 0.5],             # twice the same interior point ...
                     [0.2 + 1e-12, 0.3 - 1e-12, 0.5],              # ... and once more within tol
                     [0.6 + 1e-12, -1e-12, 0.4]])                  # on an edge within tol
    new, vertex = insert_points(mesh, face, bary)
    assert np.array_equal(vertex, [f[3, 0], f[3, 1], f[3, 2], n, n, n + 1, n + 1, n + 1, n + 2])
    assert new.n_vertices == n + 3
    assert new.n_faces == mesh.n_faces + 2 + 2 + 2  # both faces on each split edge are split in two
    assert_same_surface(mesh, new, face, bary, vertex, atol=1e-11)
    assert closed_manifold_problem(new) is None  # a T-junction would leave boundary edges


@pytest.mark.parametrize("seed", range(4))
def test_several_points_in_one_face_and_on_one_edge(seed):
    mesh = icosphere(2)
    rng = np.random.default_rng(seed)
    inner = rng.dirichlet([2, 2, 2], 5)
    on_edge = np.column_stack([np.zeros(3), t := rng.uniform(0.1, 0.9, 3), 1 - t])
    on_sub_edge = (inner[0] + [0, 1, 0]) / 2  # halfway between a point and a corner: on an edge made for it
    order = rng.permutation(9)
    i, j = np.flatnonzero(order == 0)[0], np.flatnonzero(order == 8)[0]
    order[[i, j]] = order[[min(i, j), max(i, j)]]  # the sub-edge point after the point that makes its edge
    bary = np.concatenate([inner, on_edge, [on_sub_edge]])[order]
    face = np.zeros(9, dtype=int)
    new, vertex = insert_points(mesh, face, bary)
    assert len(np.unique(vertex)) == 9 and new.n_vertices == mesh.n_vertices + 9
    # Five splits into three (+2 faces), three edge splits across two faces (+2), one edge split inside (+2).
    assert new.n_faces == mesh.n_faces + 2 * 9
    assert_same_surface(mesh, new, face, bary, vertex)
    assert closed_manifold_problem(new) is None


def test_a_point_on_a_non_manifold_edge_splits_every_face_on_it():
    v = np.array([[0, 0, 0], [0, 0, 1], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]], float)
    mesh = Mesh(v, [[0, 1, 2], [1, 0, 3], [0, 1, 4], [1, 0, 5]])
    new, vertex = insert_points(mesh, [2], [[0.25, 0.75, 0]])
    assert vertex.tolist() == [6] and new.n_faces == 8
    assert_same_surface(mesh, new, [2], [[0.25, 0.75, 0]], vertex)
    counts = edge_face_counts(new.faces)[1]
    assert np.array_equal(counts[counts > 2], [4, 4])


def test_flat_geodesics_between_inserted_points_are_straight_lines():
    mesh = unit_square(21)
    rng = np.random.default_rng(3)
    inner_face = rng.integers(0, mesh.n_faces, 40)
    edge_face = rng.integers(0, mesh.n_faces, 12)  # some of these edges are on the square's boundary
    edge_bary = np.column_stack([t := rng.uniform(0.05, 0.95, 12), 1 - t, np.zeros(12)])[:, rng.permutation(3)]
    face = np.concatenate([inner_face, edge_face, inner_face[:3], [5]])
    bary = np.concatenate([rng.dirichlet([1, 1, 1], 40), edge_bary, rng.dirichlet([1, 1, 1], 3), [[0, 0, 1]]])
    new, vertex = insert_points(mesh, face, bary)
    assert_same_surface(mesh, new, face, bary, vertex)
    edges, counts = edge_face_counts(new.faces)
    assert counts.max() == 2
    boundary = new.vertices[edges[counts == 1]]
    # Boundary edges only along the square (a T-junction would add inner ones): their lengths sum to 4.
    assert np.linalg.norm(boundary[:, 0] - boundary[:, 1], axis=1).sum() == pytest.approx(4.0, abs=1e-12)
    solver, x = geodesic_solver(new), new.vertices[vertex]
    for p in (0, 7, 40, 45, 51, 55):
        np.testing.assert_allclose(solver(vertex[p])[vertex], np.linalg.norm(x - x[p], axis=1), rtol=0, atol=1e-9)


def test_sphere_distances_between_old_vertices_are_unchanged_and_points_lie_in_their_faces():
    mesh = icosphere(3)
    rng = np.random.default_rng(4)
    face = rng.integers(0, mesh.n_faces, 300)
    bary = rng.dirichlet([1, 1, 1], 300)
    bary[:60, 2] = 0
    bary[:60] /= bary[:60].sum(axis=1, keepdims=True)
    new, vertex = insert_points(mesh, face, bary)
    assert closed_manifold_problem(new) is None and not degenerate_faces(new).any()
    before, after = geodesic_solver(mesh), geodesic_solver(new)
    for source in (0, 100, 641):
        np.testing.assert_allclose(after(source)[:mesh.n_vertices], before(source), rtol=1e-9, atol=0)
    x = new.vertices[vertex]
    for p in (0, 1, 100, 200, 299):  # the straight segment to a corner lies in the face: it is the geodesic
        d = after(vertex[p])
        corners = mesh.faces[face[p]]
        chords = np.linalg.norm(mesh.vertices[corners] - x[p], axis=1)
        np.testing.assert_allclose(d[corners], chords, rtol=1e-9, atol=1e-12)
        assert (d[vertex] >= np.linalg.norm(x - x[p], axis=1) - 1e-12).all()  # never shorter than the chord


@pytest.mark.parametrize("face, bary, message", [
    ([0, 1, 80], [[1, 0, 0]] * 3, r"point 2 has face 80, not in 0\.\.79"),
    ([0, -1], [[1, 0, 0]] * 2, r"point 1 has face -1"),
    ([0, 1], [[1, 0, 0], [0.5, 0.7, -0.2]], r"point 1 has barycentric coordinates \[0\.5, 0\.7, -0\.2\]"),
    ([0, 1, 2], [[1, 0, 0], [1, 0, 0], [0.5, 0.4, 0]], r"point 2 has barycentric coordinates \[0\.5, 0\.4, 0\.0\]"),
    ([0], [[np.nan, 0.5, 0.5]], r"point 0 has barycentric coordinates \[nan, 0\.5, 0\.5\]"),
    ([0, 1], [[1, 0, 0]], r"need face \(P,\) integers and bary \(P, 3\); got face \(2,\) int64, bary \(1, 3\)"),
    ([0.0], [[1, 0, 0]], r"got face \(1,\) float64"),
    ([0], [1, 0, 0], r"bary \(3,\)"),
])
def test_bad_points_are_refused_naming_the_point(face, bary, message):
    with pytest.raises(ValueError, match=message) as err:
        insert_points(icosphere(1), np.array(face), np.array(bary, dtype=float))
    assert "\n" not in str(err.value)


def test_no_points_leave_the_mesh_as_it_is():
    mesh = icosphere(1)
    new, vertex = insert_points(mesh, np.zeros(0, dtype=int), np.zeros((0, 3)))
    assert np.array_equal(new.vertices, mesh.vertices) and np.array_equal(new.faces, mesh.faces) and len(vertex) == 0


def test_ten_thousand_points_on_a_real_mesh():
    path = SHARED / "dev" / "odedstein-meshes" / "skull_low_resolution.obj"
    if not path.exists():
        pytest.skip(f"shared mesh {path} not available")
    tm = trimesh.load(str(path), force="mesh", process=False)
    tm.merge_vertices()
    mesh = Mesh(tm.vertices, tm.faces)
    rng = np.random.default_rng(5)
    face = rng.integers(0, mesh.n_faces, 10_000)
    bary = rng.dirichlet([1, 1, 1], 10_000)
    bary[:1000, rng.integers(0, 3)] = 0  # a tenth on edges
    bary[:1000] /= bary[:1000].sum(axis=1, keepdims=True)
    start = time.perf_counter()
    new, vertex = insert_points(mesh, face, bary)
    print(f"\ninsert_points: 10,000 points on {mesh.n_vertices} vertices / {mesh.n_faces} faces: "
          f"{time.perf_counter() - start:.3f} s")
    assert closed_manifold_problem(mesh) is None and closed_manifold_problem(new) is None
    np.testing.assert_allclose(new.vertices[vertex], points_of(mesh, face, bary), rtol=0, atol=1e-12)
    area = np.linalg.norm(normals(mesh), axis=1).sum()
    assert np.linalg.norm(normals(new), axis=1).sum() == pytest.approx(area, rel=1e-12)
