"""Stage 1, load: bytes of a mesh file to a validated, cleaned triangle mesh."""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import trimesh

from geodata.mesh import Mesh, MeshError, one_line

__all__ = ["MESH_SUFFIXES", "load_mesh_bytes", "load_mesh_file", "clean"]

MESH_SUFFIXES = (".obj", ".off", ".ply", ".stl", ".glb")


def load_mesh_file(path) -> tuple[Mesh, np.ndarray]:
    """Load, validate and clean a mesh file; also return, for every vertex of the file, its index in
    the cleaned mesh (-1 for vertices no face uses), so results can be reported on the file's vertices."""
    return load_mesh_bytes(Path(path).read_bytes(), Path(path).suffix, return_map=True)


def load_mesh_bytes(data: bytes, suffix: str, return_map: bool = False):
    """Parse a mesh file's bytes (format from `suffix`), validate it and clean it.

    Raises MeshError("load", reason) for anything that is not a usable triangle mesh.
    """
    if len(data) == 0:
        raise MeshError("load", "empty file")
    data = _utf8_text(data, suffix)
    try:
        # process=False: keep the file's indices so validation sees what the file really says.
        loaded = trimesh.load(io.BytesIO(data), file_type=suffix.lstrip(".").lower(), process=False,
                              force="mesh")
    except Exception as exc:  # trimesh raises many types for garbage input
        raise MeshError("load", f"unreadable as {suffix.lstrip('.').upper()}: {one_line(exc, with_type=False)}") from None
    if not isinstance(loaded, trimesh.Trimesh):
        raise MeshError("load", "file holds no triangle mesh")
    vertices = np.asarray(loaded.vertices, dtype=np.float64).reshape(-1, 3)
    faces = np.asarray(loaded.faces).reshape(-1, 3)
    return clean(vertices, faces, return_map)


TEXT_SUFFIXES = (".obj", ".off")  # always text; PLY and STL may be binary and are passed through


def _utf8_text(data: bytes, suffix: str) -> bytes:
    """Text formats as UTF-8: a file that is not valid UTF-8 (a Latin-1 byte in a material or group
    name, common in the wild) is read as Latin-1, which decodes any byte. Without this, trimesh asks
    for the optional charset_normalizer module to guess the encoding."""
    if suffix.lower() not in TEXT_SUFFIXES:
        return data
    try:
        data.decode("utf-8")
        return data
    except UnicodeDecodeError:
        return data.decode("latin-1").encode("utf-8")


def clean(vertices: np.ndarray, faces: np.ndarray, return_map: bool = False):
    """Validate raw arrays, then merge duplicate vertices and drop degenerate faces and unused vertices.

    With `return_map`, also the index in the cleaned mesh of every input vertex (-1: dropped)."""
    if len(faces) == 0:
        raise MeshError("load", "no faces")
    if not np.isfinite(vertices).all():
        raise MeshError("load", f"{int((~np.isfinite(vertices)).any(axis=1).sum())} vertices with NaN/inf coordinates")
    if not np.issubdtype(faces.dtype, np.integer):
        raise MeshError("load", "non-integer face indices")
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise MeshError("load", f"face index out of range (faces reference {int(faces.max())}, "
                                f"file has {len(vertices)} vertices)")
    # Merge coincident vertices exactly (soups duplicate them per part or per face).
    unique, inverse = np.unique(vertices, axis=0, return_inverse=True)
    faces = inverse.reshape(-1)[faces]
    keep = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 2] != faces[:, 0])
    faces = faces[keep]
    if len(faces):
        e1 = unique[faces[:, 1]] - unique[faces[:, 0]]
        e2 = unique[faces[:, 2]] - unique[faces[:, 0]]
        area2 = np.linalg.norm(np.cross(e1, e2), axis=1)
        scale = np.ptp(unique, axis=0).max()
        faces = faces[area2 > 1e-12 * scale * scale]
    if len(faces) == 0:
        raise MeshError("load", "all faces are degenerate (zero area)")
    used, compact = np.unique(faces, return_inverse=True)
    mesh = Mesh(unique[used], compact.reshape(-1, 3))
    if not return_map:
        return mesh
    to_clean = np.full(len(unique), -1, dtype=np.int64)
    to_clean[used] = np.arange(len(used))
    return mesh, to_clean[inverse.reshape(-1)]

