"""Store creation when several shards start at the same moment (zarr-python#1435)."""
import multiprocessing

import numpy as np
import pytest
import zarr

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
    """A store keeps one setting: another is refused, naming the stored values that differ (and only
    those); the shared parents exist before any worker writes; a foreign zarr group is not taken over."""
    out = tmp_path / "s.zarr"
    store.create_store(out, {"pairs": 1, "seed": 0})
    assert (out / "meshes").is_dir() and (out / "failed").is_dir()
    with pytest.raises(store.StoreError, match=r"was made with \{'pairs': 1\}; use another OUT"):
        store.create_store(out, {"pairs": 2, "seed": 0})
    other = tmp_path / "other.zarr"
    zarr.open_group(other, mode="w", attributes={"made_by": "someone else"})
    with pytest.raises(store.StoreError, match=f"{other} is not a geodata store"):
        store.create_store(other, {"pairs": 1})


def test_opening_what_is_not_a_store_says_so_and_writes_nothing(tmp_path):
    """`geodata info DIR` on a folder that holds no store, or another zarr group: the path and the reason,
    and the folder left as it was (no group created by looking)."""
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(store.StoreError, match=f"{empty}: no geodata store here"):
        store.open_store(empty)
    assert list(empty.iterdir()) == []
    other = tmp_path / "other.zarr"
    zarr.open_group(other, mode="w", attributes={"made_by": "someone else"})
    with pytest.raises(store.StoreError, match=f"{other} is not a geodata store"):
        store.open_store(other)


def test_failures_and_meshes_are_recorded_replaced_and_removed(tmp_path, monkeypatch):
    """A retry replaces a mesh's failure record (the second reason is read back), clears it, and removes a
    half-written mesh group; clearing or removing what is not there changes nothing; committing a group that
    was never written is an error, not an empty committed mesh."""
    out = tmp_path / "s.zarr"
    store.create_store(out, {"pairs": 1})
    store.record_failure(out, "a", "a.obj", "load", "first reason")
    store.record_failure(out, "a", "a.obj", "remesh", "second reason")
    store.record_failure(out, "b", "b.obj", "load", "kept")
    assert store.list_failures(out)["a"] == {"source": "a.obj", "stage": "remesh", "error": "second reason"}
    store.clear_failure(out, "a")
    store.clear_failure(out, "never")
    assert list(store.list_failures(out)) == ["b"]
    store.write_group(out, "meshes/m", {"vertices": np.zeros((3, 3))}, {"source": "m.obj"})
    store.write_group(out, "meshes/n", {"vertices": np.ones((3, 3))}, {"source": "n.obj"})
    store.commit(out, "meshes/n")
    assert store.mesh_status(out, "m") is None and store.mesh_status(out, "n") == "ok"
    store.remove_mesh(out, "m")
    store.remove_mesh(out, "never")
    assert list(store.list_meshes(out)) == ["n"]
    with pytest.raises(FileNotFoundError):
        store.commit(out, "meshes/never")
    assert list(store.list_meshes(out)) == ["n"]
    local = store.list_meshes(out), store.list_failures(out)

    class Remote:  # Path(out) / parent of an s3:// store: no local folder, so zarr lists the groups
        def __init__(self, *parts):
            pass

        def __truediv__(self, other):
            return self

        def is_dir(self):
            return False
    monkeypatch.setattr(store, "Path", Remote)
    assert (store.list_meshes(out), store.list_failures(out)) == local
