"""The offscreen rasterizer: coverage, depth order and per-pixel interpolation against known answers."""
from pathlib import Path

import numpy as np
import pytest

from geodata.examples import example_soups
from gegnn.pictures.render import UP_AXES, View, default_view, rasterize, shade_field, up_axis

FRONT = View(np.eye(3), np.zeros(3))  # screen right = x, up = y, viewer on +z


def test_square_coverage_and_linear_interpolation():
    v = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
    f = np.array([[0, 1, 2], [0, 2, 3]])
    face, bary, xy, _ = rasterize(v, f, FRONT, size=100, margin=0.1)
    covered = face >= 0
    assert abs(covered.sum() - 80 * 80) <= 2 * 80  # the square spans 80x80 pixels, edges aside
    field = v[:, 0] * 3 + 1  # linear in x: interpolation must reproduce it at every pixel centre
    value = (field[f[np.where(covered, face, 0)]] * bary).sum(axis=2)
    cols = np.arange(100) + 0.5
    expected = ((cols - 50) / 40 * 3 + 1)[None, :].repeat(100, axis=0)
    np.testing.assert_allclose(value[covered], expected[covered], atol=1e-9)


def test_nearer_triangle_wins():
    back = [[-1, -1, -1], [1, -1, -1], [0, 1, -1]]
    front = [[-1, -1, 1], [1, -1, 1], [0, 1, 1]]
    v = np.array(back + front, float)
    for f in (np.array([[0, 1, 2], [3, 4, 5]]), np.array([[3, 4, 5], [0, 1, 2]])):  # order must not matter
        face, *_ = rasterize(v, f, FRONT, size=64)
        front_index = int(np.flatnonzero(f[:, 0] == 3)[0])
        assert (face[face >= 0] == front_index).all()


def test_isolines_and_background():
    v = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], float)
    f = np.array([[0, 1, 2], [0, 2, 3]])
    img = shade_field(v, f, v[:, 0], FRONT, size=100, isolines=4, vmin=-1, vmax=1)
    assert (img[0, 0] == (1, 1, 1, 0)).all()  # transparent background
    row = img[50, :, :3].sum(axis=1)  # the square spans pixels 5..95 (5% margin): levels at x = -0.5, 0, 0.5
    dark = np.flatnonzero(row < 0.4 * np.median(row[5:95]))
    assert len(dark) == 3 and np.all(np.abs(dark - np.array([27.5, 50, 72.5])) <= 1)


def test_nan_values_are_grey_without_isolines():
    """Two squares side by side; the right one has no values (another part than the source's)."""
    v = np.array([[-1, -1, 0], [0, -1, 0], [0, 1, 0], [-1, 1, 0]], float)
    v = np.concatenate([v, v + [1.0, 0, 0]])
    f = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    field = np.r_[v[:4, 0], [np.nan] * 4]
    img = shade_field(v, f, field, FRONT, size=100, isolines=8, vmin=-1, vmax=0)
    right = img[20:80, 60:90, :3]
    np.testing.assert_allclose(right, 0.62)  # facing the viewer: full light, one flat grey, no isoline
    left = img[20:80, 10:40, :3]
    assert np.ptp(left[..., 0]) > 0.1  # the colormap on the reachable part


# -- which way is up -------------------------------------------------------------------------------------
DEV = Path(__file__).resolve().parents[3] / "shared" / "meshes" / "dev"
Z_UP = {"common-3d-test-models/nefertiti.obj", "common-3d-test-models/horse.ply", "milianw-scivi/buddha.obj",
        "milianw-scivi/dragon.obj"}  # judged by eye; every other development mesh is y-up, but these:
NO_UP = {"libigl-tutorial-data/bumpy-cube.obj", "libigl-tutorial-data/arm.obj", "odedstein-meshes/hand_closed.obj"}
MISSED = {"common-3d-test-models/igea.ply"}  # y-up by eye; a head without a base, called z-up
Z_TO_Y = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])  # (x, y, z) -> (x, z, -y): a z-up mesh written y-up


@pytest.mark.parametrize("name", sorted(example_soups()))
def test_the_examples_are_z_up_and_y_up_when_turned(name):
    """The examples are modelled z-up, standing on z = 0; lifted off it, their stance alone must tell
    (but the shelf's: it lies more stably on its back than it stands, so it is called y-up)."""
    mesh = example_soups()[name]
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    assert up_axis(v, f) == "+z"
    assert up_axis(v @ Z_TO_Y.T, f) == "+y"
    assert up_axis(v + (0.13, 0.37, 0.29), f) == ("+y" if name == "shelf" else "+z")


def test_a_flat_mesh_is_seen_face_on():
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    f = np.array([[0, 1, 2], [0, 2, 3]])
    assert up_axis(v, f) == "+y"  # in the xy plane: y up, seen along z
    assert up_axis(v[:, [0, 2, 1]], f) == "+z"  # in the xz plane


def development_meshes():
    """Every development mesh that has an up by eye, the miss marked as an expected (strict) failure."""
    names = sorted(f"{p.parent.name}/{p.name}" for p in DEV.glob("*/*.*")) if DEV.exists() else []
    return [pytest.param(n, marks=pytest.mark.xfail(strict=True, reason="a head without a base: its stance "
                                                   "says z-up")) if n in MISSED else n
            for n in names if n not in NO_UP]


@pytest.mark.skipif(not DEV.exists(), reason="../shared/meshes not available")
@pytest.mark.parametrize("name", development_meshes())
def test_up_axis_of_the_development_meshes(name):
    """As the files come, by eye; and Lucy (y-up here) turned z-up as Stanford's scan is."""
    from geodata.stages.load import load_mesh_file

    mesh, _ = load_mesh_file(DEV / name)
    if name == "continuous-remeshing/lucy.obj":
        assert up_axis(mesh.vertices @ Z_TO_Y, mesh.faces) == "+z"
    assert up_axis(mesh.vertices, mesh.faces) == ("+z" if name in Z_UP else "+y")


@pytest.mark.parametrize("up", ["+y", "+z", "-x"])
def test_the_view_keeps_up_on_the_screen_and_faces_the_source(up):
    mesh = example_soups()["chair"]
    v, f = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    u = np.asarray(UP_AXES[up])
    towards = np.array([0.6, -0.8, 0.0]) if up != "-x" else np.array([0, 0.6, 0.8])
    view = default_view(v, f, up, towards)
    np.testing.assert_allclose(view.rotation @ view.rotation.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(view.rotation) > 0
    assert abs(view.rotation[0] @ u) < 1e-12  # screen right is level
    assert view.rotation[1] @ u > 0.9  # up is up, seen from a little above
    assert view.rotation[2] @ towards > 0  # the camera on the side of the source
