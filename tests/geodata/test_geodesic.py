"""Exact geodesics against known answers: flat grid = Euclidean, sphere -> great circles, gdist = libigl."""
import numpy as np
import pytest
import trimesh

from geodata.geodesic import BACKENDS, PATHS_TOLERANCE, exact_geodesic_distances, exact_geodesic_pairs
from geodata.mesh import Mesh, MeshError


def flat_grid(n=21, jitter=0.0, seed=0):
    x, y = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n), indexing="ij")
    v = np.stack([x.ravel(), y.ravel(), np.zeros(n * n)], axis=1)
    rng = np.random.default_rng(seed)
    inner = (v[:, 0] > 0) & (v[:, 0] < 1) & (v[:, 1] > 0) & (v[:, 1] < 1)
    v[inner, :2] += rng.uniform(-jitter, jitter, (inner.sum(), 2)) / n
    i = np.arange(n - 1)[:, None] * n + np.arange(n - 1)[None, :]
    i = i.ravel()
    f = np.concatenate([np.stack([i, i + n, i + 1], 1), np.stack([i + 1, i + n, i + n + 1], 1)])
    return Mesh(v, f)


@pytest.mark.parametrize("backend", BACKENDS)
def test_flat_grid_distances_are_euclidean(backend):
    """Every backend but paths is exact on a convex planar domain; paths' values are real paths' lengths, never
    below the straight line, within its tolerance on average and a few times it at the worst vertex."""
    mesh = flat_grid(jitter=0.3)  # irregular triangles: still a convex planar domain
    for source in (0, 220, 440):
        d = exact_geodesic_distances(mesh, source, backend)
        euclid = np.linalg.norm(mesh.vertices - mesh.vertices[source], axis=1)
        if backend != "paths":
            np.testing.assert_allclose(d, euclid, atol=1e-12)
            continue
        far = euclid > 0
        ratio = d[far] / euclid[far] - 1
        assert ratio.min() > -1e-12 and ratio.mean() < PATHS_TOLERANCE and ratio.max() < 5 * PATHS_TOLERANCE
        assert d[source] == 0 and ratio.max() > 0  # pruned: not the exact solver under another name


def test_sphere_distances_approach_great_circles():
    errors = []
    for level in (2, 3, 4):
        s = trimesh.creation.icosphere(level)
        mesh = Mesh(s.vertices, s.faces)
        d = exact_geodesic_distances(mesh, 0, "gdist")
        cosines = np.clip(mesh.vertices @ mesh.vertices[0], -1, 1)
        great = np.arccos(cosines)
        far = great > 0.1
        errors.append(np.abs(d[far] - great[far]).max() / np.pi)
    assert errors[0] > errors[1] > errors[2]
    assert errors[2] < 0.01


def test_gdist_equals_libigl_on_an_irregular_closed_mesh():
    s = trimesh.creation.icosphere(3)
    rng = np.random.default_rng(1)
    v = s.vertices * (1 + 0.2 * rng.random((len(s.vertices), 1)))  # bumpy, irregular triangles
    mesh = Mesh(v * [1.0, 2.0, 0.5], s.faces)
    for source in (0, 17, 400):
        a = exact_geodesic_distances(mesh, source, "gdist")
        b = exact_geodesic_distances(mesh, source, "libigl")
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-9)


def test_pairs_are_sources_times_other_vertices_within_components():
    s = trimesh.creation.icosphere(2)
    two = trimesh.util.concatenate([s, s.copy().apply_translation([3, 0, 0])])
    mesh = Mesh(two.vertices, two.faces)
    pairs, dist, skipped = exact_geodesic_pairs(mesh, 1000, np.random.default_rng(0))
    assert pairs.dtype == np.uint32 and dist.dtype == np.float32 and len(pairs) >= 1000 and len(skipped) == 0
    n = len(s.vertices)
    assert ((pairs[:, 0] < n) == (pairs[:, 1] < n)).all()  # never across components
    assert (pairs[:, 0] != pairs[:, 1]).all() and (dist > 0).all() and np.isfinite(dist).all()
    for source in np.unique(pairs[:, 0]):  # every other vertex of the component, once
        assert len(np.unique(pairs[pairs[:, 0] == source, 1])) == n - 1
    again = exact_geodesic_pairs(mesh, 1000, np.random.default_rng(0))
    assert np.array_equal(again[0], pairs) and np.array_equal(again[1], dist)


def test_non_manifold_mesh_is_refused_before_native_code():
    # Four triangles on one edge: Kirsanov's code segfaults on this; we must raise instead.
    v = np.array([[0, 0, 0], [0, 0, 1], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]], float)
    f = np.array([[0, 1, 2], [0, 1, 3], [0, 1, 4], [0, 1, 5]])
    with pytest.raises(MeshError, match="boundary edges|non-manifold"):
        exact_geodesic_pairs(Mesh(v, f), 10, np.random.default_rng(0))


def test_a_source_that_leaves_a_vertex_unreached_is_replaced(monkeypatch):
    """Kirsanov's code rarely leaves one vertex unreached from one source (libigl#1013): skip that source."""
    import geodata.geodesic as geodesic

    s = trimesh.creation.icosphere(2)
    mesh = Mesh(s.vertices, s.faces)
    clean, _, _ = exact_geodesic_pairs(mesh, 1000, np.random.default_rng(0))
    bad_source = int(clean[0, 0])
    real = geodesic.geodesic_solver

    def flaky(mesh, backend):
        solve = real(mesh, backend)

        def distances(source):
            d = solve(source)
            if source == bad_source:
                d[(source + 5) % len(d)] = np.inf
            return d
        return distances

    monkeypatch.setattr(geodesic, "geodesic_solver", flaky)
    pairs, dist, skipped = exact_geodesic_pairs(mesh, 1000, np.random.default_rng(0))
    assert skipped.tolist() == [bad_source] and bad_source not in pairs[:, 0]
    assert len(pairs) >= 1000 and np.isfinite(dist).all()
    kept = np.isin(clean[:, 0], pairs[:, 0])  # the other sources are the same, with the same values
    assert np.array_equal(clean[kept], pairs[: kept.sum()])


def test_the_approximate_backends_speed_is_stated_one_way():
    """The module's docstring and `geodata prepare --help` state the same speed-ups of paths and vsp over vtp (the
    docstring said "an order of magnitude", the help 6-8x, as docs/benchmarks.md measured)."""
    import re

    import geodata.geodesic
    from click.testing import CliRunner
    from geodata.cli import main

    text = " ".join(CliRunner().invoke(main, ["prepare", "--help"], terminal_width=1000).output.split())
    stated = re.findall(r"(\S+x) faster than vtp", text)
    assert stated and set(stated) == set(re.findall(r"(\S+x) faster than\s+vtp", geodata.geodesic.__doc__))
