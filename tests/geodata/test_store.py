"""Store creation when several shards start at the same moment (zarr-python#1435)."""
import multiprocessing

import pytest

from geodata import store


def _create(path):
    try:
        store.create_store(path, {"pairs": 1})
        return "ok"
    except Exception as exc:  # the test reports whatever escaped
        return f"{type(exc).__name__}: {exc}"


def test_simultaneous_shards_all_open_one_store(tmp_path):
    with multiprocessing.get_context("fork").Pool(4) as pool:
        for round_ in range(10):
            path = str(tmp_path / f"s{round_}.zarr")
            assert pool.map(_create, [path] * 4) == ["ok"] * 4
            assert store.list_meshes(path) == {} and store.list_failures(path) == {}


def test_other_parameters_are_refused(tmp_path):
    store.create_store(tmp_path / "s.zarr", {"pairs": 1})
    with pytest.raises(store.StoreError, match="pairs"):
        store.create_store(tmp_path / "s.zarr", {"pairs": 2})
