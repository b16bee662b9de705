"""A zoo of generated surfaces on which geodesic field solvers fail in different ways, each a function of a
size factor: the field solver's benchmark (benchmarks/bench_field_solver.py --zoo) runs them at size 1,
the tests at a small size, against the exact solver.

- tori of several aspect ratios, regular and isotropically remeshed: geodesics wrap round smooth saddle
  regions whose excess angle is spread over many vertices (each vertex's small);
- thin tubes swept along bent centrelines (a U bend, a coil, a trefoil knot): the same, sharper;
- a T of two pipes (a boolean union, remeshed): a saddle ring where they join;
- a saddle patch z = (x^2 - y^2) / 2 with a boundary;
- a plate with three holes (genus 3) and a CAD-like part with fillets and holes (a box with holes rounded
  by a Minkowski sum with a sphere), both remeshed;
- sliver triangles (a remeshed torus with a third of its faces split near an edge) and noisy vertices (a
  torus jittered along its normals by 0.3 mean edge lengths): the surface as given is the truth.

Every shape is a closed manifold (the exact solver's condition) but the saddle patch, which has one
boundary loop. ``ZOO`` maps a name to its builder; ``zoo_mesh(name, size)`` returns float64 vertices (N, 3)
and int64 faces (M, 3). Vertex counts grow about linearly with ``size`` (1: 3-10k vertices).
"""
from __future__ import annotations

from typing import Callable

import numpy as np

__all__ = ["ZOO", "zoo_mesh", "zoo_variants", "torus", "tube", "saddle_patch", "split_faces"]

Mesh = tuple[np.ndarray, np.ndarray]


def torus(major: float, minor: float, n_major: int, n_minor: int) -> Mesh:
    """The torus of radii ``major`` and ``minor`` on an ``n_major`` x ``n_minor`` grid of its angles."""
    u, w = np.meshgrid(np.arange(n_major) * 2 * np.pi / n_major, np.arange(n_minor) * 2 * np.pi / n_minor,
                       indexing="ij")
    ring = major + minor * np.cos(w)
    v = np.stack([ring * np.cos(u), ring * np.sin(u), minor * np.sin(w)], axis=-1).reshape(-1, 3)
    return v, _grid_faces(n_major, n_minor, closed_rows=True)


def tube(curve: np.ndarray, radius: float, n_around: int, closed: bool = False) -> Mesh:
    """A tube of ``radius`` swept along the polyline ``curve`` (P, 3) with ``n_around`` vertices a ring, its
    rings in parallel-transported frames (a closed curve's last frame turned back onto its first); an open
    tube gets a flat cap at each end (a fan round the end point)."""
    p = len(curve)
    tangent = np.gradient(curve, axis=0) if not closed else np.roll(curve, -1, 0) - np.roll(curve, 1, 0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    normal = np.cross(tangent[0], [0.0, 0.0, 1.0] if abs(tangent[0, 2]) < 0.9 else [1.0, 0.0, 0.0])
    frames = np.empty((p, 3))
    frames[0] = normal / np.linalg.norm(normal)
    for i in range(1, p):  # parallel transport: remove the component along the new tangent
        n = frames[i - 1] - tangent[i] * (frames[i - 1] @ tangent[i])
        frames[i] = n / np.linalg.norm(n)
    angle = np.zeros(p)
    if closed:  # the twist the transport left between the last ring and the first, spread along the tube
        last = frames[-1] - tangent[0] * (frames[-1] @ tangent[0])
        twist = np.arctan2(np.cross(last, frames[0]) @ tangent[0], last @ frames[0])
        angle = twist * np.arange(p) / p
    theta = angle[:, None] + np.arange(n_around)[None, :] * 2 * np.pi / n_around
    binormal = np.cross(tangent, frames)
    v = (curve[:, None, :] + radius * (np.cos(theta)[..., None] * frames[:, None, :]
                                       + np.sin(theta)[..., None] * binormal[:, None, :])).reshape(-1, 3)
    f = _grid_faces(p, n_around, closed_rows=closed)[:, ::-1]  # outward: the rings turn about the tangent
    if closed:
        return v, f
    ends = len(v) + np.arange(2)
    ring = np.arange(n_around)
    cap0 = np.stack([np.full(n_around, ends[0]), (ring + 1) % n_around, ring], axis=1)
    last = (p - 1) * n_around
    cap1 = np.stack([np.full(n_around, ends[1]), last + ring, last + (ring + 1) % n_around], axis=1)
    return np.concatenate([v, curve[[0, -1]]]), np.concatenate([f, cap0, cap1])


def saddle_patch(n: int) -> Mesh:
    """z = (x^2 - y^2) / 2 over [-1, 1]^2 on an n x n grid, each square cut along alternating diagonals."""
    x, y = np.meshgrid(np.linspace(-1, 1, n), np.linspace(-1, 1, n), indexing="ij")
    v = np.stack([x, y, (x ** 2 - y ** 2) / 2], axis=-1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="ij")
    a, b, c, d = (i * n + j).ravel(), (i * n + j + 1).ravel(), ((i + 1) * n + j).ravel(), ((i + 1) * n + j + 1).ravel()
    even = ((i + j) % 2 == 0).ravel()
    f1 = np.where(even[:, None], np.stack([a, c, d], 1), np.stack([a, c, b], 1))
    f2 = np.where(even[:, None], np.stack([a, d, b], 1), np.stack([b, c, d], 1))
    return v, np.concatenate([f1, f2]).astype(np.int64)


def _grid_faces(rows: int, cols: int, closed_rows: bool) -> np.ndarray:
    """Two triangles a cell of a rows x cols grid whose columns close into rings (and rows too if asked)."""
    i, j = np.meshgrid(np.arange(rows if closed_rows else rows - 1), np.arange(cols), indexing="ij")
    a = i * cols + j
    b = i * cols + (j + 1) % cols
    c = ((i + 1) % rows) * cols + j
    d = ((i + 1) % rows) * cols + (j + 1) % cols
    faces = np.concatenate([np.stack([a, c, d], -1).reshape(-1, 3), np.stack([a, d, b], -1).reshape(-1, 3)])
    return faces.astype(np.int64)


def _remeshed(v: np.ndarray, f: np.ndarray, edge: float) -> Mesh:
    """Isotropic remeshing (pymeshlab) to edge length ``edge``, the surface kept closed."""
    import pymeshlab

    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(v, f))
    ms.meshing_isotropic_explicit_remeshing(targetlen=pymeshlab.PureValue(edge), iterations=6)
    m = ms.current_mesh()
    return np.asarray(m.vertex_matrix(), dtype=np.float64), np.asarray(m.face_matrix(), dtype=np.int64)


def _solid(manifold) -> Mesh:
    m = manifold.to_mesh()
    return np.asarray(m.vert_properties[:, :3], dtype=np.float64), np.asarray(m.tri_verts, dtype=np.int64)


def _t_pipe(size: float) -> Mesh:
    from manifold3d import Manifold

    seg = 48
    along = Manifold.cylinder(4.0, 0.5, 0.5, seg, True).rotate([0.0, 90.0, 0.0])
    branch = Manifold.cylinder(2.0, 0.4, 0.4, seg).translate([0.0, 0.0, 0.0])
    return _remeshed(*_solid(along + branch), 0.09 / np.sqrt(size))


def _plate(size: float, fillet: bool) -> Mesh:
    from manifold3d import Manifold

    body = Manifold.cube([4.0, 1.6, 0.5], True)
    for x in (-1.2, 0.0, 1.2):
        body -= Manifold.cylinder(1.0, 0.35, 0.35, 48, True).translate([x, 0.0, 0.0])
    if fillet:  # every edge rounded: a Minkowski sum with a small sphere
        body = body.minkowski_sum(Manifold.sphere(0.12, 16))
    return _remeshed(*_solid(body), 0.08 / np.sqrt(size))


def split_faces(v: np.ndarray, f: np.ndarray, share: float, near_edge: bool, seed: int = 0) -> Mesh:
    """``share`` of the faces split at a random interior point (barycentric weights), or at a point within
    0.2-2% of the face's first edge (needle triangles); the surface and its exact distances stay the same."""
    rng = np.random.default_rng(seed)
    chosen = rng.random(len(f)) < share
    w = rng.dirichlet([1, 1, 1], int(chosen.sum()))
    if near_edge:
        w[:, 2] = rng.uniform(0.002, 0.02, len(w))
        w[:, :2] *= ((1 - w[:, 2]) / w[:, :2].sum(1))[:, None]
    tri = f[chosen]
    new = len(v) + np.arange(len(tri))
    a, b, c = tri.T
    faces = np.concatenate([f[~chosen], np.stack([a, b, new], 1), np.stack([b, c, new], 1), np.stack([c, a, new], 1)])
    return np.concatenate([v, np.einsum("fk,fkd->fd", w, v[tri])]), faces


def _noisy(v: np.ndarray, f: np.ndarray, amount: float, seed: int = 0) -> Mesh:
    """Each vertex moved along its normal by a uniform amount in +-``amount`` mean edge lengths."""
    import trimesh

    m = trimesh.Trimesh(v, f, process=False)
    step = amount * m.edges_unique_length.mean()
    return v + m.vertex_normals * np.random.default_rng(seed).uniform(-step, step, (len(v), 1)), f


def _helix(size: float) -> Mesh:
    t = np.linspace(0, 3 * 2 * np.pi, int(600 * size))
    return tube(np.stack([np.cos(t), np.sin(t), 0.07 * t], 1), 0.1, max(8, int(16 * np.sqrt(size))))


def _u_bend(size: float) -> Mesh:
    n = int(80 * size)
    leg = np.linspace(0, 1, n, endpoint=False)
    arc = np.linspace(0, np.pi, n, endpoint=False)
    curve = np.concatenate([np.stack([0.5 + 0 * leg, -1 + leg, 0 * leg], 1),
                            np.stack([0.5 * np.cos(arc), 0.5 * np.sin(arc), 0 * arc], 1),
                            np.stack([-0.5 + 0 * leg, -leg, 0 * leg], 1)])
    return tube(curve, 0.15, max(8, int(24 * np.sqrt(size))))


def _trefoil(size: float) -> Mesh:
    t = np.linspace(0, 2 * np.pi, int(400 * size), endpoint=False)
    curve = np.stack([np.sin(t) + 2 * np.sin(2 * t), np.cos(t) - 2 * np.cos(2 * t), -np.sin(3 * t)], 1) / 3
    return tube(curve, 0.12, max(8, int(20 * np.sqrt(size))), closed=True)


def _torus(major: float, minor: float, n_major: int, n_minor: int) -> Callable[[float], Mesh]:
    return lambda size: torus(major, minor, max(8, int(n_major * np.sqrt(size))), max(6, int(n_minor * np.sqrt(size))))


ZOO: dict[str, Callable[[float], Mesh]] = {
    "torus-r0.3": _torus(1.0, 0.3, 128, 32),
    "torus-r0.5": _torus(1.0, 0.5, 96, 48),
    "torus-r0.1": _torus(1.0, 0.1, 256, 24),
    "torus-remeshed": lambda size: _remeshed(*torus(1.0, 0.3, 256, 64), 0.055 / np.sqrt(size)),
    "u-bend": _u_bend,
    "coil": _helix,
    "trefoil": _trefoil,
    "t-pipe": _t_pipe,
    "saddle-patch": lambda size: saddle_patch(max(8, int(64 * np.sqrt(size)))),
    "genus-3-plate": lambda size: _plate(size, fillet=False),
    "filleted-part": lambda size: _plate(size, fillet=True),
    "slivers": lambda size: split_faces(*_torus(1.0, 0.3, 96, 24)(size), share=1 / 3, near_edge=True),
    "noisy": lambda size: _noisy(*_torus(1.0, 0.3, 128, 32)(size), amount=0.3),
}


def zoo_mesh(name: str, size: float = 1.0) -> Mesh:
    """The zoo's shape ``name`` (a key of ``ZOO``) at ``size`` (1: 3-10k vertices)."""
    if name not in ZOO:
        raise ValueError(f"no zoo shape {name!r}; the zoo has {', '.join(ZOO)}")
    v, f = ZOO[name](size)
    return np.ascontiguousarray(v, dtype=np.float64), np.ascontiguousarray(f, dtype=np.int64)


def zoo_variants(count: int, seed: int = 0):
    """``count`` random shapes of the zoo's tubular kinds, for training data: (name, vertices, faces) with
    tori of major / minor radius 1.5-12, tubes along arcs of 90-330 degrees, helices of 1.5-4 turns and
    (p, q) torus knots, tube radii and resolutions drawn at random (3-12k vertices before remeshing)."""
    rng = np.random.default_rng(seed)
    for i in range(count):
        kind = ("torus", "arc", "helix", "knot")[i % 4]
        if kind == "torus":
            ratio = rng.uniform(1.5, 12.0)
            n_minor = int(rng.integers(16, 40))
            v, f = torus(1.0, 1.0 / ratio, int(n_minor * ratio * rng.uniform(0.6, 1.2)), n_minor)
        elif kind == "arc":
            bend = np.radians(rng.uniform(90, 330))
            t = np.linspace(0, bend, int(rng.integers(150, 400)))
            v, f = tube(np.stack([np.cos(t), np.sin(t), 0 * t], 1), rng.uniform(0.08, 0.3), int(rng.integers(12, 28)))
        elif kind == "helix":
            turns = rng.uniform(1.5, 4.0)
            t = np.linspace(0, turns * 2 * np.pi, int(300 * turns))
            radius = rng.uniform(0.06, 0.14)
            pitch = rng.uniform(2.5, 4.0) * radius / np.pi
            v, f = tube(np.stack([np.cos(t), np.sin(t), pitch * t], 1), radius, int(rng.integers(12, 24)))
        else:
            p, q = ((2, 3), (2, 5), (3, 4), (3, 5))[int(rng.integers(4))]
            t = np.linspace(0, 2 * np.pi, int(200 * (p + q)), endpoint=False)
            r = 2 + np.cos(q * t)
            curve = np.stack([r * np.cos(p * t), r * np.sin(p * t), -np.sin(q * t)], 1) / 3
            v, f = tube(curve, rng.uniform(0.06, 0.1), int(rng.integers(12, 20)), closed=True)
        yield f"{kind}-{i:03d}", v, f
