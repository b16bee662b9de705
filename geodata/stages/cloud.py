"""Point-cloud files to validated points (and normals where the file has them).

Formats: ``.xyz``/``.txt``/``.pts``/``.csv`` (one point a line: x y z, or x y z nx ny nz; with other counts
x y z are the first three; separators spaces, tabs or commas; a header line and ``#`` comments
allowed), ``.npy`` ((N, 3) or more columns, the same way), ``.ply`` (the vertex element's x, y, z and,
where present, nx, ny, nz; faces are ignored). Every failure is a MeshError("load", reason) in the
file's terms: which line, which value.

Defined behaviour for what scans hold: exact duplicates are kept (the model merges them and gives them
one code); points far from all others (``outliers``: their mean distance to their k nearest neighbours
over OUTLIER_RATIO times their neighbours') are found, and left out by ``gegnn query``; zero or non-finite normals
make the file's normals unusable (they are then estimated, with a note).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from geodata.mesh import MeshError
from geodata.stages.load import explain, is_number

__all__ = ["CLOUD_SUFFIXES", "PointCloud", "load_cloud_file", "outliers", "OUTLIER_RATIO"]

CLOUD_SUFFIXES = (".xyz", ".txt", ".pts", ".csv", ".npy", ".ply")
OUTLIER_RATIO = 5.0
OUTLIER_K = 8


@dataclass
class PointCloud:
    """Points (N, 3) float64 in the file's units and order, the file's unit normals (N, 3) or None, and
    notes on what was found (one line each)."""

    points: np.ndarray
    normals: np.ndarray | None = None
    notes: list[str] = field(default_factory=list)


def load_cloud_file(path) -> PointCloud:
    """Read and validate a point-cloud file (see the module for formats); MeshError("load", reason)."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in CLOUD_SUFFIXES:
        raise MeshError("load", f"not a point-cloud file ({', '.join(CLOUD_SUFFIXES)})")
    columns = {".npy": _npy_columns, ".ply": _ply_columns}.get(suffix, _text_columns)(path)
    if len(columns) == 0:
        raise MeshError("load", "no points")
    cloud = PointCloud(np.ascontiguousarray(columns[:, :3], dtype=np.float64))
    if columns.shape[1] not in (3, 6):
        cloud.notes.append(f"{columns.shape[1]} values a point: x y z read from the first three, the rest ignored "
                           "(normals are read from exactly six: x y z nx ny nz)")
    elif columns.shape[1] == 6:
        normals = columns[:, 3:6].astype(np.float64)
        length = np.linalg.norm(normals, axis=1)
        bad = ~np.isfinite(length) | (length < 1e-12)
        if bad.any():
            cloud.notes.append(f"{int(bad.sum())} normals are zero or not finite (the first at point "
                               f"{int(np.argmax(bad))}): normals estimated from the points instead")
        else:
            cloud.normals = normals / length[:, None]
    return cloud


def outliers(points: np.ndarray, k: int = OUTLIER_K, ratio: float = OUTLIER_RATIO) -> np.ndarray:
    """Indices of points far from all others: their mean distance to their k nearest neighbours over the
    median of their neighbours' own exceeds ``ratio`` (a local comparison, so a cloud whose density varies
    tenfold, by sqrt(10) in spacing, keeps its sparse parts); none below 2k + 2 points."""
    from scipy.spatial import cKDTree

    if len(points) < 2 * k + 2:
        return np.zeros(0, dtype=np.int64)
    d, nbrs = cKDTree(points).query(points, k + 1)
    spread = d[:, 1:].mean(axis=1)
    local = np.median(spread[nbrs[:, 1:]], axis=1)
    return np.flatnonzero(spread > ratio * np.maximum(local, 1e-300))


def _text_columns(path: Path) -> np.ndarray:
    text = path.read_bytes().decode("utf-8", errors="replace")
    rows, width, start = [], None, None
    for number, line in enumerate(text.splitlines(), 1):
        line = line.split("#", 1)[0].strip()
        if not line:
            continue
        words = line.replace(",", " ").replace(";", " ").split()
        try:
            values = [float(w) for w in words]
        except ValueError:
            if not rows and start is None:  # a header line
                start = number
                continue
            bad = next(w for w in words if not is_number(w))
            raise MeshError("load", f"line {number}: {bad[:20]!r} is not a number") from None
        if width is None:
            if len(values) < 3:
                raise MeshError("load", f"line {number}: {len(values)} values (expected x y z, optionally "
                                        "followed by nx ny nz)")
            width = len(values)
        elif len(values) != width:
            raise MeshError("load", f"line {number}: {len(values)} values where the lines before have {width}")
        if not all(np.isfinite(values)):
            raise MeshError("load", f"line {number}: a value is not finite ({line[:60]})")
        rows.append(values)
    return np.asarray(rows) if rows else np.zeros((0, 3))


def _npy_columns(path: Path) -> np.ndarray:
    try:
        a = np.load(path, allow_pickle=False)
    except ValueError as exc:
        raise MeshError("load", "not a NumPy array file of numbers (object arrays are refused)"
                        if "pickle" in str(exc) else "not a readable NumPy .npy file") from None
    except (OSError, EOFError):
        raise MeshError("load", "not a readable NumPy .npy file (truncated or another format)") from None
    if a.ndim != 2 or a.shape[1] < 3 or not np.issubdtype(a.dtype, np.number):
        raise MeshError("load", f"array of shape {a.shape} and type {a.dtype}: expected (N, 3) points or (N, 6) "
                                "points and normals")
    bad = np.flatnonzero(~np.isfinite(a[:, :3]).all(axis=1))
    if len(bad):
        raise MeshError("load", f"row {bad[0]}: a coordinate is not finite")
    return a.astype(np.float64)


def _ply_columns(path: Path) -> np.ndarray:
    import trimesh

    try:
        loaded = trimesh.load(path, file_type="ply", process=False)
    except Exception:  # trimesh raises many types for garbage input
        reason = explain(path.read_bytes(), ".ply") or "the data does not follow the PLY format"
        raise MeshError("load", reason) from None
    points = np.asarray(getattr(loaded, "vertices", np.zeros((0, 3))), dtype=np.float64)
    raw = loaded.metadata.get("_ply_raw", {}).get("vertex", {}).get("data")  # {property: values}
    names = raw.dtype.names if isinstance(raw, np.ndarray) else raw if isinstance(raw, dict) else ()
    if all(name in (names or ()) for name in ("nx", "ny", "nz")):
        normals = np.stack([np.ravel(raw["nx"]), np.ravel(raw["ny"]), np.ravel(raw["nz"])], axis=1).astype(np.float64)
        if len(normals) == len(points):
            points = np.concatenate([points, normals], axis=1)
    bad = np.flatnonzero(~np.isfinite(points[:, :3]).all(axis=1))
    if len(bad):
        raise MeshError("load", f"vertex {bad[0]}: a coordinate is not finite")
    return points
