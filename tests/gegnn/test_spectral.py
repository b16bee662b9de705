"""The biharmonic model's cheap part: truncated spectral codes (a lower bound), the Weyl-law tail, and the
SpectralDecoder built on them."""
import numpy as np
import pytest
import torch
from gegnn_stores import ellipsoid, overfit, small_config, write_store
from scipy.integrate import quad
from scipy.special import j0

from geodata.biharmonic import biharmonic_distances
from geodata.mesh import Mesh
from gegnn import GeGnn
from gegnn.decoders import SpectralDecoder
from gegnn.fields.spectral import spectral_codes, weyl_shape, weyl_table


def truncated(codes, i, j, m):
    return np.sqrt(((codes[i, :m] - codes[j, :m]) ** 2).sum(-1))


def mre(d, exact):
    return float(np.mean(np.abs(d - exact) / exact))


@pytest.fixture(scope="module")
def mesh():
    v, f = ellipsoid((1.0, 0.7, 0.5), subdivisions=3)  # 642 vertices
    return v, f, biharmonic_distances(Mesh(v, f), np.arange(0, 642, 40))


def test_truncation_is_a_lower_bound_that_tightens_with_modes(mesh):
    v, f, exact = mesh
    src = np.arange(0, 642, 40)[:, None]
    tgt = np.arange(642)[None]
    off = src != tgt
    errors = []
    for m in (8, 32):
        d = truncated(spectral_codes(v, f, m), src, tgt, m)
        assert (d <= exact * (1 + 1e-6) + 1e-9).all()
        errors.append(mre(d[off], exact[off]))
    assert errors[1] < errors[0] / 2


def test_all_modes_give_the_exact_distance_and_no_tail():
    v, f = ellipsoid(subdivisions=1)  # 42 vertices: 41 non-constant modes
    codes = spectral_codes(v, f, 60)
    exact = biharmonic_distances(Mesh(v, f), np.arange(42))
    d = truncated(codes, np.arange(42)[:, None], np.arange(42)[None], 60)
    np.testing.assert_allclose(d, exact, rtol=1e-5, atol=1e-9)
    assert (codes[:, 60] == 0).all()


def test_codes_are_per_component_and_in_the_mesh_units():
    v, f = ellipsoid(subdivisions=2)
    two = (np.concatenate([v, v + 5.0]), np.concatenate([f, f + len(v)]))
    codes = spectral_codes(*two, 16)
    one = spectral_codes(v, f, 16)
    pair = (np.arange(len(v)), np.arange(len(v))[::-1])
    np.testing.assert_allclose(truncated(codes, *pair, 16), truncated(one, *pair, 16), rtol=1e-4)
    np.testing.assert_allclose(codes[len(v):, 16], one[:, 16], rtol=1e-4)  # each part its own tail scale
    scaled = spectral_codes(3.0 * v, f, 16)  # d scales as length, tau as length^2
    np.testing.assert_allclose(truncated(scaled, *pair, 16), 3.0 * truncated(one, *pair, 16), rtol=1e-4)
    np.testing.assert_allclose(scaled[:, 16], 9.0 * one[:, 16], rtol=1e-4)


def test_no_biharmonic_distance_is_a_clear_error():
    v, f = ellipsoid(subdivisions=1)
    f = f.copy()
    f[0] = [f[0, 0], f[0, 0], f[0, 1]]  # a zero-area face
    with pytest.raises(ValueError, match="no biharmonic distance on this mesh: 1 zero-area faces"):
        spectral_codes(v, f, 8)


def test_weyl_shape_matches_direct_quadrature():
    table = weyl_table()
    s = np.array([0.0, 1e-3, 0.05, 0.3, 1.0, 2.5, 7.0, 30.0, 100.0])
    got = weyl_shape(torch.tensor(s, dtype=torch.float32), table).numpy()

    def direct(x):  # F(s) = int_1^inf (1 - J0(s sqrt(u))) / u^2 du, another form of the same integral
        return quad(lambda u: (1 - j0(x * np.sqrt(u))) / u ** 2, 1, np.inf, limit=2000)[0]

    want = np.array([direct(x) for x in s])
    np.testing.assert_allclose(got, want, rtol=3e-3, atol=1e-6)
    assert got[0] == 0.0


def test_weyl_tail_recovers_most_of_what_truncation_misses(mesh):
    v, f, exact = mesh
    m = 16
    codes = spectral_codes(v, f, m)
    src, tgt = np.arange(0, 642, 40)[:, None], np.arange(642)[None]
    off = np.broadcast_to(src != tgt, exact.shape)
    dm = truncated(codes, src, tgt, m)
    tau = codes[src, m]
    r = np.linalg.norm(v[src] - v[tgt], axis=-1)
    shape = weyl_shape(torch.as_tensor(r / np.sqrt(2 * np.pi * tau), dtype=torch.float32), weyl_table()).numpy()
    d = np.sqrt(dm ** 2 + tau * shape)
    assert mre(d[off], exact[off]) < mre(dm[off], exact[off]) / 4


def test_decoder_is_symmetric_zero_on_the_diagonal_and_above_its_bound():
    torch.manual_seed(0)
    v, f = ellipsoid(subdivisions=2)
    dec = SpectralDecoder(8, 16, 32)
    for p in dec.parameters():  # a decoder far from its zero start
        torch.nn.init.normal_(p, std=0.5)
    codes = SpectralDecoder.codes(torch.randn(len(v), 8), torch.as_tensor(spectral_codes(v, f, 16)),
                                  torch.as_tensor(v, dtype=torch.float32))
    i, j = torch.randint(len(v), (2, 5000))
    d = dec(codes[i], codes[j])
    torch.testing.assert_close(d, dec(codes[j], codes[i]))
    assert (dec(codes[i], codes[i]) == 0).all()
    bound = (codes[i, 8:24] - codes[j, 8:24]).norm(dim=1)
    assert (d >= bound * (1 - 1e-6)).all() and (d > bound).float().mean() > 0.5


@pytest.mark.parametrize("embedding", [True, False])
def test_decoder_features_and_output_by_hand(embedding):
    """The decoder's inputs and output against the formula written out here: d_m^2, tau, r, s = r / sqrt(2 pi
    tau), the Weyl estimate w = tau F(s), features [(e_i - e_j)^2, F, d_m^2 / (d_m^2 + w), log s] and
    d^2 = d_m^2 + w exp(MLP); with or without the embedding (the --spectral-no-embedding ablation)."""
    torch.manual_seed(0)
    d, m = 4, 3
    dec = SpectralDecoder(d, m, 8, embedding=embedding)
    for p in dec.parameters():
        torch.nn.init.normal_(p, std=0.3)
    a = SpectralDecoder.codes(torch.randn(5, d), torch.rand(5, m + 1) + 0.1, torch.randn(5, 3))
    b = SpectralDecoder.codes(torch.randn(5, d), torch.rand(5, m + 1) + 0.1, torch.randn(5, 3))
    bound = ((a[:, d:d + m] - b[:, d:d + m]) ** 2).sum(dim=1)
    tau = (a[:, d + m] + b[:, d + m]) / 2
    r = torch.sqrt(((a[:, d + m + 1:] - b[:, d + m + 1:]) ** 2).sum(dim=1))
    s = r / torch.sqrt(2 * np.pi * tau)
    shape = weyl_shape(s, weyl_table())
    w = tau * shape
    feats = torch.stack([shape, bound / (bound + w), torch.log(s)], dim=1)
    if embedding:
        feats = torch.cat([(a[:, :d] - b[:, :d]) ** 2, feats], dim=1)
    x, (got_bound, got_tail) = dec.inputs(a, b)
    torch.testing.assert_close(x, feats)
    torch.testing.assert_close((got_bound, got_tail), (bound, w))
    t = dec.mlp(feats)
    torch.testing.assert_close(dec(a, b), torch.sqrt(bound + w * torch.exp(t[:, 0])))
    assert "weyl" not in dec.state_dict()  # a table of the code, not a weight: checkpoints do not carry it


def test_model_embeds_and_queries_match_the_decoder():
    torch.manual_seed(0)
    model = GeGnn(small_config(spectral=16)).eval()
    v, f = ellipsoid(subdivisions=2)
    emb = model.embed(v * 2.0, f, precision="fp32")
    emb.dtype = torch.float32
    emb._layers = emb._decoder_layers()
    i, j = np.random.default_rng(0).integers(len(v), size=(2, 3000))
    with torch.no_grad():
        want = model.distance(emb.features[i], emb.features[j]).numpy() * emb.scale
    np.testing.assert_allclose(emb.distance(i, j), np.where(i == j, 0, want), rtol=1e-5, atol=1e-7)
    # An untrained correction is zero: the model is the Weyl estimate, near the exact distance.
    exact = biharmonic_distances(Mesh(v * 2.0, f), i[:50])[np.arange(50), j[:50]]
    keep = i[:50] != j[:50]
    assert mre(emb.distance(i[:50], j[:50])[keep], exact[keep]) < 0.05


def test_small_model_overfits_one_mesh_below_the_weyl_estimate(tmp_path):
    store = write_store(tmp_path / "b.zarr", {"ellipsoid": ellipsoid((1.0, 0.7, 0.5))}, num_sources=16,
                        biharmonic=True)
    weyl, mre_after = overfit(store, 150, distance="biharmonic", spectral=8)
    assert weyl > 0.005 and mre_after < weyl / 4  # measured: 2.2% and 0.13%
