"""`geodata verify`: the store doctor. Opens every published zip and every ledger and names each entry that is
damaged, orphaned, duplicated or unaccounted for, with what to do about it (docs/store.md)."""
from __future__ import annotations

import contextlib
import shutil
from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path

from geodata import store
from geodata.accounting import fates, orphans, read_attrs

__all__ = ["Finding", "KINDS", "examine", "remove_orphans", "remove_damaged", "summary"]

KINDS = ("damaged", "orphan", "duplicated", "unaccounted")


@dataclass(frozen=True)
class Finding:
    kind: str      # one of KINDS
    name: str      # the entry: a path relative to the store, or an input's source
    detail: str    # what is wrong
    remedy: str    # what to do

    def line(self) -> str:
        return f"{self.kind}: {self.name}  {self.detail}; {self.remedy}"


def _redo(subgroup: str | None) -> str:
    step = {None: "`geodata prepare RAW_DIR OUT` (the run that made it)", "biharmonic": "`geodata biharmonic OUT`",
            "points": "`geodata points OUT`"}[subgroup]
    return f"a rerun of {step} replaces it"


def _mesh_files(out) -> tuple[list[tuple[str, str | None]], list[str]]:
    """Every published zip as (mesh id, subgroup or None), and the other names in meshes/ that are neither a
    zip nor a writer's temporary file."""
    zips, strays = [], []
    for path in sorted((Path(out) / "meshes").iterdir()):
        name = path.name
        if name.startswith(".") and name.endswith(".tmp"):
            continue
        if not name.endswith(".zip") or name.startswith("."):
            strays.append(name)
            continue
        stem = name[:-4]
        sub = next((s for s in store.SUBGROUPS if stem.endswith(f".{s}")), None)
        zips.append((stem if sub is None else stem[:-len(sub) - 1], sub))
    return zips, strays


def examine(out, progress=None) -> list[Finding]:
    """Every damaged, orphaned, duplicated and unaccounted entry of store OUT (which must open: StoreError)."""
    store.open_store(out)
    findings = []
    zips, strays = _mesh_files(out)
    for mesh_id, sub in (progress or (lambda x: x))(zips):
        reason = store.damage(out, mesh_id, sub, thorough=True)
        if reason:  # a run finds what the quick check finds; damage only the CRCs show must be removed first
            remedy = _redo(sub) if store.damage(out, mesh_id, sub) else \
                f"`geodata verify OUT --remove-damaged` deletes it, then {_redo(sub)}"
            findings.append(Finding("damaged", f"meshes/{store.mesh_file(out, mesh_id, sub).name}", reason, remedy))
    bad = {f.name for f in findings}
    meshes = {m: set() for m, sub in zips if sub is None and f"meshes/{m}.zip" not in bad}
    for mesh_id, sub in zips:
        if sub is not None and mesh_id not in meshes and f"meshes/{mesh_id}.zip" not in bad:
            findings.append(Finding("unaccounted", f"meshes/{mesh_id}.{sub}.zip",
                                    f"its mesh {mesh_id} is not published", "delete it while no run writes the store"))
    findings += [Finding("unaccounted", f"meshes/{name}", "not a file of the store",
                         "move it elsewhere (a store's meshes/ holds zips alone)") for name in strays]
    broken: dict[str, str] = {}
    ledgers = store.read_ledgers(out, broken)
    findings += [Finding("damaged", f"sources/{name}.json", reason,
                         "rerun the prepare run (shard) that wrote it: it writes its ledger again")
                 for name, reason in broken.items()]
    attrs = read_attrs(out, meshes)
    failures = store.list_failures(out)
    unreadable = sorted(p.name for p in (Path(out) / "failed").iterdir() if p.is_dir() and p.name not in failures)
    findings += [Finding("damaged", f"failed/{name}", "a failure record that cannot be read",
                         "delete the folder: the next run tries the mesh again") for name in unreadable]
    orphaned = orphans(ledgers, meshes, broken)
    findings += [Finding("orphan", f"meshes/{m}.zip", f"(source {attrs.get(m, {}).get('source', '?')}) no input "
                         f"maps to it any more: its file changed or is gone; left out of training",
                         "`geodata verify OUT --remove-orphans` deletes it") for m in orphaned]
    findings += _duplicates(attrs, set(orphaned))
    for row in fates(ledgers, meshes, attrs, failures):
        if row["fate"] == "pending" and f"meshes/{row['mesh_id']}.zip" not in bad:
            findings.append(Finding("unaccounted", row["source"], f"(mesh {row['mesh_id']}) neither published nor "
                                    "failed: a run is at it, or was killed", "rerun `geodata prepare` on its folder"))
    return findings


def _duplicates(attrs: dict, orphaned: set) -> list[Finding]:
    """Published meshes, none an orphan, that hold one input (its name and sha256) under two ids: e.g. a format-1
    id and its 32-hex one from before 0.3.1's prepare knew upgraded stores. Training sees such an input twice."""
    same = defaultdict(list)
    for mesh_id, a in attrs.items():
        if mesh_id not in orphaned and a.get("sha256") and a.get("source"):
            same[(a["source"], a["sha256"])].append(mesh_id)
    return [Finding("duplicated", ", ".join(f"meshes/{m}.zip" for m in sorted(ids)),
                    f"one input ({source}, sha256 {digest[:12]}...) published {len(ids)} times: training sees it "
                    f"{len(ids)} times", f"delete all but {sorted(ids)[0]} (each with its .biharmonic/.points zips) "
                    f"while no run writes the store")
            for (source, digest), ids in sorted(same.items()) if len(ids) > 1]


def _remove(path: Path) -> bool:
    with contextlib.suppress(FileNotFoundError):
        path.unlink()
        return True
    return False


def remove_orphans(out, findings: list[Finding]) -> list[str]:
    """Delete the orphans among ``findings`` (each mesh with its subgroups); the files removed."""
    removed = []
    for f in findings:
        if f.kind == "orphan":
            mesh_id = f.name[len("meshes/"):-len(".zip")]
            for sub in (*store.SUBGROUPS, None):  # the mesh's own zip last: a crash leaves it orphaned still
                path = store.mesh_file(out, mesh_id, sub)
                if _remove(path):
                    removed.append(f"meshes/{path.name}")
    return removed


def remove_damaged(out, findings: list[Finding]) -> list[str]:
    """Delete the damaged zips and failure records among ``findings`` (a rerun of their stage redoes them); the
    entries removed."""
    removed = []
    for f in findings:
        if f.kind != "damaged":
            continue
        path = Path(out) / f.name
        if f.name.startswith("meshes/") and _remove(path):
            removed.append(f.name)
        elif f.name.startswith("failed/") and path.is_dir():
            shutil.rmtree(path, ignore_errors=True)
            removed.append(f.name)
    return removed


def summary(findings: list[Finding]) -> str:
    counts = {k: sum(f.kind == k for f in findings) for k in KINDS}
    return ", ".join(f"{n} {k}" for k, n in counts.items())
