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

import gegnn.fields.landmarks as landmarks_module
import gegnn.training.loop as gtrain
from gegnn import GeGnn, GeGnnConfig
from gegnn.checkpoint import load_checkpoint
from gegnn.decoders import LandmarkDecoder
from gegnn.distributed import Dist
from gegnn.fields.cache import FieldSpec
from gegnn.fields.heat import HeatDistance, cover_problem
from gegnn.fields.landmarks import landmark_fields
from gegnn.metrics import relative_error
from gegnn.training.data import BatchDataset
from gegnn.training.loop import TrainConfig, train
from gegnn.training.warmup import warm_decoder


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


def test_virtual_source_fields_are_near_exact_where_the_heat_methods_are_not():
    """On a sphere (2,562 vertices) the fields by virtual source propagation are 0.09% (mean relative) from
    the great circles of the same landmarks, the heat method's 1.4%; the landmark lower bound from 32 of them
    0.87% short of the distance, the heat method's 1.89%; each field is 0 at its landmark."""
    v, f = sphere(4)
    u = v / np.linalg.norm(v, axis=1, keepdims=True)
    errors, bounds = {}, {}
    i, j = np.random.default_rng(0).integers(0, len(v), (2, 5000))
    keep = i != j
    great = np.arccos(np.clip((u[i] * u[j]).sum(1), -1, 1))[keep]
    for kind in ("heat", "vsp"):
        lf = landmark_fields(v, f, 32, fields=kind)
        exact = np.arccos(np.clip(u @ u[lf.landmarks[0]].T, -1, 1))
        assert np.abs(lf.distances[lf.landmarks[0], np.arange(32)]).max() < 1e-6
        far = exact > 0.05
        errors[kind] = np.mean(np.abs(lf.distances - exact)[far] / exact[far])
        lower = np.abs(lf.distances[i] - lf.distances[j]).max(1)[keep]
        bounds[kind] = np.mean((great - lower) / great)
    assert errors["vsp"] < 0.002 and errors["heat"] > 0.01
    assert bounds["vsp"] < 0.012 and bounds["heat"] > 1.5 * bounds["vsp"]


def test_a_part_virtual_source_propagation_refuses_is_solved_on_its_manifold_copy_with_a_warning():
    """An edge of three faces (a fin on a sphere): the fields of the sphere without the fin on its vertices,
    the fin's tip (its only face set aside) reached along its edges, said in a warning."""
    from geodata.approximate_geodesic import ApproximateGeodesicSolver

    v, f = sphere(2)
    a, b = f[0, 0], f[0, 1]
    tip = len(v)
    fin_v = np.vstack([v, 2 * v[a]])
    fin_f = np.vstack([f, [[a, b, tip]]])
    with pytest.warns(UserWarning, match="1 non-manifold edges .* 1 face.s. set aside"):
        got = landmark_fields(fin_v, fin_f, 8, fields="vsp")
    landmarks = got.landmarks[0]
    on_sphere = landmarks[landmarks < tip]
    assert len(on_sphere) >= 7
    expect = ApproximateGeodesicSolver(fin_v, f).distances(on_sphere, threads=1).T[:tip]  # the tip in no face
    np.testing.assert_allclose(got.distances[:tip, landmarks < tip], expect, rtol=1e-6)
    along = np.minimum(expect[a] + np.linalg.norm(v[a]), expect[b] + np.linalg.norm(fin_v[tip] - v[b]))
    np.testing.assert_allclose(got.distances[tip, landmarks < tip], along, rtol=1e-6)


@pytest.mark.parametrize("source", ["shared", "far"])
def test_paths_through_a_pinched_vertex_are_taken_from_fan_to_fan(monkeypatch, source):
    """Two unit icosphere(4) spheres touching at one shared vertex (pinched: two fans), the source there or
    at the first sphere's far pole: its manifold copy splits the vertex, and the paths through it are taken
    from fan to fan, so each sphere's field is the great-circle distance (on the second sphere, plus the field
    at the shared vertex) to solver accuracy. Measured: 0.074% / 0.05% mean on the second sphere; before, solved from
    the first fan only, it was filled along its edges: 8.5% mean, 23% max for a source at the shared vertex,
    2.8% mean for the far one. No vertex is left to the edge fill (`_along_edges`, ~36x slower on a
    20k-vertex pair)."""
    a = trimesh.creation.icosphere(4)
    p = 0
    q = int(np.argmin(np.linalg.norm(a.vertices + a.vertices[p], axis=1)))  # opposite p
    shift = a.vertices[p] - a.vertices[q]
    b = a.copy()
    b.apply_translation(shift)
    pair = trimesh.util.concatenate([a, b])
    pair.merge_vertices()
    v, f = np.asarray(pair.vertices), np.asarray(pair.faces)
    assert len(v) == 2 * len(a.vertices) - 1
    shared = int(np.argmin(np.linalg.norm(v - a.vertices[p], axis=1)))
    s = shared if source == "shared" else int(np.argmin(np.linalg.norm(v - a.vertices[q], axis=1)))
    reached = []
    along_edges = landmarks_module._along_edges
    monkeypatch.setattr(landmarks_module, "_along_edges",
                        lambda fields, *rest: reached.append(np.isfinite(fields).all()) or along_edges(fields, *rest))
    with pytest.warns(UserWarning, match="solved on a copy"):
        field = landmarks_module._vsp_field(v, f, landmarks_module.T_COEF, 1)([s])[:, 0]
    assert reached == [True]  # every vertex reached by the solver itself
    for centre, start, before in ((np.zeros(3), s, 0.0), (shift, shared, field[shared])):
        on = np.abs(np.linalg.norm(v - centre, axis=1) - 1) < 1e-6
        great = before + np.arccos(np.clip((v[on] - centre) @ (v[start] - centre), -1, 1))
        far = great > 0.05
        error = np.abs(field[on] - great)[far] / great[far]
        assert error.mean() < 0.002 and error.max() < 0.01


def test_paths_through_pinched_vertices_are_made_in_bounded_chunks(monkeypatch):
    """Four spheres in a row, each touching the next at a vertex (three pinched vertices, six copy fields): the
    copy fields are solved SPLIT_CHUNK at a time and closed SPLIT_BLOCK vertices at a time (all at once before:
    (>= 2 P) x N' floats and a transposed copy, ~12 GB at 1M vertices with 256 pinched vertices), with the
    paths of solving them all at once."""
    from geodata.approximate_geodesic import ApproximateGeodesicSolver, manifold_copy

    ball = trimesh.creation.icosphere(2)
    left = int(np.argmin(ball.vertices[:, 0]))
    right = int(np.argmax(ball.vertices[:, 0]))
    step = ball.vertices[right] - ball.vertices[left]
    chain = trimesh.util.concatenate([ball.copy().apply_translation(i * step) for i in range(4)])
    chain.merge_vertices()
    v, f = np.asarray(chain.vertices), np.asarray(chain.faces)
    assert len(v) == 4 * len(ball.vertices) - 3
    cv, cf, origin, _ = manifold_copy(v, f)
    solver = ApproximateGeodesicSolver(cv, cf)
    asked = []

    class Counting:
        def distances(self, sources, threads=None):
            asked.append(len(sources))
            return solver.distances(sources, threads=threads)

    monkeypatch.setattr(landmarks_module, "SPLIT_CHUNK", 1000)
    monkeypatch.setattr(landmarks_module, "SPLIT_BLOCK", 10 ** 9)
    whole = landmarks_module._SplitVertexPaths(Counting(), origin, len(v))
    assert asked == [6]
    monkeypatch.setattr(landmarks_module, "SPLIT_CHUNK", 4)
    monkeypatch.setattr(landmarks_module, "SPLIT_BLOCK", 7)
    asked.clear()
    chunked = landmarks_module._SplitVertexPaths(Counting(), origin, len(v))
    assert asked == [4, 2]
    np.testing.assert_allclose(chunked.through, whole.through, rtol=1e-12)
    # the first contact reaches the far pole of the last sphere through the other two: about 3 pi
    assert np.isfinite(chunked.through).all() and chunked.through.max() > 2.8 * np.pi


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


def test_point_codes_blend_the_corners_and_take_the_nearest_landmark_of_the_blend():
    """A point inside a face: embedding, fields and position are sum_k b_k (corner k's), written out by
    hand; the nearest-landmark distance is the minimum of the blended fields, not the blend of the
    corners' minima (they differ here: each corner is nearest another landmark)."""
    d, k = 2, 3
    dec = LandmarkDecoder(d, k, 8)
    e = torch.tensor([[1.0, 0.0], [0.0, 2.0], [4.0, 4.0]])
    f = torch.tensor([[0.0, 3.0, 3.0], [3.0, 0.0, 3.0], [3.0, 3.0, 1.0]])
    pos = torch.tensor([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    corners = LandmarkDecoder.codes(e, f, pos).unsqueeze(0).repeat(2, 1, 1)
    bary = torch.tensor([[0.5, 0.25, 0.25], [0.0, 0.0, 1.0]])  # and a second point: at corner 2
    both = dec.point_codes(corners, bary)
    assert both[1, d + k] == 1.0  # each point its own nearest landmark (not the minimum over points)
    got = both[0]
    blended_f = [0.5 * 0 + 0.25 * 3 + 0.25 * 3, 0.5 * 3 + 0.25 * 0 + 0.25 * 3, 0.5 * 3 + 0.25 * 3 + 0.25 * 1]
    expected = [0.5 * 1 + 0.25 * 0 + 0.25 * 4, 0.5 * 0 + 0.25 * 2 + 0.25 * 4,   # embedding
                *blended_f,                                                        # 1.5, 2.25, 2.5
                1.5,                                                               # min of the blend (blend of the minima: 0.25)
                0.25, 0.25, 0.0]                                                   # position
    torch.testing.assert_close(got, torch.tensor(expected))
    on_corner = dec.point_codes(corners[:1], torch.tensor([[0.0, 1.0, 0.0]]))[0]
    torch.testing.assert_close(on_corner, corners[0, 1])  # a corner's own code


def test_decoders_defaults_are_the_models():
    """A decoder built with its defaults is the one a default config builds (the ratio form reading the
    embedding and the straight line; the paper's MLP decoder)."""
    from gegnn.decoders import DistanceDecoder

    model = GeGnn(small_config(landmarks=4))
    dec = LandmarkDecoder(model.config.embed_dim, 4, model.config.decoder_hidden)
    assert (dec.kind, dec.embedding, dec.euclidean) == (model.distance.kind, True, True) == ("ratio", True, True)
    assert (dec.mlp[-1].weight == 0).all()  # the ratio form starts as the bound
    assert DistanceDecoder(8, 16).kind == "mlp" and DistanceDecoder(8, 16).mlp is not None


def test_euclidean_decoder_is_the_embedding_distance():
    """The paper's ablation decoder: ||e_i - e_j||, 0 on i = j with a finite gradient there."""
    from gegnn.decoders import DistanceDecoder

    dec = DistanceDecoder(8, 16, kind="euclidean")
    a, b = torch.randn(50, 8), torch.randn(50, 8)
    torch.testing.assert_close(dec(a, b), (a - b).norm(dim=1))
    same = a.clone().requires_grad_(True)
    d = dec(same, a)
    assert (d.detach() < 1e-5).all() and not d.isnan().any()
    d.sum().backward()
    assert torch.isfinite(same.grad).all()


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


@pytest.mark.parametrize("batch", [4, 16])
def test_batched_sampling_starts_each_round_at_the_farthest_vertex_and_covers_as_sequential_sampling(batch):
    """Landmarks chosen `batch` a round: distinct, `first` first; each round's first landmark is the vertex
    farthest from all fields before it (what sequential sampling does every time); the fields are the solver's
    own; the covering radius (max over vertices of the distance to the nearest landmark) within 10% of
    sequential sampling's on a bumpy sphere."""
    v, f = bumpy_sphere()
    solver = HeatDistance(v, f)
    k, first = 48, 7
    chosen, fields = landmarks_module.batched_farthest_point_fields(solver.distances, v, k, first, batch)
    assert chosen[0] == first and len(set(chosen)) == k and fields.shape == (len(v), k)
    exact = np.maximum(solver.distances(chosen), 0)
    exact[chosen, np.arange(k)] = 0
    np.testing.assert_allclose(fields, exact, rtol=1e-6, atol=1e-7)
    for start in range(1, k, batch):  # the first round is `first` alone
        nearest = fields[:, :start].astype(np.float64).min(axis=1)
        assert nearest[chosen[start]] >= nearest.max() * (1 - 1e-6)
    seq_chosen, seq = landmarks_module.farthest_point_fields(solver.distance, len(v), k, first)
    assert seq_chosen != chosen  # the rounds really choose otherwise
    radius, seq_radius = fields.min(axis=1).max(), seq.min(axis=1).max()
    assert radius < 1.1 * seq_radius


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
    keys = gtrain.single_mesh_keys(ids, Dist())
    warm_decoder(model, (dataset[k] for k in keys), 200, 3e-3, torch.device("cpu"), logging.getLogger("test"))
    assert error() < 0.7 * before
    for name, value in network.items():
        torch.testing.assert_close(model.state_dict()[name], value)


# --- The heat method: potpourri3d's robust fields, reproduced (gegnn.fields.heat) -------------------------

def bumpy_sphere(seed=0):
    """No symmetry left, and noise that takes 350 intrinsic flips on the cover (3,840 edges)."""
    v, f = sphere(3)
    rng = np.random.default_rng(seed)
    return v * (1 + 0.05 * rng.standard_normal((len(v), 1))) + 0.04 * rng.standard_normal(v.shape), f


def open_bent_grid(seed=0):
    """A jittered, bent square: boundary edges whose opposite angle is obtuse flip in the tufted cover."""
    v, f = flat_grid(14)
    v = v + np.random.default_rng(seed).uniform(-0.06, 0.06, v.shape) * [1, 1, 0]
    v[:, 2] = 0.3 * np.sin(2 * v[:, 0]) * v[:, 1]
    return v, f


def sliver_sphere():
    """Three of four faces split by a vertex exactly on an edge (zero area: mollification), just off an
    edge (slivers) or next to a corner (needles)."""
    v, f = sphere(2)
    v, out = list(v), []
    for i, (a, b, c) in enumerate(f):
        mid = (v[a] + v[b]) / 2
        p = [mid, mid + 1e-4 * (v[c] - mid), v[a] + 1e-3 * ((v[b] + v[c]) / 2 - v[a]), None][i % 4]
        if p is None:
            out.append((a, b, c))
            continue
        v.append(p)
        out += [(a, b, len(v) - 1), (b, c, len(v) - 1), (c, a, len(v) - 1)]
    return np.asarray(v), np.asarray(out)


def elliptic_prism(n=32, a=1.0, b=0.3, h=0.8):
    """Caps fanned from one vertex (long thin triangles: flips) over points symmetric about both axes
    (isosceles trapezoids: cocircular quads, Delaunay either way). The cover's two sheets re-queue edges
    in mirrored order and end with different diagonals in some tied quads: both sheets count."""
    t = 2 * np.pi * np.arange(n) / n
    ring = np.stack([a * np.cos(t), b * np.sin(t)], 1)
    v = np.concatenate([np.c_[ring, np.zeros(n)], np.c_[ring, np.full(n, h)]])
    i = np.arange(n)
    j = (i + 1) % n
    sides = np.concatenate([np.stack([i, j, n + j], 1), np.stack([i, n + j, n + i], 1)])
    fan = np.stack([np.zeros(n - 2, dtype=int), np.arange(1, n - 1), np.arange(2, n)], 1)
    return v, np.concatenate([sides, fan[:, ::-1], fan + n])


def potpourri3d_fields(v, f, sources):
    import potpourri3d as pp3d

    solver = pp3d.MeshHeatMethodDistanceSolver(v, f, t_coef=0.5, use_robust=True)
    return np.stack([solver.compute_distance(int(s)) for s in sources], axis=1)


@pytest.mark.parametrize("make", [bumpy_sphere, open_bent_grid, sliver_sphere], ids=["closed", "boundary", "slivers"])
def test_heat_fields_equal_potpourri3d_robust_fields(make):
    """Every vertex as a source: where the Delaunay triangulation is unique our fields are potpourri3d's
    to solver rounding (measured <= 1e-9 of the largest distance), though the flips run in rounds, not
    in the library's queue order."""
    from gegnn.fields.heat import mollify, tufted_cover

    v, f = make()
    assert cover_problem(v, f) is None
    solver = HeatDistance(v, f)
    assert solver.n_flips > 50  # every mesh here needs intrinsic flips
    cover = tufted_cover(v, f)
    before = cover.length.copy()
    mollify(cover, before.mean())
    assert (cover.length > before).all() == (make is sliver_sphere)  # only the slivers need mollifying
    sources = np.arange(len(v))
    ours, theirs = solver.distances(sources), potpourri3d_fields(v, f, sources)
    assert np.abs(ours - theirs).max() <= 1e-9 * np.abs(theirs).max()


def test_heat_method_refuses_what_it_does_not_cover_and_says_why():
    """cover_problem names why a mesh is not for HeatDistance (landmark_fields then takes another solver),
    and HeatDistance refuses it with the same reason; a good mesh has none."""
    v, f = open_bent_grid()
    assert cover_problem(v, f) is None
    extra = np.concatenate([v, [[9.0, 9.0, 9.0]]])
    edges, count = np.unique(np.sort(f[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1), axis=0, return_counts=True)
    a, b = edges[count == 2][0]  # an interior edge: a third face makes it non-manifold
    bad = {"not a triangle mesh": [(v, f[:, :2]), (v[:, :2], f), (v, f[:0]), (v[None], f), (v, f[None])],
           "non-finite vertex coordinates": [(np.where(np.arange(len(v))[:, None] == 5, np.nan, v), f)],
           "face indices out of range or unreferenced vertices": [(v, np.where(f == 7, -1, f)),
                                                                 (v, np.where(f == 7, len(v), f)), (extra, f)],
           "face with a repeated vertex": [(v, np.concatenate([f, [[a, b, c]]]))
                                           for a, b, c in ((1, 1, 2), (1, 2, 2), (2, 1, 2))],
           "non-manifold edges": [(extra, np.concatenate([f, [[a, b, len(v)]]]))]}
    for reason, meshes in bad.items():
        for vertices, faces in meshes:
            assert cover_problem(vertices, faces) == reason
            with pytest.raises(ValueError, match=f"^heat method: {reason}$"):
                HeatDistance(vertices, faces)


def test_cocircular_heat_fields_are_as_near_exact_distances_as_potpourri3ds():
    """Where four vertices are cocircular either diagonal is Delaunay: the rounds of flips keep other
    diagonals than the library's queue in some tied quads of the cover's two sheets, and the fields
    differ (measured 1.6e-2 of the largest distance, 2026-11-26). Both are the method's: their mean
    relative error to the exact distances must agree (measured 6.516% ours, 6.508% potpourri3d's)."""
    from geodata.geodesic import geodesic_solver
    from geodata.mesh import Mesh

    v, f = elliptic_prism()
    sources = np.arange(len(v))
    ours, theirs = HeatDistance(v, f).distances(sources), potpourri3d_fields(v, f, sources)
    exact = np.stack([geodesic_solver(Mesh(v, f))(s) for s in sources], 1)
    far = exact > 1e-9
    assert np.abs(ours - theirs).max() <= 2e-2 * theirs.max()
    error = [(np.abs(d - exact)[far] / exact[far]).mean() for d in (ours, theirs)]
    assert error[0] <= 1.01 * error[1]


def test_heat_fields_solved_together_on_threads_are_each_sources_own_and_the_systems_solutions(monkeypatch):
    """src/heat_ops.cpp solves the sources in blocks of 16 (the rest in 8, 4, 2, 1) against the factors
    in Eigen's order of operations: every column is bit for bit its source's field alone, on one thread
    or two; and it solves the heat method's systems (SciPy's sparse LU on the same operators, 1e-10)."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as sla

    import gegnn.fields.heat as heat

    kept = {}
    factor = heat.HeatSolver._factor
    monkeypatch.setattr(heat.HeatSolver, "_factor", lambda self, what, lap, mass, grad, div:
                        kept.update(lap=lap.copy(), mass=mass) or factor(self, what, lap, mass, grad, div))
    v, f = open_bent_grid()
    solver = HeatDistance(v, f)
    sources = np.array([3, 77, 150, 3] + list(range(100, 133)))  # 37 = 16 + 16 + 4 + 1
    before = torch.get_num_threads()
    try:
        torch.set_num_threads(1)
        many = solver.distances(sources)
        torch.set_num_threads(2)
        np.testing.assert_array_equal(solver.distances(sources), many)
    finally:
        torch.set_num_threads(before)
    assert many.shape == (len(v), len(sources))
    np.testing.assert_array_equal(many[:, 0], many[:, 3])
    for j, s in enumerate(sources):
        np.testing.assert_array_equal(many[:, j], solver.distance(s))
    lap, n = kept["lap"], len(v)
    rhs = np.zeros((n, 3))
    rhs[sources[:3], np.arange(3)] = 1.0
    u = sla.splu((sp.diags(kept["mass"]) + solver.t * lap).tocsc()).solve(rhs)
    phi = sla.splu((lap + heat.POISSON_SHIFT * sp.identity(n)).tocsc()).solve(solver._divergence(u))
    expected = phi - phi[sources[:3], np.arange(3)]
    assert np.abs(many[:, :3] - expected).max() <= 1e-10 * np.abs(expected).max()


def test_graph_farthest_points_are_those_of_full_dijkstra_searches():
    """Landmarks along a neighbour graph (src/farthest_points.cpp, each search pruned where it brings no
    vertex closer) are those of SciPy's full Dijkstra search from every landmark with the same rule (the
    lowest index within TIE of the farthest): on a regular grid, full of exact ties, and on two parts,
    where the other part's lowest index comes second (infinitely far)."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import dijkstra

    from gegnn.fields.pointcloud import knn_edges

    grid = np.stack(np.meshgrid(np.arange(12.0), np.arange(9.0), [0.0], indexing="ij"), -1).reshape(-1, 3)
    apart = np.concatenate([grid, grid + [0.0, 50.0, 0.0]])
    for points, first in ((grid, 40), (apart, 7)):
        n = len(points)
        neighbors = knn_edges(points, 6)[1]
        rows = np.repeat(np.arange(n), neighbors.shape[1])
        lengths = np.linalg.norm(points[rows] - points[neighbors.ravel()], axis=1)
        graph = sp.csr_matrix((lengths, (rows, neighbors.ravel())), shape=(n, n))
        nearest, expected = np.full(n, np.inf), [first]
        for _ in range(30):
            np.minimum(nearest, dijkstra(graph, directed=False, indices=expected[-1]), out=nearest)
            far = np.isinf(nearest)
            expected.append(int(np.argmax(far)) if far.any() else landmarks_module._farthest(nearest))
        edges = np.stack([rows, neighbors.ravel()], axis=1)
        chosen = landmarks_module.graph_farthest_points(points, edges, 31, first)
        np.testing.assert_array_equal(chosen, expected)
        assert len(set(chosen.tolist())) == 31
    assert chosen[1] == len(grid)  # the other part's lowest index


def test_heat_gradient_divergence_equals_scipy_products_bit_for_bit(monkeypatch):
    """The compiled middle step (src/heat_ops.cpp) is SciPy's G u, NumPy's normalization and D X, in their
    order of sums: one source and several, with a zero gradient (u = 0) kept zero."""
    import gegnn.fields.heat as heat

    kept = {}
    factor = heat.HeatSolver._factor
    monkeypatch.setattr(heat.HeatSolver, "_factor", lambda self, what, lap, mass, grad, div:
                        kept.update(grad=grad.tocsr(), div=div.tocsr()) or factor(self, what, lap, mass, grad, div))
    v, f = bumpy_sphere()
    solver = HeatDistance(v, f)
    u = np.random.default_rng(0).random((len(v), 3))
    u[:, 2] = 0.0
    g = kept["grad"] @ u
    x, y = g[:len(g) // 2], g[len(g) // 2:]
    norm = x * x
    norm += y * y
    np.sqrt(norm, out=norm)
    norm[norm <= 0] = 1.0
    np.divide(1.0, norm, out=norm)
    x *= norm
    y *= norm
    expected = kept["div"] @ g
    assert (expected[:, 2] == 0).all() and np.abs(expected[:, :2]).max() > 0
    np.testing.assert_array_equal(solver._divergence(u), expected)
    np.testing.assert_array_equal(solver._divergence(u[:, 0]), expected[:, :1])
    with pytest.raises(ValueError, match="one row a vertex"):
        solver._divergence(u[:-1])


@pytest.mark.parametrize("spec", [FieldSpec("landmark", 16), FieldSpec("landmark", 16, cloud=8),
                                  FieldSpec("spectral", 8)], ids=["mesh", "cloud", "spectral"])
def test_draws_set_up_once_equal_draws_made_one_by_one(spec):
    """A fill computes a mesh's draws with one set-up of the heat method: the same bits as a fresh set-up
    per draw, in any order (no draw leaves state behind for the next)."""
    v, f = bumpy_sphere()
    v = np.concatenate([v, v[:200] * 0.3 + [4.0, 0.0, 0.0]]) if spec.cloud else v  # a cloud of two parts
    together = spec.compute_draws(v, f, [2, 0, 3])
    for seed, fields in zip([2, 0, 3], together):
        np.testing.assert_array_equal(fields, spec.compute(v, f, seed))
    if spec.kind == "landmark":
        assert not np.array_equal(together[0], together[1])  # the seed picks other landmarks


def test_heat_refuses_non_manifold_edges_and_landmarks_fall_back_to_potpourri3d():
    v, f = bumpy_sphere()
    a, b = f[0, 0], f[0, 1]
    v = np.concatenate([v, [[0.0, 0.0, 3.0]]])
    f = np.concatenate([f, [[a, b, len(v) - 1]]])  # a third face on edge ab
    assert cover_problem(v, f) == "non-manifold edges"
    with pytest.raises(ValueError):
        HeatDistance(v, f)
    got = landmark_fields(v, f, 40)  # 642 vertices, 40 fields: HeatDistance would be used
    assert np.isfinite(got.distances).all() and (got.distances[got.landmarks[0], np.arange(40)] == 0).all()
    np.testing.assert_allclose(got.distances[:, :3], potpourri3d_fields(v, f, got.landmarks[0, :3]), atol=1e-6)


def test_landmarks_unchanged_from_potpourri3d_selection(monkeypatch):
    """The same farthest-point landmarks and fields as with potpourri3d's solver, also on a symmetric
    mesh, where equally far vertices differ by solver rounding only (landmarks.TIE)."""
    grid = open_bent_grid()
    parts = [bumpy_sphere(), sphere(3), (grid[0] * 1.5, grid[1]), sphere(1)]  # the last one: potpourri3d's
    v = np.concatenate([p[0] + [4.0 * i, 0, 0] for i, p in enumerate(parts)])
    f = np.concatenate([p[1] + sum(len(q[0]) for q in parts[:i]) for i, p in enumerate(parts)])
    used = []
    monkeypatch.setattr(landmarks_module, "HeatDistance", lambda *a, **k: used.append(len(a[0])) or HeatDistance(*a, **k))
    ours = landmark_fields(v, f, 40, seed=5)
    assert used == [642, 642]  # the 196-vertex grid and the 42-vertex sphere are too small to pay
    import potpourri3d as pp3d

    def potpourri3d_fields(v, f, t, k):
        solver = pp3d.MeshHeatMethodDistanceSolver(v, f, t_coef=t, use_robust=True)
        return lambda sources: np.stack([solver.compute_distance(int(s)) for s in sources], axis=1)

    monkeypatch.setattr(landmarks_module, "_heat_field", potpourri3d_fields)
    theirs = landmark_fields(v, f, 40, seed=5)
    np.testing.assert_array_equal(ours.landmarks, theirs.landmarks)
    np.testing.assert_allclose(ours.distances, theirs.distances, rtol=0, atol=1e-6)


def test_exact_landmark_fields_are_the_exact_solver_s_and_a_model_reads_them_by_name(monkeypatch):
    """fields="exact": each landmark's field is the exact solver's (a real shortest path at every vertex), on
    any number of threads; fields="paths": its windows pruned within PATHS_TOLERANCE, never below exact and
    within 0.1% of it on average. The shipped default reads both by name (embed's ``fields``), closer to the
    truth than with its own vsp fields on a torus; a solver it does not know is refused by name."""
    from geodata._exact_geodesic import Surface
    from geodata.zoo import zoo_mesh

    from gegnn import threads

    v, f = zoo_mesh("torus-r0.3", 0.3)
    got = landmark_fields(v, f, 8, fields="exact")
    expect = Surface(v, f.astype(np.int32)).distances(got.landmarks[0]).T
    np.testing.assert_allclose(got.distances, expect, rtol=1e-6)
    monkeypatch.setattr(threads, "count", lambda: 3)
    np.testing.assert_array_equal(landmark_fields(v, f, 8, fields="exact").distances, got.distances)
    paths = landmark_fields(v, f, 8, fields="paths")
    exact = Surface(v, f.astype(np.int32)).distances(paths.landmarks[0]).T.astype(np.float32)
    ratio = paths.distances[exact > 0] / exact[exact > 0] - 1
    assert ratio.min() > -1e-6 and 0 < ratio.mean() < 1e-3, (ratio.min(), ratio.mean())
    model = GeGnn.pretrained()
    sources = [0, len(v) // 2]
    truth = Surface(v, f.astype(np.int32)).distances(np.array(sources))
    errors = {}
    for fields in (None, "exact", "paths"):
        emb = model.embed(v, f, fields=fields)
        d = np.stack([emb.field(s) for s in sources])
        errors[fields] = float(np.mean(np.abs(d - truth)[truth > 0] / truth[truth > 0]))
    assert errors["exact"] < 0.8 * errors[None] and errors["paths"] < 0.8 * errors[None], errors
    with pytest.raises(ValueError, match="fields='exakt'"):
        model.embed(v, f, fields="exakt")
