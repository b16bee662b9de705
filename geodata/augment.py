"""`geodata augment`: randomized variants of raw meshes, made before `prepare` so their distances are exact.

Each variant composes, with its own random stream (seed, file content, variant number):
  - anisotropic scaling along a random frame (factors in [1/1.6, 1.6]), always;
  - a bend about a random axis (up to +-90 degrees over the shape), half of the time;
  - a twist about a random axis (up to +-90 degrees over the shape), half of the time;
  - 1-3 random cuts that open holes (faces within a ball around a surface point are removed),
    half of the time. `prepare` closes a hole into a thin shell, so geodesics must go round its rim.
Coarse triangle soups are subdivided first (edges at most 1/40 of the diagonal) so that bends and
twists stay smooth.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import trimesh

from geodata.mesh import Mesh, MeshError, face_areas, one_line
from geodata.stages.load import load_mesh_bytes
from geodata.stages.repair import compact

__all__ = ["AugmentConfig", "bend", "twist", "cut", "variant", "augment_file"]


@dataclass(frozen=True)
class AugmentConfig:
    variants: int = 2
    seed: int = 0
    max_scale: float = 1.6       # anisotropic factors in [1/max_scale, max_scale]
    max_angle: float = np.pi / 2  # bend and twist over the whole shape
    p_bend: float = 0.5
    p_twist: float = 0.5
    p_cut: float = 0.5


def _random_frame(rng) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    return q * np.sign(np.diag(r))


def bend(v: np.ndarray, frame: np.ndarray, angle: float) -> np.ndarray:
    """Bend about ``frame``'s first axis by ``angle`` radians over the shape's extent along it: the plane
    of the first and third axes (through the mean) rolls onto a cylinder without stretching."""
    local = v @ frame
    t, y = local[:, 0], local[:, 1]
    length = np.ptp(t)
    if length == 0 or abs(angle) < 1e-6:
        return v.copy()
    radius = length / angle
    phi = (t - t.mean()) / radius
    local[:, 0] = (radius - y) * np.sin(phi)
    local[:, 1] = radius - (radius - y) * np.cos(phi)
    return local @ frame.T


def twist(v: np.ndarray, frame: np.ndarray, angle: float) -> np.ndarray:
    """Rotate each slice across ``frame``'s first axis about it, linearly up to +-angle/2 at the ends."""
    local = v @ frame
    t = local[:, 0]
    phi = angle * (t - t.mean()) / max(np.ptp(t), 1e-12)
    c, s = np.cos(phi), np.sin(phi)
    y, z = local[:, 1].copy(), local[:, 2].copy()
    local[:, 1], local[:, 2] = c * y - s * z, s * y + c * z
    return local @ frame.T


def cut(v: np.ndarray, f: np.ndarray, centers: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """The faces whose centroid lies outside every ball (center, radius), unless that removes half."""
    centroids = v[f].mean(axis=1)
    inside = (np.linalg.norm(centroids[:, None] - centers[None], axis=2) <= radii[None]).any(axis=1)
    return f[~inside] if inside.mean() < 0.5 else f


def variant(mesh: Mesh, rng: np.random.Generator, cfg: AugmentConfig = AugmentConfig()) -> Mesh:
    """One random variant of a cleaned mesh (see the module docstring)."""
    v, f = mesh.vertices, mesh.faces
    diag = np.linalg.norm(np.ptp(v, axis=0))
    v, f = trimesh.remesh.subdivide_to_size(v, f, max_edge=diag / 40, max_iter=6)
    v = v - v.mean(axis=0)
    frame = _random_frame(rng)
    factors = np.exp(rng.uniform(-np.log(cfg.max_scale), np.log(cfg.max_scale), 3))
    v = ((v @ frame) * factors) @ frame.T
    if rng.random() < cfg.p_bend:
        v = bend(v, _random_frame(rng), rng.uniform(-cfg.max_angle, cfg.max_angle))
    if rng.random() < cfg.p_twist:
        v = twist(v, _random_frame(rng), rng.uniform(-cfg.max_angle, cfg.max_angle))
    if rng.random() < cfg.p_cut:
        area = face_areas(v, f)
        n = rng.integers(1, 4)
        centers = v[f[rng.choice(len(f), n, p=area / area.sum())]].mean(axis=1)
        f = cut(v, f, centers, rng.uniform(0.05, 0.15, n) * np.linalg.norm(np.ptp(v, axis=0)))
    return compact(v, f)


def augment_file(path: str, source: str, out_dir: str, cfg: AugmentConfig) -> dict:
    """Write cfg.variants variants of one raw file as `<out_dir>/<source without suffix>.aug<k>.ply`.

    Returns a row {source, status, written | error}; a bad file is one line, never an exception.
    """
    data = Path(path).read_bytes()
    try:
        mesh = load_mesh_bytes(data, Path(path).suffix)
    except MeshError as exc:
        return {"source": source, "status": "failed", "error": f"[{exc.stage}] {exc.reason}"}
    key = int.from_bytes(hashlib.sha256(data).digest()[:8], "big")
    written = []
    for k in range(cfg.variants):
        target = Path(out_dir) / f"{Path(source).with_suffix('')}.aug{k}.ply"
        try:
            m = variant(mesh, np.random.default_rng([cfg.seed, key, k]), cfg)
            ply = trimesh.Trimesh(m.vertices, m.faces, process=False).export(file_type="ply")
        except Exception as exc:  # a library error on one variant: report it, keep the others
            return {"source": source, "status": "failed", "error": f"[augment] {one_line(exc)}",
                    "written": written}
        target.parent.mkdir(parents=True, exist_ok=True)
        tmp = target.with_suffix(".ply.tmp")
        tmp.write_bytes(ply)
        tmp.replace(target)  # a killed run never leaves half a file under the final name
        written.append(str(target))
    return {"source": source, "status": "ok", "written": written}
