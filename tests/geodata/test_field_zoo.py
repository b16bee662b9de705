"""The field solver on the shape zoo (geodata.zoo) against the exact solver: every shape at a small size
within the stated tolerance, the torus without a systematic shortcut (docs/benchmarks.md, "The shape zoo",
has the full-size table)."""
import numpy as np
import pytest

from geodata._exact_geodesic import Surface
from geodata.approximate_geodesic import approximate_geodesic_distances
from geodata.zoo import ZOO, zoo_mesh


def signed_errors(v, f, sources):
    exact = Surface(v, f.astype(np.int32)).distances(np.asarray(sources))
    d = approximate_geodesic_distances(v, f, sources, threads=1)
    keep = exact > 0
    return (d[keep] - exact[keep]) / exact[keep]


@pytest.mark.parametrize("name", list(ZOO))
def test_every_zoo_shape_is_near_exact(name):
    v, f = zoo_mesh(name, 0.2)  # 480-1,140 vertices
    r = signed_errors(v, f, [0, len(v) // 3, 2 * len(v) // 3])
    assert np.abs(r).mean() < 0.005  # measured 0.05-0.33%
    assert np.quantile(np.abs(r), 0.99) < 0.05  # measured 0.3-3.3%; the worst vertex, beside a source, up to 12%


def test_a_torus_has_no_shortcut_across_its_saddles():
    # one vertex's excess is small on the inner side; gates at 0.05 rad let the strips through: 1.92% mean
    # error, -1.81% signed, before gates at every saddle vertex
    v, f = zoo_mesh("torus-r0.3")
    r = signed_errors(v, f, np.random.default_rng(0).choice(len(v), 4, replace=False))
    assert np.abs(r).mean() < 0.003  # measured 0.216%
    assert -0.001 < r.mean() < 0.003  # measured +0.198%: a little long, never short


def test_a_coil_is_near_exact():
    v, f = zoo_mesh("coil", 0.5)
    r = signed_errors(v, f, [0, len(v) // 2])
    assert np.abs(r).mean() < 0.004 and r.mean() > -0.001
