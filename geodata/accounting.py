"""Every input file accounted for: the fate of each file that a prepare run found (its ledger), from the
published meshes and the failure records (`geodata info`, docs/store.md)."""
from __future__ import annotations

from collections import defaultdict

from geodata import store

__all__ = ["read_attrs", "CaseFoldedListing", "fates", "orphans", "orphan_rows", "REMOVE_ORPHANS"]


def read_attrs(out, meshes: dict, damaged: dict | None = None) -> dict[str, dict]:
    """Every published mesh's attributes (a few threads: each is one small read from its zip); a damaged zip's
    id goes to ``damaged`` with the reason instead."""
    from concurrent.futures import ThreadPoolExecutor

    def attrs(mesh_id):
        try:
            return store.mesh_attrs(out, mesh_id)
        except store.DamagedMeshError as exc:
            return exc

    with ThreadPoolExecutor(8) as pool:
        found = dict(zip(meshes, pool.map(attrs, meshes)))
    if damaged is not None:
        damaged.update({k: a.reason for k, a in found.items() if isinstance(a, store.DamagedMeshError)})
    return {k: a for k, a in found.items() if isinstance(a, dict)}


class CaseFoldedListing(dict):
    """A listing of meshes/ (or failed/) that finds a name as the filesystem would on a case-insensitive one:
    exactly where the name is there, else by its case-folded form. Ids differing only in case share their
    hash digits (hex is lower case), so they are byte copies: never two different meshes."""

    def __init__(self, listing):
        super().__init__(listing)
        self.folded = {}
        for name in sorted(listing):
            self.folded.setdefault(name.casefold(), name)

    def name(self, name: str) -> str:
        """The listed name this name is found under (itself where it is not listed)."""
        return name if dict.__contains__(self, name) else self.folded.get(name.casefold(), name)

    def __contains__(self, name) -> bool:
        return dict.__contains__(self, self.name(name))

    def __getitem__(self, name):
        return dict.__getitem__(self, self.name(name))


def fates(ledgers: dict, meshes: dict, attrs: dict, failures: dict, damaged: dict | None = None) -> list[dict]:
    """The fate of every input file in the runs' ledgers: ok (the source its published mesh records),
    duplicate (a byte copy of the same file name: the mesh records another source), failed (the mesh's
    failure record), damaged (its mesh's zip cannot be read: a rerun redoes it), pending. A byte copy under
    another file name is a mesh of its own: its detail says so. On a case-insensitive filesystem (macOS,
    Windows) ids that differ only in case (byte copies Chair.obj and chair.obj) are one file, listed under the
    first writer's name: the other input is its duplicate (:class:`CaseFoldedListing`)."""
    damaged = damaged or {}
    meshes, failures = CaseFoldedListing(meshes), CaseFoldedListing(failures)
    published_as = defaultdict(set)  # byte copies under another file name are meshes of their own
    for entry in ledgers.values():
        if entry["mesh_id"] in meshes:
            published_as[entry["sha256"]].add(meshes.name(entry["mesh_id"]))
    rows = []
    for (root, source), entry in sorted(ledgers.items(), key=lambda kv: kv[0][1]):
        mesh_id = meshes.name(entry["mesh_id"])
        row = {"source": source, "sha256": entry["sha256"], "mesh_id": entry["mesh_id"], "fate": "pending",
               "detail": ""}
        if mesh_id in damaged:
            row.update(fate="damaged", detail=f"{damaged[mesh_id]}: a rerun of prepare redoes it")
        elif mesh_id in meshes:
            owner = attrs.get(mesh_id, {}).get("source")
            if owner != source:
                row.update(fate="duplicate", detail=f"duplicate of {mesh_id} ({owner})")
            else:
                others = sorted(published_as[entry["sha256"]] - {mesh_id})
                row.update(fate="ok", detail=f"same bytes as {', '.join(others)}" if others else "")
        elif entry["mesh_id"] in failures:
            failure = failures[entry["mesh_id"]]
            row.update(fate="failed", detail=f"[{failure.get('stage')}] {failure.get('error')}")
        rows.append(row)
    return rows


REMOVE_ORPHANS = "geodata verify OUT --remove-orphans"


def orphans(ledgers: dict, meshes, unreadable: dict | None = None) -> list[str]:
    """The published meshes no input maps to any more: an input edited since (its ledger entry now names its new
    mesh) or gone from its folder. None in a store without ledgers (one not written by prepare: nothing to
    tell), nor while a ledger is ``unreadable`` (:func:`geodata.store.read_ledger_files`: its meshes would look
    orphaned; `geodata verify` names it)."""
    if not ledgers or unreadable:
        return []
    mapped = {entry["mesh_id"].casefold() for entry in ledgers.values()}  # one file where names fold (fates)
    return sorted(m for m in meshes if m.casefold() not in mapped)


def orphan_rows(orphaned: list[str], attrs: dict) -> list[dict]:
    """`info --csv` rows of the orphans: the source and hash their mesh records."""
    return [{"source": attrs.get(m, {}).get("source", ""), "sha256": attrs.get(m, {}).get("sha256", ""), "mesh_id": m,
             "fate": "orphan", "detail": f"no input maps to this mesh any more (its file changed or is gone): left "
                                         f"out of training; `{REMOVE_ORPHANS}` deletes it"} for m in orphaned]
