"""Meshes whose geodesic distances are known in closed form (every unfolding flat), shared by the tests of the
exact and the approximate solvers: a grid over the unit square (optionally jittered, holed or lifted into a
height field), the L-shaped plane around its reflex corner, and an open prism (its unrolled strip)."""
import numpy as np

from geodata.mesh import Mesh


def grid(n, jitter=0.0, height=0.0, seed=0, keep=None) -> Mesh:
    """An n x n grid over [0, 1]^2 (cells where keep(center) is false left out), interior vertices moved by
    up to `jitter` cells, z a random height field of amplitude `height` (obtuse triangles, saddles)."""
    rng = np.random.default_rng(seed)
    x, y = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n), indexing="ij")
    v = np.stack([x.ravel(), y.ravel(), height * rng.standard_normal(n * n)], axis=1)
    inner = (v[:, 0] > 0) & (v[:, 0] < 1) & (v[:, 1] > 0) & (v[:, 1] < 1)
    v[inner, :2] += rng.uniform(-jitter, jitter, (inner.sum(), 2)) / n
    faces = []
    for i in range(n - 1):
        for j in range(n - 1):
            if keep is None or keep((i + 0.5) / (n - 1), (j + 0.5) / (n - 1)):
                a, b, c, d = i * n + j, (i + 1) * n + j, i * n + j + 1, (i + 1) * n + j + 1
                faces += [[a, b, c], [c, b, d]]
    used, f = np.unique(np.array(faces), return_inverse=True)
    return Mesh(v[used], f.reshape(-1, 3))


def l_shape():
    """[0,1]^2 without the square (0.5,1)^2 (21 x 21 grid), a source on its boundary at (1, 0), and the exact
    distances from it: straight where the segment stays in the plane, around the corner (0.5, 0.5) where not
    (over 50 vertices)."""
    mesh = grid(21, keep=lambda x, y: x < 0.5 or y < 0.5)
    p, corner = mesh.vertices[:, :2], np.array([0.5, 0.5])
    source = int(np.argmin(np.linalg.norm(p - [1.0, 0.0], axis=1)))
    t = np.linspace(0, 1, 2001)[:, None, None]
    seg = p[source] + t * (p[None] - p[source])  # points along each straight segment
    blocked = ((seg[..., 0] > 0.5 + 1e-9) & (seg[..., 1] > 0.5 + 1e-9)).any(axis=0)
    assert blocked.sum() > 50
    expect = np.where(blocked, np.linalg.norm(p[source] - corner) + np.linalg.norm(p - corner, axis=1),
                      np.linalg.norm(p - p[source], axis=1))
    return mesh, source, expect


def open_prism(n=24, rings=9, radius=0.5):
    """An open prism of n sides and `rings` rings, three sources (both boundary rings and the middle) and the
    exact distances from each: its unrolled strip's straight lines, the shorter way around."""
    k, z = np.meshgrid(np.arange(n), np.linspace(0, 1, rings), indexing="xy")
    k, z = k.ravel(), z.ravel()
    angle = 2 * np.pi * k / n
    v = np.stack([radius * np.cos(angle), radius * np.sin(angle), z], axis=1)
    idx = np.arange(rings * n).reshape(rings, n)
    a, b = idx[:-1], np.roll(idx[:-1], -1, axis=1)
    c, d = idx[1:], np.roll(idx[1:], -1, axis=1)
    f = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([c, b, d], -1).reshape(-1, 3)])
    side = 2 * radius * np.sin(np.pi / n)
    sources = [0, 5 * n + 7, (rings - 1) * n + 3]
    steps = [np.abs(k - k[s]) for s in sources]
    expect = [np.hypot(np.minimum(st, n - st) * side, z - z[s]) for st, s in zip(steps, sources)]
    return Mesh(v, f), sources, expect
