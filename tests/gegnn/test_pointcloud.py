"""Point clouds as GeGnn inputs: the neighbour graph, oriented normals and landmark fields from the points
alone, against known answers (a sphere's normals are radial and outward, its distances great circles),
and the point-cloud model end to end (embed, duplicates, training on a store's vertices)."""
import csv

import numpy as np
import pytest
from gegnn_stores import ellipsoid, fibonacci_sphere, small_config

from gegnn import GeGnn
from gegnn.fields.pointcloud import (_tree_signs, cloud_graph, cloud_landmark_fields, knn_edges, mls_project,
                                     pca_normals, surface_neighbors)


def test_knn_edges_are_each_pair_once_and_hold_every_points_neighbours():
    p = np.random.default_rng(0).normal(size=(300, 3))
    edges, nbrs = knn_edges(p, 6)
    assert (edges[:, 0] < edges[:, 1]).all() and len(np.unique(edges, axis=0)) == len(edges)
    brute = np.argsort(np.linalg.norm(p[:, None] - p[None], axis=2), axis=1)[:, 1:7]
    np.testing.assert_array_equal(np.sort(nbrs, axis=1), np.sort(brute, axis=1))
    have = set(map(tuple, edges.tolist()))
    assert all((min(i, j), max(i, j)) in have for i in range(len(p)) for j in brute[i])


def test_mls_projection_keeps_quadrics_and_takes_noise_out():
    rng = np.random.default_rng(1)
    xy = rng.uniform(-1, 1, size=(1500, 2))
    paraboloid = np.c_[xy, 0.3 * xy[:, 0] ** 2 - 0.2 * xy[:, 0] * xy[:, 1] + 0.1 * xy[:, 1] ** 2]
    # spacing ~0.05: a curved surface moves by 1e-3 of it, a plane in any pose not at all
    np.testing.assert_allclose(mls_project(paraboloid), paraboloid, atol=1e-4)
    plane = np.c_[xy, np.zeros(1500)] @ np.linalg.qr(rng.normal(size=(3, 3)))[0] + (1.0, -2.0, 0.5)
    np.testing.assert_allclose(mls_project(plane), plane, atol=1e-12)
    sphere = fibonacci_sphere(3000)
    assert np.abs(np.linalg.norm(mls_project(sphere), axis=1) - 1).max() < 1e-4
    noisy = sphere * (1 + rng.normal(scale=0.01, size=(3000, 1)))
    before = np.abs(np.linalg.norm(noisy, axis=1) - 1).mean()
    after = np.abs(np.linalg.norm(mls_project(noisy), axis=1) - 1).mean()
    assert after < 0.5 * before
    line = np.c_[np.linspace(0, 1, 40), np.zeros((40, 2))]  # no surface to fit: the points stay
    np.testing.assert_array_equal(mls_project(line), line)


def test_surface_neighbours_do_not_cross_a_gap_and_are_the_nearest_where_there_is_none():
    h = 0.05
    x, y = np.meshgrid(np.arange(40) * h, np.arange(40) * h)
    sheet = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    p = np.concatenate([sheet, sheet + (0.3 * h, 0.4 * h, 1.2 * h)])  # two sheets 1.2 spacings apart
    inner = np.flatnonzero((np.abs(p[:, :2] - 1.0) < 0.7).all(axis=1))  # away from the sheets' edges
    plain = np.argsort(np.linalg.norm(p[:, None] - p[None], axis=2), axis=1)[:, 1:16]
    other_sheet = (plain[inner] >= 1600) != (inner[:, None] >= 1600)
    assert other_sheet.any(axis=1).all()  # the plain 15 nearest of every inner point reach across
    ours = surface_neighbors(p, 15)
    assert not ((ours[inner] >= 1600) != (inner[:, None] >= 1600)).any()
    sphere = fibonacci_sphere(1000)
    np.testing.assert_array_equal(np.sort(surface_neighbors(sphere, 15), axis=1),
                                  np.sort(knn_edges(sphere, 15)[1], axis=1))


def test_a_scans_own_normals_keep_the_two_sides_of_a_thin_wall_apart():
    h = 0.05
    x, y = np.meshgrid(np.arange(40) * h, np.arange(40) * h)
    sheet = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    p = np.concatenate([sheet, sheet + (0.5 * h, 0.5 * h, 0.5 * h)])  # a wall half a spacing thick
    normals = np.repeat([[0, 0, -1.0], [0, 0, 1.0]], 1600, axis=0)   # its two sides face away
    side = np.arange(3200) >= 1600
    inner = np.flatnonzero((np.abs(p[:, :2] - 1.0) < 0.7).all(axis=1))
    assert (side[surface_neighbors(p, 15)[inner]] != side[inner, None]).any(axis=1).all()  # the cone alone: no
    assert not (side[surface_neighbors(p, 15, normals=normals)[inner]] != side[inner, None]).any()
    assert (side[knn_edges(p, 8)[1][inner]] != side[inner, None]).any(axis=1).all()  # nor the plain graph
    edges, nbrs = knn_edges(p, 8, normals)
    assert not (side[edges[:, 0]] != side[edges[:, 1]]).any()
    front = inner[inner < 1600]  # its own side's nearest
    np.testing.assert_array_equal(np.sort(nbrs[front], axis=1), np.sort(knn_edges(sheet, 8)[1][front], axis=1))


def test_normals_are_radial_and_outward_on_each_of_two_spheres():
    a, b = fibonacci_sphere(800), fibonacci_sphere(300, center=(5.0, 0, 0), radius=0.5)
    p = np.concatenate([a, b])
    g = cloud_graph(p, 8)
    radial = np.concatenate([a, (b - (5.0, 0, 0)) / 0.5])
    dots = np.einsum("ij,ij->i", g.normals, radial)
    assert dots.min() > 0.99  # radial, and every one outward: the orientation reached all points
    assert np.array_equal(np.unique(g.part[:800]), [g.part[0]]) and g.part[800] != g.part[0]


def test_tree_flips_equal_flipping_each_normal_after_its_parent():
    rng = np.random.default_rng(3)
    for n in (1, 2, 50, 2000):
        order = rng.permutation(n)                       # a random tree, parents before children
        parent = np.full(n, -9999)
        parent[order[1:]] = order[rng.integers(0, np.arange(1, n))]
        normals = rng.integers(-1, 2, size=(n, 3)).astype(float)  # exact dot products, many of them 0
        expected = normals.copy()
        for v in order[1:]:
            if expected[v] @ expected[parent[v]] < 0:
                expected[v] = -expected[v]
        flipped = normals.copy()
        flipped[order] *= _tree_signs(order, parent, normals)[:, None]
        assert np.array_equal(flipped, expected)


def test_landmark_fields_of_a_sphere_are_great_circle_distances():
    p = fibonacci_sphere(2000)
    g = cloud_graph(p, 8)
    lf = cloud_landmark_fields(p, g.part, 8, seed=3)
    exact = np.arccos(np.clip(p @ p[lf.landmarks[0]].T, -1, 1))  # (N, K) to the chosen landmarks
    far = exact > 0.2
    assert np.mean(np.abs(lf.distances[far] - exact[far]) / exact[far]) < 0.03
    # farthest-point sampling: the second landmark is (near) the antipode of the first
    assert exact[lf.landmarks[0][1], 0] > 0.95 * np.pi


def test_the_projection_takes_the_noise_out_of_a_noisy_spheres_distances():
    """Noise of 2% of the radius lengthens the heat method's distances by ~4.6% (their zigzag); on the
    projected points they are within 0.3% of the clean cloud's (whose own bias, -1.2%, is the method's)."""
    p = fibonacci_sphere(2000)
    noisy = p * (1 + np.random.default_rng(2).normal(scale=0.02, size=(2000, 1)))
    bias = []
    for q in (p, noisy, cloud_graph(noisy, 8).points):
        lf = cloud_landmark_fields(q, np.zeros(2000, dtype=np.int64), 8, seed=3)
        exact = np.arccos(np.clip(p @ p[lf.landmarks[0]].T, -1, 1))
        far = exact > 0.2
        bias.append(np.mean((lf.distances[far] - exact[far]) / exact[far]))
    clean, raw, projected = bias
    assert raw - clean > 0.03 and abs(projected - clean) < 0.2 * (raw - clean)


@pytest.fixture(scope="module")
def cloud_model():
    import torch
    torch.manual_seed(0)
    return GeGnn(small_config(landmarks=8, points=8)).eval()


def test_a_cloud_model_embeds_points_and_duplicates_share_codes(cloud_model):
    p = fibonacci_sphere(600) * 2.0
    emb = cloud_model.embed(np.concatenate([p, p[:5]]))  # five points twice
    assert emb.num_vertices == 605
    np.testing.assert_array_equal(emb.features[600:].numpy(), emb.features[:5].numpy())
    d = emb.distance(np.arange(5), np.arange(600, 605))
    np.testing.assert_array_equal(d, 0)
    far = emb.distance(np.zeros(600, dtype=int), np.arange(600))
    assert np.isfinite(far).all() and far.max() > 0


def test_a_cloud_embedding_labels_the_parts_of_its_neighbour_graph(cloud_model):
    a, b = fibonacci_sphere(400), fibonacci_sphere(300, center=(6.0, 0, 0))
    emb = cloud_model.embed(np.concatenate([a, b, a[:3]]))  # three points twice
    assert emb.part.shape == (703,) and len(np.unique(emb.part[:400])) == len(np.unique(emb.part[400:700])) == 1
    assert emb.part[0] != emb.part[400] and (emb.part[700:] == emb.part[:3]).all()
    assert GeGnn(small_config(landmarks=8)).embed(*ellipsoid()).part is None  # a mesh's parts: its faces


def test_a_cloud_model_says_what_it_takes(cloud_model):
    p = fibonacci_sphere(100)
    with pytest.raises(ValueError, match="points only"):
        cloud_model.embed(p, np.array([[0, 1, 2]]))
    with pytest.raises(ValueError, match="more than the 8 neighbours"):
        cloud_model.embed(np.concatenate([p[:5]] * 3))
    with pytest.raises(ValueError, match="finite"):
        cloud_model.embed(np.where(np.arange(100)[:, None] == 7, np.nan, p))
    with pytest.raises(ValueError, match="give faces"):
        GeGnn(small_config()).embed(p)


def test_given_normals_are_used_as_they_are(cloud_model):
    p = fibonacci_sphere(400)
    inward = cloud_model.cloud_inputs(p, -p, "cpu")[0]().graphs[0].normal.numpy()
    np.testing.assert_allclose(inward, -p[np.unique(p, axis=0, return_index=True)[1]], atol=1e-6)


def test_train_a_cloud_model_on_a_stores_vertices(tiny_store, tmp_path):
    from click.testing import CliRunner

    from gegnn.cli import main

    run = tmp_path / "run"
    result = CliRunner().invoke(main, ["train", tiny_store, "--run", str(run), "--epochs", "1", "--batch-size", "2",
                                       "--device", "cpu", "--channels", "16", "--blocks", "1,1,1,1,1",
                                       "--pairs-per-mesh", "200", "--landmarks", "8", "--neighbors", "6"])
    assert result.exit_code == 0, result.output
    model = GeGnn.from_checkpoint(run / "best.safetensors")
    assert model.config.points == 6 and model.config.landmarks == 8
    assert (run / "fields" / "k8-cloud6-surface2-v2").exists()  # the cloud's fields, apart from a mesh model's
    with open(run / "metrics.csv") as f:
        assert float(next(csv.DictReader(f))["val_mre"]) < 1.0
    from gegnn.cli import train  # --neighbors alone is the shipped model's 8 neighbours; so is DESIGN's --points
    assert train.make_context("train", [tiny_store, "--neighbors", "--run", str(run)]).params["neighbors"] == 8
    assert train.make_context("train", [tiny_store, "--points", "--run", str(run)]).params["old_points"] == 8


def test_query_a_cloud_with_an_outlier_against_the_exact_field(cloud_model, tmp_path):
    """gegnn query with a point-cloud model: the field over the cloud in the file's order, NaN at the outlier;
    --exact --mesh reads the exact field of the sphere it was taken from at every point."""
    import trimesh
    from click.testing import CliRunner

    from gegnn.cli import main
    from gegnn.fields.exact import exact_at_points

    sphere = trimesh.creation.icosphere(4)
    p = fibonacci_sphere(1500)
    np.savetxt(tmp_path / "cloud.xyz", np.concatenate([p, [[40.0, 0, 0]]]))
    sphere.export(tmp_path / "sphere.obj")
    cloud_model.save(tmp_path / "cloud.safetensors")
    result = CliRunner().invoke(main, ["query", str(tmp_path / "cloud.safetensors"), str(tmp_path / "cloud.xyz"),
                                       "--source", "3", "--exact", "--mesh", str(tmp_path / "sphere.obj"),
                                       "-o", str(tmp_path / "field.npy")])
    assert result.exit_code == 0, result.output
    assert "1 points far from all others (the first: point 1500)" in result.output
    assert "mean relative error vs exact on sphere.obj" in result.output
    field = np.load(tmp_path / "field.npy")
    assert field.shape == (1501,) and np.isnan(field[1500]) and np.isfinite(field[:1500]).all() and field[3] == 0
    result = CliRunner().invoke(main, ["query", str(tmp_path / "cloud.safetensors"), str(tmp_path / "cloud.xyz"),
                                       "--source", "3", "-o", str(tmp_path / "field.png")])
    assert result.exit_code == 0 and (tmp_path / "field.png").stat().st_size > 10_000, result.output
    result = CliRunner().invoke(main, ["query", str(tmp_path / "cloud.safetensors"), str(tmp_path / "cloud.xyz"),
                                       "--source", "3", "-o", str(tmp_path / "field.ply")])
    colored = trimesh.load(tmp_path / "field.ply")
    assert result.exit_code == 0 and isinstance(colored, trimesh.PointCloud), result.output
    colors = np.asarray(colored.colors)
    np.testing.assert_allclose(colored.vertices, np.concatenate([p, [[40.0, 0, 0]]]), atol=1e-6)
    assert (colors[1500, :3] == colors[1500, 0]).all() and len(np.unique(colors[:1500], axis=0)) > 50  # outlier grey

    exact, offset = exact_at_points(sphere_mesh(sphere), p, 3)
    great_circle = np.arccos(np.clip(p @ p[3], -1, 1))
    far = great_circle > 0.3
    assert offset.max() < 0.01
    assert np.mean(np.abs(exact[far] - great_circle[far]) / great_circle[far]) < 0.01


def sphere_mesh(tm):
    from geodata.mesh import Mesh
    return Mesh(np.asarray(tm.vertices), np.asarray(tm.faces))


def test_a_part_too_small_for_the_heat_method_gets_no_fields():
    """potpourri3d's cloud solver needs more than 30 points (a 13-point part of a training mesh raised)."""
    p = np.concatenate([fibonacci_sphere(500), fibonacci_sphere(13, center=(9.0, 0, 0), radius=0.2)])
    g = cloud_graph(p, 8)
    lf = cloud_landmark_fields(p, g.part, 4)
    assert len(np.unique(g.part)) == 2
    assert (lf.distances[500:] == 0).all() and (lf.distances[:500].max(axis=0) > 2.5).all()


def test_a_part_on_a_line_gets_no_fields_and_a_cloud_on_a_line_is_refused(cloud_model, tmp_path):
    """A straight wire beside a sphere has no surface: no fields (potpourri3d's solver raised a
    GC_SAFETY_ASSERT on it); a cloud that is only a line is refused, by the CLI naming the file."""
    from click.testing import CliRunner

    from gegnn.cli import main

    x = np.linspace(0, 1, 200)
    line = np.stack([x, 2 * x, np.zeros_like(x)], axis=1)
    p = np.concatenate([fibonacci_sphere(500), line + [3.0, 0, 0]])
    g = cloud_graph(p, 8)
    lf = cloud_landmark_fields(p, g.part, 4)
    assert len(np.unique(g.part)) == 2
    assert (lf.distances[500:] == 0).all() and (lf.distances[:500].max(axis=0) > 2.5).all()
    with pytest.raises(ValueError, match="200 distinct points lie on a line"):
        cloud_model.embed(line)
    cloud_model.save(tmp_path / "cloud.safetensors")
    np.savetxt(tmp_path / "wire.xyz", line)
    result = CliRunner().invoke(main, ["query", str(tmp_path / "cloud.safetensors"), str(tmp_path / "wire.xyz"),
                                       "--source", "0"])
    assert result.exit_code == 1 and "wire.xyz: the 200 distinct points lie on a line" in result.output
    assert "Traceback" not in result.output


def test_mesh_commands_refuse_a_point_cloud_model(cloud_model, tmp_path):
    import trimesh
    from click.testing import CliRunner

    from gegnn.cli import main

    cloud_model.save(tmp_path / "cloud.safetensors")
    trimesh.creation.icosphere(2).export(tmp_path / "m.obj")
    result = CliRunner().invoke(main, ["texture", str(tmp_path / "cloud.safetensors"), str(tmp_path / "m.obj"),
                                       "--center", "0", "-o", str(tmp_path / "t.png")])
    assert result.exit_code == 2 and "is a point-cloud model" in result.output, result.output
    for command in (["view", "-o", str(tmp_path / "v.html")], ["query", "--source", "0"],  # these take clouds
                    ["pairwise", "-o", str(tmp_path / "d.npy")]):
        result = CliRunner().invoke(main, [command[0], str(tmp_path / "cloud.safetensors"), str(tmp_path / "m.obj"),
                                           *command[1:]])
        assert result.exit_code == 1 and "m.obj: not a point-cloud file" in result.output, result.output


def test_export_points_turns_a_landmark_mesh_model_into_a_cloud_model_of_the_same_weights(tmp_path):
    import torch
    from click.testing import CliRunner

    from gegnn.cli import main

    torch.manual_seed(1)
    mesh_model = GeGnn(small_config(landmarks=8))
    mesh_model.save(tmp_path / "mesh.safetensors")
    result = CliRunner().invoke(main, ["export", str(tmp_path / "mesh.safetensors"),
                                       str(tmp_path / "cloud.safetensors"), "--neighbors", "6", "--dtype", "fp32"])
    assert result.exit_code == 0 and "a point-cloud model (6 neighbours)" in result.output, result.output
    cloud = GeGnn.from_checkpoint(tmp_path / "cloud.safetensors")
    assert cloud.config.points == 6 and cloud.config.landmarks == 8
    for name, tensor in mesh_model.state_dict().items():
        torch.testing.assert_close(cloud.state_dict()[name], tensor, rtol=0, atol=0)
    assert np.isfinite(cloud.embed(fibonacci_sphere(300)).field(0)).all()
    GeGnn(small_config()).save(tmp_path / "paper.safetensors")
    result = CliRunner().invoke(main, ["export", str(tmp_path / "paper.safetensors"), str(tmp_path / "x.safetensors"),
                                       "--points", "6"])  # the old name: a warning, the same check
    assert result.exit_code == 2 and "paper.safetensors is not a landmark model" in result.output



def test_a_mesh_model_given_a_cloud_names_the_model_that_takes_it(tmp_path):
    import trimesh
    from click.testing import CliRunner

    from gegnn.cli import main

    p = fibonacci_sphere(200)
    np.savetxt(tmp_path / "scan.xyz", p)
    trimesh.PointCloud(p).export(tmp_path / "scan.ply")
    for name in ("scan.xyz", "scan.ply"):
        result = CliRunner().invoke(main, ["query", "--pretrained", str(tmp_path / name), "--source", "0"])
        assert result.exit_code == 1 and f"gegnn query --pretrained points {name} --source I" in result.output


def plane_normals_reference(centers, near):
    """NumPy: the least-variance direction of each center (N, 3) with its neighbours (N, m, 3)."""
    hood = np.concatenate([centers[:, None], near], axis=1)
    centered = hood - hood.mean(axis=1, keepdims=True)
    return np.linalg.eigh(np.einsum("nki,nkj->nij", centered, centered))[1][:, :, 0]


def cone_reference(p, nbrs, k, cone_deg, given):
    """NumPy: each point's k nearest candidates within the cone about its tangent plane (the plane fitted to
    the point and its 5 nearest, then to the point and its 5 nearest within that cone; or its given normal,
    and then facing its side), the others after them."""
    offset = p[nbrs] - p[:, None]
    sin_dist = np.sin(np.radians(cone_deg)) * np.linalg.norm(offset, axis=2)

    def cone(normal):
        off_plane = np.abs(np.einsum("nkd,nd->nk", offset, normal)) >= sin_dist
        if given is not None:
            off_plane |= np.einsum("nkd,nd->nk", given[nbrs], given) <= 0
        return np.argsort(off_plane, axis=1, kind="stable")

    if given is None:
        order = cone(plane_normals_reference(p, p[nbrs[:, :5]]))
        order = cone(plane_normals_reference(p, p[np.take_along_axis(nbrs, order[:, :5], axis=1)]))
    else:
        order = cone(given)
    return np.take_along_axis(nbrs, order[:, :k], axis=1)


def test_surface_neighbours_from_2k_candidates_then_6k_where_needed_equal_those_of_all_6k():
    """The compiled cone (2k candidates, then 6k for the rows that need them) against NumPy's on all 6k."""
    h = 0.05
    x, y = np.meshgrid(np.arange(30) * h, np.arange(30) * h)
    sheet = np.stack([x.ravel(), y.ravel(), 0.1 * np.sin(3 * x.ravel())], axis=1)
    p = np.concatenate([sheet, sheet + (0.3 * h, 0.4 * h, 1.2 * h)])  # a gap: many rows need the 6k
    p += np.random.default_rng(0).normal(scale=1e-4 * h, size=p.shape)  # no ties: a scan's order is unique
    normals = np.repeat([[0, 0, -1.0], [0, 0, 1.0]], len(sheet), axis=0)
    for given in (None, normals):
        def among(candidates):
            return cone_reference(p, knn_edges(p, candidates)[1], 15, 30.0, given)

        assert (among(30) != among(90)).any()  # the 2k nearest alone would not do
        np.testing.assert_array_equal(surface_neighbors(p, 15, normals=given), among(90))


def test_compiled_fits_equal_numpys():
    """The projection's quadric fits and the PCA normals (src/cloud_ops.cpp) against NumPy's eigh and solve."""
    from scipy.spatial import cKDTree

    rng = np.random.default_rng(1)
    p = fibonacci_sphere(3000) * (1.0, 0.7, 0.5) + rng.normal(scale=0.01, size=(3000, 3))
    dist, nbrs = cKDTree(p).query(p, 31)
    hood = p[nbrs]
    radius = dist[:, -1:]
    w = np.exp(-(2.0 * dist / radius) ** 2)
    centroid = (w[..., None] * hood).sum(1) / w.sum(1, keepdims=True)
    spread = (hood - centroid[:, None]) * np.sqrt(w)[..., None]
    frame = np.linalg.eigh(spread.transpose(0, 2, 1) @ spread)[1]
    z, v, u = np.moveaxis((hood - p[:, None]) @ frame, 2, 0)
    u, v, sw = u / radius, v / radius, np.sqrt(w)
    a = np.stack([np.ones_like(u), u, v, u * u, u * v, v * v], axis=2) * sw[..., None]
    c0 = np.linalg.solve(a.transpose(0, 2, 1) @ a + 1e-10 * np.eye(6), a.transpose(0, 2, 1) @ (z * sw)[..., None])
    c0 = np.where(np.abs(c0[:, 0, 0]) <= 0.5 * radius[:, 0], c0[:, 0, 0], 0.0)
    projected = mls_project(p)
    np.testing.assert_allclose(projected, p + c0[:, None] * frame[:, :, 0], rtol=0, atol=1e-13)
    assert np.abs(projected - p).max() > 0.01  # the noise taken out
    ours, numpys = pca_normals(p, nbrs[:, 1:9]), plane_normals_reference(p, p[nbrs[:, 1:9]])
    np.testing.assert_allclose(np.abs(np.einsum("nd,nd->n", ours, numpys)), 1.0, rtol=0, atol=1e-12)


def test_query_pairs_of_a_cloud_in_file_numbering(cloud_model, tmp_path):
    """gegnn query --pairs with a point-cloud model: each pair's distance is the embedding's, in the file's
    numbering; NaN where a point is a far outlier or the two lie on different parts; a point out of range
    is named."""
    from click.testing import CliRunner

    from gegnn.cli import main

    a, b = fibonacci_sphere(400), fibonacci_sphere(300, center=(6.0, 0, 0))
    cloud = np.concatenate([a, [[40.0, 0, 0]], b])  # point 400: an outlier
    np.savetxt(tmp_path / "cloud.xyz", cloud)
    cloud_model.save(tmp_path / "cloud.safetensors")
    pairs = np.array([[0, 7], [3, 399], [401, 650], [5, 400], [2, 450], [7, 7]])
    np.savetxt(tmp_path / "pairs.csv", pairs, fmt="%d", delimiter=",", header="i,j", comments="")
    result = CliRunner().invoke(main, ["query", str(tmp_path / "cloud.safetensors"), str(tmp_path / "cloud.xyz"),
                                       "--pairs", str(tmp_path / "pairs.csv"), "-o", str(tmp_path / "d.csv")])
    assert result.exit_code == 0, result.output
    assert "2 pairs have no distance" in result.output
    got = np.loadtxt(tmp_path / "d.csv", delimiter=",", skiprows=1)
    np.testing.assert_array_equal(got[:, :2], pairs)
    kept = np.delete(np.arange(len(cloud)), 400)
    emb = cloud_model.embed(cloud[kept])
    local = np.searchsorted(kept, pairs[[0, 1, 2, 5]])
    np.testing.assert_allclose(got[[0, 1, 2, 5], 2], emb.distance(local[:, 0], local[:, 1]), rtol=1e-5)
    assert np.isnan(got[[3, 4], 2]).all() and got[5, 2] == 0 and (got[:3, 2] > 0).all()

    np.savetxt(tmp_path / "bad.csv", [[0, 701]], fmt="%d", delimiter=",")
    result = CliRunner().invoke(main, ["query", str(tmp_path / "cloud.safetensors"), str(tmp_path / "cloud.xyz"),
                                       "--pairs", str(tmp_path / "bad.csv")])
    assert result.exit_code != 0 and "pair 1: point 701 out of range: cloud.xyz has 701 points" in result.output
    result = CliRunner().invoke(main, ["query", str(tmp_path / "cloud.safetensors"), str(tmp_path / "cloud.xyz"),
                                       "--pairs", str(tmp_path / "pairs.csv"), "--exact"])
    assert result.exit_code != 0 and "--exact goes with --source" in result.output


def test_pairwise_matrix_of_a_cloud_in_file_numbering(cloud_model, tmp_path):
    """gegnn pairwise with a point-cloud model: the embedding's matrix in the file's numbering, exactly
    symmetric, NaN in the outlier's row and column and between the two parts; --rows gives those rows."""
    from click.testing import CliRunner

    from gegnn.cli import main

    a, b = fibonacci_sphere(400), fibonacci_sphere(300, center=(6.0, 0, 0))
    cloud = np.concatenate([a, [[40.0, 0, 0]], b])  # point 400: an outlier
    np.savetxt(tmp_path / "cloud.xyz", cloud)
    cloud_model.save(tmp_path / "cloud.safetensors")
    args = ["pairwise", str(tmp_path / "cloud.safetensors"), str(tmp_path / "cloud.xyz")]
    result = CliRunner().invoke(main, [*args, "-o", str(tmp_path / "d.npy")])
    assert result.exit_code == 0 and "701 x 701 predicted geodesic distances" in result.output, result.output
    d = np.load(tmp_path / "d.npy")
    kept = np.delete(np.arange(len(cloud)), 400)
    reference = cloud_model.embed(cloud[kept]).matrix()
    first, second = np.arange(400), np.arange(401, 701)
    np.testing.assert_allclose(d[np.ix_(first, first)], reference[:400, :400], rtol=1e-6)
    np.testing.assert_allclose(d[np.ix_(second, second)], reference[400:, 400:], rtol=1e-6)
    assert np.isnan(d[400]).all() and np.isnan(d[:, 400]).all() and np.isnan(d[np.ix_(first, second)]).all()
    np.testing.assert_array_equal(d, d.T)
    np.savetxt(tmp_path / "rows.txt", [5, 400, 650], fmt="%d")
    result = CliRunner().invoke(main, [*args, "--rows", str(tmp_path / "rows.txt"), "-o", str(tmp_path / "r.npy")])
    assert result.exit_code == 0, result.output
    np.testing.assert_allclose(np.load(tmp_path / "r.npy"), d[[5, 400, 650]], rtol=1e-6)
    np.savetxt(tmp_path / "bad.txt", [701], fmt="%d")
    result = CliRunner().invoke(main, [*args, "--rows", str(tmp_path / "bad.txt"), "-o", str(tmp_path / "x.npy")])
    assert result.exit_code != 0 and "point 701 out of range: cloud.xyz has 701 points" in result.output
    result = CliRunner().invoke(main, [*args, "--exact", "-o", str(tmp_path / "x.npy")])
    assert result.exit_code == 2 and "--exact, --heat and --prepare take a mesh" in result.output
