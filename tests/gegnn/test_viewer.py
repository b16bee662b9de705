"""gegnn view: the page is self-contained, its own decoder gives Embedding's distances, and in a real browser
(headless Chromium, Debian's package, driven by Playwright) it draws the mesh and a click changes the field."""
from __future__ import annotations

import os
import re
import shutil

import numpy as np
import pytest

from geodata.examples import bumpy_sphere
from geodata.mesh import Mesh, vertex_components
from gegnn.model import GeGnn
from gegnn.pictures.viewer import view_page

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
        "--disable-background-networking", "--disable-component-update", "--disable-sync"]


def two_parts() -> Mesh:
    """An irregular closed surface of ~600 vertices and a smaller one beside it (two parts)."""
    a, b = bumpy_sphere(600, seed=1), bumpy_sphere(120, seed=2, offset=(3.0, 0.0, 0.0))
    return Mesh(np.concatenate([a.vertices, b.vertices]), np.concatenate([a.faces, b.faces + len(a.vertices)]))


@pytest.fixture(scope="module")
def mesh():
    return two_parts()


@pytest.fixture(scope="module")
def embeddings(mesh):
    return {name: GeGnn.pretrained(name).embed(mesh.vertices, mesh.faces, precision="fp32")
            for name in ("landmark", "paper", "biharmonic")}


@pytest.fixture(scope="module")
def browser():
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        sync_playwright = None
    if CHROMIUM is None or sync_playwright is None:
        message = "headless Chromium (Debian: chromium) and playwright are needed for the browser tests"
        if os.environ.get("CI"):
            pytest.fail(message + ": .ci/run installs them")
        pytest.skip(message)
    with sync_playwright() as p:
        chromium = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        yield chromium
        chromium.close()


def open_page(browser, tmp_path, text: str):
    path = tmp_path / "view.html"
    path.write_text(text, encoding="utf-8")
    page = browser.new_page(viewport={"width": 900, "height": 700})
    errors = []
    page.on("pageerror", lambda exc: errors.append(str(exc)))
    page.goto(path.as_uri())
    page.wait_for_function("document.body.dataset.frames >= 1", timeout=60_000)
    assert not errors
    return page


def expected_field(emb, mesh, source) -> np.ndarray:
    """Embedding's field, NaN off the source's part (as gegnn query and the page)."""
    labels = vertex_components(mesh)
    return np.where(labels == labels[source], emb.field(source), np.nan)


def test_the_page_is_self_contained(embeddings):
    text = view_page(embeddings["landmark"], title="<two parts>", sources=[3])
    assert not re.search(r"""(src|href)\s*=\s*["']?[a-z]*:?//""", text)  # nothing loaded from anywhere
    assert "&lt;two parts&gt;" in text and "<two parts>" not in text  # the title is escaped


@pytest.mark.parametrize("name", ["landmark", "paper", "biharmonic"])
def test_the_pages_decoder_gives_embeddings_distances(browser, tmp_path, embeddings, mesh, name):
    emb = embeddings[name]
    page = open_page(browser, tmp_path, view_page(emb, title=name, sources=[5]))
    for source in (5, 400, len(mesh.vertices) - 1):  # the last vertex is on the small part
        in_page = np.array(page.evaluate(f"gegnn.field({source})"), dtype=float)
        np.testing.assert_allclose(in_page, expected_field(emb, mesh, source), rtol=2e-5, atol=1e-6 * emb.scale)
    page.close()


def test_float16_codes_stay_within_a_thousandth(browser, tmp_path, embeddings, mesh):
    emb = embeddings["landmark"]
    page = open_page(browser, tmp_path, view_page(emb, title="half", dtype="float16"))
    in_page = np.array(page.evaluate("gegnn.field(7)"), dtype=float)
    truth = expected_field(emb, mesh, 7)
    far = truth > 0.1 * np.nanmax(truth)
    assert np.nanmedian(np.abs(in_page[far] / truth[far] - 1)) < 1e-3
    page.close()


def canvas_pixels(page) -> np.ndarray:
    """The canvas as the browser shows it, RGB 0-255 (H, W, 3)."""
    from io import BytesIO

    from matplotlib.image import imread
    return np.round(imread(BytesIO(page.locator("#gegnn-canvas").screenshot()), format="png")[..., :3] * 255)


def test_a_click_shows_the_clicked_vertexs_field(browser, tmp_path, embeddings, mesh):
    emb = embeddings["landmark"]
    page = open_page(browser, tmp_path, view_page(emb, title="click", sources=[0]))
    before = canvas_pixels(page)
    drawn = (before < 250).any(axis=2)
    assert drawn.mean() > 0.05  # the mesh is on the canvas, not a blank page
    assert len(np.unique(before[drawn] // 8, axis=0)) > 50  # coloured by a field, shaded
    box = page.locator("#gegnn-canvas").bounding_box()
    x, y = box["x"] + box["width"] * 0.45, box["y"] + box["height"] * 0.5
    target = page.evaluate(f"gegnn.pick({x}, {y})")
    assert target >= 0 and target != 0
    frames = int(page.evaluate("document.body.dataset.frames"))
    page.mouse.click(x, y)
    page.wait_for_function(f"document.body.dataset.frames > {frames}")
    assert page.evaluate("gegnn.source()") == target
    shown = np.array(page.evaluate("gegnn.shown()"), dtype=float)
    np.testing.assert_allclose(shown, expected_field(emb, mesh, target), rtol=2e-5, atol=1e-6 * emb.scale)
    after = canvas_pixels(page)
    assert (np.abs(after - before).sum(axis=2) > 30).mean() > 0.02  # the picture changed
    assert f"vertex {target}" in page.inner_text("#gegnn-source")
    page.close()


def test_exact_fields_and_their_error(browser, tmp_path, embeddings, mesh):
    emb = embeddings["landmark"]
    predicted = expected_field(emb, mesh, 0)
    exact = predicted * 1.1  # any field: the page shows what it is given
    page = open_page(browser, tmp_path, view_page(emb, title="exact", sources=[0], exact={0: exact}))
    truth = np.abs(predicted - exact) / (exact + 1e-3 * emb.scale)  # gegnn.queries.files.relative_errors
    truth[0] = 0
    mre = np.nanmean(truth[1:])
    assert f"mean relative error vs exact {100 * mre:.2f}%" in page.inner_text("#gegnn-source")
    page.check("input[value=exact]")
    np.testing.assert_allclose(np.array(page.evaluate("gegnn.shown()"), dtype=float), exact, rtol=1e-6)
    page.check("input[value=error]")
    np.testing.assert_allclose(np.array(page.evaluate("gegnn.shown()"), dtype=float), truth, rtol=1e-4)
    page.close()


def test_gegnn_view_numbers_vertices_as_the_file_does(browser, tmp_path):
    """A file whose vertex 0 is used by no face: the mesh drops it, the page still says the file's numbers."""
    import base64
    import json

    from click.testing import CliRunner

    from gegnn.cli import main

    part = bumpy_sphere(300, seed=3)
    lines = ["v 9 9 9"] + [f"v {x} {y} {z}" for x, y, z in part.vertices]
    lines += [f"f {a + 2} {b + 2} {c + 2}" for a, b, c in part.faces]
    (tmp_path / "m.obj").write_text("\n".join(lines) + "\n")
    result = CliRunner().invoke(main, ["view", "--pretrained", str(tmp_path / "m.obj"), "--source", "3", "--source",
                                       "10", "--exact", "-o", str(tmp_path / "v.html")])
    assert result.exit_code == 0, result.output
    assert "written" in result.output and "MB" in result.output
    text = (tmp_path / "v.html").read_text()
    data = json.loads(re.search(r'<script id="gegnn-data" type="application/json">(.*?)</script>', text).group(1))
    file_index = np.frombuffer(base64.b64decode(data["file_index"]["data"]), dtype="<i4")
    assert len(file_index) == 300 and file_index[data["sources"]].tolist() == [3, 10]  # the file's numbers
    assert sorted(map(int, data["exact"])) == sorted(data["sources"])
    page = browser.new_page()
    page.goto((tmp_path / "v.html").as_uri())
    page.wait_for_function("document.body.dataset.frames >= 1", timeout=60_000)
    assert "source: vertex 3 ·" in page.inner_text("#gegnn-source")
    assert "mean relative error vs exact" in page.inner_text("#gegnn-source")
    page.close()


@pytest.fixture(scope="module")
def cloud():
    """Two parts: a sphere of 1,200 points and a smaller one of 300 beside it."""
    from gegnn_stores import fibonacci_sphere
    return np.concatenate([fibonacci_sphere(1200), fibonacci_sphere(300, center=(3.0, 0.0, 0.0), radius=0.5)])


def test_a_cloud_page_draws_points_and_decodes_the_clicked_points_field(browser, tmp_path, cloud):
    """A point-cloud model's page: the points drawn as discs, the field of any point decoded in the page
    (Embedding's, NaN on the other part), a click on a disc making its point the source."""
    emb = GeGnn.pretrained("points").embed(cloud)
    assert emb.faces is None and emb.part.max() == 1
    page = open_page(browser, tmp_path, view_page(emb, title="cloud", sources=[0]))
    for source in (0, 700, 1350):
        expected = np.where(emb.part == emb.part[source], emb.field(source), np.nan)
        np.testing.assert_allclose(np.array(page.evaluate(f"gegnn.field({source})"), dtype=float), expected,
                                   rtol=2e-5, atol=1e-6 * emb.scale)
    before = canvas_pixels(page)
    drawn = (before < 250).any(axis=2)
    assert drawn.mean() > 0.05 and len(np.unique(before[drawn] // 8, axis=0)) > 50
    box = page.locator("#gegnn-canvas").bounding_box()
    x, y = box["x"] + box["width"] * 0.45, box["y"] + box["height"] * 0.5  # on the big sphere
    target = page.evaluate(f"gegnn.pick({x}, {y})")
    assert 0 < target < 1200
    assert np.hypot(*(np.array(page.evaluate(f"gegnn.screen({target})")) - [x, y])) < 15  # its disc is there
    frames = int(page.evaluate("document.body.dataset.frames"))
    page.mouse.click(x, y)
    page.wait_for_function(f"document.body.dataset.frames > {frames}")
    assert page.evaluate("gegnn.source()") == target and f"point {target}" in page.inner_text("#gegnn-source")
    shown = np.array(page.evaluate("gegnn.shown()"), dtype=float)
    np.testing.assert_allclose(shown, np.where(emb.part == 0, emb.field(target), np.nan), rtol=2e-5,
                               atol=1e-6 * emb.scale)
    assert (np.abs(canvas_pixels(page) - before).sum(axis=2) > 30).mean() > 0.02  # the picture changed
    page.close()


def test_gegnn_view_of_a_cloud_numbers_points_as_the_file_does(browser, tmp_path, cloud):
    """A cloud file with an outlier at point 0: the page leaves it out and still says the file's numbers;
    --exact --mesh gives the exact fields at the points."""
    import base64
    import json

    import trimesh
    from click.testing import CliRunner

    from gegnn.cli import main

    np.savetxt(tmp_path / "c.xyz", np.concatenate([[[60.0, 0.0, 0.0]], cloud[:1200]]))
    trimesh.creation.icosphere(4).export(tmp_path / "sphere.obj")
    args = ["view", "--pretrained", "points", str(tmp_path / "c.xyz"), "-o", str(tmp_path / "c.html")]
    result = CliRunner().invoke(main, args + ["--source", "5", "--source", "800", "--exact"])
    assert result.exit_code == 2 and "--exact with a point cloud needs --mesh" in result.output, result.output
    result = CliRunner().invoke(main, args + ["--source", "0"])
    assert result.exit_code == 1 and "point 0 is far from all other points" in result.output, result.output
    result = CliRunner().invoke(main, args + ["--source", "5", "--source", "800", "--exact", "--mesh",
                                              str(tmp_path / "sphere.obj")])
    assert result.exit_code == 0, result.output
    assert "1 points far from all others (the first: point 0)" in result.output and "written" in result.output
    text = (tmp_path / "c.html").read_text()
    data = json.loads(re.search(r'<script id="gegnn-data" type="application/json">(.*?)</script>', text).group(1))
    file_index = np.frombuffer(base64.b64decode(data["file_index"]["data"]), dtype="<i4")
    assert file_index.tolist() == list(range(1, 1201)) and file_index[data["sources"]].tolist() == [5, 800]
    exact = np.frombuffer(base64.b64decode(data["exact"][str(data["sources"][0])]["data"]), dtype="<f4")
    great_circle = np.arccos(np.clip(cloud[:1200] @ cloud[4], -1, 1))  # file point 5 is cloud point 4
    far = great_circle > 0.3
    assert np.mean(np.abs(exact[far] - great_circle[far]) / great_circle[far]) < 0.01
    page = browser.new_page()
    page.goto((tmp_path / "c.html").as_uri())
    page.wait_for_function("document.body.dataset.frames >= 1", timeout=60_000)
    assert "source: point 5 ·" in page.inner_text("#gegnn-source")
    assert "mean relative error vs exact" in page.inner_text("#gegnn-source")
    assert "click: the field of that point" in page.inner_text("body")
    page.close()


# -- a mesh too large for a page: drawn decimated, clicks decoding the full embedding -----------------------
def page_data(text: str) -> dict:
    """The page's data: its JSON, each array (a {dtype, data} blob) as a NumPy array."""
    import base64
    import json

    data = json.loads(re.search(r'<script id="gegnn-data" type="application/json">(.*?)</script>', text,
                                re.S).group(1).replace("<\\/", "</"))

    def arrays(x):
        if isinstance(x, dict) and set(x) == {"dtype", "data"}:
            return np.frombuffer(base64.b64decode(x["data"]), dtype=np.dtype(x["dtype"]).newbyteorder("<"))
        return {k: arrays(v) for k, v in x.items()} if isinstance(x, dict) else x
    return arrays(data)


def test_gegnn_view_draws_a_mesh_above_its_display_budget_decimated(browser, tmp_path):
    """--display-vertices below the mesh's count: the page shows that many vertices, says so, names each by
    the file vertex nearest it, and puts the sources exactly on their vertices (exact field 0 there)."""
    from click.testing import CliRunner

    from gegnn.cli import main

    part = bumpy_sphere(300, seed=3)
    lines = ["v 9 9 9"] + [f"v {x} {y} {z}" for x, y, z in part.vertices]  # file vertex 0 is used by no face
    lines += [f"f {a + 2} {b + 2} {c + 2}" for a, b, c in part.faces]
    (tmp_path / "m.obj").write_text("\n".join(lines) + "\n")
    result = CliRunner().invoke(main, ["view", "--pretrained", str(tmp_path / "m.obj"), "--display-vertices", "150",
                                       "--source", "3", "--source", "10", "--exact", "-o", str(tmp_path / "v.html")])
    assert result.exit_code == 0, result.output
    assert "300 vertices, drawn decimated to about 150" in result.output
    text = (tmp_path / "v.html").read_text()
    data = page_data(text)
    assert data["display"] == {"vertices": 300, "faces": len(part.faces), "numbering": "file"}
    vertices = data["vertices"].reshape(-1, 3)
    assert len(vertices) == 150 and len(data["faces"]) == 3 * (2 * 150 - 4)  # a closed mesh: exactly the budget
    sources = data["sources"]
    assert data["file_index"][sources].tolist() == [3, 10]  # the file's numbers
    np.testing.assert_allclose(vertices[sources], part.vertices[[2, 9]], atol=1e-6)  # on the sources exactly
    assert all(data["exact"][str(s)][s] < 1e-6 for s in sources)
    assert "drawn decimated: 150 of 300 vertices (50.0%)" in text
    page = open_page(browser, tmp_path, text)
    assert "source: near vertex 3 ·" in page.inner_text("#gegnn-source")
    page.close()


LARGE_SOURCE = 123_456


@pytest.fixture(scope="module")
def large():
    """A stretched icosphere of 655,362 vertices (the model embeds it through its proxy), its page with
    the default display budget, and the page's data."""
    import trimesh

    sphere = trimesh.creation.icosphere(8)
    emb = GeGnn.pretrained("landmark").embed(np.asarray(sphere.vertices) * [1.3, 1.0, 0.8], np.asarray(sphere.faces))
    text = view_page(emb, title="large", sources=[LARGE_SOURCE])
    return emb, text, page_data(text)


def page_embedding(emb, data):
    """The page's codes as an Embedding with the model's decoder: what the page decodes."""
    import torch

    from gegnn.queries.embedding import Embedding
    codes = torch.from_numpy(data["codes"].astype(np.float32).reshape(-1, data["code_width"]))
    return Embedding(codes, emb.decoder, emb.scale)


def test_a_large_mesh_is_drawn_decimated_within_the_page_budget(large):
    """655k vertices: a page under 100 MB of DISPLAY_VERTICES display vertices on the surface, each with the
    full embedding's code at its point (float16), decoding the full embedding's surface_distance."""
    from gegnn.pictures.display import DISPLAY_VERTICES

    emb, text, data = large
    assert len(text.encode()) < 100e6
    assert data["codes"].dtype == np.float16  # dtype "auto" above 64 MiB of float32 codes
    n = len(emb.vertices)
    assert data["display"] == {"vertices": n, "faces": len(emb.faces), "numbering": "mesh"}
    assert f"drawn decimated: {DISPLAY_VERTICES:,} of {n:,} vertices ({100 * DISPLAY_VERTICES / n:.1f}%)" in text
    vertices = data["vertices"].reshape(-1, 3).astype(np.float64)
    assert len(vertices) == DISPLAY_VERTICES and len(data["faces"]) == 3 * (2 * DISPLAY_VERTICES - 4)
    place = emb.locate(vertices)
    assert place.offset.max() < 1e-6 * emb.scale  # on the surface (float32 rounding)
    source = data["sources"][0]
    np.testing.assert_allclose(vertices[source], emb.vertices[LARGE_SOURCE], atol=1e-6 * emb.scale)
    assert data["file_index"][source] == LARGE_SOURCE
    # the codes are the full embedding's blends at the display points, to float16's rounding
    full = emb.at_points(place.face, place.bary).features.numpy()
    ulp = np.spacing(np.abs(full).astype(np.float16)).astype(np.float32)
    worst = (np.abs(data["codes"].reshape(full.shape).astype(np.float32) - full) / ulp).max()
    assert worst <= 1, f"codes {worst:.2f} float16 steps from the full embedding's at the display points"
    # and decode to the full embedding's distances between those points
    in_page = page_embedding(emb, data)
    for v in (source, 5_000):
        truth = emb.surface_distance(place.face[v], place.bary[v], place.face, place.bary)
        decoded = in_page.field(v)
        far = truth > 0.1 * truth.max()
        assert np.median(np.abs(decoded[far] / truth[far] - 1)) < 1e-3  # float16 codes (as above)
        assert np.abs(decoded - truth).max() < 5e-3 * emb.scale


def test_a_click_on_a_large_meshs_page_decodes_the_full_embedding(browser, tmp_path, large):
    emb, text, data = large
    page = open_page(browser, tmp_path, text)
    # no file_index: named in the embedded mesh's numbering (as a page of a remeshed file says)
    assert f"source: near vertex {LARGE_SOURCE} (of the remeshed mesh) ·" in page.inner_text("#gegnn-source")
    assert "drawn decimated: 100,000 of 655,362 vertices" in page.inner_text("header")
    box = page.locator("#gegnn-canvas").bounding_box()
    x, y = box["x"] + box["width"] * 0.45, box["y"] + box["height"] * 0.5
    target = page.evaluate(f"gegnn.pick({x}, {y})")
    assert target >= 0 and target != data["sources"][0]
    frames = int(page.evaluate("document.body.dataset.frames"))
    page.mouse.click(x, y)
    page.wait_for_function(f"document.body.dataset.frames > {frames}")
    assert page.evaluate("gegnn.source()") == target
    shown = np.array(page.evaluate("gegnn.shown()"), dtype=float)
    np.testing.assert_allclose(shown, page_embedding(emb, data).field(target), rtol=2e-5, atol=1e-6 * emb.scale)
    place = emb.locate(data["vertices"].reshape(-1, 3).astype(np.float64))
    truth = emb.surface_distance(place.face[target], place.bary[target], place.face, place.bary)
    assert np.abs(shown - truth).max() < 5e-3 * emb.scale
    print(f"a click on {len(shown):,} display vertices of {len(emb.vertices):,}: decoded in "
          f"{page.evaluate('document.body.dataset.decodeMs')} ms ({len(text) / 2 ** 20:.1f} MiB page)")
    page.close()


def test_a_cloud_above_the_display_budget_is_drawn_as_a_sample(browser, tmp_path, cloud):
    """A cloud of more points than display_vertices: that many of its points, the sources among them, each
    with its own code and the file's number."""
    emb = GeGnn.pretrained("points").embed(cloud)
    text = view_page(emb, title="sampled", sources=[7, 1350], display_vertices=500)
    data = page_data(text)
    keep = data["file_index"]
    assert len(keep) == 500 and len(np.unique(keep)) == 500 and data["display"] == {"points": 1500}
    assert keep[data["sources"]].tolist() == [7, 1350]
    np.testing.assert_array_equal(data["codes"].reshape(500, -1), emb.features.numpy()[keep])
    np.testing.assert_array_equal(data["vertices"].reshape(-1, 3), cloud[keep].astype(np.float32))
    page = open_page(browser, tmp_path, text)
    assert "drawn sampled: 500 of 1,500 points (33.3%, at random)" in page.inner_text("header")
    assert "source: point 7 ·" in page.inner_text("#gegnn-source")
    expected = np.where(emb.part == emb.part[1350], emb.field(1350), np.nan)[keep]
    np.testing.assert_allclose(np.array(page.evaluate(f"gegnn.field({data['sources'][1]})"), dtype=float), expected,
                               rtol=2e-5, atol=1e-6 * emb.scale)
    page.close()
