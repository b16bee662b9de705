"""Large meshes embedded through a proxy (gegnn.queries.proxy): the answers are on the user's own vertices and
as accurate as at the resolution the model was trained at; surface points as an embedding of their own."""
import warnings

import numpy as np
import pytest
import torch
import trimesh

from gegnn import GeGnn
from gegnn.queries.proxy import PROXY_ABOVE, PROXY_VERTICES, decimate, proxy_size
from geodata.mesh import Mesh


@pytest.fixture(scope="module")
def model():
    torch.manual_seed(0)
    return GeGnn.pretrained()


def great_circle(v, source):
    u = v / np.linalg.norm(v, axis=1, keepdims=True)
    return np.arccos(np.clip(u @ u[source], -1, 1))


def test_a_dense_sphere_through_a_proxy_answers_on_its_own_vertices(model):
    """40,962 vertices (above the threshold) through the default proxy: one code per vertex of the user's mesh,
    distances from any vertex within 1% (MRE) of the great circles, as on the 5k sphere of the model card."""
    sphere = trimesh.creation.icosphere(6)
    v, f = np.asarray(sphere.vertices) * 2.0, np.asarray(sphere.faces)  # radius 2: answers in the input's units
    assert len(v) > PROXY_ABOVE
    emb = model.embed(v, f)
    assert emb.num_vertices == len(v) and emb.vertices.shape == v.shape and np.array_equal(emb.faces, f)
    for source in (0, 12345, len(v) - 1):
        truth = 2.0 * great_circle(v, source)
        d = emb.field(source)
        keep = np.arange(len(v)) != source
        assert d[source] == 0 and np.mean(np.abs(d - truth)[keep] / (truth[keep] + 2e-3)) < 0.01
    np.testing.assert_allclose(emb.matrix(rows=[0], cols=np.arange(len(v)))[0], emb.field(0), rtol=1e-6, atol=1e-6)


def test_a_proxy_is_a_remeshed_stand_in_of_the_same_surface():
    sphere = trimesh.creation.icosphere(6)
    v, f = np.asarray(sphere.vertices), np.asarray(sphere.faces)
    coarse = decimate(v, f, 4000)
    assert abs(coarse.n_vertices - 4000) < 0.25 * 4000
    assert np.abs(np.linalg.norm(coarse.vertices, axis=1) - 1).max() < 0.01  # on the sphere
    edges = np.linalg.norm(coarse.vertices[coarse.faces] - np.roll(coarse.vertices[coarse.faces], 1, axis=1), axis=2)
    assert edges.max() / edges.min() < 4  # isotropic: no long thin triangles of a bare edge collapse


def test_a_mesh_of_slivers_gets_a_proxy_of_the_size_asked(monkeypatch):
    """Each triangle of a sphere split at a random interior point, twice: most faces are slivers, which
    fast-simplification barely collapses; the proxy still has about the vertices asked, on the sphere, and
    well-shaped."""
    import gegnn.queries.proxy as proxy
    from geodata.mesh import Mesh

    sphere = trimesh.creation.icosphere(4)
    v, f = np.asarray(sphere.vertices), np.asarray(sphere.faces)
    rng = np.random.default_rng(0)
    for _ in range(2):
        w = rng.dirichlet(np.ones(3), len(f))
        c = len(v) + np.arange(len(f))
        v = np.vstack([v, np.einsum("fk,fkd->fd", w, v[f])])
        f = np.concatenate([np.stack([f[:, 0], f[:, 1], c], 1), np.stack([f[:, 1], f[:, 2], c], 1),
                            np.stack([f[:, 2], f[:, 0], c], 1)])
    assert np.mean(proxy.triangle_quality(Mesh(v, f)) < 0.1) > proxy.SLIVERS
    coarse = decimate(v, f, 600)
    assert abs(coarse.n_vertices - 600) < 0.25 * 600
    assert np.abs(np.linalg.norm(coarse.vertices, axis=1) - 1).max() < 0.05
    assert np.median(proxy.triangle_quality(coarse)) > 0.8


def test_the_proxy_setting():
    assert proxy_size(PROXY_ABOVE, "auto") is None and proxy_size(PROXY_ABOVE + 1, "auto") == PROXY_VERTICES
    assert proxy_size(10**6, None) is None and proxy_size(10**6, 0) is None
    assert proxy_size(6000, 5000) == 5000 and proxy_size(5000, 5000) is None
    for bad in (50, 2.5, "big", True):
        with pytest.raises(ValueError, match="proxy must be"):
            proxy_size(10**6, bad)


def test_small_meshes_are_embedded_as_they_are(model):
    sphere = trimesh.creation.icosphere(4)
    v, f = np.asarray(sphere.vertices), np.asarray(sphere.faces)
    auto, itself = model.embed(v, f), model.embed(v, f, proxy=None)
    assert torch.equal(auto.features, itself.features)


def test_surface_points_as_an_embedding_answer_as_surface_distance(model):
    sphere = trimesh.creation.icosphere(3)
    v, f = np.asarray(sphere.vertices), np.asarray(sphere.faces)
    emb = model.embed(v, f)
    rng = np.random.default_rng(0)
    face = rng.integers(0, len(f), 50)
    bary = rng.dirichlet(np.ones(3), 50)
    points = emb.at_points(face, bary)
    a, b = rng.integers(0, 50, 200), rng.integers(0, 50, 200)
    expected = emb.surface_distance(face[a], bary[a], face[b], bary[b])
    got = points.distance(a, b)
    np.testing.assert_allclose(got[a != b], expected[a != b], rtol=1e-5, atol=1e-6)
    corner = emb.at_points(np.array([0]), np.array([[1.0, 0.0, 0.0]]))  # a point at a vertex is that vertex
    np.testing.assert_allclose(corner.features[0], emb.features[f[0, 0]], rtol=1e-6, atol=1e-6)


def test_a_dense_cloud_through_a_subset_answers_on_all_its_points():
    """60,000 points of a sphere (above the threshold): a random 20,000 embedded, every point blended from its 3
    nearest there; distances from any point within 1.5% (MRE) of the great circles, 0 at the source."""
    from gegnn_stores import fibonacci_sphere

    points = fibonacci_sphere(60_000) * 3.0
    emb = GeGnn.pretrained("points").embed(points)
    assert emb.num_vertices == len(points) and emb.part.shape == (len(points),) and len(set(emb.part)) == 1
    for source in (0, 33_333):
        truth = 3.0 * great_circle(points, source)
        d = emb.field(source)
        keep = np.arange(len(points)) != source
        assert d[source] == 0 and np.mean(np.abs(d - truth)[keep] / (truth[keep] + 3e-3)) < 0.015


def two_spheres(subdivisions: int, radius: float, offset: float = 3.0):
    """A unit icosphere and a separate small sphere of ``radius`` beside it (642 vertices): a bolt on a body."""
    big, small = trimesh.creation.icosphere(subdivisions), trimesh.creation.icosphere(3, radius=radius)
    v = np.vstack([big.vertices, np.asarray(small.vertices) + [offset, 0, 0]])
    f = np.vstack([big.faces, np.asarray(small.faces) + len(big.vertices)])
    return v, f, len(big.vertices)


@pytest.mark.parametrize("radius", [0.02, 0.05])
def test_a_small_detached_part_keeps_its_own_distances_through_the_proxy(model, radius):
    """Decimated with the body, the small sphere kept 4 proxy vertices and its antipodes came out 0 apart (exact
    pi r). Each part gets its own proxy now, the small one kept whole: its antipodes within 10% of pi r (without
    a proxy: 1.7% and 3.6% short), and the body's distances within 1% of its great circles."""
    v, f, n_big = two_spheres(5, radius)
    emb = model.embed(v, f, proxy=2000)
    small = v[n_big:] - [3.0, 0, 0]
    a = n_big + int(np.argmax(small[:, 2]))
    b = n_big + int(np.argmin(small[:, 2]))
    exact = np.pi * radius
    assert abs(emb.distance(a, b) - exact) < 0.1 * exact
    truth = great_circle(v[:n_big], 0)
    d = emb.field(0)[:n_big]
    assert np.mean(np.abs(d - truth)[1:] / (truth[1:] + 1e-3)) < 0.01


def test_every_vertex_lies_on_its_own_parts_proxy():
    """A part of at most 2 x PART_VERTICES vertices is kept as it is (its vertices at themselves); a large
    part is decimated to the rest of the budget; no vertex is placed on another part's proxy."""
    from gegnn.queries.proxy import PART_VERTICES, proxy_of
    from geodata.mesh import Mesh, vertex_components

    v, f, n_big = two_spheres(5, 0.05)
    proxy = proxy_of(v, f, 2000)
    rest = 2000 - (len(v) - n_big)  # the small sphere's 642 vertices and the body's rest: 2,000 at most
    assert 0.75 * rest < proxy.mesh.n_vertices - (len(v) - n_big) <= rest
    labels = vertex_components(proxy.mesh)[proxy.mesh.faces[proxy.face, 0]]
    assert len(set(labels[:n_big])) == 1 and len(set(labels[n_big:])) == 1 and labels[0] != labels[-1]
    placed = np.einsum("pk,pkd->pd", proxy.bary, proxy.mesh.vertices[proxy.mesh.faces[proxy.face]])
    np.testing.assert_allclose(placed[n_big:], v[n_big:], atol=1e-12)  # 642 < 2 x PART_VERTICES: whole
    assert np.abs(np.linalg.norm(placed[:n_big], axis=1) - 1).max() < 0.01
    assert len(v) - n_big < 2 * PART_VERTICES
    one = proxy_of(*two_spheres(5, 0.05)[:2], 2000)
    assert np.array_equal(one.face, proxy.face) and np.array_equal(one.mesh.faces, proxy.mesh.faces)
    alone = Mesh(np.vstack([v, [[9.0, 9.0, 9.0]]]), f)  # a vertex on no face: the closest point of the proxy
    placed = proxy_of(alone.vertices, alone.faces, 2000)
    assert placed.face.shape == (len(v) + 1,) and placed.face[-1] >= 0


def spheres(n_parts: int, subdivisions: int = 3, radius: float = 1.0, spacing: float = 3.0):
    """``n_parts`` separate icospheres on a grid (642 vertices each at subdivision 3)."""
    sphere = trimesh.creation.icosphere(subdivisions, radius=radius)
    sv, sf = np.asarray(sphere.vertices), np.asarray(sphere.faces)
    side = int(np.ceil(n_parts ** (1 / 3)))
    grid = spacing * np.stack(np.unravel_index(np.arange(n_parts), (side,) * 3), axis=1)
    return (np.concatenate([sv + g for g in grid]), np.concatenate([sf + i * len(sv) for i in range(n_parts)]),
            len(sv))


def test_the_proxy_of_many_parts_stays_within_its_budget():
    """300 parts of 642 vertices (192,600) in a proxy of 20,000: each part used to keep all its vertices (at most
    1,000), a 192,600-vertex "proxy" on which the network and fields ran at full size. Now at most 20,000, every
    part with its own share (66 vertices here: 4.3% MRE within parts, 0.22% for the mesh itself), each vertex on
    its own part's proxy, and a warning that says what keeps the parts whole."""
    from gegnn.queries.proxy import proxy_of
    from geodata.mesh import vertex_components

    v, f, n = spheres(300)
    assert len(v) == 192_600
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        proxy = proxy_of(v, f, PROXY_VERTICES)
    assert proxy.mesh.n_vertices <= PROXY_VERTICES
    assert any("300 of them get as few as 66 proxy vertices" in str(w.message) for w in caught)
    labels = vertex_components(proxy.mesh)
    assert labels.max() + 1 == 300 and np.bincount(labels).min() >= 60
    placed = labels[proxy.mesh.faces[proxy.face, 0]]  # each vertex's proxy part: one per part, never shared
    assert all(len(set(placed[i * n:(i + 1) * n])) == 1 for i in range(300)) and len(set(placed[::n])) == 300
    points = np.einsum("pk,pkd->pd", proxy.bary, proxy.mesh.vertices[proxy.mesh.faces[proxy.face]])
    assert np.linalg.norm(points - v, axis=1).max() < 0.2  # on its own sphere's proxy (spheres 3 apart)


def test_part_budgets_never_exceed_the_proxy():
    """Whatever the parts: at most their own vertices each, at most the budget in all, the floors first (a small
    part beside a body kept whole); too many parts for PART_FEWEST vertices each is refused, with what to do."""
    from gegnn.queries.proxy import FLOORS, PART_FEWEST, PART_VERTICES, part_budget

    body_and_bolt = part_budget(np.array([100_000, 642]), np.array([12.5, 0.03]), 2000)
    assert body_and_bolt.tolist() == [2000 - 642, 642]
    assert part_budget(np.array([100_000]), np.array([1.0]), 20_000).tolist() == [20_000]
    rng = np.random.default_rng(0)
    for _ in range(200):
        k = int(rng.integers(1, 3000))
        size = rng.integers(3, 5000, k) * (rng.random(k) < 0.9) + rng.integers(3, 8, k)
        area = rng.random(k) ** 3 * (rng.random(k) < 0.95)  # some parts of no area
        target = int(rng.integers(100, 40_000))
        if np.minimum(size, PART_FEWEST).sum() > target:
            with pytest.raises(ValueError, match="proxy=None"):
                part_budget(size, area, target)
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            budget = part_budget(size, area, target)
        assert budget.sum() <= target and (budget <= size).all()
        assert (budget >= np.minimum(size, PART_FEWEST)).all()
        if np.where(size <= 2 * PART_VERTICES, size, PART_VERTICES).sum() <= FLOORS * target:
            assert (budget >= np.minimum(size, np.where(size <= 2 * PART_VERTICES, size, PART_VERTICES))).all()
    with pytest.raises(ValueError, match="15,000 connected parts"):  # a triangle soup: 45,000 vertices
        part_budget(np.full(15_000, 3), np.ones(15_000), 20_000)


def test_a_stray_degenerate_part_leaves_the_body_its_budget():
    """A collapsed triangle beside the body (three vertices within 2e-9, area ~1e-18, as CAD soups and scans
    carry) made the budgets' scale overflow the cast and settle on the floors: the body's proxy had 500
    vertices of 20,000, silently. The body now gets the rest of the budget, and the proxy of a small sphere
    with such a part is about as large as the sphere's own (its budget 997 instead of 1,000)."""
    import trimesh
    from gegnn.queries.proxy import proxy_of, part_budget

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no cast warning, no "parts get fewer"
        assert part_budget(np.array([327_682, 3]), np.array([12.57, 1e-18]), 20_000).tolist() == [19_997, 3]
        sphere = trimesh.creation.icosphere(4)  # 2,562 vertices
        n = len(sphere.vertices)
        v = np.vstack([sphere.vertices, [[2, 2, 2], [2, 2, 2 + 1e-9], [2 + 2e-9, 2, 2]]])
        f = np.vstack([sphere.faces, [[n, n + 1, n + 2]]])
        with_part = proxy_of(v, f, 1000).mesh
    alone = proxy_of(sphere.vertices, sphere.faces, 1000).mesh
    assert abs(with_part.n_vertices - alone.n_vertices) < 0.05 * alone.n_vertices  # 500 before


def test_a_thin_tube_is_collapsed_without_creases():
    """fast-simplification collapses a fine U-bent tube (239k vertices) to 60k with 19% more area and a third of
    its faces slivers, its geodesics 13% longer than the tube's (the proxy's model answered 16% off), where its
    input is the tube's regular lattice; moved off the lattice (``unlatticed``) it keeps the area to 0.1%."""
    from gegnn.queries.proxy import collapse, triangle_quality
    from geodata.zoo import zoo_mesh

    v, f = zoo_mesh("u-bend", 12)
    mesh = Mesh(v, f)
    coarse = collapse(mesh, int(round(60000 * mesh.n_faces / mesh.n_vertices)))
    assert coarse.n_vertices <= 61000
    assert np.mean(triangle_quality(coarse) < 0.1) < 0.05  # measured 0.4% (fast-simplification's: 34%)


def test_a_collapse_that_creases_the_surface_is_not_kept(monkeypatch):
    """A creased collapse is caught by the area it adds (``CREASED``) and replaced by pymeshlab's: fast-
    simplification on a U-bent tube's own lattice (83k vertices, not unlatticed) to a tenth of its faces adds 3.9%
    of area, pymeshlab's collapse none (1e-6). Kept, the proxy's geodesics run over the creases (16% off on the finer
    tube)."""
    import gegnn.queries.proxy as proxy
    from geodata.mesh import face_areas
    from geodata.zoo import zoo_mesh

    v, f = zoo_mesh("u-bend", 6)
    mesh = Mesh(v, f)
    monkeypatch.setattr(proxy, "unlatticed", lambda m: m.vertices)  # the lattice that fast-simplification creases
    coarse = proxy.collapse(mesh, mesh.n_faces // 10)
    assert coarse.n_faces <= 1.5 * (mesh.n_faces // 10)
    area = face_areas(coarse.vertices, coarse.faces).sum() / face_areas(v, f).sum()
    assert area < 1.01  # fast-simplification's: 1.039


def test_a_mesh_subdivided_by_midpoints_is_collapsed_fast_without_the_fallback(monkeypatch):
    """An icosphere(1) subdivided 5 times (41k vertices: every face of the original a flat lattice of 1,024):
    fast-simplification all but stops on such lattices: it stopped at 6,921 of the 1,002 vertices asked (the
    1.29M spot at 377,646 of 60,000, in 34 s); its input moved 1% of an edge in the tangent planes
    (``unlatticed``) reaches them, so pymeshlab's collapse is not needed (it raises here)."""
    import gegnn.queries.proxy as proxy
    import geodata.stages.repair as repair
    from geodata.mesh import face_areas

    s = trimesh.creation.icosphere(1)
    v, f = np.asarray(s.vertices), np.asarray(s.faces)
    for _ in range(5):
        v, f = trimesh.remesh.subdivide(v, f)
    mesh = Mesh(v, f)

    def refused(*args, **kwargs):
        raise AssertionError("pymeshlab's collapse was needed")
    monkeypatch.setattr(repair, "meshlab_filter", refused)
    coarse = proxy.collapse(mesh, 2000)
    assert coarse.n_faces <= 2000 * 1.01
    import igl

    off = np.sqrt(igl.point_mesh_squared_distance(coarse.vertices, np.asarray(s.vertices), np.asarray(s.faces))[0])
    assert np.median(off) < 1e-3 and off.max() < 0.1  # on the surface (measured: median 2e-6, max 0.057)
    assert abs(face_areas(coarse.vertices, coarse.faces).sum() / s.area - 1) < 0.01


def test_unlatticed_moves_each_vertex_in_its_tangent_plane_by_a_share_of_its_shortest_edge():
    """A flat grid stays in its plane exactly and each vertex moves by at most share x its shortest edge
    (times sqrt 2 in the plane); on a sphere the moved points leave it by O(share^2) of an edge."""
    from gegnn.queries.proxy import unlatticed

    x, y = np.meshgrid(np.arange(30.0), np.arange(20.0) * 0.5)
    v = np.stack([x.ravel(), y.ravel(), np.full(x.size, 2.0)], 1)
    q = (np.arange(29)[None, :] + 30 * np.arange(19)[:, None]).ravel()
    f = np.concatenate([np.stack([q, q + 1, q + 30], 1), np.stack([q + 1, q + 31, q + 30], 1)])
    moved = unlatticed(Mesh(v, f), 0.1) - v
    assert np.abs(moved[:, 2]).max() < 1e-12 and np.abs(moved).max() > 0.03
    assert np.linalg.norm(moved, axis=1).max() <= 0.1 * 0.5 * np.sqrt(2) + 1e-12  # the shortest edge: 0.5
    s = trimesh.creation.icosphere(4)
    edge = s.edges_unique_length.min()
    moved = unlatticed(Mesh(np.asarray(s.vertices), np.asarray(s.faces)), 0.05)
    assert np.abs(np.linalg.norm(moved, axis=1) - 1).max() < 0.05 ** 2 * edge
