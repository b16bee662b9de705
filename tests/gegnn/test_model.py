import math

import numpy as np
import pytest
import torch
from gegnn_stores import ellipsoid, small_config

from gegnn import GeGnn, GeGnnConfig
from geodata.mesh import Mesh, unique_edges, vertex_normals


def mesh_hierarchy(model, v, f):
    return model.hierarchy(model.mesh_graph(v, vertex_normals(Mesh(v, f)).astype(np.float32), unique_edges(np.asarray(f))))


def test_default_is_the_paper_network():
    cfg = GeGnn().config
    assert (cfg.channels, cfg.embed_dim, cfg.encoder_blocks, cfg.decoder_blocks, cfg.groups) == \
        (256, 256, (2, 3, 3, 3, 2), (2, 3, 3, 3, 2), 4)
    assert (cfg.sigma_c, cfg.sigma_n, cfg.aggr, cfg.decoder) == (1 / 16, 3 / 16, "max", "mlp")


def test_permutation_equivariance():
    torch.manual_seed(0)
    model = GeGnn(small_config()).eval()
    v, f = ellipsoid()
    perm = np.random.default_rng(0).permutation(len(v))
    inverse = np.argsort(perm)
    e = model(mesh_hierarchy(model, v, f))
    e_perm = model(mesh_hierarchy(model, v[perm], inverse[f]))
    torch.testing.assert_close(e_perm, e[perm], atol=1e-5, rtol=1e-4)


def test_decoder_symmetric_and_non_negative():
    torch.manual_seed(0)
    model = GeGnn(small_config())
    a, b = torch.randn(100, 16), torch.randn(100, 16)
    torch.testing.assert_close(model.distance(a, b), model.distance(b, a))
    assert (model.distance(a, b) >= 0).all()


@pytest.mark.parametrize("variant", [dict(aggr="mean"), dict(aggr="sum"), dict(edge_length=False),
                                     dict(relative_position=False), dict(sigma_n=math.inf),
                                     dict(decoder="euclidean")])
def test_ablation_variants_run_and_round_trip_config(variant):
    cfg = small_config(**variant)
    assert GeGnnConfig.from_json(cfg.to_json()) == cfg
    model = GeGnn(cfg)
    v, f = ellipsoid()
    h = mesh_hierarchy(model, v, f)
    d = model(h, torch.tensor([[0, 5], [3, 9]]))
    assert d.shape == (2,) and torch.isfinite(d).all() and (d >= 0).all()
    d.sum().backward()


def test_embed_any_units_and_queries():
    torch.manual_seed(0)
    model = GeGnn(small_config())
    v, f = ellipsoid()
    e1 = model.embed(v, f)
    # Other units: distances scale with the mesh. (A power of two keeps normalization exact; otherwise
    # round-off may move a vertex lying exactly on a pooling-cell boundary into the next cell.)
    e2 = model.embed(v * 256.0, f)
    i, j = np.arange(50), np.arange(50, 100)
    np.testing.assert_allclose(e2.distance(i, j), 256.0 * e1.distance(i, j), rtol=1e-4)
    field = e1.field(3)
    assert field.shape == (len(v),)
    np.testing.assert_allclose(field[10:20], e1.distance(3, np.arange(10, 20)), rtol=1e-6)
    assert e1.distance(np.zeros((4, 5), int), np.ones((4, 5), int)).shape == (4, 5)
    with pytest.raises(IndexError):
        e1.distance([0], [len(v)])
    with pytest.raises(ValueError):
        model.embed(v[:, :2], f)


def test_bf16_queries_close_to_fp32():
    from gegnn.queries.embedding import Embedding

    torch.manual_seed(0)
    model = GeGnn(small_config(channels=32))
    v, f = ellipsoid()
    e = model.embed(v, f)
    rng = np.random.default_rng(0)
    i, j = rng.integers(0, len(v), 5000), rng.integers(0, len(v), 5000)
    exact = model.distance(e.features[i], e.features[j]).detach().numpy() * e.scale
    exact[i == j] = 0  # Embedding.distance: a vertex is at distance 0 from itself
    assert (i == j).any()
    fp32 = Embedding(e.features, model.distance, e.scale, precision="fp32").distance(i, j)
    bf16 = Embedding(e.features, model.distance, e.scale, precision="bf16").distance(i, j)
    np.testing.assert_allclose(fp32, exact, rtol=1e-5, atol=1e-6)
    assert np.median(np.abs(bf16 - exact) / (exact + 1e-3)) < 0.01
