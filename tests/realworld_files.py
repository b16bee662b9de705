"""Generated mesh files of the kinds real catalogs are full of (issue 11), and what `geodata prepare`
must make of each: "ok" (with the warnings it must record) or the words of its failure reason."""
from __future__ import annotations

from pathlib import Path

import numpy as np

CUBE_V = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]
CUBE_QUADS = [(1, 4, 3, 2), (5, 6, 7, 8), (1, 2, 6, 5), (2, 3, 7, 6), (3, 4, 8, 7), (4, 1, 5, 8)]


def vertex_lines(vertices) -> str:
    return "".join(f"v {x} {y} {z}\n" for x, y, z in vertices)


def ring_obj(n: int = 24, r_in: float = 0.5) -> tuple[bytes, float]:
    """A flat annulus as ONE concave OBJ face: outer ring, a bridge edge, the inner ring backwards;
    and its area."""
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    outer = np.stack([np.cos(t), np.sin(t), np.zeros(n)], 1)
    corners = list(range(1, n + 1)) + [1, n + 1] + list(range(2 * n, n + 1, -1)) + [n + 1]
    area = 0.5 * n * np.sin(2 * np.pi / n) * (1 - r_in ** 2)
    text = vertex_lines(np.concatenate([outer, r_in * outer])) + "f " + " ".join(map(str, corners)) + "\n"
    return text.encode(), area


def ring_ply() -> bytes:
    """The same annulus as one polygon face of an ASCII PLY (PLY counts from 0)."""
    lines = ring_obj()[0].decode().splitlines()
    corners = [int(t) - 1 for t in lines[-1].split()[1:]]
    vertices = [line[2:] for line in lines[:-1]]
    head = (f"ply\nformat ascii 1.0\nelement vertex {len(vertices)}\nproperty float x\nproperty float y\n"
            "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n")
    return (head + "\n".join(vertices) + f"\n{len(corners)} " + " ".join(map(str, corners)) + "\n").encode()


def quads_obj() -> bytes:
    """The unit cube as quads, two of them 5-gons sharing an edge's midpoint."""
    text = vertex_lines(CUBE_V + [(0.5, 0, 0)])
    text += "".join("f " + " ".join(map(str, q)) + "\n" for q in CUBE_QUADS[3:] + [CUBE_QUADS[1]])
    return (text + "f 1 4 3 2 9\nf 9 2 6 5 1\n").encode()


def negative_obj() -> bytes:
    """The cube with relative (negative) indices, each face written right after its vertices."""
    text = ""
    for q in CUBE_QUADS:
        text += vertex_lines([CUBE_V[i - 1] for i in q]) + "f -4 -3 -2 -1\n"
    return text.encode()


def latin1_obj() -> bytes:
    return b"mtllib caf\xe9.mtl\nusemtl m\xe9tal\n" + quads_obj()


def seams_obj() -> bytes:
    """Texture coordinates and normals that differ per face corner (a loader may split vertices)."""
    text = vertex_lines(CUBE_V) + "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 1\n"
    text += "".join("f " + " ".join(f"{v}/{k + 1}/1" for k, v in enumerate(q)) + "\n" for q in CUBE_QUADS)
    return text.encode()


def two_parts_obj() -> bytes:
    far = [(x + 3, y, z) for x, y, z in CUBE_V]
    text = vertex_lines(CUBE_V + far)
    text += "".join("f " + " ".join(str(i + off) for i in q) + "\n" for off in (0, 8) for q in CUBE_QUADS)
    return text.encode()


TRUNCATED_PLY = b"ply\nformat binary_little_endian 1.0\nelement vertex 8\nproperty float x\nprop"
ABSURD_OFF = b"OFF\n353535235358 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n"
POINTS_OBJ = vertex_lines(CUBE_V).encode()


def write_fixtures(folder: Path) -> dict[str, tuple[str, str]]:
    """Write every kind into ``folder``; returns file name -> ("ok", recorded warning words) or
    ("failed", reason words)."""
    files = {
        "ring.obj": (ring_obj()[0], ("ok", "flat input thickened")),
        "ring.ply": (ring_ply(), ("ok", "flat input thickened")),
        "quads.obj": (quads_obj(), ("ok", "")),
        "negative.obj": (negative_obj(), ("ok", "")),
        "latin1.obj": (latin1_obj(), ("ok", "")),
        "seams.obj": (seams_obj(), ("ok", "")),
        "two_parts.obj": (two_parts_obj(), ("ok", "")),
        "truncated.ply": (TRUNCATED_PLY, ("failed", "PLY header truncated")),
        "absurd.off": (ABSURD_OFF, ("failed", "OFF header declares 353535235358 vertices")),
        "points.obj": (POINTS_OBJ, ("failed", "point cloud: 8 vertices and no faces")),
    }
    folder.mkdir(parents=True, exist_ok=True)
    for name, (data, _) in files.items():
        (folder / name).write_bytes(data)
    return {name: expected for name, (_, expected) in files.items()}
