"""Naming a mesh of a store on a benchmark's command line: its id, or a unique prefix of it.

Store format 2 ids are ``<stem>-<32 hex digits of the file's sha256>``; the documented commands name
meshes by their format-1 ids (``dragon-4af53808``: the stem and 8 hex digits), which are prefixes of the
new ones, so a prefix that picks one mesh is accepted wherever a benchmark takes a mesh id.
"""
from __future__ import annotations

from geodata import store as geostore

__all__ = ["MeshIdError", "mesh_id"]


class MeshIdError(LookupError):
    """No mesh, or more than one, of a store has an id starting with the given prefix."""


def mesh_id(store_path, prefix: str, ids=None) -> str:
    """The id of the mesh of the store at ``store_path`` that is ``prefix`` or starts with it.

    ``ids``: the ids to choose from (default: every published mesh of the store). MeshIdError naming the
    candidates when none or several match; geodata.store.StoreError where ``store_path`` is not a store.
    """
    if ids is None:
        geostore.open_store(store_path)  # a clear StoreError for a missing or format-1 store
        ids = geostore.list_meshes(store_path)
    ids = sorted(ids)
    if prefix in ids:
        return prefix
    found = [m for m in ids if m.startswith(prefix)]
    if len(found) == 1:
        return found[0]
    if found:
        raise MeshIdError(f"{prefix!r} is the start of {len(found)} mesh ids of {store_path}: {', '.join(found)}; "
                          f"give more of the id")
    stem = prefix.rsplit("-", 1)[0]
    near = [m for m in ids if m.rsplit("-", 1)[0] == stem] or ids
    shown = ", ".join(near[:20]) + (f", ... ({len(near)} in all)" if len(near) > 20 else "")
    raise MeshIdError(f"no mesh id of {store_path} starts with {prefix!r}; "
                      f"{'meshes of that name' if near is not ids else 'its meshes'}: {shown or 'none'}")
