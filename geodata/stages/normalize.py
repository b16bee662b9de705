"""Stage 5, normalize: center the bounding box, scale the longest half-extent to exactly 1, round to float32."""
from __future__ import annotations

import numpy as np

from geodata.mesh import Mesh, MeshError

__all__ = ["normalize", "normalization"]


def normalization(vertices: np.ndarray) -> tuple[np.ndarray, float]:
    """Center and scale mapping a mesh into [-1, 1]^3: normalized = (v - center) / scale."""
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    return (lo + hi) / 2, float((hi - lo).max() / 2)


def normalize(mesh: Mesh) -> Mesh:
    center, scale = normalization(mesh.vertices)
    if not scale > 0:
        raise MeshError("normalize", "mesh has zero extent")
    v = (mesh.vertices - center) / scale
    # Round-off can leave the extreme coordinate at 1 +- 1 ulp; make the contract exact.
    axis = int(np.argmax(v.max(axis=0) - v.min(axis=0)))
    v[np.argmax(v[:, axis]), axis] = 1.0
    v[np.argmin(v[:, axis]), axis] = -1.0
    # The store keeps float32: round here so that distances are computed on exactly the stored mesh.
    return Mesh(v.astype(np.float32), mesh.faces)
