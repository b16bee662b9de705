"""The paper's applications against known answers: paths (straight on a plane, great circles on a sphere),
the log map (polar coordinates on a plane and a sphere), shape distributions (the mean distance of a
square and a sphere, bend invariance), the triangle inequality, finetuning."""
import numpy as np
import pytest
import torch
import trimesh

from gegnn import Embedding, GeGnn
from gegnn.decoders import DistanceDecoder
from gegnn.queries.logmap import log_map, vector_heat_log_map
from gegnn.queries.paths import SurfaceTopology, trace_path
from gegnn.queries.statistics import histogram_l1, sample_pairs, shape_distribution, triangle_violations


def plane(n=31, jitter=0.3, seed=0):
    """A unit square grid, interior vertices jittered by up to ``jitter`` of the spacing (z = 0)."""
    x, y = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))
    v = np.c_[x.ravel(), y.ravel(), np.zeros(n * n)]
    inner = (v[:, 0] > 0) & (v[:, 0] < 1) & (v[:, 1] > 0) & (v[:, 1] < 1)
    v[inner, :2] += np.random.default_rng(seed).uniform(-jitter, jitter, (inner.sum(), 2)) / (n - 1)
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel(), idx[1:, :-1].ravel()
    return v, np.r_[np.c_[a, b, c], np.c_[a, c, d]]


def euclidean_embedding(v, f):
    """An Embedding whose distance is the straight-line one: the geodesic distance of a plane."""
    return Embedding(torch.as_tensor(v, dtype=torch.float32), DistanceDecoder(3, 0, "euclidean"),
                     precision="fp32", vertices=v, faces=f)


def great_circle(v):
    return lambda i, j: np.arccos(np.clip((v[i] * v[j]).sum(axis=-1), -1, 1))


@pytest.fixture(scope="module")
def sphere():
    m = trimesh.creation.icosphere(5)  # 10,242 vertices on the unit sphere
    return np.asarray(m.vertices), np.asarray(m.faces)


# -- paths ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("s, t", [(0, 960), (5 * 31 + 3, 28 * 31 + 25), (15 * 31 + 15, 2 * 31 + 29)])
def test_path_on_a_plane_is_the_straight_segment(s, t):
    v, f = plane()
    path = euclidean_embedding(v, f).path(s, t)
    assert path.traced and np.allclose(path.points[[0, -1]], v[[s, t]])
    seg = (v[t] - v[s])[:2] / np.linalg.norm(v[t] - v[s])
    off = (path.points - v[s])[:, :2] @ np.array([-seg[1], seg[0]])
    assert np.abs(off).max() < 1e-5  # float32 embedding
    assert path.length == pytest.approx(np.linalg.norm(v[t] - v[s]), rel=1e-5)


@pytest.mark.parametrize("s, t", [(0, 100), (5, 2000), (17, 9000)])
def test_path_on_a_sphere_follows_the_great_circle(sphere, s, t):
    v, f = sphere
    d = great_circle(v)
    path = trace_path(SurfaceTopology(v, f), lambda j: d(s, j), s, t)
    normal = np.cross(v[s], v[t])
    normal /= np.linalg.norm(normal)
    assert path.traced
    assert np.abs(path.points @ normal).max() < 0.01   # edges are ~0.04 long
    assert path.length == pytest.approx(d(s, t), rel=2e-3)  # the chords of a faceted arc are shorter


def test_a_spurious_minimum_finishes_along_edges():
    v, f = plane(jitter=0)
    s, t, pit = 0, 960, 20 * 31 + 20
    d = np.linalg.norm(v - v[s], axis=1)
    d[pit] = 0.01  # a local minimum the descent from t runs into
    path = trace_path(SurfaceTopology(v, f), lambda j: d[j], s, pit + 31 + 1)
    assert not path.traced and np.allclose(path.points[0], v[s])


def test_no_path_between_separate_parts():
    v, f = plane(n=5, jitter=0)
    two_v, two_f = np.r_[v, v + [0, 0, 1]], np.r_[f, f + len(v)]
    d = np.linalg.norm(two_v - two_v[0], axis=1)
    with pytest.raises(ValueError, match="not on the target's connected part"):
        trace_path(SurfaceTopology(two_v, two_f), lambda j: d[j], 0, len(v) + 3)


def test_pretrained_path_is_close_to_the_exact_path():
    from geodata.geodesic import edge_flip_paths, polyline_length
    from geodata.mesh import Mesh
    from gegnn.fields.exact import exact_field

    m = trimesh.creation.icosphere(4)
    v = np.asarray(m.vertices) * [1.0, 0.8, 0.6]  # an ellipsoid: not a training mesh
    f = np.asarray(m.faces)
    emb = GeGnn.pretrained().embed(v, f)
    exact = exact_field(Mesh(v, f), 0)
    targets = (700, 1500, 2400)
    for t, flip in zip(targets, edge_flip_paths(Mesh(v, f), [(0, t) for t in targets])):
        path = emb.path(0, t)
        ref = polyline_length(flip)
        assert ref == pytest.approx(exact[t], rel=1e-6)
        assert path.length == pytest.approx(ref, rel=0.03)


# -- log map ---------------------------------------------------------------------------------------------
def test_log_map_on_a_plane_is_the_polar_coordinates():
    v, f = plane()
    emb = euclidean_embedding(v, f)
    c = 15 * 31 + 15
    lm = emb.log_map(c, 0.3)
    expected = (v[lm.vertices] - v[c]) @ lm.frame.T
    assert len(lm.vertices) == (np.linalg.norm(v - v[c], axis=1) <= 0.3).sum()
    assert np.abs(lm.uv - expected).max() < 1e-5


def test_log_map_stays_on_the_center_part():
    v, f = plane(n=11, jitter=0)
    two_v, two_f = np.r_[v, v + [0, 0, 0.01]], np.r_[f, f + len(v)]  # a second sheet 0.01 above
    lm = euclidean_embedding(two_v, two_f).log_map(60, 0.5)
    assert len(lm.vertices) and lm.vertices.max() < len(v)


def test_log_map_on_a_sphere(sphere):
    v, f = sphere
    c = 10
    lm = log_map(SurfaceTopology(v, f), great_circle(v), c, 1.0, rings=1)
    p = v[lm.vertices]
    tangent = p - (p @ v[c])[:, None] * v[c]
    r = np.arccos(np.clip(p @ v[c], -1, 1))
    direction = tangent / np.maximum(np.linalg.norm(tangent, axis=1), 1e-12)[:, None]
    expected = r[:, None] * (direction @ lm.frame.T)
    assert np.linalg.norm(lm.uv - expected, axis=1).mean() < 0.01


def test_log_map_agrees_with_vector_heat_on_an_ellipsoid():
    m = trimesh.creation.icosphere(4)
    v, f = np.asarray(m.vertices) * [1.0, 0.8, 0.6], np.asarray(m.faces)
    emb = GeGnn.pretrained().embed(v, f)
    lm = emb.log_map(3, 0.5)
    _, diff = vector_heat_log_map(v, f, lm)
    assert diff < 0.1


# -- shape distributions, triangle inequality --------------------------------------------------------------
def test_d2_mean_of_the_unit_square():
    v, f = plane(n=61, jitter=0.2)
    import potpourri3d as pp3d

    assert pp3d.vertex_areas(v, f).sum() == pytest.approx(1.0)
    p = sample_pairs(v, f, 400_000, seed=1)
    d = np.linalg.norm(v[p[:, 0]] - v[p[:, 1]], axis=1)
    mean_square = (2 + np.sqrt(2) + 5 * np.log(1 + np.sqrt(2))) / 15  # 0.5214
    assert shape_distribution(d).mean == pytest.approx(mean_square, rel=0.01)


def test_d2_of_the_sphere_is_half_a_sine(sphere):
    v, f = sphere
    p = sample_pairs(v, f, 400_000, seed=2)
    h = shape_distribution(great_circle(v)(p[:, 0], p[:, 1]), bins=32, max_ratio=2.0)
    assert h.mean == pytest.approx(np.pi / 2, rel=0.01)
    # angle theta has density sin(theta) / 2; the ratio x = theta / (pi / 2) has (pi / 4) sin(pi x / 2)
    analytic = np.pi / 4 * np.sin(np.pi * h.centers / 2)
    assert (np.abs(h.density - analytic) * np.diff(h.edges)).sum() < 0.03


def test_geodesic_d2_is_invariant_to_a_bend_and_euclidean_is_not():
    from geodata.augment import bend
    from geodata.geodesic import geodesic_solver
    from geodata.mesh import Mesh

    v, f = plane(n=25, jitter=0)
    v = v * [2.0, 0.5, 1.0]  # a strip
    bent = bend(v, np.eye(3)[[0, 2, 1]], np.pi)  # rolled into half a cylinder: an isometry
    p = sample_pairs(v, f, 20_000, seed=3)
    hist = {}
    for name, verts in (("flat", v), ("bent", bent)):
        solve = geodesic_solver(Mesh(verts, f))
        fields = {s: solve(int(s)) for s in np.unique(p[:, 0])}
        geo = np.array([fields[a][b] for a, b in p])
        hist[name] = (shape_distribution(geo, 32), shape_distribution(np.linalg.norm(verts[p[:, 0]] - verts[p[:, 1]],
                                                                                      axis=1), 32))
    assert histogram_l1(hist["flat"][0], hist["bent"][0]) < 1e-3
    assert histogram_l1(hist["flat"][1], hist["bent"][1]) > 0.1


def test_triangle_inequality_counts():
    v, f = plane()
    euclid = lambda i, j: np.linalg.norm(v[i] - v[j], axis=-1)  # noqa: E731
    assert triangle_violations(euclid, len(v), 20_000).fraction == 0
    squared = triangle_violations(lambda i, j: euclid(i, j) ** 2, len(v), 20_000)  # not a metric
    assert 0.1 < squared.fraction < 1 and 0 < squared.mean_excess <= squared.max_excess <= 1


# -- finetune ------------------------------------------------------------------------------------------------
def test_finetune_lowers_the_held_out_error():
    m = trimesh.creation.icosphere(3)
    v = np.asarray(m.vertices) * [1.0, 0.5, 0.3]  # a flat ellipsoid, far from the paper model's error floor
    model = GeGnn.pretrained("paper")
    r = model.finetune(v, m.faces, sources=8, held_out=4, decoder_steps=100, head_steps=100, steps=2,
                       pairs_per_step=4096)
    assert len(set(r.train_sources) | set(r.held_out_sources)) == 12
    assert r.mre_after < 0.8 * r.mre_before
    assert not model.training


def test_finetune_scores_a_biharmonic_model_against_biharmonic_distances():
    """The held-out error before any step is the model's error against exact *biharmonic* distances
    (geodata.biharmonic, computed here independently), not against geodesic ones (~10x apart here)."""
    from geodata.biharmonic import biharmonic_distances
    from geodata.mesh import Mesh
    from gegnn.metrics import relative_error

    m = trimesh.creation.icosphere(2)
    v = np.asarray(m.vertices) * [1.0, 0.6, 0.4]  # longest half-extent 1: normalized units are the mesh's
    model = GeGnn.pretrained("biharmonic")
    r = model.finetune(v, m.faces, sources=2, held_out=3, decoder_steps=0, head_steps=0)
    exact = biharmonic_distances(Mesh(v, np.asarray(m.faces)), r.held_out_sources)  # (3, N)
    emb = model.embed(v, m.faces)
    s, t = np.nonzero(exact > 0)
    pred = emb.distance(r.held_out_sources[s], t)
    expected = relative_error(torch.as_tensor(pred), torch.as_tensor(exact[s, t], dtype=torch.float32)).mean()
    assert r.mre_before == pytest.approx(float(expected), rel=1e-3)


# -- commands ----------------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def ellipsoid_obj(tmp_path_factory):
    m = trimesh.creation.icosphere(3)
    path = tmp_path_factory.mktemp("mesh") / "ellipsoid.obj"
    trimesh.Trimesh(np.asarray(m.vertices) * [1.0, 0.7, 0.5], m.faces, process=False).export(path)
    return str(path), len(m.vertices)


def test_finetune_command_writes_a_checkpoint(ellipsoid_obj, tmp_path):
    from click.testing import CliRunner

    from gegnn.checkpoint import load_checkpoint
    from gegnn.cli import main

    path, _ = ellipsoid_obj
    out = tmp_path / "tuned.safetensors"
    result = CliRunner().invoke(main, ["finetune", "--pretrained", "paper", path, "-o", str(out), "--sources", "6",
                                       "--held-out", "2", "--steps", "1", "--decoder-steps", "20", "--head-steps", "20"])
    assert result.exit_code == 0, result.output
    assert "held-out MRE" in result.output
    meta = load_checkpoint(out).metadata
    assert meta["finetuned_on"] == "ellipsoid.obj" and meta["finetune"]["sources"] == 6
    assert GeGnn.from_checkpoint(out).config == GeGnn.pretrained("paper").config
    result = CliRunner().invoke(main, ["finetune", "--pretrained", path, "-o", str(tmp_path / "x.pt")])
    assert result.exit_code != 0 and "expected one of .safetensors" in result.output


def test_query_path_texture_and_shape_distribution_commands(ellipsoid_obj, tmp_path):
    from click.testing import CliRunner

    from gegnn.cli import main

    path, n = ellipsoid_obj
    run = CliRunner().invoke
    result = run(main, ["query", "--pretrained", path, "--source", "0", "--path", "500", "--exact", "-o",
                        str(tmp_path / "p.png")])
    assert result.exit_code == 0, result.output
    ratio = float(result.output.split("predicted path / edge-flip path ")[1].split()[0])
    assert ratio == pytest.approx(1, abs=0.05)
    result = run(main, ["query", "--pretrained", path, "--pairs-file", path, "--path", "3"])
    assert result.exit_code != 0 and "--path goes with --source" in result.output

    result = run(main, ["texture", "--pretrained", path, "--center", "7", "--compare", "-o", str(tmp_path / "t.png")])
    assert result.exit_code == 0, result.output
    assert (tmp_path / "t.png").read_bytes()[:4] == b"\x89PNG"
    result = run(main, ["texture", "--pretrained", path, "--center", "7", "--radius", "0.5", "-o",
                        str(tmp_path / "uv.npy")])
    assert result.exit_code == 0, result.output
    uv = np.load(tmp_path / "uv.npy")
    inside = ~np.isnan(uv[:, 0])
    assert uv.shape == (n, 2) and 0 < inside.sum() < n and np.all(np.linalg.norm(uv[inside], axis=1) <= 0.5 + 1e-9)

    bent = tmp_path / "bent.obj"
    from geodata.augment import bend
    m = trimesh.load(path, process=False)
    trimesh.Trimesh(bend(np.asarray(m.vertices), np.eye(3), np.pi / 2), m.faces, process=False).export(bent)
    result = run(main, ["shape-distribution", "--pretrained", path, str(bent), "--pairs", "20000", "-o",
                        str(tmp_path / "d2.csv")])
    assert result.exit_code == 0, result.output
    assert "L1 to ellipsoid.obj: geodesic" in result.output
    header = (tmp_path / "d2.csv").read_text().splitlines()[0].split(",")
    assert header == ["ratio_lo", "ratio_hi", "ellipsoid.obj:geodesic", "ellipsoid.obj:euclidean",
                      "bent.obj:geodesic", "bent.obj:euclidean"]
    result = run(main, ["shape-distribution", "--pretrained", path, "--pairs", "2000", "-o", str(tmp_path / "d.png")])
    assert result.exit_code == 0, result.output
