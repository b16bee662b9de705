"""`geodata biharmonic`: add exact biharmonic pairs to the committed meshes of a store."""
from __future__ import annotations

import time
from dataclasses import dataclass

import zarr

from geodata.biharmonic import biharmonic_pairs
from geodata.mesh import Mesh
from geodata.parallel import current_stage
from geodata.prepare import mesh_rng
from geodata.subgroup import run_subgroup

__all__ = ["BiharmonicConfig", "process_biharmonic"]


@dataclass(frozen=True)
class BiharmonicConfig:
    pairs: int = 600_000
    seed: int = 0
    timeout: float = 1800.0


def _compute(out: str, mesh_id: str, config: BiharmonicConfig) -> tuple[dict, float]:
    current_stage("biharmonic")
    group = zarr.open_group(f"{out}/meshes/{mesh_id}", mode="r")
    mesh = Mesh(group["vertices"][:], group["faces"][:])
    # The stream is distinct from the geodesic one (another key), but as reproducible.
    start = time.perf_counter()
    pairs, distances = biharmonic_pairs(mesh, config.pairs, mesh_rng(config.seed, f"{mesh_id}/biharmonic"))
    return {"pairs": pairs, "distances": distances}, time.perf_counter() - start


def process_biharmonic(task: tuple[str, str], out: str, config: BiharmonicConfig) -> dict:
    """Compute and commit one mesh's biharmonic pairs, or record why not in meshes/<id>/biharmonic."""
    return run_subgroup(task, out, "biharmonic", _compute, config, {"pairs_requested": config.pairs,
                                                                    "seed": config.seed})
