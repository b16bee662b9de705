"""Statistics of many distance queries: shape distributions and the triangle inequality.

Shape distribution (Osada et al. 2002, D2; with geodesic distances, Martinek et al. 2012): the histogram
of the distance between two random surface points. Points are vertices drawn with probability
proportional to their area (a third of the incident faces' areas), so the histogram estimates that of
uniform surface points. Distances are divided by their mean, which makes the histogram independent of
scale; two histograms are compared by the L1 distance of their densities, integral |p - q| (0 to 2).
Geodesic distances do not change under a bend without stretching, Euclidean ones do: that is why the
geodesic D2 recognizes an articulated shape.

Triangle inequality: a learned distance is not a metric by construction. For random triples (p, q, x),
the fraction with d(p, q) > d(p, x) + d(x, q), and by how much.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["sample_pairs", "ShapeDistribution", "shape_distribution", "geodesic_and_euclidean_d2", "histogram_l1",
           "TriangleReport", "triangle_violations"]


def sample_pairs(vertices, faces, n_pairs: int, seed: int = 0, part: np.ndarray | None = None) -> np.ndarray:
    """(n_pairs, 2) vertex pairs, each vertex drawn with probability proportional to its area, a third of
    its faces' (potpourri3d's ``vertex_areas``), within the vertices where ``part`` is True, when given."""
    import potpourri3d as pp3d

    weights = pp3d.vertex_areas(np.asarray(vertices, dtype=np.float64), np.asarray(faces))
    if part is not None:
        weights = np.where(part, weights, 0.0)
    rng = np.random.default_rng(seed)
    return rng.choice(len(weights), size=(n_pairs, 2), p=weights / weights.sum())


@dataclass
class ShapeDistribution:
    """Density ``density`` over ``edges`` (bins + 1) of distances / ``mean`` (``mean`` in the mesh's units)."""

    edges: np.ndarray
    density: np.ndarray
    mean: float

    @property
    def centers(self) -> np.ndarray:
        return (self.edges[1:] + self.edges[:-1]) / 2


def shape_distribution(distances: np.ndarray, bins: int = 64, max_ratio: float = 3.0) -> ShapeDistribution:
    """Histogram of ``distances`` / their mean on [0, ``max_ratio``] (values above count in the last bin)."""
    d = np.asarray(distances, dtype=np.float64)
    d = d[np.isfinite(d)]
    mean = float(d.mean())
    edges = np.linspace(0, max_ratio, bins + 1)
    counts, _ = np.histogram(np.minimum(d / mean, max_ratio), edges)
    return ShapeDistribution(edges, counts / (counts.sum() * np.diff(edges)), mean)


def geodesic_and_euclidean_d2(distance, vertices, faces, n_pairs: int, seed: int = 0, bins: int = 64,
                              part: np.ndarray | None = None) -> tuple[ShapeDistribution, ShapeDistribution]:
    """The D2 histograms of ``distance(i, j)`` (index arrays) and of the straight-line distance, over the
    same random pairs (:func:`sample_pairs`)."""
    p = sample_pairs(vertices, faces, n_pairs, seed, part)
    straight = np.linalg.norm(vertices[p[:, 0]] - vertices[p[:, 1]], axis=1)
    return shape_distribution(distance(p[:, 0], p[:, 1]), bins), shape_distribution(straight, bins)


def histogram_l1(a: ShapeDistribution, b: ShapeDistribution) -> float:
    """integral |p_a - p_b| over the common bins (0: equal, 2: disjoint)."""
    if not np.array_equal(a.edges, b.edges):
        raise ValueError("histograms with different bins")
    return float((np.abs(a.density - b.density) * np.diff(a.edges)).sum())


@dataclass
class TriangleReport:
    """Over ``triples`` random triples: the fraction violating d(p,q) <= d(p,x) + d(x,q), and the excess
    (d(p,q) - d(p,x) - d(x,q)) / d(p,q) of the violating ones (mean and max, 0 when none)."""

    triples: int
    fraction: float
    mean_excess: float
    max_excess: float


def triangle_violations(distance, n_vertices: int, triples: int = 100_000, seed: int = 0,
                        part: np.ndarray | None = None, tolerance: float = 1e-6) -> TriangleReport:
    """Check the triangle inequality of ``distance(i, j)`` (index arrays) on random vertex triples.

    ``part``: restrict to these vertices (bool (N,)), e.g. one connected part. A triple violates it when
    the excess is above ``tolerance`` (relative): rounding makes collinear triples exceed by ~1e-16.
    """
    rng = np.random.default_rng(seed)
    pool = np.flatnonzero(part) if part is not None else np.arange(n_vertices)
    p, q, x = (pool[rng.integers(len(pool), size=triples)] for _ in range(3))
    keep = (p != q) & (p != x) & (q != x)
    p, q, x = p[keep], q[keep], x[keep]
    d_pq, d_px, d_xq = distance(p, q), distance(p, x), distance(x, q)
    excess = (d_pq - d_px - d_xq) / np.maximum(d_pq, 1e-300)
    bad = excess > tolerance
    worst = excess[bad] if bad.any() else np.zeros(1)
    return TriangleReport(len(p), float(bad.mean()), float(worst.mean()), float(worst.max()))
