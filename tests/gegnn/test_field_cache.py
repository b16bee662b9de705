"""The field cache (gegnn.fields.cache): keys by mesh content, one entry per (mesh, draw), what a fill
stores is what the spec computes (float16 landmark fields), and an entry is read only once complete,
even while other processes fill the same cache."""
import json

import numpy as np
import pytest
from gegnn_stores import ellipsoid, flat_grid, small_config

from gegnn.fields.cache import FIELD_VERSIONS, LANDMARK_DRAWS, FieldCache, FieldSpec
from geodata.store import geometry_key
from gegnn.fields.landmarks import landmark_fields
from gegnn.fields.spectral import spectral_codes


def as_stored(fields):
    """Landmark fields as the cache keeps them (float16), read back as float32."""
    return fields.astype(np.float16).astype(np.float32)


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
    assert (mesh.name, cloud.name, codes.name) == ("k64-rounds16", "k64-cloud8-surface2-v2", "spectral32")
    assert (mesh.columns, codes.columns) == (64, 33)  # the spectral codes and their tail scale
    assert (mesh.draws, cloud.draws, codes.draws) == (LANDMARK_DRAWS, LANDMARK_DRAWS, 1) and LANDMARK_DRAWS > 1
    # fields by virtual source propagation: their own folder, so heat and vsp fields never mix, a mesh's and
    # a cloud's (gegnn.fields.cloud_vsp) alike
    assert FieldSpec.of(small_config(landmarks=64, landmark_fields="vsp")) == FieldSpec("landmark", 64, 0, "vsp")
    assert FieldSpec("landmark", 64, 0, "vsp").name == "k64-rounds16-vsp-v3"
    assert FieldSpec.of(small_config(landmarks=64, points=8, landmark_fields="vsp")) == FieldSpec("landmark", 64, 8, "vsp")
    assert FieldSpec("landmark", 64, 8, "vsp").name == "k64-cloud8-surface2-vsp-v4"
    assert FieldSpec.of(small_config(landmarks=64, landmark_fields="exact")).name == "k64-rounds16-exact"
    assert FieldSpec.of(small_config(landmarks=64, landmark_fields="paths")).name == "k64-rounds16-paths"
    with pytest.raises(ValueError, match="landmark_fields must be one of heat, vsp, exact, paths"):
        small_config(landmarks=64, landmark_fields="geodesic")


def test_fields_of_another_version_of_their_values_are_never_served(tmp_path, monkeypatch):
    """Each kind of field names the version of its values: the vsp fields of 0.3.2 (before the saddle-gate rule,
    and a cloud's unreached points at inf) are not read as today's, and a bump of one kind's version leaves the
    entries of the others served."""
    import gegnn.fields.cache as cache_module

    specs = {"heat": FieldSpec("landmark", 3), "vsp": FieldSpec("landmark", 3, 0, "vsp"),
             "exact": FieldSpec("landmark", 3, 0, "exact"), "paths": FieldSpec("landmark", 3, 0, "paths"),
             "cloud-heat": FieldSpec("landmark", 3, 8), "cloud-vsp": FieldSpec("landmark", 3, 8, "vsp"),
             "spectral": FieldSpec("spectral", 3)}
    assert {spec.values for spec in specs.values()} == set(FIELD_VERSIONS)
    assert (FIELD_VERSIONS["vsp"], FIELD_VERSIONS["cloud-vsp"]) >= (2, 2)  # bumped since 0.3.2's names
    assert "k3-rounds16-vsp" not in [spec.name for spec in specs.values()]
    assert "k3-cloud8-surface2-vsp" not in [spec.name for spec in specs.values()]
    fields = np.arange(16, dtype=np.float32).reshape(4, 4)
    for spec in specs.values():
        assert FieldCache(tmp_path, spec).put("mesh", 0, fields[:, :spec.columns])
    monkeypatch.setitem(cache_module.FIELD_VERSIONS, "vsp", FIELD_VERSIONS["vsp"] + 1)  # the values change
    assert FieldCache(tmp_path, specs["vsp"]).get("mesh", 0) is None
    assert specs["vsp"].name.endswith(f"-v{FIELD_VERSIONS['vsp']}")
    for kind in ("heat", "cloud-heat", "cloud-vsp", "spectral"):
        np.testing.assert_array_equal(FieldCache(tmp_path, specs[kind]).get("mesh", 0), fields[:, :specs[kind].columns])


def test_a_spec_computes_the_fields_it_names():
    v, f = ellipsoid()
    np.testing.assert_array_equal(FieldSpec("landmark", 12).compute(v, f, seed=3),
                                  landmark_fields(v, f, 12, seed=3).distances)
    np.testing.assert_array_equal(FieldSpec("spectral", 8).compute(v, f, seed=3), spectral_codes(v, f, 8))
    np.testing.assert_array_equal(FieldSpec("landmark", 12, 0, "vsp").compute(v, f, seed=3),
                                  landmark_fields(v, f, 12, seed=3, fields="vsp").distances)
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


def test_each_mesh_and_draw_is_its_own_entry_published_once(tmp_path):
    cache = FieldCache(tmp_path / "fields", FieldSpec("landmark", 3))
    a, b = np.arange(12, dtype=np.float32).reshape(4, 3), -np.ones((4, 3), np.float32)  # exact in float16
    assert not cache.has("mesh", 0) and cache.get("mesh", 0) is None
    assert cache.put("mesh", 0, a) and cache.put("mesh", 1, b) and cache.put("other", 0, b[:2])
    np.testing.assert_array_equal(cache.get("mesh", 0), a)
    np.testing.assert_array_equal(cache.get("mesh", 1), b)
    np.testing.assert_array_equal(cache.get("other", 0), b[:2])
    assert cache.get("mesh", 2) is None and cache.get("other", 1) is None
    assert not cache.put("mesh", 0, b)  # a published entry is never rewritten: the first stays
    np.testing.assert_array_equal(cache.get("mesh", 0), a)
    again = FieldCache(tmp_path / "fields", FieldSpec("landmark", 3))  # another process opening it
    np.testing.assert_array_equal(again.get("mesh", 1), b)
    assert FieldCache(tmp_path / "fields", FieldSpec("landmark", 4)).get("mesh", 1) is None  # other K
    assert json.loads((tmp_path / "fields" / "format.json").read_text()) == {"gegnn_field_cache": 2}
    # one plain .npy file an entry, no temporary file left: the layout the module's docstring gives
    files = sorted(str(f.relative_to(tmp_path / "fields")) for f in (tmp_path / "fields").rglob("*") if f.is_file())
    assert files == ["format.json", "k3-rounds16/me/mesh-0.npy", "k3-rounds16/me/mesh-1.npy",
                     "k3-rounds16/ot/other-0.npy"]
    assert np.load(tmp_path / "fields" / "k3-rounds16" / "me" / "mesh-1.npy", allow_pickle=False).dtype == np.float16
    assert cache.get("mesh", 0).dtype == np.float32


def test_landmark_fields_read_back_within_float16_rounding_and_codes_exactly(tmp_path):
    v, f = ellipsoid()
    landmark, spectral = FieldSpec("landmark", 12), FieldSpec("spectral", 8)
    fields, codes = landmark.compute(v, f, seed=1), spectral.compute(v, f)
    FieldCache(tmp_path / "c", landmark).put("e", 1, fields)
    FieldCache(tmp_path / "c", spectral).put("e", 0, codes)
    back = FieldCache(tmp_path / "c", landmark).get("e", 1)
    assert not np.array_equal(back, fields)  # rounded,
    assert np.all(np.abs(back - fields) <= 2.0 ** -11 * np.abs(fields) + 2.0 ** -25)  # by half an ulp at most
    np.testing.assert_array_equal(FieldCache(tmp_path / "c", spectral).get("e", 0), codes)


def test_an_entry_killed_while_written_is_not_read(tmp_path):
    cache = FieldCache(tmp_path / "fields", FieldSpec("landmark", 3))
    entry = cache.entry("mesh", 0)
    entry.parent.mkdir(parents=True)
    (entry.parent / f".{entry.name}.host.123.tmp").write_bytes(b"\x93NUMPY")  # a killed writer's half file
    assert not cache.has("mesh", 0) and cache.get("mesh", 0) is None
    assert cache.put("mesh", 0, np.ones((4, 3), np.float32))
    assert cache.has("mesh", 0)


def test_a_field_cache_of_the_old_zarr_format_is_refused_by_name(tmp_path):
    import zarr

    zarr.open_group(str(tmp_path / "old"), mode="w").attrs["gegnn_landmark_cache"] = 1
    with pytest.raises(ValueError, match="old: a field cache of format 1 .zarr.*delete it or give another --field"):
        FieldCache(tmp_path / "old", FieldSpec("landmark", 3)).has("mesh", 0)


def _fill_again_and_again(path, rounds):
    """A run filling the cache: every entry, ``rounds`` times over (as two runs or ranks may compute one)."""
    cache = FieldCache(path, FieldSpec("landmark", 64))
    for _ in range(rounds):
        for key, seed in CONCURRENT_ENTRIES:
            cache.put(key, seed, np.full((4000, 64), _entry_value(key, seed), np.float32))


CONCURRENT_ENTRIES = [(f"{k:02x}mesh", seed) for k in range(24) for seed in range(2)]


def _entry_value(key, seed):
    return 1 + int(key[:2], 16) * 2 + seed  # exact in float16, never 0 (the value of a chunk not written)


def test_concurrent_fills_and_reads_never_see_an_incomplete_entry(tmp_path):
    """Two processes fill one cache (each entry many times over, as concurrent runs would) while this one
    reads it: an entry that exists is whole, every time. The zarr cache of format 1 failed this: an entry
    rewritten with overwrite=True read as zeros between its `complete` check and its data."""
    import multiprocessing

    spawn = multiprocessing.get_context("spawn")
    path = tmp_path / "shared"
    FieldCache(path, FieldSpec("landmark", 64)).create()
    writers = [spawn.Process(target=_fill_again_and_again, args=(path, 6)) for _ in range(2)]
    for w in writers:
        w.start()
    cache, reads, bad = FieldCache(path, FieldSpec("landmark", 64)), 0, []
    while any(w.is_alive() for w in writers) or reads == 0:
        for key, seed in CONCURRENT_ENTRIES:
            if cache.has(key, seed):
                fields = cache.get(key, seed)
                reads += 1
                if fields is None or fields.shape != (4000, 64) or not (fields == _entry_value(key, seed)).all():
                    bad.append((key, seed))
    for w in writers:
        w.join()
    assert all(w.exitcode == 0 for w in writers)
    assert reads >= len(CONCURRENT_ENTRIES) and bad == []
    assert all((cache.get(k, s) == _entry_value(k, s)).all() for k, s in CONCURRENT_ENTRIES)
    assert not list(path.rglob("*.tmp"))  # every writer's temporary file gone


@pytest.mark.parametrize("jobs", [1, 2])
def test_a_fill_stores_each_meshs_draws_as_computed(tmp_path, jobs):
    spec = FieldSpec("landmark", 6)
    meshes = {"ellipsoid": ellipsoid(), "grid": flat_grid(9)}
    todo = [(name, v, f, seed) for name, (v, f) in meshes.items() for seed in (0, 2)] + [("grid", *meshes["grid"], 1)]
    cache = FieldCache(tmp_path / "fields", spec)
    assert cache.fill(todo, jobs=jobs, progress=False) == len(todo)  # each published by this fill
    for name, v, f, seed in todo:
        np.testing.assert_array_equal(cache.get(name, seed), as_stored(spec.compute(v, f, seed)))
    assert not np.array_equal(cache.get("grid", 0), cache.get("grid", 1))  # each draw its own landmarks
    assert cache.get("ellipsoid", 1) is None  # nothing stored that was not asked for
    assert cache.fill(todo[:2], jobs=jobs, progress=False) == 0  # computed again, published before: kept


def test_a_fill_shows_its_progress_only_when_asked(tmp_path, capsys):
    v, f = flat_grid(9)
    for progress in (False, True):
        FieldCache(tmp_path / f"{progress}", FieldSpec("landmark", 4)).fill([("grid", v, f, 0)], progress=progress)
        assert ("landmark fields" in capsys.readouterr().err) == progress


def test_a_fill_with_jobs_computes_in_fresh_processes(tmp_path, monkeypatch):
    """jobs > 1: the fields are computed in spawned processes (a fork of a process whose torch threads
    run could hang), none in this one, and stored here as each arrives."""
    spec = FieldSpec("landmark", 4)
    meshes = {"ellipsoid": ellipsoid(), "grid": flat_grid(9)}
    expected = {name: as_stored(spec.compute(v, f, 1)) for name, (v, f) in meshes.items()}
    monkeypatch.setattr(FieldSpec, "compute_draws", lambda *a: pytest.fail("computed in the calling process"))
    cache = FieldCache(tmp_path / "fields", spec)
    cache.fill([(name, v, f, 1) for name, (v, f) in meshes.items()], jobs=2, progress=False)
    for name, fields in expected.items():
        np.testing.assert_array_equal(cache.get(name, 1), fields)


def test_a_fills_estimate_is_the_bytes_it_writes_and_seconds_scaled_by_vertices(tmp_path):
    from gegnn.fields.cache import estimate_fill, readable

    spec = FieldSpec("landmark", 6)
    (ve, fe), (vg, fg) = ellipsoid(), flat_grid(9)
    todo = [("e", ve, fe, 0), ("e", ve, fe, 1), ("g", vg, fg, 0)]
    entries, nbytes, seconds = estimate_fill(todo, spec, 0.5, len(ve))
    FieldCache(tmp_path / "c", spec).fill(todo, progress=False)
    written = sum(f.stat().st_size for f in (tmp_path / "c" / spec.name).rglob("*.npy"))
    assert entries == 3 and nbytes == written == 3 * 128 + (2 * len(ve) + len(vg)) * 6 * 2  # float16
    assert seconds == 0.5 * (2 * len(ve) + len(vg)) / len(ve)
    codes = FieldSpec("spectral", 8)
    assert estimate_fill(todo[:1], codes, 0.1, len(ve))[1] == 128 + len(ve) * 9 * 4  # float32, m + 1 columns
    assert [readable(999, "B"), readable(2.5e9, "B"), readable(59, "s"), readable(90, "s"), readable(7200, "s")] == \
        ["999 B", "2.5 GB", "59 s", "1.5 min", "2 h"]
