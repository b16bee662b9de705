"""The field cache (gegnn.fields.cache): keys by mesh content, one entry per (mesh, draw), what a fill
stores is what the spec computes, and an entry is read only once complete."""
import numpy as np
import pytest
from gegnn_stores import ellipsoid, flat_grid, small_config

from gegnn.fields.cache import LANDMARK_DRAWS, FieldCache, FieldSpec, geometry_key
from gegnn.fields.landmarks import landmark_fields
from gegnn.fields.spectral import spectral_codes


def test_the_key_is_the_content_whatever_its_dtype_and_changes_with_any_vertex_or_face():
    v, f = ellipsoid()
    key = geometry_key(v, f)
    assert len(key) == 24 and int(key, 16) >= 0
    assert geometry_key(v.astype(np.float32), f.astype(np.int32)) == key  # a store's dtypes, the same mesh
    assert geometry_key(v.copy(order="F"), f) == key
    moved = v.copy()
    moved[17, 1] += 1e-4
    assert geometry_key(moved, f) != key
    assert geometry_key(v, f[:, [0, 2, 1]]) != key  # other winding
    assert geometry_key(v, f[::-1]) != key  # other face order
    assert geometry_key(v * 2, f) != key


def test_specs_name_their_fields_and_read_a_models_config():
    assert FieldSpec.of(small_config()) is None
    assert FieldSpec.of(small_config(landmarks=64)) == FieldSpec("landmark", 64)
    assert FieldSpec.of(small_config(landmarks=64, points=8)) == FieldSpec("landmark", 64, 8)
    assert FieldSpec.of(small_config(spectral=32)) == FieldSpec("spectral", 32)
    mesh, cloud, codes = FieldSpec("landmark", 64), FieldSpec("landmark", 64, 8), FieldSpec("spectral", 32)
    assert (mesh.name, cloud.name, codes.name) == ("k64", "k64-cloud8-surface2", "spectral32")
    assert (mesh.columns, codes.columns) == (64, 33)  # the spectral codes and their tail scale
    assert (mesh.draws, cloud.draws, codes.draws) == (LANDMARK_DRAWS, LANDMARK_DRAWS, 1) and LANDMARK_DRAWS > 1


def test_a_spec_computes_the_fields_it_names():
    v, f = ellipsoid()
    np.testing.assert_array_equal(FieldSpec("landmark", 12).compute(v, f, seed=3),
                                  landmark_fields(v, f, 12, seed=3).distances)
    np.testing.assert_array_equal(FieldSpec("spectral", 8).compute(v, f, seed=3), spectral_codes(v, f, 8))
    # a query's fields (no seed given) are draw 0, the draw that validation measures
    np.testing.assert_array_equal(FieldSpec("landmark", 12).compute(v, f), landmark_fields(v, f, 12, seed=0).distances)


def test_a_cloud_spec_computes_distances_along_the_points_own_graph():
    """The vertices as a point cloud: each field is the distance from its landmark (mean relative error to
    potpourri3d's mesh heat method 0.15-0.43% per field, 2026-11-26), on the spec's k-nearest-neighbour
    graph: a cluster of 12 points joins the cloud at k = 12 and is a part too small for fields at k = 8."""
    import potpourri3d as pp3d

    v, f = ellipsoid(subdivisions=3)
    cloud = FieldSpec("landmark", 12, 8).compute(v, f, seed=3)
    assert cloud.shape == (len(v), 12) and np.isfinite(cloud).all()
    solver = pp3d.MeshHeatMethodDistanceSolver(v, f)
    for field in cloud.T:
        exact = solver.compute_distance(int(np.argmin(field)))
        far = exact > 0.1 * exact.max()
        assert field.min() == 0 and np.mean(np.abs(field[far] - exact[far]) / exact[far]) < 0.006
    v, f = ellipsoid()
    cluster = np.random.default_rng(0).normal(size=(12, 3)) * 0.05 + [2.5, 0.0, 0.0]
    v = np.concatenate([v, cluster])
    assert (FieldSpec("landmark", 6, 12).compute(v, f)[-12:] > 0).any()
    assert (FieldSpec("landmark", 6, 8).compute(v, f)[-12:] == 0).all()


def test_each_mesh_and_draw_is_its_own_entry(tmp_path):
    cache = FieldCache(tmp_path / "fields.zarr", FieldSpec("landmark", 3))
    a, b = np.arange(12, dtype=np.float32).reshape(4, 3), -np.ones((4, 3), np.float32)
    assert not cache.has("mesh", 0) and cache.get("mesh", 0) is None
    cache.put("mesh", 0, a)
    cache.put("mesh", 1, b)
    cache.put("other", 0, b[:2])
    np.testing.assert_array_equal(cache.get("mesh", 0), a)
    np.testing.assert_array_equal(cache.get("mesh", 1), b)
    np.testing.assert_array_equal(cache.get("other", 0), b[:2])
    assert cache.get("mesh", 2) is None and cache.get("other", 1) is None
    cache.put("mesh", 0, b)  # a recomputed entry replaces the old one
    np.testing.assert_array_equal(cache.get("mesh", 0), b)
    again = FieldCache(tmp_path / "fields.zarr", FieldSpec("landmark", 3))  # another process opening it
    np.testing.assert_array_equal(again.get("mesh", 1), b)
    assert FieldCache(tmp_path / "fields.zarr", FieldSpec("landmark", 4)).get("mesh", 1) is None  # other K
    assert again.root.attrs["gegnn_landmark_cache"] == 1


def test_an_entry_killed_while_written_is_not_read(tmp_path):
    cache = FieldCache(tmp_path / "fields.zarr", FieldSpec("landmark", 3))
    cache.root.create_array(cache._name("mesh", 0), shape=(4, 3), dtype=np.float32)  # "complete" never set
    assert not cache.has("mesh", 0) and cache.get("mesh", 0) is None
    cache.put("mesh", 0, np.ones((4, 3), np.float32))
    assert cache.has("mesh", 0)


@pytest.mark.parametrize("jobs", [1, 2])
def test_a_fill_stores_each_meshs_draws_as_computed(tmp_path, jobs):
    spec = FieldSpec("landmark", 6)
    meshes = {"ellipsoid": ellipsoid(), "grid": flat_grid(9)}
    todo = [(name, v, f, seed) for name, (v, f) in meshes.items() for seed in (0, 2)] + [("grid", *meshes["grid"], 1)]
    cache = FieldCache(tmp_path / "fields.zarr", spec)
    cache.fill(todo, jobs=jobs, progress=False)
    for name, v, f, seed in todo:
        np.testing.assert_array_equal(cache.get(name, seed), spec.compute(v, f, seed))
    assert not np.array_equal(cache.get("grid", 0), cache.get("grid", 1))  # each draw its own landmarks
    assert cache.get("ellipsoid", 1) is None  # nothing stored that was not asked for


def test_a_fill_shows_its_progress_only_when_asked(tmp_path, capsys):
    v, f = flat_grid(9)
    for progress in (False, True):
        FieldCache(tmp_path / f"{progress}.zarr", FieldSpec("landmark", 4)).fill([("grid", v, f, 0)], progress=progress)
        assert ("landmark fields" in capsys.readouterr().err) == progress


def test_a_fill_with_jobs_computes_in_fresh_processes(tmp_path, monkeypatch):
    """jobs > 1: the fields are computed in spawned processes (a fork of a process whose torch threads
    run could hang), none in this one, and stored here as each arrives."""
    spec = FieldSpec("landmark", 4)
    meshes = {"ellipsoid": ellipsoid(), "grid": flat_grid(9)}
    expected = {name: spec.compute(v, f, 1) for name, (v, f) in meshes.items()}
    monkeypatch.setattr(FieldSpec, "compute_draws", lambda *a: pytest.fail("computed in the calling process"))
    cache = FieldCache(tmp_path / "fields.zarr", spec)
    cache.fill([(name, v, f, 1) for name, (v, f) in meshes.items()], jobs=2, progress=False)
    for name, fields in expected.items():
        np.testing.assert_array_equal(cache.get(name, 1), fields)
