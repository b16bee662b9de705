"""gegnn.fields.cloud_heat against potpourri3d's point-cloud heat solver: the same neighbourhoods, normals, local
triangles and distance fields (to solver rounding), great circles on a sphere, many sources per solve."""
import numpy as np
import pytest
from gegnn_stores import fibonacci_sphere

from geodata.examples import bumpy_sphere
from gegnn.fields.cloud_heat import CloudHeatDistance, local_triangulations

pp3d = pytest.importorskip("potpourri3d")

RTOL = 1e-9  # of the largest distance; measured <= 3e-10 here (cocircular grid), 6e-14 on validation clouds


def random_sphere(n: int, seed: int = 1) -> np.ndarray:
    p = np.random.default_rng(seed).normal(size=(n, 3))
    return p / np.linalg.norm(p, axis=1, keepdims=True)


def grid_plane(m: int) -> np.ndarray:
    """A flat m x m grid: equal distances (neighbour ties), collinear and cocircular neighbours, a boundary."""
    g = np.stack(np.meshgrid(np.arange(m, dtype=float), np.arange(m, dtype=float)), -1).reshape(-1, 2)
    return np.concatenate([g, np.zeros((len(g), 1))], axis=1)


def box_surface() -> np.ndarray:
    """Vertices of a thrice subdivided cube: mirror-symmetric neighbourhoods, where nanoflann's order of
    equally distant neighbours and Eigen's rounding decide normals' signs and cocircular triangles."""
    import trimesh

    return np.unique(np.asarray(trimesh.creation.box().subdivide().subdivide().subdivide().vertices), axis=0)


CLOUDS = {
    "random_sphere": lambda: random_sphere(1200),
    "bumpy": lambda: np.asarray(bumpy_sphere(1500, seed=3).vertices, dtype=np.float64),
    "grid_plane": lambda: grid_plane(30),
    "box": box_surface,
}


@pytest.mark.parametrize("name", list(CLOUDS))
def test_fields_equal_potpourri3d(name):
    p = CLOUDS[name]()
    theirs = pp3d.PointCloudHeatSolver(p)
    ours = CloudHeatDistance(p)
    for s in (0, len(p) // 2, len(p) - 1):
        ref = theirs.compute_distance(s)
        assert np.abs(ours.distance(s) - ref).max() <= RTOL * np.abs(ref).max()


def test_time_step_and_duplicate_points_equal_potpourri3d():
    """t_coef scales the heat step as potpourri3d's does; exact and near duplicates (pushed apart in the
    local triangulations, zero lengths mollified) stay close (measured 4e-9: zero-length edges)."""
    p = CLOUDS["bumpy"]()
    ref = pp3d.PointCloudHeatSolver(p, t_coef=0.5).compute_distance(7)
    assert np.abs(CloudHeatDistance(p, t_coef=0.5).distance(7) - ref).max() <= RTOL * ref.max()
    q = random_sphere(800, seed=3)
    q = np.concatenate([q, q[:40], q[:5] + 1e-12])
    ours, theirs = CloudHeatDistance(q), pp3d.PointCloudHeatSolver(q)
    for s in (0, 800, 840):
        ref = theirs.compute_distance(s)
        assert np.abs(ours.distance(s) - ref).max() <= 1e-7 * ref.max()


@pytest.mark.parametrize("name", ["bumpy", "grid_plane", "box"])
def test_normals_and_local_triangles_equal_potpourri3d(name):
    """The discrete choices behind the fields: each normal's sign (Eigen's SVD; flipping them all moves
    the fields by ~3e-3) and every local triangle, in order (neighbour ties on the grid and the box)."""
    p = CLOUDS[name]()
    normals, faces = local_triangulations(p)
    _, _, their_normals = pp3d.PointCloudHeatSolver(p).get_tangent_frames()
    np.testing.assert_allclose(normals, their_normals, rtol=0, atol=1e-12)
    triangles = pp3d.PointCloudLocalTriangulation(p).get_local_triangulation()
    np.testing.assert_array_equal(faces, triangles[triangles[:, :, 0] >= 0])


def test_unit_sphere_fields_are_near_great_circles():
    p = fibonacci_sphere(1500)
    sources = [0, 700, 1499]
    d = CloudHeatDistance(p).distances(sources)
    great = np.arccos(np.clip(p @ p[sources].T, -1.0, 1.0))
    err = np.abs(d - great)
    assert (d[sources, range(3)] == 0).all()
    assert err.max() < 0.06 * np.pi and err.mean() < 0.015 * np.pi  # measured 0.018 pi and 0.008 pi


def test_many_sources_per_solve_equal_one_at_a_time():
    p = CLOUDS["bumpy"]()
    solver = CloudHeatDistance(p)
    sources = np.array([5, 900, 5, 77, 1200, 3, 8, 9, 10, 11, 12])  # more than one chunk, a repeat
    many = solver.distances(sources)
    assert many.shape == (len(p), len(sources))
    np.testing.assert_array_equal(many[:, 0], many[:, 2])
    for j, s in enumerate(sources):
        one = solver.distance(s)
        assert one[s] == 0 and np.abs(many[:, j] - one).max() <= 1e-12 * one.max()
    two = solver.distances([5, 900])
    np.testing.assert_allclose(two, np.stack([solver.distance(5), solver.distance(900)], 1), rtol=0,
                               atol=1e-12 * two.max())


def test_refuses_bad_clouds():
    with pytest.raises(ValueError):
        CloudHeatDistance(random_sphere(30))          # not more than k = 30 points
    p = random_sphere(200)
    p[3, 0] = np.nan
    with pytest.raises(ValueError):
        CloudHeatDistance(p)
