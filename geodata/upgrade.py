"""`geodata upgrade`: a store of format 1 (one zarr group per mesh, ~14-20 files each) copied into format 2
(one zip per mesh and subgroup, :mod:`geodata.store`), keeping its mesh ids, so that its train/validation split
and pair sampling (both keyed by id) stay as they were. Resumable: a mesh already published in NEW is skipped."""
from __future__ import annotations

import time

import numpy as np
import zarr

from geodata import store

__all__ = ["upgrade_store"]


def _arrays(group: zarr.Group, prefix: str = "") -> dict[str, np.ndarray]:
    """Every array under ``group`` (its subgroups' too, but for the mesh's own subgroups), by path."""
    found = {f"{prefix}{name}": array[:] for name, array in group.arrays()}
    for name, sub in group.groups():
        if not prefix and name in store.SUBGROUPS:
            continue
        found.update(_arrays(sub, f"{prefix}{name}/"))
    return found


def upgrade_store(old, new, progress=None) -> dict:
    """Copy format-1 store OLD into a new format-2 store NEW: committed meshes (their biharmonic and points
    subgroups, committed or failed) and failure records; meshes a killed run left without their mark are
    not copied (prepare redoes them). Meshes of format 1 have no ``input/`` arrays. A ledger of the sources
    the old store names is written (with each file's sha256), so `geodata info` accounts for them and a later
    prepare of the same file gives it its old id (:func:`geodata.store.legacy_ids`). Returns the counts."""
    root = zarr.open_group(str(old), mode="r")
    if root.attrs.get("geodata_format") != 1:
        raise store.StoreError(f"{old} is not a geodata store of format 1")
    store.create_store(new, root.attrs.get("params", {}))
    counts = {"meshes": 0, "skipped": 0, "incomplete": 0, "failures": 0}
    inputs = {}
    published = store.list_meshes(new)
    groups = list(root["meshes"].groups()) if "meshes" in root else []
    for mesh_id, group in (progress or (lambda x: x))(groups):
        attrs = dict(group.attrs)
        if attrs.pop("status", None) != "ok":
            counts["incomplete"] += 1
            continue
        inputs[attrs.get("source", mesh_id)] = {"sha256": attrs.get("sha256"), "mesh_id": mesh_id, "size": None,
                                                "mtime_ns": None}
        if mesh_id in published:
            counts["skipped"] += 1
            continue
        arrays = _arrays(group)
        attrs["geometry_key"] = store.geometry_key(arrays["vertices"], arrays["faces"])
        for sub in store.SUBGROUPS:  # the subgroups first: the mesh's own zip marks the mesh as copied
            if sub not in group:
                continue
            sub_attrs = dict(group[sub].attrs)
            status = sub_attrs.pop("status", None)
            if status == "ok":
                store.write_mesh(new, mesh_id, _arrays(group[sub], ""), sub_attrs, sub)
            elif status == "failed":
                store.record_failure(new, f"{mesh_id}.{sub}", attrs.get("source", mesh_id), sub_attrs.get("stage", sub),
                                     sub_attrs.get("error", ""))
        store.write_mesh(new, mesh_id, arrays, attrs)
        counts["meshes"] += 1
    for name, group in (root["failed"].groups() if "failed" in root else []):
        a = dict(group.attrs)
        store.record_failure(new, name, a.get("source", name), a.get("stage", "unknown"), a.get("error", ""))
        inputs.setdefault(a.get("source", name), {"sha256": None, "mesh_id": name, "size": None, "mtime_ns": None})
        counts["failures"] += 1
    store.write_ledger(new, store.UPGRADE_LEDGER, {"root": str(old), "shard": "0/1", "written": time.time(),
                                                       "inputs": inputs})
    return counts
