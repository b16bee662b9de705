r"""Points on a mesh's surface with exact geodesic distances between them: the data of point-cloud models
(``geodata points``).

* **Samples**: N points, area-uniform: a face with probability proportional to its area, then uniform in
  it, :math:`b = (1 - \sqrt{r_1},\ \sqrt{r_1}(1 - r_2),\ \sqrt{r_1}\,r_2)` for uniform :math:`r_1, r_2`;
  each with the barycentric blend of its corners' vertex normals, normalized (what a scanner's smooth
  normals look like).
* **Exact distances**: the points inserted as vertices (:func:`geodata.surface_points.insert_points`: the
  same surface, refined), so the exact solver's vertex-to-vertex distances are exact distances between
  the points; where a point falls on a vertex it is that vertex, and its distances are the solver's own.
  Sources are random points; targets every other point of the source's connected component.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np

from geodata.mesh import Mesh, face_areas, vertex_components, vertex_normals
from geodata.surface_points import insert_points

__all__ = ["SurfaceSamples", "sample_points", "point_pairs"]


class SurfaceSamples(NamedTuple):
    """N surface points: ``face`` (N,) int64, ``bary`` (N, 3) barycentric coordinates in it, ``xyz`` (N, 3)
    and unit ``normals`` (N, 3)."""

    face: np.ndarray
    bary: np.ndarray
    xyz: np.ndarray
    normals: np.ndarray


def sample_points(mesh: Mesh, n: int, rng: np.random.Generator) -> SurfaceSamples:
    """``n`` area-uniform points of ``mesh`` with interpolated vertex normals (see the module)."""
    tri = mesh.vertices[mesh.faces]
    area = face_areas(mesh.vertices, mesh.faces)
    if not area.sum() > 0:
        raise ValueError("the mesh has no area to sample")
    face = rng.choice(len(area), size=n, p=area / area.sum())
    r1, r2 = np.sqrt(rng.random(n)), rng.random(n)
    bary = np.stack([1 - r1, r1 * (1 - r2), r1 * r2], axis=1)
    xyz = np.einsum("pk,pkd->pd", bary, tri[face])
    normals = np.einsum("pk,pkd->pd", bary, vertex_normals(mesh)[mesh.faces[face]])
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-30)
    return SurfaceSamples(face.astype(np.int64), bary, xyz, normals)


def point_pairs(mesh: Mesh, samples: SurfaceSamples, pairs: int, rng: np.random.Generator,
                backend: str = "vtp") -> tuple[np.ndarray, np.ndarray]:
    """Exact geodesic distances between the samples: ceil(pairs / N) random source points x every other
    point of their component. Returns pairs (P, 2) int64 (indices of the samples) and distances (P,)."""
    from geodata.geodesic import geodesic_solver

    n = len(samples.face)
    refined, vertex = insert_points(mesh, samples.face, samples.bary)
    component = vertex_components(refined)[vertex]
    solve = geodesic_solver(refined, backend)
    sources = rng.choice(n, size=min(n, -(-pairs // n)), replace=False)
    out_pairs, out_dist = [], []
    for s in sources:
        targets = np.flatnonzero((component == component[s]) & (np.arange(n) != s))
        out_pairs.append(np.stack([np.full(len(targets), s), targets], axis=1))
        out_dist.append(solve(int(vertex[s]))[vertex[targets]])
    return (np.concatenate(out_pairs).astype(np.int64), np.concatenate(out_dist).astype(np.float32))
