"""The zarr v3 store: one group per mesh, committed by writing its status mark last.

Layout (a contract, docs/store.md)::

    OUT/meshes/<mesh_id>/{vertices, faces, normals, edges, geodesic/{pairs,distances}, biharmonic/...}
    OUT/failed/<mesh_id>   attrs only: source, stage, error

Many processes may write one store at once: each writes only its own mesh groups, and the shared
parents are created once, before any worker starts (concurrent creation races, zarr-python#1435).
"""
from __future__ import annotations

import contextlib
import json
import time
from pathlib import Path

import numpy as np
import zarr

__all__ = ["StoreError", "FORMAT", "create_store", "open_store", "group_attrs", "mesh_status", "write_group",
           "commit", "record_failure", "clear_failure", "remove_mesh", "list_meshes", "list_failures"]

FORMAT = 1


class StoreError(Exception):
    """The store path is missing or is not a geodata store."""


def create_store(out: str | Path, params: dict) -> zarr.Group:
    """Open OUT for writing, creating the root, meshes/ and failed/ groups if missing.

    A store holds data made with one setting of `params`; a run asking for other values is refused
    rather than mixing two datasets under one name.
    """
    out = str(out)
    root = _open_or_create_root(out, {"geodata_format": FORMAT, "params": params})
    if root.attrs.get("geodata_format") != FORMAT:
        raise StoreError(f"{out} is not a geodata store")
    if root.attrs.get("params") != params:
        diff = {k: v for k, v in root.attrs.get("params", {}).items() if params.get(k) != v}
        raise StoreError(f"{out} was made with {diff}; use another OUT for other parameters")
    for name in ("meshes", "failed"):
        with contextlib.suppress(zarr.errors.ContainsGroupError):  # another shard made it between check and write
            root.require_group(name)
    return root


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
    """Open an existing store read-only; StoreError where OUT is missing or not a geodata store."""
    try:
        root = zarr.open_group(str(out), mode="r")
    except (FileNotFoundError, zarr.errors.GroupNotFoundError):
        raise StoreError(f"{out}: no geodata store here") from None
    if root.attrs.get("geodata_format") != FORMAT:
        raise StoreError(f"{out} is not a geodata store")
    return root


def group_attrs(out: str | Path, path: str) -> dict | None:
    """A group's attributes, or None when the group is missing or its metadata half-written."""
    try:
        return dict(zarr.open_group(f"{out}/{path}", mode="r").attrs)
    except (FileNotFoundError, zarr.errors.GroupNotFoundError, json.JSONDecodeError, ValueError, KeyError):
        return None


def mesh_status(out: str | Path, path: str) -> str | None:
    """The status of meshes/<path> ("ok" once committed), or None when missing or half-written."""
    return (group_attrs(out, f"meshes/{path}") or {}).get("status")


def write_group(out: str | Path, path: str, arrays: dict[str, np.ndarray], attrs: dict) -> zarr.Group:
    """(Re)create group OUT/path holding `arrays` (names may contain '/'), attrs without a commit mark."""
    group = zarr.open_group(f"{out}/{path}", mode="w", attributes=attrs)
    for name, data in arrays.items():
        group.create_array(name, data=np.ascontiguousarray(data), chunks=_chunks(data))
    return group


def _chunks(data: np.ndarray) -> tuple[int, ...]:
    rows = max(1, min(len(data), (1 << 20) // max(1, data[:1].nbytes)))  # about 1 MiB a chunk
    return (rows, *data.shape[1:])


def commit(out: str | Path, path: str) -> None:
    """Write the commit mark last: a reader counts the group only from now on."""
    zarr.open_group(f"{out}/{path}", mode="r+").attrs["status"] = "ok"


def record_failure(out: str | Path, mesh_id: str, source: str, stage: str, error: str) -> None:
    """Record why a mesh failed (failed/<mesh_id>, attrs only: source, stage, one-line error)."""
    zarr.open_group(f"{out}/failed/{mesh_id}", mode="w",
                    attributes={"source": source, "stage": stage, "error": error})


def clear_failure(out: str | Path, mesh_id: str) -> None:
    """Forget a recorded failure (before a retry)."""
    root = zarr.open_group(str(out), mode="r+")
    if f"failed/{mesh_id}" in root:
        del root[f"failed/{mesh_id}"]


def _children(out: str | Path, parent: str) -> list[str]:
    base = Path(out) / parent
    if base.is_dir():  # local store: a directory listing is far cheaper than zarr's async walk
        return sorted(p.name for p in base.iterdir() if p.is_dir())
    return sorted(zarr.open_group(f"{out}/{parent}", mode="r").group_keys())


def list_meshes(out: str | Path) -> dict[str, dict | None]:
    """Every mesh group under meshes/ with its attrs (None when unreadable)."""
    return {mesh_id: group_attrs(out, f"meshes/{mesh_id}") for mesh_id in _children(out, "meshes")}


def list_failures(out: str | Path) -> dict[str, dict]:
    """The recorded failures: mesh id -> {source, stage, error}."""
    failures = {mesh_id: group_attrs(out, f"failed/{mesh_id}") for mesh_id in _children(out, "failed")}
    return {k: v for k, v in failures.items() if v is not None}


def remove_mesh(out: str | Path, mesh_id: str) -> None:
    """Delete a (half-written) mesh group, if any."""
    root = zarr.open_group(str(out), mode="r+")
    if f"meshes/{mesh_id}" in root:
        del root[f"meshes/{mesh_id}"]
