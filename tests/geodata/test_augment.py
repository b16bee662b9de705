"""geodata augment: variants are deterministic, the bend is an isometry, cuts open holes, bad files
are reported in one line; prepare --include/--exclude select files by relative path."""
import numpy as np
import trimesh
from click.testing import CliRunner
from gegnn_stores import flat_grid

from geodata.augment import AugmentConfig, bend, cut, twist, variant
from geodata.cli import main
from geodata.geodesic import exact_geodesic_distances
from geodata.mesh import Mesh, edge_face_counts
from geodata.prepare import discover, read_list


def _sphere():
    m = trimesh.creation.icosphere(3)
    return Mesh(m.vertices, m.faces)


def test_variant_is_deterministic_and_differs_by_seed():
    cfg = AugmentConfig(p_bend=1, p_twist=1, p_cut=1)
    a = variant(_sphere(), np.random.default_rng(1), cfg)
    b = variant(_sphere(), np.random.default_rng(1), cfg)
    c = variant(_sphere(), np.random.default_rng(2), cfg)
    np.testing.assert_array_equal(a.vertices, b.vertices)
    np.testing.assert_array_equal(a.faces, b.faces)
    assert a.vertices.shape != c.vertices.shape or not np.allclose(a.vertices, c.vertices)


def test_bend_is_an_isometry_of_a_flat_sheet():
    """A sheet in the bend's neutral plane rolls onto a cylinder: its geodesics keep their length."""
    v, f = flat_grid(25)
    sheet = np.stack([2 * v[:, 0], np.zeros(len(v)), v[:, 1]], axis=1)  # in the (axis, depth) plane
    frame = np.linalg.qr(np.random.default_rng(0).normal(size=(3, 3)))[0]
    sheet = sheet @ frame.T
    bent = bend(sheet, frame, np.pi / 2)
    assert np.abs(bent - sheet).max() > 0.3  # it did bend
    before = exact_geodesic_distances(Mesh(sheet, f), 0)
    after = exact_geodesic_distances(Mesh(bent, f), 0)
    np.testing.assert_allclose(after[1:], before[1:], rtol=0.01)  # chords instead of arcs: < 1%
    euclid = np.linalg.norm(bent - bent[0], axis=1)
    assert (euclid[1:] < after[1:] - 1e-9).mean() > 0.5  # and it is curved: chords got shorter


def test_twist_keeps_distances_to_the_axis_and_cut_opens_holes():
    m = _sphere()
    frame = np.eye(3)
    twisted = twist(m.vertices, frame, 1.2)
    np.testing.assert_allclose(np.linalg.norm(twisted[:, 1:], axis=1), np.linalg.norm(m.vertices[:, 1:], axis=1),
                               atol=1e-12)
    np.testing.assert_allclose(twisted[:, 0], m.vertices[:, 0])
    assert np.abs(twisted - m.vertices).max() > 0.2
    faces = cut(m.vertices, m.faces, np.array([[1.0, 0, 0], [0, 0, -1]]), np.array([0.4, 0.3]))
    _, counts = edge_face_counts(faces)
    assert 0.5 * len(m.faces) < len(faces) < len(m.faces) and (counts == 1).sum() > 20
    assert len(cut(m.vertices, m.faces, np.zeros((1, 3)), np.array([0.99]))) == len(m.faces)  # never most


def test_augment_cli_writes_variants_and_reports_bad_files(tmp_path):
    raw = tmp_path / "raw"
    (raw / "sub").mkdir(parents=True)
    trimesh.creation.icosphere(2).export(raw / "sub" / "ball.obj")
    trimesh.creation.box().export(raw / "box.stl")
    (raw / "broken.obj").write_text("v 0 0 0\nf 1 2 3\n")
    out = tmp_path / "aug"
    result = CliRunner().invoke(main, ["augment", str(raw), str(out), "--variants", "2", "--seed", "5"])
    assert result.exit_code == 0, result.output
    written = sorted(p.relative_to(out).as_posix() for p in out.rglob("*.ply"))
    assert written == ["box.aug0.ply", "box.aug1.ply", "sub/ball.aug0.ply", "sub/ball.aug1.ply"]
    assert "FAILED broken.obj [load]" in result.output and "2 files ok, 1 failed, 4 variants" in result.output
    first = (out / "sub" / "ball.aug1.ply").read_bytes()
    assert CliRunner().invoke(main, ["augment", str(raw), str(out), "--variants", "2", "--seed", "5"]).exit_code == 0
    assert (out / "sub" / "ball.aug1.ply").read_bytes() == first  # reruns rewrite the same files


def test_include_exclude_lists(tmp_path):
    for name in ["a.obj", "b.off", "d/c.ply", "d/e.stl"]:
        (tmp_path / name).parent.mkdir(exist_ok=True)
        (tmp_path / name).write_text("")
    listing = tmp_path / "list.txt"
    listing.write_text("# validation\nd/c.ply  # a comment\n\nb.off\n")
    chosen = read_list(listing)
    assert chosen == {"d/c.ply", "b.off"}
    assert discover(tmp_path, include=chosen) == ["b.off", "d/c.ply"]
    assert discover(tmp_path, exclude=chosen) == ["a.obj", "d/e.stl"]
    # A list is the inputs (no walk): a listed file that is missing is kept, to be recorded as failed.
    assert discover(tmp_path, include={"gone.obj", "b.off"}) == ["b.off", "gone.obj"]
