r"""Polygon faces to triangles as what they are: ear clipping in the polygon's own plane.

trimesh cuts an OBJ/OFF/PLY polygon as a fan from its first corner, which fills a concave polygon (a ring
drawn as one face with a bridge edge becomes a disc). Here every face of more than three corners is
projected on its plane (Newell's normal) and ear-clipped; quads pick the diagonal that keeps both
triangles facing the quad's way. A polygon whose triangles do not cover exactly its area

.. math::
    \sum_t |A_t| = |A_{\text{polygon}}| \quad (\text{relative } 10^{-6})

(self-intersecting, or too far from planar to project) cannot be triangulated faithfully: it is an
error naming the file's line, never a guess. Quads split along a diagonal whatever their shape, and
polygons without area give no triangles (as a zero-area triangle is dropped): both are common in
catalog files and neither changes the surface.
"""
from __future__ import annotations

import numpy as np

__all__ = ["PolygonError", "triangulate_polygon", "triangulate_obj_text", "triangulate_off_text",
           "triangulate_faces", "off_layout"]

AREA_TOLERANCE = 1e-6
FLAT_AREA = 1e-9  # |area| / extent^2 below which a polygon has no area


class PolygonError(ValueError):
    """A polygon face that cannot be triangulated faithfully."""


def triangulate_polygon(points: np.ndarray) -> list[tuple[int, int, int]]:
    """Triangles (corner indices into ``points``, (n, 3)) of one simple polygon, wound as the polygon.

    Repeated corners (bridge edges joining a hole to the outer ring) are allowed; a polygon without area
    has no triangles, and a quad splits along a diagonal even when non-planar (see the module)."""
    points = np.asarray(points, dtype=np.float64)
    if len(points) == 3:
        return [(0, 1, 2)]
    if len(points) == 4:
        return _split_quad(points)  # zero-area triangles are dropped by the load stage
    extent = np.ptp(points, axis=0).max()
    xy = _project(points)  # counter-clockwise in its plane: the plane's normal is the polygon's own
    area = 0.0 if xy is None else _signed_area(xy)  # None: no area in any plane
    if area <= FLAT_AREA * extent * extent:
        return []
    tris = _ear_clip(xy, list(range(len(xy))))
    covered = sum(abs(_tri_area(xy[a], xy[b], xy[c])) for a, b, c in tris)
    if abs(covered - area) > AREA_TOLERANCE * area:
        raise PolygonError(f"self-intersecting in its plane (triangles cover {covered / area:.3g}x its area)")
    return tris


def _faithful(points: np.ndarray, where: str) -> list[tuple[int, int, int]]:
    """triangulate_polygon, its refusal naming the face (`where`: its line, or its number)."""
    try:
        return triangulate_polygon(points)
    except PolygonError as exc:
        raise PolygonError(f"{where}: polygon of {len(points)} corners cannot be triangulated faithfully: "
                           f"{exc}") from None


def _split_quad(p: np.ndarray) -> list[tuple[int, int, int]]:
    """The diagonal whose two triangles' normals agree best (both face the quad's way when convex)."""
    def agreement(t1, t2):
        n1, n2 = (np.cross(p[b] - p[a], p[c] - p[a]) for a, b, c in (t1, t2))
        return float(n1 @ n2) / max(np.linalg.norm(n1) * np.linalg.norm(n2), 1e-300)

    splits = [[(0, 1, 2), (0, 2, 3)], [(0, 1, 3), (1, 2, 3)]]
    return max(splits, key=lambda pair: agreement(*pair))


def _project(points: np.ndarray) -> np.ndarray | None:
    """The polygon in its plane (Newell's normal n, axes u and n x u): counter-clockwise there, its signed
    area |n| / 2 > 0; None when it has no normal."""
    nxt = np.roll(points, -1, axis=0)
    normal = np.array([np.sum((points[:, 1] - nxt[:, 1]) * (points[:, 2] + nxt[:, 2])),
                       np.sum((points[:, 2] - nxt[:, 2]) * (points[:, 0] + nxt[:, 0])),
                       np.sum((points[:, 0] - nxt[:, 0]) * (points[:, 1] + nxt[:, 1]))])  # Newell
    norm = np.linalg.norm(normal)
    if not norm > 0:
        return None
    normal /= norm
    u = np.cross(normal, [1.0, 0, 0] if abs(normal[0]) < 0.9 else [0, 1.0, 0])
    u /= np.linalg.norm(u)
    return np.stack([points @ u, points @ np.cross(normal, u)], axis=1)


def _signed_area(xy: np.ndarray) -> float:
    x, y = xy[:, 0], xy[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def _tri_area(a, b, c) -> float:
    return 0.5 * ((b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1]))


def _ear_clip(xy: np.ndarray, order: list[int]) -> list[tuple[int, int, int]]:
    """Counter-clockwise ``order``: clip convex corners whose triangle holds no other corner."""
    idx, tris = list(order), []
    scale = np.ptp(xy, axis=0).max()
    eps = 1e-12 * scale * scale
    while len(idx) > 3:
        n, pts = len(idx), xy[idx]
        # A zero-area ear only when no proper one is left.
        k = next((k for allow_flat in (False, True) for k in range(n) if _is_ear(pts, k, eps, allow_flat)), None)
        if k is None:
            raise PolygonError("no ear to clip (self-intersecting in its plane)")
        tris.append((idx[k - 1], idx[k], idx[(k + 1) % n]))
        del idx[k]
    tris.append(tuple(idx))
    return [t for t in tris if abs(_tri_area(*xy[list(t)])) > eps]


def _is_ear(pts: np.ndarray, k: int, eps: float, allow_flat: bool) -> bool:
    """Does corner k clip off: its triangle a, b, c turns left (or is flat, when `allow_flat`) and no
    corner other than the ear's own (or a copy of one) is inside or on it?"""
    n = len(pts)
    a, b, c = pts[k - 1], pts[k], pts[(k + 1) % n]
    area = _tri_area(a, b, c)
    if area <= eps:
        return allow_flat and area >= -eps
    others = np.delete(pts, [(k - 1) % n, k, (k + 1) % n], axis=0)
    others = others[~(np.all(others == a, axis=1) | np.all(others == b, axis=1) | np.all(others == c, axis=1))]
    d1 = (b[0] - a[0]) * (others[:, 1] - a[1]) - (b[1] - a[1]) * (others[:, 0] - a[0])
    d2 = (c[0] - b[0]) * (others[:, 1] - b[1]) - (c[1] - b[1]) * (others[:, 0] - b[0])
    d3 = (a[0] - c[0]) * (others[:, 1] - c[1]) - (a[1] - c[1]) * (others[:, 0] - c[0])
    return not np.any((d1 >= -eps) & (d2 >= -eps) & (d3 >= -eps))


def triangulate_obj_text(text: str) -> str:
    """An OBJ's polygon faces (4 or more corners) as triangle faces, corner tokens (v/vt/vn) kept, and
    relative (negative) vertex indices made absolute: trimesh counts them from the file's end, the OBJ
    format from the face's own line."""
    lines = text.splitlines()
    if not any(len(line.split()) > 4 or "-" in line for line in lines if line.startswith(("f ", "f\t"))):
        return text
    positions = np.array([[float(t) for t in line.split()[1:4]] for line in lines
                          if line.startswith(("v ", "v\t"))]).reshape(-1, 3)
    out, seen = [], {"v": 0, "vt": 0, "vn": 0}
    for number, line in enumerate(lines, 1):
        key = line.split(maxsplit=1)[0] if line.strip() else ""
        if key in seen:
            seen[key] += 1
        if key != "f":
            out.append(line)
            continue
        tokens = [_absolute(t, seen) for t in line.split()[1:]]
        if len(tokens) == 3:
            out.append("f " + " ".join(tokens))
            continue
        corners = [int(t.split("/")[0]) - 1 for t in tokens]
        if min(corners) < 0 or max(corners) >= len(positions):
            raise ValueError("a corner out of range")  # left to the parser and load.explain
        out += [f"f {tokens[a]} {tokens[b]} {tokens[c]}" for a, b, c in _faithful(positions[corners], f"line {number}")]
    return "\n".join(out) + "\n"


def _absolute(token: str, seen: dict) -> str:
    """A face corner 'v[/vt[/vn]]' with negative (relative) indices made absolute; one that points
    before the first element is left as written, for the parser to refuse."""
    parts = token.split("/")
    for part, kind in zip(range(len(parts)), ("v", "vt", "vn")):
        if parts[part].startswith("-") and seen[kind] + int(parts[part]) >= 0:
            parts[part] = str(seen[kind] + int(parts[part]) + 1)
    return "/".join(parts)


def off_layout(lines: list[str]) -> tuple[list[int], int, int, int] | None:
    """Where an OFF file's parts are: the indices of its data lines (not blank, not # comments), the
    position among them of the first vertex line, and the declared vertex and face counts; None when
    the first data line is no OFF header. The counts follow the keyword ("OFF 8 6 0") or sit on the
    next line."""
    data = [k for k, line in enumerate(lines) if line.strip() and not line.lstrip().startswith("#")]
    head = lines[data[0]].split() if data else []
    if not head or not head[0].endswith("OFF"):
        return None
    if len(head) > 1:
        return data, 1, int(head[1]), int(head[2])
    nv, nf = (int(w) for w in lines[data[1]].split()[:2])
    return data, 2, nv, nf


def triangulate_off_text(text: str) -> str:
    """An OFF's polygon faces (4 or more corners) as triangle faces (a polygon's colour is dropped)."""
    lines = text.splitlines()
    layout = off_layout(lines)
    if layout is None:
        return text
    data, first, nv, nf = layout
    vertex_lines, face_lines = data[first:first + nv], data[first + nv:first + nv + nf]
    if not any(int(lines[k].split()[0]) > 3 for k in face_lines):
        return text
    positions = np.array([[float(t) for t in lines[k].split()[:3]] for k in vertex_lines])
    faces = []
    for k in face_lines:
        words = lines[k].split()
        n = int(words[0])
        if n <= 3:
            faces.append(lines[k])
            continue
        corners = [int(w) for w in words[1:1 + n]]
        if len(corners) < n or min(corners) < 0 or max(corners) >= len(positions):
            raise ValueError("a corner missing or out of range")  # left to the parser and load.explain
        tris = _faithful(positions[corners], f"line {k + 1}")
        faces += [f"3 {corners[a]} {corners[b]} {corners[c]}" for a, b, c in tris]
    lines[data[first - 1]] = (f"{lines[data[0]].split()[0]} " if first == 1 else "") + f"{nv} {len(faces)} 0"
    return "\n".join(lines[:face_lines[0]] + faces + lines[face_lines[-1] + 1:]) + "\n"


def triangulate_faces(vertices: np.ndarray, polygons) -> np.ndarray:
    """Faces given as corner lists (e.g. a PLY's ``vertex_indices``, counted from 0) as triangles (F, 3)."""
    tris = []
    for number, corners in enumerate(polygons):
        corners = np.asarray(corners, dtype=np.int64)
        if len(corners) < 3:
            raise PolygonError(f"face {number} (counted from 0) has {len(corners)} corners; a face needs 3 or more")
        bad = corners[(corners < 0) | (corners >= len(vertices))]
        if len(bad):
            raise PolygonError(f"face {number} (counted from 0) refers to vertex {bad[0]}; the file has "
                               f"{len(vertices)} vertices (counted from 0)")
        if len(corners) == 3:
            tris.append(corners[None])
            continue
        local = _faithful(vertices[corners], f"face {number} (counted from 0)")
        tris.append(corners[np.asarray(local, dtype=np.int64).reshape(-1, 3)])
    return np.concatenate(tris) if tris else np.zeros((0, 3), dtype=np.int64)
