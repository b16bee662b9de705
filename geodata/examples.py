"""Small furniture-like triangle soups built from primitives: the project's own sample input.

They have what real catalog meshes have: intersecting parts, duplicated vertices, parts with flipped
winding, an open part, thin legs, stems and plates. No data files ship with the package.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh

__all__ = ["example_soups", "write_examples", "bumpy_sphere"]


def _box(extents, center):
    return trimesh.creation.box(extents=extents).apply_translation(center)


def _cylinder(radius, height, center, sections=16):
    return trimesh.creation.cylinder(radius=radius, height=height, sections=sections).apply_translation(center)


def _flip(mesh):
    """The same part with inverted winding, as sloppy exporters write it."""
    return trimesh.Trimesh(mesh.vertices, mesh.faces[:, ::-1], process=False)


def _soup(*parts) -> trimesh.Trimesh:
    """Concatenate parts without merging anything: intersecting, duplicated, unprocessed."""
    vertices, faces = trimesh.util.append_faces([p.vertices for p in parts], [p.faces for p in parts])
    return trimesh.Trimesh(vertices, faces, process=False)


def example_soups() -> dict[str, trimesh.Trimesh]:
    legs = [(x, y) for x in (-0.55, 0.55) for y in (-0.35, 0.35)]
    table = _soup(_box([1.3, 0.9, 0.04], [0, 0, 0.75]),
                  *[_cylinder(0.03, 0.76, [x, y, 0.38]) for x, y in legs])
    chair = _soup(_box([0.5, 0.5, 0.05], [0, 0, 0.45]),
                  _flip(_box([0.5, 0.04, 0.5], [0, 0.23, 0.72])),
                  *[_cylinder(0.025, 0.46, [x * 0.4, y * 0.6, 0.23]) for x, y in legs])
    lamp = _soup(_cylinder(0.15, 0.03, [0, 0, 0.015], sections=32),
                 _cylinder(0.012, 1.2, [0, 0, 0.6]),
                 trimesh.creation.cone(0.25, 0.3, sections=32).apply_translation([0, 0, 1.1]))
    shelf = _soup(*[_box([0.02, 0.3, 1.6], [x, 0, 0.8]) for x in (-0.4, 0.4)],
                  *[_flip(_box([0.82, 0.3, 0.02], [0, 0, z])) for z in (0.05, 0.55, 1.05, 1.55)])
    mug_body = trimesh.creation.annulus(r_min=0.3, r_max=0.34, height=0.8, sections=32)
    mug = _soup(mug_body, _cylinder(0.33, 0.04, [0, 0, -0.38]),
                trimesh.creation.torus(0.22, 0.035).apply_transform(
                    trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0])).apply_translation([0.4, 0, 0]))
    # An open part: a box with its top face removed (a hole the watertight stage must close).
    crate = _box([0.6, 0.4, 0.3], [0, 0, 0.15])
    crate = trimesh.Trimesh(crate.vertices, crate.faces[np.asarray(crate.face_normals)[:, 2] < 0.9], process=False)
    return {"table": table, "chair": chair, "lamp": lamp, "shelf": shelf, "mug": mug, "crate": crate}


def bumpy_sphere(n: int, seed: int = 0, amplitude: float = 0.15, stretch=(1.3, 1.0, 0.8),
                 offset=(0.0, 0.0, 0.0)):
    """An irregular closed mesh of about `n` vertices: the convex hull of random points on a sphere,
    bumped and stretched (for tests and benchmarks that need irregular triangles, no data files)."""
    from geodata.mesh import Mesh

    rng = np.random.default_rng(seed)
    p = rng.normal(size=(n, 3))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    hull = trimesh.convex.convex_hull(p)
    v = np.asarray(hull.vertices)
    r = 1 + amplitude * np.sin(3 * v[:, 0]) * np.cos(2 * v[:, 1]) + amplitude / 2 * np.sin(5 * v[:, 2])
    return Mesh(v * r[:, None] * np.asarray(stretch) + np.asarray(offset), np.asarray(hull.faces))


def write_examples(out_dir: str | Path) -> list[Path]:
    """Write the example soups as OBJ/PLY/STL/OFF files (one of each format at least)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    formats = {"table": "obj", "chair": "ply", "lamp": "stl", "shelf": "off", "mug": "obj", "crate": "glb"}
    paths = []
    for name, mesh in example_soups().items():
        path = out / f"{name}.{formats[name]}"
        mesh.export(path)
        paths.append(path)
    return paths
