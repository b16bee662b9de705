"""`geodata points`: add surface points with exact geodesic pairs to the committed meshes of a store."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from geodata.mesh import Mesh, MeshError
from geodata.point_samples import point_pairs, sample_points
from geodata.subgroup import run_subgroup

__all__ = ["PointsConfig", "process_points"]


@dataclass(frozen=True)
class PointsConfig:
    points: int = 8000
    pairs: int = 600_000
    seed: int = 0
    timeout: float = 1800.0
    max_memory: int | None = None  # bytes one mesh's process may use (None: no limit)


def _compute(mesh: Mesh, rng: np.random.Generator, config: PointsConfig) -> dict:
    try:
        samples = sample_points(mesh, config.points, rng)
    except ValueError as exc:
        raise MeshError("points", str(exc)) from None
    pairs, distances = point_pairs(mesh, samples, config.pairs, rng)
    return {"xyz": samples.xyz.astype(np.float32), "normals": samples.normals.astype(np.float32),
            "face": samples.face.astype(np.int32), "bary": samples.bary.astype(np.float32),
            "pairs": pairs.astype(np.uint32), "distances": distances}


def process_points(mesh_id: str, out: str, config: PointsConfig) -> dict:
    """Compute and commit one mesh's points and their pairs, or record why not as failed/<id>.points."""
    return run_subgroup(mesh_id, out, "points", _compute, config, {"points": config.points,
                                                                "pairs_requested": config.pairs, "seed": config.seed})
