"""Point-cloud fields by virtual sources on the tufted cover of the local triangles (gegnn.fields.cloud_vsp).

Known answers: a mesh's own cover gives the mesh's fields (a flat grid: Euclidean); a plane with fins
(edges of three and four triangles, which the mesh solver refuses) stays Euclidean on the plane; a sphere's
cloud is within a measured error of the great circles, several times nearer than the heat method's.
Then: a point the cover reaches only by a detour gets its neighbours' distance plus the step; the same
fields for any thread count; twins that do not glue back refused.
"""
import numpy as np
import pytest
from flat_meshes import grid
from gegnn_stores import fibonacci_sphere

from gegnn.fields.cloud_heat import local_triangulations
from gegnn.fields.cloud_vsp import CloudVirtualSources, cover_mesh, relax_along_edges
from gegnn.fields.pointcloud import cloud_landmark_fields, surface_neighbors
from geodata.approximate_geodesic import ApproximateGeodesicSolver, approximate_geodesic_distances


def test_a_meshs_own_cover_gives_its_fields_and_a_flat_grid_stays_euclidean():
    mesh = grid(20, jitter=0.3)
    v, f = mesh.vertices, mesh.faces
    faces, twins = cover_mesh(v, f)
    assert len(faces) == 2 * len(f) and (twins[twins] == np.arange(len(twins))).all()
    sources = [0, 211, len(v) - 1]
    d = ApproximateGeodesicSolver(v, faces, twins=twins).distances(sources, threads=1)
    np.testing.assert_allclose(d, approximate_geodesic_distances(v, f, sources, threads=1), rtol=1e-12)
    np.testing.assert_allclose(d, np.linalg.norm(v[None] - v[sources][:, None], axis=-1), rtol=1e-12, atol=1e-14)


def test_fins_on_a_plane_leave_it_euclidean():
    """Edges of three and four triangles (fins standing on the plane's diagonals): the mesh solver refuses
    them, the cover takes them, and paths on the plane stay straight."""
    mesh = grid(12)
    v, f = mesh.vertices, mesh.faces
    n = len(v)
    tips = np.column_stack([v[f[:6, 1], :2], np.full(6, 0.3)])
    fins = np.column_stack([f[:6, 1], f[:6, 2], n + np.arange(6)])
    fins = np.vstack([fins, fins[:2, [1, 0, 2]] + [0, 0, 4]])  # a second fin on two of the edges: four faces
    v2, f2 = np.vstack([v, tips]), np.vstack([f, fins])
    with pytest.raises(ValueError, match="non-manifold edges"):
        ApproximateGeodesicSolver(v2, f2)
    faces, twins = cover_mesh(v2, f2)
    flat = np.zeros(len(v2))  # the plane's angle excess; the fins' corners are none of it (a cloud: own_excess)
    d = ApproximateGeodesicSolver(v2, faces, twins=twins, excess=flat).distances([0, 77], threads=1)
    np.testing.assert_allclose(d[:, :n], np.linalg.norm(v[None] - v[[0, 77]][:, None], axis=-1), rtol=1e-9)
    assert np.isfinite(d).all()


def test_a_spheres_cloud_is_near_the_great_circles():
    p = fibonacci_sphere(2000)
    part = np.zeros(len(p), dtype=np.int64)
    errors = {}
    for solver in ("heat", "vsp"):
        lf = cloud_landmark_fields(p, part, 8, seed=3, solver=solver)
        exact = np.arccos(np.clip(p @ p[lf.landmarks[0]].T, -1, 1))
        far = exact > 0.2
        errors[solver] = np.mean(np.abs(lf.distances[far] - exact[far]) / exact[far])
    assert errors["vsp"] < 0.003 and errors["vsp"] < errors["heat"] / 4  # measured 0.095% and 1.21%


def test_threads_change_nothing_and_bad_twins_are_refused():
    p = fibonacci_sphere(800)
    triangles = local_triangulations(p, surface_neighbors(p))[1]
    solver = CloudVirtualSources(p, triangles)
    np.testing.assert_array_equal(solver.distances([0, 5, 99, 400], threads=1),
                                  solver.distances([0, 5, 99, 400], threads=2))
    mesh = grid(5)
    faces, twins = cover_mesh(mesh.vertices, mesh.faces)
    bad = twins.copy()
    bad[0], bad[1] = bad[1], bad[0]
    with pytest.raises(ValueError, match="twins"):
        ApproximateGeodesicSolver(mesh.vertices, faces, twins=bad)


def test_a_point_reached_by_a_detour_gets_its_neighbours_distance_plus_the_step():
    points = np.column_stack([np.arange(6.0), np.zeros(6), np.zeros(6)])
    edges = np.column_stack([np.arange(5), np.arange(1, 6)])
    fields = np.column_stack([np.arange(6.0), 5 - np.arange(6.0)])
    fields[3, 0] = 10.0  # a detour
    fields[4, 1] = 0.5   # a shortcut (a bridge): kept, and its neighbours follow it
    out = relax_along_edges(fields.copy(), points, edges)
    np.testing.assert_array_equal(out[:, 0], np.arange(6.0))
    np.testing.assert_array_equal(out[:, 1], [4.5, 3.5, 2.5, 1.5, 0.5, 0.0])
