"""Stages that add a subgroup to every published mesh of a store (``geodata biharmonic``, ``geodata
points``): which meshes still need it, and one mesh's run in an isolated process, its result published as meshes/<id>.<subgroup>.zip, or recorded as failed/<id>.<subgroup>."""
from __future__ import annotations

import time

from geodata import store
from geodata.mesh import Mesh, MeshError
from geodata.parallel import current_stage, run_isolated
from geodata.prepare import mesh_rng

__all__ = ["pending", "run_subgroup", "DAMAGED_MESH"]

DAMAGED_MESH = "damaged mesh"  # the stage of a subgroup's failure whose mesh's own zip could not be read


def pending(out, subgroup: str, keep=None, retry_failed: bool = False) -> tuple[list[str], int, int]:
    """The published meshes (those ``keep(mesh_id)`` accepts: a shard) whose ``subgroup`` is still to do, in id
    order (a damaged one too: :func:`geodata.store.damage`); and how many are done and failed. A failure for a
    damaged mesh counts until the mesh is whole again (geodata prepare redid it): then it is to do. One listing
    of meshes/, then only this shard's failure records and the directory of its published subgroup zips (and of
    a mesh whose failure was its damage): no mesh is opened."""
    meshes = store.list_meshes(out)
    mine = [m for m in meshes if keep is None or keep(m)]
    failures = store.list_failures(out, {f"{m}.{subgroup}" for m in mine})
    failed = {name.rsplit(".", 1)[0] for name, failure in failures.items() if not _repaired(out, name, failure)}
    damaged = {m for m in mine if subgroup in meshes[m] and store.damage(out, m, subgroup)}  # redone
    done = [m for m in mine if subgroup in meshes[m] and m not in damaged]
    todo = [m for m in mine if (subgroup not in meshes[m] or m in damaged) and (retry_failed or m not in failed)]
    return todo, len(done), 0 if retry_failed else len(failed - set(done))


def _repaired(out, name: str, failure: dict) -> bool:
    """Whether the failure ``name`` (<mesh_id>.<subgroup>) was its mesh's damage and that mesh is whole now."""
    return failure.get("stage") == DAMAGED_MESH and store.damage(out, name.rsplit(".", 1)[0]) is None


def run_subgroup(mesh_id: str, out: str, subgroup: str, compute, config, attrs: dict) -> dict:
    """``compute(mesh, rng, config) -> arrays`` for one published mesh in an isolated process (within
    ``config.timeout``; ``rng``: the mesh's own stream for this subgroup), published as
    meshes/<id>.<subgroup>.zip with ``attrs``; a MeshError, or the mesh's own zip found damaged, is recorded as
    failed/<id>.<subgroup> instead: one mesh never stops the shard. Returns the run's summary row."""
    start = time.perf_counter()
    row = {"mesh_id": mesh_id, "source": mesh_id, "warnings": []}
    name = f"{mesh_id}.{subgroup}"
    try:
        row["source"] = _source(out, mesh_id)
        arrays, seconds = run_isolated(_in_child, compute, out, mesh_id, subgroup, config, timeout=config.timeout,
                                       warnings_out=row["warnings"], max_memory=config.max_memory)
    except MeshError as exc:
        store.record_failure(out, name, row["source"], exc.stage, exc.reason)
        return {**row, "status": "failed", "stage": exc.stage, "error": exc.reason,
                "seconds": time.perf_counter() - start}
    store.remove_damaged(out, mesh_id, subgroup)  # a damaged one is replaced; a whole one never
    store.write_mesh(out, mesh_id, arrays, {**attrs, "seconds": round(seconds, 4)}, subgroup)
    store.clear_failure(out, name)
    return {**row, "status": "ok", "timings": {subgroup: seconds}, "seconds": time.perf_counter() - start}


def _source(out, mesh_id: str) -> str:
    """The input file a published mesh was prepared from (its id where it does not say); MeshError(DAMAGED_MESH)
    where the mesh's zip is damaged, for the caller to record as this mesh's failure."""
    try:
        return (store.mesh_attrs(out, mesh_id) or {}).get("source", mesh_id)
    except store.DamagedMeshError as exc:
        raise MeshError(DAMAGED_MESH, f"{exc.reason}: a rerun of geodata prepare redoes the mesh, and a rerun of "
                                      f"this stage then its subgroup") from None


def _in_child(compute, out: str, mesh_id: str, subgroup: str, config) -> tuple[dict, float]:
    """The isolated process's part: the published mesh, its random stream for ``subgroup`` (distinct from
    the geodesic one and from other subgroups', as reproducible), ``compute`` timed."""
    current_stage(subgroup)
    with store.read_mesh(out, mesh_id) as group:
        mesh = Mesh(group["vertices"][:], group["faces"][:])
    start = time.perf_counter()
    arrays = compute(mesh, mesh_rng(config.seed, f"{mesh_id}/{subgroup}"), config)
    return arrays, time.perf_counter() - start
