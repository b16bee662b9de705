"""The offscreen rasterizer: coverage, depth order and per-pixel interpolation against known answers."""
import numpy as np

from gegnn.render import View, rasterize, shade_field

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
