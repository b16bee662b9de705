"""The store: a zarr v3 root group, one zip file per mesh (a zarr group inside), published by an atomic link.

Layout (a contract, docs/store.md)::

    OUT/zarr.json                     root group; attrs geodata_format, params, writer
    OUT/meshes/<mesh_id>.zip          the mesh: vertices, faces, normals, edges, geodesic/, input/
    OUT/meshes/<mesh_id>.<sub>.zip    a later stage's subgroup (biharmonic, points)
    OUT/failed/<name>/                attrs only: source, stage, error (name: a mesh id, or <mesh_id>.<sub>)
    OUT/sources/<ledger>.json         what each prepare run found: source path -> sha256, mesh id

A file is written under a temporary name in its folder, flushed to disk and published with ``os.link`` (which
refuses to replace an existing name; without hard links, a rename that never replaces): a mesh exists completely
or not at all, a published one is never rewritten (one found damaged is removed and redone), and a killed
writer leaves only a temporary file. Many processes may write one store at once: each
publishes only its own meshes, and the shared folders are made once, before any worker starts
(concurrent zarr group creation races, zarr-python#1435). Few files per mesh (1 to 3) keep a store of
50k meshes within the file-count quotas of HPC project spaces. Filesystems only (local, NFS, Lustre, GPFS, SMB),
not object stores.
"""
from __future__ import annotations

import contextlib
import hashlib
import json
import os
import socket
import time
import zipfile
import zlib
from pathlib import Path

import numpy as np
import zarr

from geodata.mesh import one_line

__all__ = ["StoreError", "DamagedMeshError", "FORMAT", "SUBGROUPS", "create_store", "open_store", "geometry_key",
           "mesh_file", "temporary_name", "publish", "write_mesh", "read_mesh", "damage", "remove_damaged",
           "mesh_attrs", "list_meshes", "record_failure", "clear_failure", "list_failures", "write_ledger",
           "read_ledgers", "read_ledger_files", "legacy_ids", "UPGRADE_LEDGER", "temporary_files"]

FORMAT = 2  # 1: one zarr group per mesh (~14-20 files a mesh), before 2026-11-26
SUBGROUPS = ("biharmonic", "points")


class StoreError(Exception):
    """The store path is missing or is not a geodata store of this format."""


class DamagedMeshError(StoreError):
    """A published zip that cannot be read whole (empty, truncated, not a zarr group): e.g. a node that crashed
    while its file was still in the page cache. A rerun of the stage that wrote it redoes it."""

    def __init__(self, path: Path, reason: str):
        self.path, self.reason = Path(path), reason
        super().__init__(f"{path}: damaged ({reason}); rerun the stage that wrote it (geodata prepare, biharmonic "
                         f"or points: it replaces a damaged file)")


def _check_format(out: str, root: zarr.Group) -> None:
    found = root.attrs.get("geodata_format")
    if found == FORMAT:
        return
    if isinstance(found, int) and found < FORMAT:
        raise StoreError(f"{out} is a geodata store of format {found} (one folder per mesh); this geodata reads "
                         f"format {FORMAT} (one zip per mesh): convert it with `geodata upgrade {out} NEW_OUT`")
    if isinstance(found, int):
        raise StoreError(f"{out} is a geodata store of format {found}, newer than this geodata's {FORMAT}: "
                         f"upgrade geogegnn")
    raise StoreError(f"{out} is not a geodata store")


def create_store(out: str | Path, params: dict) -> zarr.Group:
    """Open OUT for writing, creating the root group and the meshes/, failed/ and sources/ folders if missing.

    A store holds data made with one setting of `params` (values, never prose); a run asking for other values
    is refused rather than mixing two datasets under one name, the error saying what differs as the command
    line says it.
    """
    out, params = str(out), _identity(params)
    from geodata import __version__
    root = _open_or_create_root(out, {"geodata_format": FORMAT, "params": params, "writer": __version__})
    _check_format(out, root)
    made = _identity(root.attrs.get("params", {}))
    if made != params:
        raise StoreError(f"{out} {'; '.join(_differences(made, params))}: use another OUT for other parameters")
    for name in ("meshes", "failed", "sources"):
        (Path(out) / name).mkdir(exist_ok=True)
    return root


# Words that geodata 0.3.2-0.3.3 kept among an approximate store's parameters (what its distances are); they
# describe a store and do not identify it, so they are read past.
DESCRIPTIONS = ("geodesic_error",)


def _identity(params: dict) -> dict:
    return {k: v for k, v in params.items() if k not in DESCRIPTIONS}


def _differences(made: dict, asked: dict) -> list[str]:
    """What differs between a store's parameters and a run's, each as its option (``--geodesic-backend``)."""
    out = []
    for key in sorted(set(made) | set(asked)):
        option = "--" + key.replace("_", "-")
        if key in made and key in asked:
            if made[key] != asked[key]:
                out.append(f"was made with {option} {made[key]}, this run asks for {asked[key]}")
        elif key in asked:
            out.append(f"was made by an older geodata, which did not record {option} (this run: {asked[key]})")
        elif key in made:
            out.append(f"was made with {option} {made[key]}, which this geodata does not know (a newer one's store)")
    return out


def _open_or_create_root(out: str, attrs: dict, attempts: int = 50) -> zarr.Group:
    """Open the root group, or create it; several shards may start at the same moment."""
    for _ in range(attempts):
        # Else missing, or its metadata is being written this instant.
        with contextlib.suppress(FileNotFoundError, zarr.errors.GroupNotFoundError, json.JSONDecodeError):
            return zarr.open_group(out, mode="r+")
        try:
            return zarr.open_group(out, mode="w-", attributes=attrs)
        except (zarr.errors.ContainsGroupError, FileExistsError):
            time.sleep(0.1)  # another shard is creating it right now: open it once written
    raise StoreError(f"{out}: could not open or create the store")


def open_store(out: str | Path) -> zarr.Group:
    """Open an existing store read-only; StoreError where OUT is missing or not a geodata store of this format."""
    try:
        root = zarr.open_group(str(out), mode="r")
    except (FileNotFoundError, zarr.errors.GroupNotFoundError):
        raise StoreError(f"{out}: no geodata store here") from None
    _check_format(str(out), root)
    return root


def geometry_key(vertices: np.ndarray, faces: np.ndarray) -> str:
    """A content hash of a mesh: 24 hex digits of the SHA-256 of its float32 vertices and int64 faces.
    Recorded at prepare time (attribute ``geometry_key``) so that readers need not read the geometry to
    key per-mesh caches by content."""
    h = hashlib.sha256(np.ascontiguousarray(vertices, dtype=np.float32).tobytes())
    h.update(np.ascontiguousarray(faces, dtype=np.int64).tobytes())
    return h.hexdigest()[:24]


def mesh_file(out: str | Path, mesh_id: str, subgroup: str | None = None) -> Path:
    """The zip file of a mesh, meshes/<mesh_id>.zip, or of its subgroup, meshes/<mesh_id>.<subgroup>.zip."""
    return Path(out) / "meshes" / (f"{mesh_id}.zip" if subgroup is None else f"{mesh_id}.{subgroup}.zip")


def _chunks(data: np.ndarray) -> tuple[int, ...]:
    rows = max(1, min(len(data), (1 << 20) // max(1, data[:1].nbytes)))  # about 1 MiB a chunk
    return (rows, *data.shape[1:])


def publish(tmp: Path, final: Path) -> bool:
    """Give the finished file ``tmp`` its name ``final`` unless that exists (``tmp`` is removed either way); True
    when this call published. Also the field cache's (:mod:`gegnn.fields.cache`)."""
    try:
        os.link(tmp, final)  # atomic, and never replaces: the first writer of a name wins
        return True
    except FileExistsError:
        return False
    except OSError:  # a filesystem without hard links (SMB, some FUSE mounts)
        return _rename_noreplace(Path(tmp), Path(final))
    finally:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()


def _native_rename_noreplace():
    """The C library's rename that fails where the target exists, as ``f(src, dst) -> 0 or -1`` (errno set), or
    None: renameat2(RENAME_NOREPLACE) (Linux, glibc >= 2.28) or renamex_np(RENAME_EXCL) (macOS)."""
    import ctypes
    import ctypes.util
    import sys

    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c"), use_errno=True)
        if sys.platform.startswith("linux"):
            at_fdcwd, noreplace, fn = -100, 1, libc.renameat2
            return lambda src, dst: fn(at_fdcwd, os.fsencode(src), at_fdcwd, os.fsencode(dst), noreplace)
        if sys.platform == "darwin":
            excl, fn = 4, libc.renamex_np
            return lambda src, dst: fn(os.fsencode(src), os.fsencode(dst), excl)
    except (OSError, AttributeError, TypeError):
        pass
    return None


def _rename_noreplace(tmp: Path, final: Path) -> bool:
    """Rename ``tmp`` to ``final`` unless that exists, atomically against other writers; True when renamed. Windows'
    rename never replaces; elsewhere the C library's no-replace rename where the filesystem has it; else the
    name is claimed first (an empty file made with O_EXCL, which one writer alone can) and the file moved onto
    it: a writer killed in between leaves that empty file, which the next run finds damaged and redoes."""
    import ctypes
    import errno

    if os.name == "nt":
        try:
            os.rename(tmp, final)
            return True
        except FileExistsError:
            return False
    native = _native_rename_noreplace()
    if native is not None:
        if native(tmp, final) == 0:
            return True
        code = ctypes.get_errno()
        if code == errno.EEXIST:
            return False
        if code not in (errno.EINVAL, errno.ENOSYS, errno.ENOTSUP, errno.EOPNOTSUPP, errno.EPERM):
            raise OSError(code, os.strerror(code), str(final))
    try:
        os.close(os.open(final, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644))
    except FileExistsError:
        return False
    os.replace(tmp, final)
    return True


def write_mesh(out: str | Path, mesh_id: str, arrays: dict[str, np.ndarray], attrs: dict,
               subgroup: str | None = None) -> bool:
    """Write meshes/<mesh_id>[.<subgroup>].zip holding ``arrays`` (names may contain '/') and ``attrs``
    (with status "ok"), then publish it; False (nothing changed) when another writer published it first."""
    final = mesh_file(out, mesh_id, subgroup)
    tmp = temporary_name(final)
    zip_store = zarr.storage.ZipStore(tmp, mode="w")
    try:
        group = zarr.open_group(zip_store, mode="w", attributes={**attrs, "status": "ok"})
        for name, data in arrays.items():
            group.create_array(name, data=np.ascontiguousarray(data), chunks=_chunks(data))
    finally:
        zip_store.close()
    _flush_to_disk(tmp)  # else a node crash can leave the published name on an empty or partial file
    return publish(tmp, final)


def _flush_to_disk(path: Path) -> None:
    with open(path, "rb") as f:
        os.fsync(f.fileno())


def temporary_name(final: Path) -> Path:
    """A writer's temporary file for ``final``, in its folder: ``.<name>.<host>.<pid>.<random>.tmp``, unique
    also among containers that share a hostname and a pid namespace's numbers."""
    return final.with_name(f".{final.name}.{socket.gethostname()}.{os.getpid()}.{os.urandom(4).hex()}.tmp")


@contextlib.contextmanager
def read_mesh(out: str | Path, mesh_id: str, subgroup: str | None = None):
    """The published zarr group of a mesh (or of its subgroup), read-only; the zip is closed on exit.
    FileNotFoundError where it is not published."""
    path = mesh_file(out, mesh_id, subgroup)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such mesh")
    reason = damage(out, mesh_id, subgroup)
    if reason:
        raise DamagedMeshError(path, reason)
    zip_store = zarr.storage.ZipStore(path, mode="r")
    try:
        try:
            group = zarr.open_group(zip_store, mode="r")
        except (zarr.errors.GroupNotFoundError, FileNotFoundError, KeyError, ValueError,
                zipfile.BadZipFile) as exc:
            raise DamagedMeshError(path, f"not a zarr group: {exc}") from None
        yield group
    finally:
        if hasattr(zip_store, "_zf"):  # else it never opened: its close() would hide why (AttributeError)
            zip_store.close()


def damage(out: str | Path, mesh_id: str, subgroup: str | None = None, thorough: bool = False) -> str | None:
    """Why a published zip is damaged, or None where it looks whole (also where it is not published). Quick by
    default: the zip's directory, read from its end, must list the group (an empty, truncated or zero-filled
    file fails). ``thorough``: every member's CRC is checked and the group's ``status`` must be "ok". A file
    that cannot be read at all (no permission, an I/O error) raises OSError: that is not damage to redo."""
    path = mesh_file(out, mesh_id, subgroup)
    try:
        if path.stat().st_size == 0:
            return "empty file"
        with zipfile.ZipFile(path) as zf:
            if "zarr.json" not in zf.namelist():
                return "no zarr group in the zip"
            if thorough:
                bad = zf.testzip()
                if bad is not None:
                    return f"{bad}: CRC mismatch"
                status = json.loads(zf.read("zarr.json")).get("attributes", {}).get("status")
                if status != "ok":
                    return f"status {status!r}, not 'ok'"
    except FileNotFoundError:
        return None
    except (zipfile.BadZipFile, EOFError, ValueError, zlib.error) as exc:  # not an OSError: no permission is no damage
        return f"not a readable zip: {one_line(exc, with_type=False)}"
    return None


def remove_damaged(out: str | Path, mesh_id: str, subgroup: str | None = None) -> bool:
    """Delete a published zip found damaged (:func:`damage`), so that the stage can publish it again; True when
    this call removed it. A whole file is never removed: it is checked again just before."""
    path = mesh_file(out, mesh_id, subgroup)
    if damage(out, mesh_id, subgroup) is None:
        return False
    with contextlib.suppress(FileNotFoundError):
        path.unlink()
        return True
    return False


def mesh_attrs(out: str | Path, mesh_id: str, subgroup: str | None = None) -> dict | None:
    """A published mesh's (or subgroup's) attributes, or None where it is not published; DamagedMeshError
    where its zip is damaged."""
    try:
        with read_mesh(out, mesh_id, subgroup) as group:
            return dict(group.attrs)
    except FileNotFoundError:
        return None


def list_meshes(out: str | Path) -> dict[str, set[str]]:
    """Every published mesh, with the subgroups published beside it, from one listing of meshes/ (no file
    is opened)."""
    meshes: dict[str, set[str]] = {}
    subs = []
    with os.scandir(Path(out) / "meshes") as entries:
        for entry in entries:
            name = entry.name
            if name.startswith(".") or not name.endswith(".zip"):
                continue  # a writer's temporary file
            stem = name[:-4]
            sub = next((s for s in SUBGROUPS if stem.endswith(f".{s}")), None)
            if sub is None:
                meshes[stem] = set()
            else:
                subs.append((stem[:-len(sub) - 1], sub))
    for mesh_id, sub in subs:
        if mesh_id in meshes:
            meshes[mesh_id].add(sub)
    return dict(sorted(meshes.items()))


def temporary_files(out: str | Path) -> list[str]:
    """Temporary files in meshes/: writers at work now, or killed ones' leftovers."""
    return sorted(p.name for p in (Path(out) / "meshes").glob(".*.tmp"))


def record_failure(out: str | Path, name: str, source: str, stage: str, error: str) -> None:
    """Record why a mesh (name: its id) or a mesh's subgroup (name: <mesh_id>.<subgroup>) failed: failed/<name>,
    attrs only (source, stage, one-line error)."""
    zarr.open_group(f"{out}/failed/{name}", mode="w", attributes={"source": source, "stage": stage, "error": error})


def clear_failure(out: str | Path, name: str) -> None:
    """Forget a recorded failure (before a retry, or once the mesh is published)."""
    root = zarr.open_group(str(out), mode="r+")
    if f"failed/{name}" in root:
        del root[f"failed/{name}"]


def _group_attrs(path: str) -> dict | None:
    try:
        return dict(zarr.open_group(path, mode="r").attrs)
    except (FileNotFoundError, zarr.errors.GroupNotFoundError, json.JSONDecodeError, ValueError, KeyError):
        return None


def list_failures(out: str | Path, names=None) -> dict[str, dict]:
    """The recorded failures: name -> {source, stage, error}; only those of ``names`` where given (a shard's:
    no other record is read)."""
    base = Path(out) / "failed"
    if names is None:
        found = sorted(p.name for p in base.iterdir() if p.is_dir())
    else:
        found = sorted(n for n in names if (base / n).is_dir())
    failures = {name: _group_attrs(f"{out}/failed/{name}") for name in found}
    return {k: v for k, v in failures.items() if v is not None}


def write_ledger(out: str | Path, name: str, ledger: dict) -> None:
    """Publish sources/<name>.json (a prepare run's inputs: see :func:`read_ledgers`), replacing the same
    run's earlier one atomically."""
    final = Path(out) / "sources" / f"{name}.json"
    tmp = temporary_name(final)
    with open(tmp, "w") as f:
        f.write(json.dumps(ledger))
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, final)


UPGRADE_LEDGER = "upgraded-from-format-1"  # written by `geodata upgrade`: the old store's sources and ids


def read_ledger_files(out: str | Path) -> tuple[dict[str, dict], dict[str, str]]:
    """Every ledger in sources/ by name, and those that cannot be read (name -> why)."""
    ledgers, damaged = {}, {}
    for path in sorted((Path(out) / "sources").glob("*.json")):
        try:
            ledger = json.loads(path.read_text())
            if not isinstance(ledger.get("inputs"), dict) or "root" not in ledger or "written" not in ledger:
                raise ValueError("no root, written or inputs")
            ledgers[path.stem] = ledger
        except (json.JSONDecodeError, OSError, ValueError, AttributeError) as exc:
            damaged[path.stem] = one_line(exc, with_type=False)
    return ledgers, damaged


def read_ledgers(out: str | Path, unreadable: dict | None = None) -> dict[tuple[str, str], dict]:
    """Every input file any prepare run found: (input root, source) -> {sha256, mesh_id, size, mtime_ns, ...},
    the newest ledger's entry where several runs saw one file. An upgraded store's sources (the ledger of
    `geodata upgrade`) count until a prepare run finds a file of that name: that run's entry replaces it. The
    ledgers that cannot be read go to ``unreadable`` (name -> why)."""
    ledgers, damaged = read_ledger_files(out)
    if unreadable is not None:
        unreadable.update(damaged)
    upgraded = ledgers.pop(UPGRADE_LEDGER, None)
    inputs = {}
    for ledger in sorted(ledgers.values(), key=lambda led: led["written"]):
        for source, entry in ledger["inputs"].items():
            inputs[(ledger["root"], source)] = entry
    if upgraded is not None:
        seen = {source for _, source in inputs}
        inputs.update({(upgraded["root"], source): entry for source, entry in upgraded["inputs"].items()
                       if source not in seen})
    return inputs


def legacy_ids(out: str | Path) -> dict[tuple[str, str], str]:
    """The ids an upgraded store kept from format 1 (8 hex digits): (source, sha256) -> mesh id, from the
    upgrade's ledger (empty for a store not upgraded). A prepare run gives a file of that name and content
    this id, so that it is not published twice."""
    path = Path(out) / "sources" / f"{UPGRADE_LEDGER}.json"
    try:
        inputs = json.loads(path.read_text())["inputs"]
    except (FileNotFoundError, json.JSONDecodeError, KeyError, TypeError):
        return {}
    return {(source, e["sha256"]): e["mesh_id"] for source, e in inputs.items() if e.get("sha256")}
