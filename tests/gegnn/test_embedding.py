"""Embedding queries: the fused landmark features against the torch reference, whole matrices against
single distances."""
import numpy as np
import pytest
import torch
from gegnn_stores import ellipsoid, small_config

from gegnn import GeGnn
from gegnn.decoders import LandmarkDecoder
from gegnn.embedding import Embedding


def landmark_codes(n=300, d=8, k=21, seed=0):
    g = torch.Generator().manual_seed(seed)
    fields = torch.rand(n, k, generator=g) * 2
    return LandmarkDecoder.codes(torch.randn(n, d, generator=g), fields, torch.randn(n, 3, generator=g))


@pytest.mark.parametrize("embedding,euclidean", [(True, True), (False, True), (True, False)])
@pytest.mark.parametrize("k", [21, 128])  # 21: not a multiple of the kernel's 8 lanes
def test_fused_landmark_features_equal_the_torch_reference(embedding, euclidean, k):
    from gegnn._pair_features import landmark_features

    codes = landmark_codes(k=k)
    dec = LandmarkDecoder(8, k, 16, embedding=embedding, euclidean=euclidean)
    rng = np.random.default_rng(1)
    i, j = (torch.as_tensor(rng.integers(0, len(codes), 5000)) for _ in range(2))
    i[:10] = j[:10]  # i = j: lower bound 0
    ref, (lower, upper) = dec.inputs(codes[i], codes[j])
    with torch.inference_mode():
        fused, (f_lower, f_upper) = dec.pair_inputs(codes, i, j)
    torch.testing.assert_close(fused, ref, rtol=2e-6, atol=1e-6)
    torch.testing.assert_close(f_lower, lower, rtol=0, atol=0)  # max and min: no rounding
    torch.testing.assert_close(f_upper, upper, rtol=0, atol=0)
    x2, lo2, up2 = torch.empty_like(fused), torch.empty_like(f_lower), torch.empty_like(f_upper)
    landmark_features(codes, i, j, 8, k, embedding, euclidean, x2, lo2, up2, threads=3)
    assert torch.equal(x2, fused) and torch.equal(lo2, f_lower)  # threads split pairs, not sums
    with pytest.raises(IndexError):
        landmark_features(codes, i, j.clone().fill_(len(codes)), 8, k, embedding, euclidean, x2, lo2, up2)


def test_fused_decoder_distances_equal_the_module():
    torch.manual_seed(0)
    dec = LandmarkDecoder(8, 21, 16)
    torch.nn.init.normal_(dec.mlp[-1].weight, std=0.3)  # not the zero start: the MLP must matter
    codes = landmark_codes()
    emb = Embedding(codes, dec, scale=2.0, precision="fp32")
    rng = np.random.default_rng(2)
    i, j = rng.integers(0, len(codes), 3000), rng.integers(0, len(codes), 3000)
    ref = dec(codes[i], codes[j]).detach().numpy() * 2.0
    ref[i == j] = 0
    np.testing.assert_allclose(emb.distance(i, j), ref, rtol=1e-5, atol=1e-7)


@pytest.fixture(scope="module")
def landmark_embedding():
    torch.manual_seed(0)
    model = GeGnn(small_config(landmarks=8))
    torch.nn.init.normal_(model.distance.mlp[-1].weight, std=0.3)
    v, f = ellipsoid()
    return model.embed(v, f)


@pytest.mark.parametrize("tile", [7, 64, 4096])
def test_matrix_is_symmetric_zero_on_the_diagonal_and_equals_distance(landmark_embedding, tile):
    emb = landmark_embedding
    n = emb.num_vertices
    d = emb.matrix(tile=tile)
    assert d.shape == (n, n) and d.dtype == np.float32
    assert np.array_equal(d, d.T) and not np.diag(d).any()
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    np.testing.assert_allclose(d, emb.distance(i, j), rtol=1e-6, atol=1e-7)


def test_matrix_blocks_rows_cols_and_out(landmark_embedding, tmp_path):
    import zarr

    emb = landmark_embedding
    rows, cols = np.array([5, 0, 17, 5, 99]), np.arange(3, 60, 2)
    block = emb.matrix(rows, cols, tile=4)
    np.testing.assert_allclose(block, emb.distance(rows[:, None], cols[None, :]), rtol=1e-6, atol=1e-7)
    out = zarr.create_array(tmp_path / "d.zarr", shape=(len(rows), len(cols)), chunks=(4, 4), dtype="float16")
    emb.matrix(rows, cols, dtype=np.float16, out=out, tile=4)
    np.testing.assert_allclose(out[:], block, rtol=1e-3)
    with pytest.raises(ValueError, match="shape"):
        emb.matrix(rows, cols, out=np.empty((2, 2)))
    tiny = Embedding(emb.features, emb.decoder, scale=1e6, precision="fp32")
    with pytest.raises(ValueError, match="float16"):
        tiny.matrix(rows, cols, dtype=np.float16)
