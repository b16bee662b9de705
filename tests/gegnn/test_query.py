"""gegnn query and export: file numbering, exact comparison, pairs CSV, pictures, clear errors."""
import numpy as np
import pytest
import trimesh
from click.testing import CliRunner
from gegnn_stores import ellipsoid

from gegnn import GeGnn, GeGnnConfig
from gegnn.checkpoint import load_checkpoint
from gegnn.cli import main
from gegnn.queries.files import load_query_mesh, read_pairs

SMALL = GeGnnConfig(channels=16, embed_dim=16, decoder_hidden=16, encoder_blocks=(1,) * 5,
                    decoder_blocks=(1,) * 5)


@pytest.fixture(scope="module")
def ckpt(tmp_path_factory):
    torch_model = GeGnn(SMALL)
    path = tmp_path_factory.mktemp("ckpt") / "model.safetensors"
    torch_model.save(path)
    return str(path)


@pytest.fixture(scope="module")
def soup(tmp_path_factory):
    """An ellipsoid written as a soup (every face has its own three vertices) in centimetres."""
    v, f = ellipsoid((1.0, 0.7, 0.5), subdivisions=3)
    path = tmp_path_factory.mktemp("mesh") / "soup.obj"
    trimesh.Trimesh(v[f].reshape(-1, 3) * 100, np.arange(3 * len(f)).reshape(-1, 3), process=False).export(path)
    return str(path), len(v), 3 * len(f)


def test_soup_is_merged_and_reported_in_file_numbering(soup, ckpt, tmp_path):
    path, n_merged, n_file = soup
    qm = load_query_mesh(path)
    assert len(qm.mesh.vertices) == n_merged and len(qm.to_mesh) == n_file
    out = tmp_path / "f.npy"
    result = CliRunner().invoke(main, ["query", ckpt, path, "--source", "4", "-o", str(out)])
    assert result.exit_code == 0, result.output
    field = np.load(out)
    assert field.shape == (n_file,) and field[4] == 0
    # copies of one vertex in the soup carry the same value
    same = np.flatnonzero(qm.to_mesh == qm.to_mesh[7])
    assert len(same) > 1 and np.all(field[same] == field[same[0]])


def test_exact_png_and_prepare(soup, ckpt, tmp_path):
    path, _, _ = soup
    out = tmp_path / "cmp.png"
    result = CliRunner().invoke(main, ["query", ckpt, path, "--source", "0", "--exact", "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert "mean relative error vs exact" in result.output
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    import matplotlib.image
    img = matplotlib.image.imread(out)
    assert img.shape[1] > 2.5 * img.shape[0]  # three panels side by side
    result = CliRunner().invoke(main, ["query", ckpt, path, "--source", "0", "--prepare", "-o",
                                       str(tmp_path / "p.ply")])
    assert result.exit_code == 0, result.output
    m = trimesh.load(tmp_path / "p.ply", process=False)
    assert 4000 < len(m.vertices) < 6000  # the pipeline's ~5k-vertex remesh
    assert np.ptp(m.vertices, axis=0).max() == pytest.approx(200, rel=0.02)  # still in the file's units


def test_pairs_csv_matches_the_field(soup, ckpt, tmp_path):
    path, _, _ = soup
    pairs = tmp_path / "pairs.csv"
    pairs.write_text("i,j\n0,5\n0,9\n3,3\n")
    out = tmp_path / "d.csv"
    result = CliRunner().invoke(main, ["query", ckpt, path, "--pairs-file", str(pairs), "-o", str(out)])
    assert result.exit_code == 0, result.output
    rows = out.read_text().splitlines()
    assert rows[0] == "i,j,distance" and len(rows) == 4
    d = np.array([float(r.split(",")[2]) for r in rows[1:]])
    CliRunner().invoke(main, ["query", ckpt, path, "--source", "0", "-o", str(tmp_path / "f.npy")])
    field = np.load(tmp_path / "f.npy")
    np.testing.assert_allclose(d[:2], field[[5, 9]], rtol=1e-5)
    assert d[2] == 0


def test_clear_errors(soup, ckpt, tmp_path):
    path, _, n_file = soup
    runner = CliRunner()
    r = runner.invoke(main, ["query", ckpt, path, "--source", str(n_file)])
    assert r.exit_code != 0 and f"soup.obj has {n_file} vertices" in r.output
    bad = tmp_path / "bad.obj"
    bad.write_text("v 0 0 0\nv 1 0 0\nf 1 2 3\n")
    r = runner.invoke(main, ["query", ckpt, str(bad), "--source", "0"])
    assert r.exit_code != 0 and "bad.obj: load: line 3: face refers to vertex 3; the file has 2 vertices" in r.output
    r = runner.invoke(main, ["query", ckpt, path])
    assert r.exit_code != 0 and "--source, --pairs-file or --points-file" in r.output
    r = runner.invoke(main, ["query", path, "--source", "0"])
    assert r.exit_code != 0 and "--pretrained [NAME] MESH" in r.output
    (tmp_path / "afile").write_text("")
    r = runner.invoke(main, ["query", ckpt, path, "--source", "0", "-o", str(tmp_path / "afile" / "f.npy")])
    assert r.exit_code != 0 and "f.npy: cannot write there" in r.output and "Traceback" not in r.output
    r = runner.invoke(main, ["query", "--pretrained", "papr", path, "--source", "0"])
    assert r.exit_code != 0 and "no pretrained model 'papr'; shipped: landmark, landmark-v3, landmark-v2, landmark-v1, paper" in r.output
    r = runner.invoke(main, ["query", "--pretrained", str(tmp_path / "missing.obj"), "--source", "0"])
    assert r.exit_code != 0 and "missing.obj: no such file" in r.output
    with pytest.raises(ValueError, match="two integer columns"):
        (tmp_path / "p.csv").write_text("0,1\nx,y\n")
        read_pairs(tmp_path / "p.csv")


def test_export_fp16_roundtrip(ckpt, tmp_path):
    out = tmp_path / "w.safetensors"
    result = CliRunner().invoke(main, ["export", ckpt, str(out)])
    assert result.exit_code == 0, result.output
    from safetensors import safe_open
    with safe_open(str(out), framework="pt") as f:
        assert {f.get_tensor(k).dtype for k in f.keys()} <= {__import__("torch").float16,
                                                              __import__("torch").int64}
    a, b = GeGnn.from_checkpoint(ckpt), GeGnn.from_checkpoint(out)
    v, f = ellipsoid()
    ea, eb = a.embed(v, f).field(0), b.embed(v, f).field(0)
    np.testing.assert_allclose(eb, ea, rtol=0.02, atol=1e-3)  # fp16 weights: close, not equal
    assert load_checkpoint(out).metadata["dtype"] == "fp16"


def test_multi_part_mesh_defines_distances_on_the_source_part(ckpt, tmp_path):
    """Two spheres far apart: the other one has no geodesic distance from the source (NaN in .npy,
    grey in the picture, out of the metric); the metric is the source part's alone."""
    a, fa = ellipsoid((1.0, 1.0, 1.0), subdivisions=3)
    v = np.concatenate([a, a * 0.5 + [100.0, 0, 0]])
    f = np.concatenate([fa, fa + len(a)])
    path = tmp_path / "two.obj"
    trimesh.Trimesh(v, f, process=False).export(path)
    result = CliRunner().invoke(main, ["query", ckpt, str(path), "--source", "0", "--exact", "-o",
                                       str(tmp_path / "f.npy")])
    assert result.exit_code == 0, result.output
    assert f"2 separate parts; source 0 is on a part of {len(a)} vertices" in result.output
    assert "on the source's part" in result.output
    field = np.load(tmp_path / "f.npy")
    assert np.isnan(field[len(a):]).all() and np.isfinite(field[:len(a)]).all()
    result = CliRunner().invoke(main, ["query", ckpt, str(path), "--source", "0", "--exact", "-o",
                                       str(tmp_path / "f.png")])
    assert result.exit_code == 0, result.output


def test_coarse_mesh_gets_a_resolution_note(ckpt, tmp_path):
    path = tmp_path / "box.obj"
    trimesh.creation.box().export(path)
    result = CliRunner().invoke(main, ["query", ckpt, str(path), "--source", "0"])
    assert result.exit_code == 0 and "note: 8 vertices: the shipped paper model's error grows away from the ~5k" in result.output
    assert "--prepare remeshes" in result.output


def test_resolution_note_follows_the_measurements():
    """The landmark model was measured at 1k-100k vertices without loss (docs/applications.md): no note at 80k
    nor at 1M (through its 20k proxy); the paper model drifts beyond 20k, so it gets one at 30k, but not at 80k,
    which it meets as its 20k proxy."""
    from gegnn.queries.files import resolution_note

    assert resolution_note(80_000, GeGnn.pretrained().config) is None
    assert resolution_note(1_000_000, GeGnn.pretrained().config) is None
    assert "11.3% at 80k" in resolution_note(30_000, GeGnn.pretrained("paper").config)
    assert resolution_note(80_000, GeGnn.pretrained("paper").config) is None
    assert "measured from 1,000 to 100,000 vertices" in resolution_note(500, GeGnn.pretrained().config)


def test_pairwise_matrix_in_file_numbering_exact_and_heat(soup, ckpt, tmp_path):
    import zarr

    path, n_mesh, n_file = soup
    runner = CliRunner()
    r = runner.invoke(main, ["pairwise", ckpt, path, "-o", str(tmp_path / "d.npy")])
    assert r.exit_code == 0, r.output
    assert f"{n_file} x {n_file} predicted geodesic distances" in r.output
    d = np.load(tmp_path / "d.npy")
    assert d.shape == (n_file, n_file) and np.array_equal(d, d.T) and not np.diag(d).any()
    qm = load_query_mesh(path)
    twins = np.flatnonzero(qm.to_mesh == qm.to_mesh[0])  # the soup's copies of one vertex
    assert len(twins) > 1 and not d[np.ix_(twins, twins)].any()
    pairs = tmp_path / "pairs.csv"
    pairs.write_text("i,j\n0,5\n7,300\n")
    runner.invoke(main, ["query", ckpt, path, "--pairs-file", str(pairs), "-o", str(tmp_path / "p.csv")])
    answered = [float(line.split(",")[2]) for line in (tmp_path / "p.csv").read_text().splitlines()[1:]]
    np.testing.assert_allclose([d[0, 5], d[7, 300]], answered, rtol=1e-5)

    r = runner.invoke(main, ["pairwise", ckpt, path, "-o", str(tmp_path / "d.zarr"), "--dtype", "float16"])
    assert r.exit_code == 0, r.output
    np.testing.assert_allclose(zarr.open_array(tmp_path / "d.zarr", mode="r")[:], d, rtol=1e-3, atol=1e-3)
    assert not list(tmp_path.glob("*.partial"))

    rows = tmp_path / "rows.txt"
    rows.write_text("3\n0\n")
    r = runner.invoke(main, ["pairwise", ckpt, path, "--rows", str(rows), "--exact", "-o", str(tmp_path / "e.npy")])
    assert r.exit_code == 0, r.output
    e = np.load(tmp_path / "e.npy")
    from gegnn.fields.exact import exact_field
    np.testing.assert_allclose(e[1], qm.to_file(exact_field(qm.mesh, int(qm.to_mesh[0]))), rtol=1e-6)  # float32
    assert np.array_equal(d[[3, 0]] == 0, e == 0)  # the same layout: 0 at the row vertex and its copies
    r = runner.invoke(main, ["pairwise", ckpt, path, "--rows", str(rows), "--heat", "-o", str(tmp_path / "h.npy")])
    assert r.exit_code == 0, r.output
    h = np.load(tmp_path / "h.npy")
    assert np.mean(np.abs(h - e)[e > 0] / e[e > 0]) < 0.05  # the heat method's error on a smooth ellipsoid

    rows.write_text(f"0\n{n_file}\n")
    r = runner.invoke(main, ["pairwise", ckpt, path, "--rows", str(rows), "-o", str(tmp_path / "x.npy")])
    assert r.exit_code != 0 and f"vertex {n_file} out of range: soup.obj has {n_file} vertices" in r.output
    r = runner.invoke(main, ["pairwise", ckpt, path, "--exact", "--heat", "-o", str(tmp_path / "x.npy")])
    assert r.exit_code != 0 and "at most one of --exact and --heat" in r.output
    r = runner.invoke(main, ["pairwise", ckpt, path, "-o", str(tmp_path / "x.csv")])
    assert r.exit_code != 0 and ".npy or .zarr" in r.output


def test_query_points_on_the_surface(soup, ckpt, tmp_path):
    path, _, _ = soup
    qm = load_query_mesh(path)
    v, f = qm.mesh.vertices, qm.mesh.faces
    inside = v[f[:5]].mean(axis=1)  # face centres
    from geodata.mesh import vertex_normals
    above = v[f[0, :1]] + 0.5 * vertex_normals(qm.mesh)[f[0, :1]]  # off the surface, closest to the vertex
    points = np.concatenate([v[f[0, :1]], inside, above])
    np.save(tmp_path / "pts.npy", points)
    runner = CliRunner()
    r = runner.invoke(main, ["query", ckpt, path, "--points-file", str(tmp_path / "pts.npy"), "--exact",
                             "-o", str(tmp_path / "d.npy")])
    assert r.exit_code == 0, r.output
    assert "7 points, at most" in r.output and "mean relative error vs exact (points inserted as vertices)" in r.output
    d = np.load(tmp_path / "d.npy")
    assert d.shape == (7, 7) and not np.diag(d).any() and d[0, 6] == 0  # the off-surface copy lands on the vertex
    np.testing.assert_allclose(d, d.T, rtol=1e-5)
    (tmp_path / "pts.csv").write_text("x,y,z\n" + "\n".join(",".join(map(str, p)) for p in points[:3]))
    r = runner.invoke(main, ["query", ckpt, path, "--points", str(tmp_path / "pts.csv")])  # the old name, with a warning
    assert r.exit_code == 0, r.output
    assert "warning: --points is now --points-file; --points goes in gegnn 0.4.0" in r.stderr
    printed = np.array([[float(x) for x in line.split(",")] for line in r.stdout.splitlines()[1:]])
    np.testing.assert_allclose(printed, d[:3, :3], rtol=1e-5)
    (tmp_path / "bad.csv").write_text("1,2\n")
    r = runner.invoke(main, ["query", ckpt, path, "--points-file", str(tmp_path / "bad.csv")])
    assert r.exit_code != 0 and "bad.csv: expected three number columns x,y,z" in r.output
    r = runner.invoke(main, ["query", ckpt, path, "--points-file", str(tmp_path / "pts.csv"), "--source", "0"])
    assert r.exit_code != 0 and "one of --source, --pairs-file or --points-file" in r.output


def test_fields_by_name_from_the_command_line(ckpt, tmp_path):
    """--fields: query, pairwise and view embed with the landmark fields named, the same values as the API's
    embed(..., fields=...), and say so; a model that reads no landmark fields, or --fields beside pairwise's
    --exact, is a usage error."""
    from geodata.zoo import zoo_mesh

    v, f = zoo_mesh("torus-r0.3", 0.2)
    path = tmp_path / "torus.obj"
    trimesh.Trimesh(v, f, process=False).export(path)
    qm = load_query_mesh(str(path))
    model = GeGnn.pretrained()
    runner = CliRunner()
    fields = {}
    for name in ("own", "paths"):
        out = tmp_path / f"{name}.npy"
        r = runner.invoke(main, ["query", "--pretrained", str(path), "--source", "3", "--fields", name, "-o", str(out)])
        assert r.exit_code == 0, r.output
        assert ("landmark fields by paths" in r.output) == (name == "paths")
        emb = model.embed(qm.mesh.vertices, qm.mesh.faces, fields=None if name == "own" else name)
        np.testing.assert_allclose(np.load(out), qm.to_file(emb.field(int(qm.vertices(3)))), rtol=1e-6)
        fields[name] = np.load(out)
    assert not np.allclose(fields["own"], fields["paths"], rtol=1e-4)
    out = tmp_path / "D.npy"
    r = runner.invoke(main, ["pairwise", "--pretrained", str(path), "--fields", "exact", "-o", str(out)])
    assert r.exit_code == 0, r.output
    emb = model.embed(qm.mesh.vertices, qm.mesh.faces, fields="exact")
    rows = qm.vertices(np.arange(qm.n_file_vertices))
    np.testing.assert_allclose(np.load(out), emb.matrix()[np.ix_(rows, rows)], rtol=1e-5, atol=1e-6)
    page = tmp_path / "v.html"
    r = runner.invoke(main, ["view", "--pretrained", str(path), "--fields", "paths", "-o", str(page)])
    assert r.exit_code == 0, r.output
    assert "landmark fields by paths" in page.read_text()
    for args in (["query", ckpt, str(path), "--source", "0", "--fields", "paths"],
                 ["pairwise", "--pretrained", str(path), "--fields", "paths", "--exact", "-o", str(out)],
                 ["query", "--pretrained", str(path), "--source", "0", "--fields", "exakt"]):
        r = runner.invoke(main, args)
        assert r.exit_code == 2 and "--fields" in r.output, r.output
