"""Landmark-guided GeGnn: the landmark fields, the bounds and the decoder's invariances, training and
checkpoints."""
import dataclasses
import logging

import gdist

import numpy as np
import pytest
import torch
import trimesh
from gegnn_stores import ellipsoid, exact_pairs, flat_grid, overfit, small_config

from gegnn import GeGnn, GeGnnConfig
from gegnn.checkpoint import load_checkpoint
from gegnn.data import BatchDataset
from gegnn.decoders import LandmarkDecoder
from gegnn.fields import FieldSpec
from gegnn.landmarks import landmark_fields
import gegnn.train as gtrain
from gegnn.train import TrainConfig, relative_error, train


def exact_matrix(v, f) -> np.ndarray:
    """All-pairs exact polyhedral geodesic distances (tvb-gdist)."""
    pairs, d = exact_pairs(v, f, np.arange(len(v)))
    out = np.zeros((len(v), len(v)))
    out[pairs[:, 0], pairs[:, 1]] = d
    return out


def sphere(subdivisions=2):
    m = trimesh.creation.icosphere(subdivisions)
    return np.asarray(m.vertices), np.asarray(m.faces)


def random_decoder(k, output, embed_dim=8):
    """A decoder whose MLP matters (the ratio form's last layer starts at zero)."""
    torch.manual_seed(0)
    dec = LandmarkDecoder(embed_dim, k, 16, output=output)
    torch.nn.init.normal_(dec.mlp[-1].weight, std=0.5)
    return dec


def decoder_codes(fields, k, embed_dim=8, seed=0):
    g = torch.Generator().manual_seed(seed)
    n = len(fields)
    return LandmarkDecoder.codes(torch.randn(n, embed_dim, generator=g), torch.as_tensor(fields),
                                 torch.randn(n, 3, generator=g))


@pytest.mark.parametrize("mesh", [flat_grid(10), sphere(2)], ids=["flat grid", "sphere"])
def test_bounds_hold_with_exact_fields(mesh):
    """max_k |d_ik - d_jk| <= d_ij <= min_k d_ik + d_jk, and the decoder's output lies between them."""
    v, f = mesh
    exact = exact_matrix(v, f)
    if np.ptp(v[:, 2]) == 0:
        np.testing.assert_allclose(exact, np.linalg.norm(v[:, None] - v[None], axis=2), atol=1e-9)
    chosen = landmark_fields(v, f, 8).landmarks[0]
    fields = exact[:, chosen].astype(np.float32)
    dec = random_decoder(8, "interval")
    codes = decoder_codes(fields, 8)
    i, j = np.triu_indices(len(v), 1)
    x, (lower, upper) = dec.inputs(codes[i], codes[j])
    d = torch.as_tensor(exact[i, j], dtype=torch.float32)
    assert (lower <= d + 1e-5).all() and (d <= upper + 1e-5).all()
    pred = dec(codes[i], codes[j])
    assert (lower - 1e-6 <= pred).all() and (pred <= upper + 1e-6).all()
    assert (lower < d).float().mean() > 0.5  # the bound is not trivially tight: there is work left


@pytest.mark.parametrize("output", ["ratio", "interval"])
def test_decoder_invariant_to_landmark_order_symmetric_zero_on_diagonal(output):
    k = 12
    dec = random_decoder(k, output)
    fields = np.random.default_rng(0).random((50, k)).astype(np.float32) * 2
    codes = decoder_codes(fields, k)
    perm = np.random.default_rng(1).permutation(k)
    permuted = decoder_codes(fields[:, perm], k)
    i, j = np.random.default_rng(2).integers(0, 50, (2, 400))
    torch.testing.assert_close(dec(codes[i], codes[j]), dec(permuted[i], permuted[j]))
    torch.testing.assert_close(dec(codes[i], codes[j]), dec(codes[j], codes[i]))
    same = torch.arange(50)
    assert (dec(codes[same], codes[same]) == 0).all()
    assert (dec(codes[i], codes[j])[i != j] > 0).all()


def test_fields_are_deterministic_and_within_one_component():
    a, fa = ellipsoid(subdivisions=2)
    b, fb = ellipsoid((0.3, 0.3, 0.3), subdivisions=1)
    v = np.concatenate([a, b + [3.0, 0, 0]])
    f = np.concatenate([fa, fb + len(a)])
    first = landmark_fields(v, f, 16, seed=3)
    again = landmark_fields(v, f, 16, seed=3)
    np.testing.assert_array_equal(first.distances, again.distances)
    assert not np.array_equal(first.distances, landmark_fields(v, f, 16, seed=4).distances)
    assert first.landmarks.shape == (2, 16)
    for c, rows in enumerate(first.landmarks):
        assert (first.component[rows] == c).all()  # each component's landmarks are its own vertices
    # Farthest-point sampling: the first landmarks are far apart on the ellipsoid.
    lm = first.landmarks[0]
    exact = gdist.compute_gdist(a, fa.astype(np.int32), np.array([lm[0]], np.int32), np.array([lm[1]], np.int32))
    assert exact[0] > 1.5  # the ellipsoid's half-circumference along its long axis is ~2.7
    assert np.isfinite(first.distances).all() and (first.distances >= 0).all()


@pytest.mark.parametrize("k", [4, 64])
def test_several_components_and_tiny_meshes_give_finite_distances(k):
    """Two parts, a lone triangle (3 vertices < K) and an unused vertex: all finite, 0 on the diagonal."""
    a, fa = ellipsoid(subdivisions=1)
    tri = np.array([[5.0, 0, 0], [5.5, 0, 0], [5.0, 0.5, 0]])
    v = np.concatenate([a, tri, [[9.0, 9, 9]]])
    f = np.concatenate([fa, [[len(a), len(a) + 1, len(a) + 2]]])
    torch.manual_seed(0)
    emb = GeGnn(small_config(landmarks=k)).embed(v, f)
    n = len(v)
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    d = emb.distance(i, j)
    assert np.isfinite(d).all() and (d >= 0).all()
    assert (np.diag(d) == 0).all()
    # The lone triangle's distances come from its own landmarks' bounds: Euclidean up to the heat
    # method's error on one triangle (7% here).
    t = len(a) + np.arange(3)
    true = np.linalg.norm(tri[:, None] - tri[None], axis=2)
    assert np.abs(d[np.ix_(t, t)] - true).max() < 0.1 * true.max()


def test_small_model_overfits_one_mesh_far_below_the_bound(one_mesh_store):
    # The ratio decoder starts as the lower bound, so the error before the first step is the bound's.
    bound, mre = overfit(one_mesh_store, 200, landmarks=8)
    assert bound > 0.03 and mre < bound / 4  # measured: 8.7% and 1.5%


def test_paper_checkpoint_made_before_landmarks_still_loads():
    """The shipped paper model predates the landmark decoder: same tensor names, landmarks = 0."""
    model = GeGnn.pretrained("paper")
    assert model.config.landmarks == 0
    v, f = sphere(4)
    d = model.embed(v, f).distance(0, np.arange(len(v)))
    exact = np.arccos(np.clip(v @ v[0], -1, 1))
    assert np.mean(np.abs(d - exact) / (exact + 1e-3)) < 0.12  # as when it shipped (8.5% over random pairs)


def test_checkpoint_round_trip_with_landmarks(tmp_path):
    torch.manual_seed(0)
    model = GeGnn(small_config(landmarks=16, landmark_output="interval")).eval()
    model.save(tmp_path / "m.safetensors")
    again = GeGnn.from_checkpoint(tmp_path / "m.safetensors")
    assert again.config == model.config
    v, f = ellipsoid()
    i, j = np.arange(40), np.arange(40, 80)
    np.testing.assert_array_equal(model.embed(v, f).distance(i, j), again.embed(v, f).distance(i, j))


def test_init_from_paper_model_keeps_its_network(tiny_store, tmp_path):
    """`gegnn train --init paper.ckpt --landmarks K`: the network's weights come from the checkpoint, the
    landmark decoder starts fresh."""
    torch.manual_seed(0)
    paper = GeGnn(small_config())
    paper.save(tmp_path / "paper.safetensors")
    cfg = TrainConfig(store=tiny_store, run=str(tmp_path / "run"), epochs=1, batch_size=2, lr=0.0,
                      pairs_per_mesh=200, init=str(tmp_path / "paper.safetensors"))
    # The command line's defaults (e.g. a 256-wide decoder from --channels) choose nothing but the kind of
    # decoder: its width comes with the checkpoint.
    train(cfg, dataclasses.replace(GeGnnConfig(), landmarks=8))
    got = load_checkpoint(tmp_path / "run" / "last.safetensors")
    assert got.config == dataclasses.replace(paper.config, landmarks=8)
    for name, value in paper.state_dict().items():
        if not name.startswith("distance."):
            torch.testing.assert_close(got.model_state[name], value)
    fresh = GeGnn(got.config).distance
    for name, value in fresh.state_dict().items():  # the ratio decoder's last layer starts at zero
        if name.startswith("mlp.4"):
            torch.testing.assert_close(got.model_state["distance." + name], value)


def test_decoder_warmup_trains_the_decoder_alone(tiny_store):
    """--decoder-warmup: the decoder learns on frozen codes (its error falls), the network is untouched."""
    torch.manual_seed(0)
    paper = GeGnn(small_config())
    model = GeGnn(small_config(landmarks=8))
    model.load_state_dict({k: v for k, v in paper.state_dict().items() if not k.startswith("distance.")},
                          strict=False)
    dataset = BatchDataset(tiny_store, "geodesic", 0, 400, False, 5, 1 / 16, 3 / 16, FieldSpec("landmark", 8))
    ids = ["ellipsoid_a", "ellipsoid_b", "sphere"]

    def error():
        with torch.no_grad():
            return np.mean([relative_error(model(b.hierarchy, b.pairs, b.fields), b.distances).mean().item()
                            for b in (dataset[(-1, (m,))] for m in ids)])

    before, network = error(), {k: v.clone() for k, v in model.state_dict().items() if not k.startswith("distance.")}
    keys = gtrain.single_mesh_keys(ids, gtrain.Dist())
    gtrain.warm_decoder(model, (dataset[k] for k in keys), 200, 3e-3, torch.device("cpu"), logging.getLogger("test"))
    assert error() < 0.7 * before
    for name, value in network.items():
        torch.testing.assert_close(model.state_dict()[name], value)
