"""Stage 1, load: bytes of a mesh file to a validated, cleaned triangle mesh."""
from __future__ import annotations

import contextlib
import io
import logging
import warnings
from pathlib import Path

import numpy as np
import trimesh

from geodata.mesh import Mesh, MeshError, face_areas, one_line
from geodata.stages.polygons import (PolygonError, off_layout, triangulate_faces, triangulate_obj_text,
                                     triangulate_off_text)

__all__ = ["MESH_SUFFIXES", "load_mesh_bytes", "load_mesh_file", "clean", "explain"]

MESH_SUFFIXES = (".obj", ".off", ".ply", ".stl", ".glb")


def load_mesh_file(path) -> tuple[Mesh, np.ndarray]:
    """Load, validate and clean a mesh file; also return, for every vertex of the file, its index in
    the cleaned mesh (-1 for vertices no face uses), so results can be reported on the file's vertices."""
    return load_mesh_bytes(Path(path).read_bytes(), Path(path).suffix, return_map=True)


class _AsWarning(logging.Handler):
    def emit(self, record: logging.LogRecord) -> None:
        warnings.warn(f"trimesh: {record.getMessage()}", stacklevel=1)


@contextlib.contextmanager
def _library_log_as_warnings():
    """trimesh logs what it skips in a file at WARNING with a traceback (e.g. "failed to extract
    face_normals" of an ASCII STL whose normals do not parse: normals are recomputed anyway), which an
    unconfigured program prints whole. Here each becomes one Python warning, without the traceback:
    geodata prepare writes each distinct one to its --log file, a command prints one line."""
    log = logging.getLogger("trimesh")
    handler, propagate = _AsWarning(logging.WARNING), log.propagate
    log.addHandler(handler)
    log.propagate = False
    try:
        yield
    finally:
        log.removeHandler(handler)
        log.propagate = propagate


def load_mesh_bytes(data: bytes, suffix: str, return_map: bool = False):
    """Parse a mesh file's bytes (format from `suffix`), validate and clean the mesh (see `load_mesh_file`);
    MeshError("load", reason) for anything that is not a usable triangle mesh."""
    if len(data) == 0:
        raise MeshError("load", "empty file")
    data = _utf8_text(data, suffix)
    parsed = _triangulated(data, suffix)
    try:
        # process=False: keep the file's indices so validation sees what the file really says;
        # maintain_order: an OBJ's vertices are not split at texture or normal seams, so vertex k of
        # the result is the file's k-th `v` line.
        with _library_log_as_warnings():
            loaded = trimesh.load(io.BytesIO(parsed), file_type=suffix.lstrip(".").lower(), process=False,
                                  force="mesh", maintain_order=True)
    except Exception as exc:  # trimesh raises many types for garbage input
        raise MeshError("load", explain(data, suffix) or _unreadable(exc, suffix)) from None
    if not isinstance(loaded, trimesh.Trimesh):
        raise MeshError("load", "file holds no triangle mesh")
    vertices = np.asarray(loaded.vertices, dtype=np.float64)
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise MeshError("load", explain(data, suffix) or "vertex coordinates are not (x, y, z) triples")
    faces = np.asarray(loaded.faces).reshape(-1, 3)
    polygons = _ply_polygons(loaded) if suffix.lower() == ".ply" else None
    if polygons is not None:  # trimesh fanned them: ear-clip the file's own corner lists instead
        try:
            faces = triangulate_faces(vertices, polygons)
        except PolygonError as exc:
            raise MeshError("load", str(exc)) from None
    if len(faces) == 0:  # a truncated file, or a point cloud (trimesh drops an OBJ's lone vertices)
        n = len(vertices) or _file_vertex_count(data, suffix)
        raise MeshError("load", explain(data, suffix) or (f"point cloud: {n} vertices and no faces" if n
                                                          else "no vertices and no faces"))
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


def _ply_polygons(loaded):
    """A PLY's face corner lists as read by trimesh, when some face has more than 3 corners (else None)."""
    face = loaded.metadata.get("_ply_raw", {}).get("face", {}).get("data", {})
    lists = face.get("vertex_indices", face.get("vertex_index")) if isinstance(face, dict) else None
    if lists is None or (lists.dtype != object and lists.ndim == 2 and lists.shape[1] == 3):
        return None
    return list(lists) if lists.dtype == object else lists


def _triangulated(data: bytes, suffix: str) -> bytes:
    """OBJ/OFF polygon faces ear-clipped in their plane (trimesh would fan them: wrong when concave);
    MeshError where a polygon cannot be."""
    triangulate = {".obj": triangulate_obj_text, ".off": triangulate_off_text}.get(suffix.lower())
    if triangulate is None:
        return data
    try:
        return triangulate(data.decode("utf-8")).encode("utf-8")
    except PolygonError as exc:
        raise MeshError("load", str(exc)) from None
    except (ValueError, IndexError):
        return data  # malformed: the parser and `explain` say why


def explain(data: bytes, suffix: str) -> str | None:
    """Why a file the parser refused is broken, in the file's own terms (its line numbers, its index
    base, its header's counts); None when no structural defect is found."""
    check = {".obj": _explain_obj, ".off": _explain_off, ".ply": _explain_ply, ".stl": _explain_stl}.get(
        suffix.lower())
    try:
        return check(data) if check else None
    except (ValueError, IndexError, KeyError, StopIteration, UnicodeDecodeError):
        return None


# What the parser's own words mean in the file's terms, for the defects `explain` cannot pin down.
PARSER_SAYS = {
    "unexpected length": "the binary data does not match the header's elements and properties (a truncated "
                         "file, or counts or property types changed in the header)",
    "chunk was not expected length": "its chunk lengths do not match the data (a truncated or corrupted file)",
    "multiple of element size": "a buffer's length does not match its accessors (a truncated or corrupted file)",
}


def _unreadable(exc: BaseException, suffix: str) -> str:
    """The reason for a file the parser refused and `explain` found nothing in: the parser's complaint
    where it speaks of the file, never a Python error message."""
    what = suffix.lstrip(".").upper()
    said = one_line(exc, with_type=False)
    meaning = next((m for key, m in PARSER_SAYS.items() if key in said), None)
    return f"unreadable as {what}: {meaning or f'the data does not follow the {what} format'}"


def is_number(word: str) -> bool:
    """Whether a text field reads as a number (int, float, nan, inf)."""
    try:
        float(word)
    except ValueError:
        return False
    return True


def is_index(word: str) -> bool:
    """Whether a text field reads as an integer (a sign allowed)."""
    return word.lstrip("-").isdigit()


def _obj_vertex_count(data: bytes) -> int:
    return sum(line.startswith((b"v ", b"v\t")) for line in data.splitlines())


def _file_vertex_count(data: bytes, suffix: str) -> int:
    """Vertices the file holds (OBJ) or declares (PLY header); 0 when unknown."""
    if suffix.lower() == ".obj":
        return _obj_vertex_count(data)
    if suffix.lower() == ".ply":
        for line in data[:data.find(b"end_header")].splitlines():
            words = line.split()
            if words[:2] == [b"element", b"vertex"]:
                return int(words[2])
    return 0


def _explain_obj(data: bytes) -> str | None:
    n = _obj_vertex_count(data)
    seen, width = 0, None
    for number, line in enumerate(data.decode("latin-1").splitlines(), 1):
        words = line.split()
        if line.startswith(("v ", "v\t")):
            seen += 1
            bad = next((w for w in words[1:] if not is_number(w)), None)
            if bad is not None:
                return f"line {number}: vertex value {bad!r} is not a number"
            if len(words) < 4:
                return f"line {number}: a vertex needs three coordinates x y z, this one has {len(words) - 1}"
            if width is not None and len(words) != width:
                return (f"line {number}: a vertex with {len(words) - 1} values where the ones before have "
                        f"{width - 1} (x y z, and optionally w or r g b, alike on every line)")
            width = len(words)
        elif line.startswith(("f ", "f\t")):
            if len(words) < 4:
                return f"line {number}: a face needs 3 or more corners, this one has {len(words) - 1}"
            for token in words[1:]:
                head = token.split("/")[0]
                if not is_index(head):
                    return f"line {number}: face corner {token!r} is not a vertex index"
                index = int(head)
                resolved = seen + index + 1 if index < 0 else index
                if not 1 <= resolved <= n:
                    return f"line {number}: face refers to vertex {index}; the file has {n} vertices " \
                           f"(OBJ counts from 1)"
    return None


def _data_lines(lines: list[str]) -> list[str]:
    return [line for line in lines if line.strip() and not line.lstrip().startswith(("#", "comment"))]


def _explain_off(data: bytes) -> str | None:
    text = data.decode("latin-1").splitlines()
    try:
        layout = off_layout(text)
    except (ValueError, IndexError):
        return "the OFF header's counts (vertices faces edges) are not integers"
    if layout is None:
        return "not an OFF file: no OFF header on the first line"
    lines, first, nv, nf = layout
    if len(lines) - first < nv + nf:
        return f"OFF header declares {nv} vertices and {nf} faces but the file holds {len(lines) - first} data lines"
    for k in lines[first:first + nv]:
        words = text[k].split()
        bad = next((w for w in words if not is_number(w)), None)
        if bad is not None or len(words) < 3:
            return f"line {k + 1}: a vertex needs three numbers x y z" + (f"; {bad!r} is not one" if bad else "")
    for k in lines[first + nv:first + nv + nf]:
        words = text[k].split()
        bad = next((w for w in words if not is_number(w)), None)
        if bad is not None:
            return f"line {k + 1}: {bad!r} is not a number"
        if not is_index(words[0]) or int(words[0]) < 3 or len(words) < 1 + int(words[0]):
            return f"line {k + 1}: a face is a corner count of 3 or more and that many vertex indices"
        corners = words[1:1 + int(words[0])]
        bad = next((w for w in corners if not is_index(w)), None)
        if bad is not None:
            return f"line {k + 1}: face corner {bad!r} is not a vertex index"
        bad = next((w for w in corners if not 0 <= int(w) < nv), None)
        if bad is not None:
            return f"line {k + 1}: face refers to vertex {bad}; the file has {nv} vertices (OFF counts from 0)"
    return None


PLY_SIZES = {"char": 1, "uchar": 1, "int8": 1, "uint8": 1, "short": 2, "ushort": 2, "int16": 2,
             "uint16": 2, "int": 4, "uint": 4, "int32": 4, "uint32": 4, "float": 4, "float32": 4,
             "double": 8, "float64": 8}


def _explain_ply(data: bytes) -> str | None:
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        return "PLY header truncated (no end_header line)" if data.startswith(b"ply") else \
            "not a PLY file: it does not start with 'ply'"
    odd = next((k for k, byte in enumerate(data[:end]) if byte > 127), None)
    if odd is not None:
        return f"the PLY header is not ASCII text (byte 0x{data[odd]:02x} at offset {odd})"
    header = data[:end].decode("latin-1").splitlines()
    for number, line in enumerate(header, 1):
        words = line.split()
        if words[:1] == ["element"] and (len(words) < 3 or not words[2].isdigit()):
            return f"header line {number}: {line.strip()!r}: an element needs a name and a count"
        if words[:1] == ["property"]:
            types = words[2:4] if words[1:2] == ["list"] else words[1:2]  # list: count type, item type
            if len(words) < 3 + (words[1:2] == ["list"]) or not all(t in PLY_SIZES for t in types):
                return f"header line {number}: {line.strip()!r}: a property is a known type and a name"
    body = data[data.index(b"\n", end) + 1:] if b"\n" in data[end:] else b""
    fmt = next(line.split()[1] for line in header if line.startswith("format"))
    elements, scalar_bytes = [], {}
    for line in header:
        words = line.split()
        if words and words[0] == "element":
            elements.append((words[1], int(words[2])))
        elif words and words[0] == "property" and words[1] != "list":
            scalar_bytes[elements[-1][0]] = scalar_bytes.get(elements[-1][0], 0) + PLY_SIZES[words[1]]
    counts = dict(elements)
    nv, nf = counts.get("vertex", 0), counts.get("face", 0)
    if fmt == "ascii":
        rows = _data_lines(body.decode("latin-1").splitlines())
        if len(rows) < sum(counts.values()):
            return f"PLY header declares {nv} vertices and {nf} faces but the file holds {len(rows)} data lines"
        bad = next(((k, w) for k, line in enumerate(rows, 1) for w in line.split() if not is_number(w)), None)
        if bad:
            return f"data line {bad[0]} after the header: {bad[1]!r} is not a number"
    elif elements and elements[0][0] == "vertex" and nv * scalar_bytes.get("vertex", 0) > len(body):
        return f"PLY header declares {nv} vertices ({nv * scalar_bytes['vertex']} bytes) but only " \
               f"{len(body)} bytes follow the header"
    return None


def _explain_stl(data: bytes) -> str | None:
    if len(data) >= 84 and 84 + 50 * int.from_bytes(data[80:84], "little") == len(data):
        return None  # binary, of the size its header says
    if not data.lstrip().startswith(b"solid"):
        count = int.from_bytes(data[80:84], "little") if len(data) >= 84 else 0
        return (f"binary STL header declares {count} triangles ({84 + 50 * count} bytes) but the file has "
                f"{len(data)} bytes") if len(data) >= 84 else f"not an STL file: {len(data)} bytes, no 'solid' header"
    vertices = 0
    for number, line in enumerate(data.decode("latin-1").splitlines(), 1):
        words = line.split()
        if words[:1] == ["vertex"]:
            vertices += 1
            if len(words) != 4 or not all(is_number(w) for w in words[1:]):
                return f"line {number}: a vertex line is 'vertex x y z', got {line.strip()[:60]!r}"
        elif words[:1] == ["endfacet"]:
            if vertices != 3:
                return f"line {number}: a facet has {vertices} vertices; it needs 3"
            vertices = 0
    return None


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
        scale = np.ptp(unique, axis=0).max()
        faces = faces[2 * face_areas(unique, faces) > 1e-12 * scale * scale]
    if len(faces) == 0:
        raise MeshError("load", "all faces are degenerate (zero area)")
    used, compact = np.unique(faces, return_inverse=True)
    mesh = Mesh(unique[used], compact.reshape(-1, 3))
    if not return_map:
        return mesh
    to_clean = np.full(len(unique), -1, dtype=np.int64)
    to_clean[used] = np.arange(len(used))
    return mesh, to_clean[inverse.reshape(-1)]

