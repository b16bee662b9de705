"""The store: creation when several shards start at the same moment (zarr-python#1435), publishing meshes,
failure records, ledgers, the format check."""
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
    """A store keeps one setting: another is refused, naming each value that differs (and only those) as its
    option, and the parameters an older store lacks or a newer one has; words an older geodata kept among
    them (0.3.2's and 0.3.3's ``geodesic_error`` sentence) do not identify a store; the shared parents exist
    before any worker writes; a foreign zarr group is not taken over."""
    out = tmp_path / "s.zarr"
    store.create_store(out, {"pairs": 1, "seed": 0})
    assert (out / "meshes").is_dir() and (out / "failed").is_dir() and (out / "sources").is_dir()
    with pytest.raises(store.StoreError, match=r"was made with --pairs 1, this run asks for 2: use another OUT"):
        store.create_store(out, {"pairs": 2, "seed": 0})
    with pytest.raises(store.StoreError, match=r"was made by an older geodata, which did not record "
                                               r"--geodesic-backend \(this run: vtp\)"):
        store.create_store(out, {"pairs": 1, "seed": 0, "geodesic_backend": "vtp"})
    with pytest.raises(store.StoreError, match=r"was made with --seed 0, which this geodata does not know"):
        store.create_store(out, {"pairs": 1})
    old = tmp_path / "old-vsp.zarr"  # as geodata 0.3.2 made it: a sentence among the values
    store.create_store(old, {"pairs": 1, "geodesic_backend": "vsp"})
    root = zarr.open_group(old, mode="r+")
    root.attrs["params"] = {**root.attrs["params"], "geodesic_error": "approximate: virtual source propagation"}
    store.create_store(old, {"pairs": 1, "geodesic_backend": "vsp"})  # resumed
    with pytest.raises(store.StoreError) as refused:
        store.create_store(old, {"pairs": 1, "geodesic_backend": "vtp"})
    assert str(refused.value) == (f"{old} was made with --geodesic-backend vsp, this run asks for vtp: use another "
                                  f"OUT for other parameters")
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


def test_failures_are_recorded_replaced_and_cleared(tmp_path):
    """A retry replaces a mesh's failure record (the second reason is read back) and clears it; clearing
    what is not there changes nothing; a shard's look-up by name reads only the names it asks for."""
    out = tmp_path / "s.zarr"
    store.create_store(out, {"pairs": 1})
    store.record_failure(out, "a", "a.obj", "load", "first reason")
    store.record_failure(out, "a", "a.obj", "remesh", "second reason")
    store.record_failure(out, "b", "b.obj", "load", "kept")
    store.record_failure(out, "c.biharmonic", "c.obj", "biharmonic", "singular")
    assert store.list_failures(out)["a"] == {"source": "a.obj", "stage": "remesh", "error": "second reason"}
    store.clear_failure(out, "a")
    store.clear_failure(out, "never")
    assert list(store.list_failures(out)) == ["b", "c.biharmonic"]
    assert list(store.list_failures(out, {"c.biharmonic", "never"})) == ["c.biharmonic"]


def test_a_mesh_is_published_whole_once_and_read_back(tmp_path):
    """write_mesh publishes one zip per mesh (and per subgroup) that plain zarr reads back, arrays and
    attributes with the commit mark; a second writer of the same mesh changes nothing and is told so; a
    listing sees published meshes with their subgroups and skips writers' temporary files."""
    out = tmp_path / "s.zarr"
    store.create_store(out, {"pairs": 1})
    v = np.arange(12, dtype=np.float32).reshape(4, 3)
    assert store.write_mesh(out, "m-1", {"vertices": v, "geodesic/pairs": np.ones((5, 2), np.uint32)}, {"source": "m.obj"})
    assert not store.write_mesh(out, "m-1", {"vertices": v + 1}, {"source": "copy/m.obj"})
    assert store.write_mesh(out, "m-1", {"pairs": np.zeros((2, 2), np.uint32)}, {"seed": 3}, "biharmonic")
    assert store.write_mesh(out, "n-2", {"vertices": v}, {"source": "n.obj"})
    (out / "meshes" / ".o-3.zip.host.7.tmp").write_bytes(b"PK")
    assert store.list_meshes(out) == {"m-1": {"biharmonic"}, "n-2": set()}
    assert store.temporary_files(out) == [".o-3.zip.host.7.tmp"]
    assert sorted(p.name for p in (out / "meshes").iterdir()) == [
        ".o-3.zip.host.7.tmp", "m-1.biharmonic.zip", "m-1.zip", "n-2.zip"]  # one file per mesh and subgroup
    group = zarr.open_group(zarr.storage.ZipStore(out / "meshes" / "m-1.zip", mode="r"), mode="r")
    np.testing.assert_array_equal(group["vertices"][:], v)
    assert group["geodesic/pairs"].shape == (5, 2) and dict(group.attrs) == {"source": "m.obj", "status": "ok"}
    assert store.mesh_attrs(out, "m-1", "biharmonic") == {"seed": 3, "status": "ok"}
    assert store.mesh_attrs(out, "never") is None
    with pytest.raises(FileNotFoundError, match="never.zip: no such mesh"):
        with store.read_mesh(out, "never"):
            pass


def test_a_store_of_format_1_is_refused_with_the_way_out(tmp_path):
    old = tmp_path / "old.zarr"
    zarr.open_group(old, mode="w", attributes={"geodata_format": 1, "params": {}})
    with pytest.raises(store.StoreError, match=r"format 1 \(one folder per mesh\).*geodata upgrade"):
        store.open_store(old)
    with pytest.raises(store.StoreError, match="format 1"):
        store.create_store(old, {})


def test_ledgers_merge_newest_first(tmp_path):
    """Two runs over one input root (a sharded one, then a whole one): each file's newest entry counts."""
    out = tmp_path / "s.zarr"
    store.create_store(out, {})
    store.write_ledger(out, "b", {"root": "/r", "written": 2.0, "inputs": {"x.obj": {"mesh_id": "new"}}})
    store.write_ledger(out, "a", {"root": "/r", "written": 1.0, "inputs": {"x.obj": {"mesh_id": "old"},
                                                                          "y.obj": {"mesh_id": "y"}}})
    assert store.read_ledgers(out) == {("/r", "x.obj"): {"mesh_id": "new"}, ("/r", "y.obj"): {"mesh_id": "y"}}
