"""`geodata biharmonic`: add exact biharmonic pairs to the committed meshes of a store."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from geodata.biharmonic import biharmonic_pairs
from geodata.mesh import Mesh
from geodata.subgroup import run_subgroup

__all__ = ["BiharmonicConfig", "process_biharmonic"]


@dataclass(frozen=True)
class BiharmonicConfig:
    pairs: int = 600_000
    seed: int = 0
    timeout: float = 1800.0
    max_memory: int | None = None  # bytes one mesh's process may use (None: no limit)


def _compute(mesh: Mesh, rng: np.random.Generator, config: BiharmonicConfig) -> dict:
    pairs, distances = biharmonic_pairs(mesh, config.pairs, rng)
    return {"pairs": pairs, "distances": distances}


def process_biharmonic(mesh_id: str, out: str, config: BiharmonicConfig) -> dict:
    """Compute and commit one mesh's biharmonic pairs, or record why not as failed/<id>.biharmonic."""
    return run_subgroup(mesh_id, out, "biharmonic", _compute, config, {"pairs_requested": config.pairs,
                                                                    "seed": config.seed})
