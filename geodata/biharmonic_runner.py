"""`geodata biharmonic`: add exact biharmonic pairs to the committed meshes of a store."""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import zarr

from geodata import store
from geodata.biharmonic import biharmonic_pairs
from geodata.mesh import Mesh, MeshError
from geodata.parallel import current_stage, in_shard, run_isolated
from geodata.prepare import mesh_rng

__all__ = ["BiharmonicConfig", "select_biharmonic", "process_biharmonic"]


@dataclass(frozen=True)
class BiharmonicConfig:
    pairs: int = 600_000
    seed: int = 0
    timeout: float = 1800.0


def select_biharmonic(out: str, shard: tuple[int, int], retry_failed: bool = False
                      ) -> tuple[list[tuple[str, str]], int, int]:
    """(mesh id, source) of this shard's committed meshes still needing biharmonic data; counts done, failed."""
    committed = {k: a["source"] for k, a in store.list_meshes(out).items() if a and a.get("status") == "ok"}
    status = {k: store.mesh_status(out, f"{k}/biharmonic") for k in committed if in_shard(k, shard)}
    todo = [(k, committed[k]) for k, s in sorted(status.items())
            if s is None or (s == "failed" and retry_failed)]
    n_failed = sum(s == "failed" for s in status.values())
    return todo, sum(s == "ok" for s in status.values()), 0 if retry_failed else n_failed


def _compute(out: str, mesh_id: str, config: BiharmonicConfig) -> tuple[np.ndarray, np.ndarray, float]:
    current_stage("biharmonic")
    group = zarr.open_group(f"{out}/meshes/{mesh_id}", mode="r")
    mesh = Mesh(group["vertices"][:], group["faces"][:])
    # The stream is distinct from the geodesic one (another key), but as reproducible.
    start = time.perf_counter()
    pairs, distances = biharmonic_pairs(mesh, config.pairs, mesh_rng(config.seed, f"{mesh_id}/biharmonic"))
    return pairs, distances, time.perf_counter() - start


def process_biharmonic(task: tuple[str, str], out: str, config: BiharmonicConfig) -> dict:
    """Compute and commit one mesh's biharmonic pairs, or record why not in meshes/<id>/biharmonic."""
    mesh_id, source = task
    start = time.perf_counter()
    row = {"mesh_id": mesh_id, "source": source, "warnings": []}
    path = f"meshes/{mesh_id}/biharmonic"
    try:
        pairs, distances, seconds = run_isolated(_compute, out, mesh_id, config, timeout=config.timeout,
                                                 warnings_out=row["warnings"])
    except MeshError as exc:
        store.write_group(out, path, {}, {"status": "failed", "stage": exc.stage, "error": exc.reason})
        return {**row, "status": "failed", "stage": exc.stage, "error": exc.reason,
                "seconds": time.perf_counter() - start}
    store.write_group(out, path, {"pairs": pairs, "distances": distances},
                      {"pairs_requested": config.pairs, "seed": config.seed, "seconds": round(seconds, 4)})
    store.commit(out, path)
    return {**row, "status": "ok", "timings": {"biharmonic": seconds}, "seconds": time.perf_counter() - start}
