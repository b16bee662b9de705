"""Nothing stale, nothing lost, no wrong answer (issue 56): a damaged zip is found and redone, an input edited
in place is hashed again, a mesh no input maps to any more is an orphan left out of training, an upgraded store
is extended without duplicates, and `geodata verify` names every such entry."""
import csv
import io
import os

import numpy as np
import pytest
import trimesh
from click.testing import CliRunner

from geodata import store
from geodata.cli import main
from storetools import ball_obj

ARGS = ["--pairs", "300", "--target-vertices", "150"]  # small: a mesh in ~0.5 s


def run(*args, code=0):
    result = CliRunner().invoke(main, [str(a) for a in args])
    assert result.exit_code == code, result.output
    return result


def prepared(tmp_path, files=None):
    raw, out = tmp_path / "raw", tmp_path / "out.zarr"
    raw.mkdir()
    for name, data in (files or {"ball.obj": ball_obj()}).items():
        (raw / name).write_bytes(data)
    run("prepare", raw, out, *ARGS)
    return raw, out


def csv_rows(out) -> list[dict]:
    return list(csv.DictReader(io.StringIO(run("info", out, "--csv", "-").output)))


@pytest.mark.parametrize("damage", ["empty", "truncated", "no group"])
def test_a_damaged_zip_is_reported_by_name_and_redone(tmp_path, damage):
    """A node crash can publish an empty or partial zip: prepare --check, info and readers name it, a rerun
    redoes it."""
    raw, out = prepared(tmp_path)
    (mesh_id,) = store.list_meshes(out)
    path = store.mesh_file(out, mesh_id)
    good = path.read_bytes()
    path.unlink()
    if damage == "empty":
        path.write_bytes(b"")
    elif damage == "truncated":
        path.write_bytes(good[:len(good) // 2])
    else:
        import zipfile

        with zipfile.ZipFile(path, "w") as z:
            z.writestr("vertices/zarr.json", "{}")
    check = run("prepare", raw, out, *ARGS, "--check", code=3)
    assert "1 damaged" in check.output
    info = run("info", out)
    assert f"damaged: {mesh_id}" in info.output and "rerun" in info.output
    assert [r["fate"] for r in csv_rows(out)] == ["damaged"]
    with pytest.raises(store.DamagedMeshError, match=mesh_id):
        with store.read_mesh(out, mesh_id):
            pass
    with pytest.raises(store.DamagedMeshError, match=mesh_id):
        store.mesh_attrs(out, mesh_id)
    run("prepare", raw, out, *ARGS)
    assert store.mesh_attrs(out, mesh_id)["status"] == "ok"
    assert [r["fate"] for r in csv_rows(out)] == ["ok"]
    run("prepare", raw, out, *ARGS, "--check")


def test_a_zip_is_on_disk_before_it_is_published(tmp_path, monkeypatch):
    """write_mesh flushes the zip to disk (fsync) before linking it: a crash then publishes nothing or all."""
    events, real_fsync, real_link = [], os.fsync, os.link
    monkeypatch.setattr(os, "fsync", lambda fd: events.append(("fsync", os.readlink(f"/proc/self/fd/{fd}")))
                        or real_fsync(fd))
    monkeypatch.setattr(os, "link", lambda src, dst: events.append(("link", str(src))) or real_link(src, dst))
    store.create_store(tmp_path, {})
    store.write_mesh(tmp_path, "m", {"vertices": np.zeros((3, 3), np.float32)}, {})
    link = events.index(next(e for e in events if e[0] == "link"))
    assert ("fsync", events[link][1]) in events[:link]


def test_a_damaged_subgroup_zip_is_to_do_again(tmp_path):
    from geodata.subgroup import pending

    store.create_store(tmp_path, {})
    for mesh_id in ("a", "b"):
        store.write_mesh(tmp_path, mesh_id, {"vertices": np.zeros((3, 3), np.float32)}, {})
        store.write_mesh(tmp_path, mesh_id, {"pairs": np.zeros((1, 2), np.uint32)}, {}, "biharmonic")
    store.mesh_file(tmp_path, "b", "biharmonic").write_bytes(b"")
    assert pending(tmp_path, "biharmonic") == (["b"], 1, 0)
    assert store.remove_damaged(tmp_path, "b", "biharmonic") and not store.remove_damaged(tmp_path, "a", "biharmonic")


def test_a_damaged_mesh_is_a_failure_of_the_later_stage_and_the_others_go_on(tmp_path):
    """`geodata biharmonic` over a store whose first mesh's zip is empty: that mesh's subgroup is recorded as failed
    with the reason, the other meshes are done, a rerun and --check exit 0 and count it failed, info lists it;
    once prepare has redone the mesh, the stage does it."""
    raw, out = prepared(tmp_path, {f"{name}.obj": ball_obj(z) for name, z in (("a", 1.0), ("b", 0.5), ("c", 0.7))})
    damaged, *others = sorted(store.list_meshes(out))
    store.mesh_file(out, damaged).write_bytes(b"")
    bh = ["biharmonic", out, "--pairs", "300"]
    assert "summary: 2 ok, 1 failed this run" in run(*bh).output
    assert all("biharmonic" in store.list_meshes(out)[m] for m in others)
    failure = store.list_failures(out)[f"{damaged}.biharmonic"]
    assert failure["stage"] == "damaged mesh" and failure["error"].startswith("empty file")
    assert "0 to do, 2 already done, 1 failed before" in run(*bh).output
    assert "2 done, 1 failed, 0 pending" in run(*bh, "--check").output
    info = run("info", out).output
    assert "biharmonic: 2 ok, 1 failed" in info and f"{damaged} (biharmonic)  [damaged mesh]  empty file" in info
    run("prepare", raw, out, *ARGS)
    assert "1 to do, 2 already done, 0 failed before" in run(*bh).output
    assert store.list_failures(out) == {} and "biharmonic: 3 ok, 0 failed" in run("info", out).output


def test_an_input_rewritten_in_place_with_its_size_and_mtime_is_hashed_again(tmp_path):
    """A generated OBJ keeps its size, `cp -p`/`touch -r`/`rsync -t` its mtime: the rerun still sees the new bytes
    (the file's ctime and inode changed), prepares them and records their hash."""
    import hashlib

    raw, out = prepared(tmp_path)
    ball = raw / "ball.obj"
    before, ellipsoid = ball.stat(), ball_obj(0.5)
    assert len(ellipsoid) == before.st_size
    ball.write_bytes(ellipsoid)
    os.utime(ball, ns=(before.st_atime_ns, before.st_mtime_ns))
    assert ball.stat().st_mtime_ns == before.st_mtime_ns
    result = run("prepare", raw, out, *ARGS)
    assert "1 to do" in result.output
    rows = [r for r in csv_rows(out) if r["source"] == "ball.obj" and r["fate"] != "orphan"]
    assert [r["sha256"] for r in rows] == [hashlib.sha256(ellipsoid).hexdigest()]
    with store.read_mesh(out, rows[0]["mesh_id"]) as g:
        extent = np.ptp(g["vertices"][:], axis=0)
    assert extent[2] < 0.7 * extent[0]  # the ellipsoid, not the sphere


def test_rehash_reads_every_file_again(tmp_path):
    """--rehash: no hash is taken from the ledger (for a change no file time shows)."""
    import hashlib
    import json

    raw, out = prepared(tmp_path)
    (ledger,) = (out / "sources").glob("*.json")
    content = json.loads(ledger.read_text())
    right = content["inputs"]["ball.obj"]["sha256"]
    content["inputs"]["ball.obj"]["sha256"] = hashlib.sha256(b"stale").hexdigest()
    ledger.write_text(json.dumps(content))
    run("prepare", raw, out, *ARGS, "--rehash")
    assert json.loads(ledger.read_text())["inputs"]["ball.obj"]["sha256"] == right


def test_a_hash_taken_within_a_coarse_filesystem_tick_of_a_change_is_not_reused():
    from geodata.prepare import reusable_hash

    stat = {"size": 10, "mtime_ns": 5_000_000_000, "ctime_ns": 7_000_000_000, "inode": 3}
    assert reusable_hash({**stat, "sha256": "ab", "checked_ns": 8_000_000_000}, stat) is None  # whole seconds
    assert reusable_hash({**stat, "sha256": "ab", "checked_ns": 9_500_000_000}, stat) == "ab"
    fine = {**stat, "ctime_ns": 7_000_000_123}
    assert reusable_hash({**fine, "sha256": "ab", "checked_ns": 7_000_100_000}, fine) == "ab"
    for key in stat:
        assert reusable_hash({**fine, "sha256": "ab", "checked_ns": 9_500_000_000}, {**fine, key: 1}) is None
    assert reusable_hash({"sha256": "ab", "size": 10, "mtime_ns": 5_000_000_000}, stat) is None  # an old ledger


def test_the_mesh_of_an_edited_input_is_an_orphan_left_out_of_training(tmp_path):
    """After an input is edited and prepared again, its old mesh is no input's: info and --csv say `orphan`, the
    trainer's GeodesicStore leaves it out unless asked for it."""
    from gegnn.training.data import GeodesicStore

    raw, out = prepared(tmp_path)
    (old,) = store.list_meshes(out)
    (raw / "ball.obj").write_bytes(ball_obj(0.5))
    run("prepare", raw, out, *ARGS)
    (new,) = set(store.list_meshes(out)) - {old}
    info = run("info", out).output
    assert "inputs: 1 files: 1 ok" in info and "meshes: 2 published (1 orphan)" in info
    assert f"orphan: {old}  ball.obj" in info
    rows = {r["mesh_id"]: r for r in csv_rows(out)}
    assert rows[new]["fate"] == "ok" and rows[old]["fate"] == "orphan" and rows[old]["source"] == "ball.obj"
    assert GeodesicStore(out).mesh_ids == [new]
    assert GeodesicStore(out).orphans == [old]
    assert GeodesicStore(out, include_orphans=True).mesh_ids == sorted([old, new])


def test_preparing_into_an_upgraded_store_publishes_no_file_twice(tmp_path):
    """A format-1 mesh keeps its 8-hex id through `geodata upgrade`; a later prepare of the same file recognises
    it (the upgrade's ledger maps the file's sha256 to it) instead of publishing it again under a 32-hex id."""
    import hashlib

    import zarr

    from geodata.prepare import PrepareConfig

    raw = tmp_path / "raw"
    raw.mkdir()
    data = ball_obj()
    (raw / "ball.obj").write_bytes(data)
    (raw / "egg.obj").write_bytes(ball_obj(0.5))
    digest = hashlib.sha256(data).hexdigest()
    params = PrepareConfig(300, 150).store_params()
    old, new = tmp_path / "old.zarr", tmp_path / "new.zarr"
    root = zarr.open_group(str(old), mode="w", attributes={"geodata_format": 1, "params": params})
    legacy = f"ball-{digest[:8]}"
    g = root.create_group("meshes").create_group(legacy)
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], np.float32)
    f = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], np.int32)
    for name, a in {"vertices": v, "faces": f, "normals": v, "edges": f[:, :2],
                    "geodesic/pairs": np.zeros((1, 2), np.uint32),
                    "geodesic/distances": np.ones(1, np.float32)}.items():
        g.create_array(name, data=a)
    g.attrs.update(source="ball.obj", sha256=digest, status="ok")
    run("upgrade", old, new)
    result = run("prepare", raw, new, *ARGS)
    assert "1 published" in result.output and "1 to do" in result.output  # the egg alone
    meshes = store.list_meshes(new)
    assert len(meshes) == 2 and legacy in meshes
    assert "inputs: 2 files: 2 ok, 0 duplicate, 0 failed, 0 pending" in run("info", new).output
    assert {r["source"]: r["mesh_id"] for r in csv_rows(new)}["ball.obj"] == legacy


def test_verify_names_one_of_each_problem_and_a_rerun_redoes_the_damaged(tmp_path):
    """The store doctor on a store with a damaged zip, an orphan, a duplicated input and an unaccounted one:
    each named with what to do, exit 1; prepare redoes the damaged mesh, --remove-orphans deletes the orphan."""
    import json
    import shutil

    raw, out = prepared(tmp_path, {"ball.obj": ball_obj(), "cube.obj": trimesh.exchange.obj.export_obj(
        trimesh.creation.box()).encode()})
    ids = {a["source"]: m for m, a in ((m, store.mesh_attrs(out, m)) for m in store.list_meshes(out))}
    (raw / "ball.obj").write_bytes(ball_obj(0.5))  # orphan: the sphere's mesh
    run("prepare", raw, out, *ARGS)
    cube = store.mesh_file(out, ids["cube.obj"])
    twin = store.mesh_file(out, "cube-0123abcd")  # duplicated: the same input under an 8-hex id, in a ledger
    shutil.copyfile(cube, twin)
    store.write_ledger(out, "elsewhere", {"root": "/elsewhere", "shard": "0/1", "written": 0.0, "inputs": {
        "cube.obj": {"sha256": store.mesh_attrs(out, ids["cube.obj"])["sha256"], "mesh_id": "cube-0123abcd"},
        "gone.obj": {"sha256": "cd" * 32, "mesh_id": "gone-" + "cd" * 16}}})  # unaccounted: never published
    (egg,) = {m for m in store.list_meshes(out)} - set(ids.values()) - {"cube-0123abcd"}
    egg_file = store.mesh_file(out, egg)
    egg_file.write_bytes(egg_file.read_bytes()[:100])  # damaged
    result = run("verify", out, code=1)
    lines = result.output.splitlines()
    assert f"verify {out}: 1 damaged, 1 orphan, 1 duplicated, 1 unaccounted" in lines
    assert any(line.startswith(f"damaged: meshes/{egg}.zip") and "geodata prepare" in line for line in lines)
    assert any(line.startswith(f"orphan: meshes/{ids['ball.obj']}.zip") and "--remove-orphans" in line
               for line in lines)
    assert any(line.startswith("duplicated: meshes/cube-0123abcd.zip, ") and ids["cube.obj"] in line for line in lines)
    assert any(line.startswith("unaccounted: gone.obj") for line in lines)
    run("prepare", raw, out, *ARGS)  # redoes the damaged mesh
    again = run("verify", out, "--remove-orphans", code=1).output
    assert f"removed: meshes/{ids['ball.obj']}.zip" in again
    assert f"verify {out}: 0 damaged, 0 orphan, 1 duplicated, 1 unaccounted" in again
    twin.unlink()
    store.write_ledger(out, "elsewhere", {"root": "/elsewhere", "shard": "0/1", "written": 0.0, "inputs": {}})
    assert "0 damaged, 0 orphan, 0 duplicated, 0 unaccounted" in run("verify", out).output
    assert json.loads((out / "sources" / "elsewhere.json").read_text())["inputs"] == {}


def test_a_zip_damaged_inside_is_found_by_verify_and_removed_for_a_rerun(tmp_path):
    """A flipped byte inside a zip whose directory is whole: verify's CRC check finds it, --remove-damaged
    deletes it, a rerun of prepare publishes it again."""
    raw, out = prepared(tmp_path)
    (mesh_id,) = store.list_meshes(out)
    path = store.mesh_file(out, mesh_id)
    data = bytearray(path.read_bytes())
    with __import__("zipfile").ZipFile(path) as z:
        info = z.getinfo("geodesic/distances/c/0")
    data[info.header_offset + 30 + len(info.filename) + 5] ^= 0xFF
    path.unlink()
    path.write_bytes(bytes(data))
    assert "CRC" in run("verify", out, code=1).output
    removed = run("verify", out, "--remove-damaged", code=1).output
    assert f"removed: meshes/{mesh_id}.zip" in removed and "unaccounted: ball.obj" in removed  # to do again
    run("prepare", raw, out, *ARGS)
    assert "0 damaged, 0 orphan, 0 duplicated, 0 unaccounted" in run("verify", out).output


def test_ids_that_differ_only_in_case_are_one_file_on_a_case_insensitive_filesystem():
    """Byte copies Chair.obj and sub/chair.obj get ids that differ only in case: one file on macOS or Windows,
    where meshes/ lists the first one's name alone. The second input is its duplicate, not pending forever, and
    the mesh is no orphan."""
    from geodata.accounting import fates, orphans

    digest = "ab" * 32
    upper, lower = f"Chair-{digest[:32]}", f"chair-{digest[:32]}"
    ledgers = {("/raw", "Chair.obj"): {"sha256": digest, "mesh_id": upper},
               ("/raw", "sub/chair.obj"): {"sha256": digest, "mesh_id": lower}}
    meshes = {upper: set()}  # what a case-insensitive filesystem holds: one name
    rows = {r["source"]: r for r in fates(ledgers, meshes, {upper: {"source": "Chair.obj"}}, {})}
    assert rows["Chair.obj"]["fate"] == "ok"
    assert rows["sub/chair.obj"]["fate"] == "duplicate" and upper in rows["sub/chair.obj"]["detail"]
    assert orphans(ledgers, meshes) == []
    failed = fates(ledgers, {}, {}, {upper: {"stage": "load", "error": "empty file"}})
    assert [r["fate"] for r in failed] == ["failed", "failed"]
    both = {upper: set(), lower: set()}  # a case-sensitive filesystem: two meshes, each its own input's
    rows = fates(ledgers, both, {upper: {"source": "Chair.obj"}, lower: {"source": "sub/chair.obj"}}, {})
    assert [r["fate"] for r in rows] == ["ok", "ok"]


@pytest.mark.parametrize("native_rename", [True, False])
def test_publish_without_hard_links_never_replaces_a_published_file(tmp_path, monkeypatch, native_rename):
    """On a filesystem without hard links (SMB, some FUSE mounts: link fails with EPERM) publication is still
    first-writer-wins against writers racing for the name: a no-replace rename (renameat2, renamex_np, Windows'
    rename) or, without one, a name claimed with O_EXCL before the file is moved onto it."""
    import contextlib
    import errno
    import pathlib
    import threading

    def no_link(src, dst):
        raise PermissionError(errno.EPERM, "Operation not permitted")

    monkeypatch.setattr(os, "link", no_link)
    if not native_rename:
        monkeypatch.setattr(store, "_native_rename_noreplace", lambda: None)
    tmps = [tmp_path / f".m.zip.{i}.tmp" for i in range(8)]
    real_exists, looked = pathlib.Path.exists, threading.Barrier(len(tmps), timeout=2)

    def exists_once_all_looked(self, **kw):  # a check-then-rename lets every writer look before any renames
        found = real_exists(self, **kw)
        with contextlib.suppress(threading.BrokenBarrierError):
            looked.wait()
        return found

    monkeypatch.setattr(pathlib.Path, "exists", exists_once_all_looked)
    final = tmp_path / "m.zip"
    for i, tmp in enumerate(tmps):
        tmp.write_bytes(b"writer %d" % i)
    results = [None] * len(tmps)
    barrier = threading.Barrier(len(tmps))

    def writer(i):
        barrier.wait()
        results[i] = store.publish(tmps[i], final)

    threads = [threading.Thread(target=writer, args=(i,)) for i in range(len(tmps))]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert sum(results) == 1 and final.read_bytes() == b"writer %d" % results.index(True)
    assert not any(real_exists(t) for t in tmps)


def test_temporary_names_differ_between_containers_with_one_hostname_and_pid(monkeypatch):
    import socket

    monkeypatch.setattr(socket, "gethostname", lambda: "node")
    monkeypatch.setattr(os, "getpid", lambda: 1)
    names = {store.temporary_name(store.mesh_file("out", "m")) for _ in range(100)}
    assert len(names) == 100 and all(n.name.startswith(".m.zip.node.1.") and n.suffix == ".tmp" for n in names)


def test_an_unreadable_ledger_makes_no_orphans_and_is_named(tmp_path):
    """A ledger that cannot be read would make its meshes look orphaned (and leave them out of training): while
    one is, there are no orphans, and info and verify name it."""
    from gegnn.training.data import GeodesicStore

    raw, out = prepared(tmp_path)
    (ledger,) = (out / "sources").glob("*.json")
    ledger.write_text(ledger.read_text()[:20])
    store.write_ledger(out, "other", {"root": "/other", "shard": "0/1", "written": 0.0, "inputs": {}})
    assert GeodesicStore(out).mesh_ids == list(store.list_meshes(out)) and GeodesicStore(out).orphans == []
    assert f"damaged ledger: sources/{ledger.name}" in run("info", out).output
    verify = run("verify", out, code=1).output
    assert f"damaged: sources/{ledger.name}" in verify and "0 orphan" in verify
    run("prepare", raw, out, *ARGS)
    assert "0 damaged, 0 orphan, 0 duplicated, 0 unaccounted" in run("verify", out).output
