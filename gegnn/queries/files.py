"""A user's mesh file to predicted (and optionally exact) distances: the work behind ``gegnn query``.

Indices are the file's own vertex indices. The network runs on the file's mesh after cleaning
(coincident vertices merged, degenerate faces and unused vertices dropped), or with ``prepare`` on the
output of the geodata pipeline (watertight, remeshed to ~5k vertices: the meshes the model was trained
on); results are carried back to the file's vertices (through the merge, or to the nearest prepared
vertex).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from geodata.mesh import Mesh, MeshError

from ..fields.cache import FieldSpec
from ..metrics import METRIC_EPS

__all__ = ["QueryMesh", "load_query_mesh", "relative_errors", "read_pairs", "resolution_note", "read_indices",
           "read_points"]


@dataclass
class QueryMesh:
    path: str
    n_file_vertices: int
    mesh: Mesh              # the mesh the network runs on, in the file's units
    to_mesh: np.ndarray     # (n_file_vertices,) index into `mesh` (-1: vertex used by no face)
    scale: float            # half the longest bounding-box extent: the unit of the metric's offset

    def vertices(self, idx) -> np.ndarray:
        """The network-mesh vertices standing for file vertices ``idx`` (an int or an index array)."""
        idx = np.asarray(idx, dtype=np.int64)
        bad = (idx < 0) | (idx >= self.n_file_vertices)
        if bad.any():
            raise ValueError(f"vertex {idx[bad].flat[0]} out of range: {Path(self.path).name} has "
                             f"{self.n_file_vertices} vertices")
        out = self.to_mesh[idx]
        if (out < 0).any():
            raise ValueError(f"vertex {idx[out < 0].flat[0]} of {Path(self.path).name} is used by no face")
        return out

    def to_file(self, values: np.ndarray) -> np.ndarray:
        """Per-vertex values of `mesh` as values of the file's vertices (NaN where unused)."""
        out = np.full(self.n_file_vertices, np.nan, dtype=np.float64)
        used = self.to_mesh >= 0
        out[used] = values[self.to_mesh[used]]
        return out


def load_query_mesh(path, prepare: bool = False, target_vertices: int = 5000) -> QueryMesh:
    """Load and validate ``path`` (MeshError with the reason when it is not a usable mesh)."""
    from geodata.stages.load import load_mesh_file
    from geodata.stages.normalize import normalization

    mesh, to_clean = load_mesh_file(path)
    center, scale = normalization(mesh.vertices)
    if not scale > 0:
        raise MeshError("load", "mesh has zero extent")
    if not prepare:
        return QueryMesh(str(path), len(to_clean), mesh, to_clean, scale)

    from scipy.spatial import cKDTree

    from geodata.prepare import PrepareConfig, prepare_geometry

    prepared = prepare_geometry(mesh, PrepareConfig(target_vertices=target_vertices))
    p_center, p_scale = normalization(np.asarray(prepared.vertices, dtype=np.float64))
    # Back to the file's units: the prepared mesh spans (almost exactly) the input's bounding box.
    vertices = (prepared.vertices - p_center) * (scale / p_scale) + center
    nearest = cKDTree(vertices).query(mesh.vertices)[1]
    to_mesh = np.where(to_clean >= 0, nearest[np.maximum(to_clean, 0)], -1)
    return QueryMesh(str(path), len(to_clean), Mesh(vertices, prepared.faces), to_mesh, scale)


# Where the accuracy of each kind of model is known to hold (by the fields it reads), and what was measured
# of the shipped one (docs/applications.md, "Scalability and convergence"; biharmonic: docs/model-card.md).
RESOLUTION = {
    "landmark": (1000, 100_000, "the shipped landmark model was measured from 1,000 to 100,000 vertices "
                                "(1.0-1.2% on the validation meshes at 5k-80k, 0.5-0.7% on spheres of 1k-100k)"),
    "paper": (2000, 20_000, "the shipped paper model's error grows away from the ~5k vertices it was trained on "
                            "(9.8% at 5k, 11.3% at 80k, 16% on a sphere of 1k)"),
    "spectral": (4000, 6000, "the shipped biharmonic model was measured on meshes of ~5k vertices only"),
}


def resolution_note(n_vertices: int, config) -> str | None:
    """A word for a mesh outside the vertex counts where the model's accuracy is known to hold (by the
    fields the model reads: landmark, spectral, or none for the paper model), saying what was measured. A mesh
    embedded through a proxy (:mod:`gegnn.queries.proxy`) is judged by the proxy's size."""
    from .proxy import PROXY_ABOVE, PROXY_VERTICES

    spec = FieldSpec.of(config)
    low, high, measured = RESOLUTION[spec.kind if spec else "paper"]
    if low <= (PROXY_VERTICES if n_vertices > PROXY_ABOVE else n_vertices) <= high:  # what the network meets
        return None
    return (f"{n_vertices:,} vertices: {measured}; --prepare remeshes to ~5k first (results are carried back to "
            "this file's vertices)")


def relative_errors(pred: np.ndarray, exact: np.ndarray, scale: float, source: int) -> np.ndarray:
    """|pred - exact| / (exact + 1e-3 in normalized units): the training metric, per vertex (NaN at the
    source and where exact is undefined, e.g. another component)."""
    err = np.abs(pred - exact) / (exact + METRIC_EPS * scale)
    err[source] = np.nan
    return err


def read_indices(path) -> np.ndarray:
    """Vertex indices (R,) int64 from a .npy array or a text/CSV file of one integer per line (a header
    line is allowed)."""
    if str(path).endswith(".npy"):
        values = np.load(path, allow_pickle=False)
        if not np.issubdtype(values.dtype, np.integer) or values.ndim != 1:
            raise ValueError(f"{path}: expected a 1-D array of integer vertex indices, got {values.dtype} "
                             f"{values.shape}")
        return values.astype(np.int64)
    return _read_columns(path, np.int64, 0, "one integer vertex index per line")


def read_points(path) -> np.ndarray:
    """xyz points (P, 3) float64 from a .npy array or a CSV file of three columns x,y,z (a header line is
    allowed)."""
    if str(path).endswith(".npy"):
        points = np.load(path, allow_pickle=False)
    else:
        points = _read_columns(path, np.float64, (0, 1, 2), "three number columns x,y,z")
    if points.ndim != 2 or points.shape[1] != 3 or not len(points) or not np.isfinite(points).all():
        raise ValueError(f"{path}: expected finite points of shape (P, 3), got {points.dtype} {points.shape}")
    return np.asarray(points, dtype=np.float64)


def read_pairs(path) -> np.ndarray:
    """Pairs (P, 2) int64 from a CSV file of two integer columns; a header line is allowed."""
    pairs = _read_columns(path, np.int64, (0, 1), "two integer columns i,j")
    if not len(pairs):
        raise ValueError(f"{path}: no pairs")
    return pairs


def _read_columns(path, dtype, columns, expected: str) -> np.ndarray:
    """Columns of a CSV text file as ``dtype`` (1-D for one column); a first line whose first field is no
    such number is a header and skipped."""
    from geodata.stages.load import is_index, is_number

    lines = [line for line in Path(path).read_text().splitlines() if line.strip()]
    is_value = is_index if np.issubdtype(dtype, np.integer) else is_number
    header = bool(lines) and not is_value(lines[0].split(",")[0].strip())
    try:
        return np.loadtxt(lines[header:], delimiter=",", dtype=dtype, usecols=columns,
                          ndmin=1 if np.isscalar(columns) else 2)
    except ValueError as exc:
        raise ValueError(f"{path}: expected {expected} ({exc})") from None
