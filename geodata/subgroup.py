"""Stages that add a subgroup to every committed mesh of a store (``geodata biharmonic``, ``geodata
points``): which meshes still need it, and one mesh's run in an isolated process, committed by its own
status "ok" written last, or recorded there as failed."""
from __future__ import annotations

import time

import zarr

from geodata import store
from geodata.mesh import Mesh, MeshError
from geodata.parallel import current_stage, run_isolated
from geodata.prepare import mesh_rng

__all__ = ["pending", "run_subgroup"]


def pending(out, subgroup: str, keep=None, retry_failed: bool = False) -> tuple[list[tuple[str, str]], int, int]:
    """(mesh id, source) of the committed meshes (those ``keep(mesh_id)`` accepts: a shard) whose
    ``subgroup`` is still to do, in id order; and how many are done and failed."""
    committed = {k: a["source"] for k, a in store.list_meshes(out).items() if a and a.get("status") == "ok"}
    status = {k: store.mesh_status(out, f"{k}/{subgroup}") for k in committed if keep is None or keep(k)}
    todo = [(k, committed[k]) for k, s in sorted(status.items()) if s is None or (s == "failed" and retry_failed)]
    n_failed = sum(s == "failed" for s in status.values())
    return todo, sum(s == "ok" for s in status.values()), 0 if retry_failed else n_failed


def run_subgroup(task: tuple[str, str], out: str, subgroup: str, compute, config, attrs: dict) -> dict:
    """``compute(mesh, rng, config) -> arrays`` for one committed mesh in an isolated process (within
    ``config.timeout``; ``rng``: the mesh's own stream for this subgroup), written to
    meshes/<id>/<subgroup> with ``attrs`` and committed; a MeshError is recorded there instead. Returns the
    run's summary row."""
    mesh_id, source = task
    start = time.perf_counter()
    row = {"mesh_id": mesh_id, "source": source, "warnings": []}
    path = f"meshes/{mesh_id}/{subgroup}"
    try:
        arrays, seconds = run_isolated(_in_child, compute, out, mesh_id, subgroup, config, timeout=config.timeout,
                                       warnings_out=row["warnings"])
    except MeshError as exc:
        store.write_group(out, path, {}, {"status": "failed", "stage": exc.stage, "error": exc.reason})
        return {**row, "status": "failed", "stage": exc.stage, "error": exc.reason,
                "seconds": time.perf_counter() - start}
    store.write_group(out, path, arrays, {**attrs, "seconds": round(seconds, 4)})
    store.commit(out, path)
    return {**row, "status": "ok", "timings": {subgroup: seconds}, "seconds": time.perf_counter() - start}


def _in_child(compute, out: str, mesh_id: str, subgroup: str, config) -> tuple[dict, float]:
    """The isolated process's part: the committed mesh, its random stream for ``subgroup`` (distinct from
    the geodesic one and from other subgroups', as reproducible), ``compute`` timed."""
    current_stage(subgroup)
    group = zarr.open_group(f"{out}/meshes/{mesh_id}", mode="r")
    mesh = Mesh(group["vertices"][:], group["faces"][:])
    start = time.perf_counter()
    arrays = compute(mesh, mesh_rng(config.seed, f"{mesh_id}/{subgroup}"), config)
    return arrays, time.perf_counter() - start
