"""`geodata prepare` end to end: store contract, bad input, resume after SIGKILL, job/shard determinism."""
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import zarr
from click.testing import CliRunner

from geodata import store
from geodata.cli import main
from geodata.mesh import Mesh, closed_manifold_problem, unique_edges
from storetools import ARGS, BAD, assert_same_arrays as assert_same, prepare, published, store_arrays as arrays

def test_store_holds_valid_meshes_and_records_bad_input(reference):
    out, output = reference
    ok = published(out)
    assert sorted(a["source"] for a in ok.values()) == ["crate.glb", "lamp.ply", "nested/table.obj"]
    root = zarr.open_group(str(out), mode="r")
    assert root.attrs["geodata_format"] == 2
    for mesh_id in ok:
        with store.read_mesh(out, mesh_id) as g:
            v, f, n, e = g["vertices"][:], g["faces"][:], g["normals"][:], g["edges"][:]
            p, d = g["geodesic/pairs"][:], g["geodesic/distances"][:]
            attrs = dict(g.attrs)
        assert attrs["status"] == "ok" and attrs["geometry_key"] == store.geometry_key(v, f)
        assert (v.dtype, f.dtype, n.dtype, e.dtype, p.dtype, d.dtype) == (
            np.float32, np.int32, np.float32, np.int32, np.uint32, np.float32)
        assert closed_manifold_problem(Mesh(v, f)) is None
        assert abs(len(v) - 600) <= 0.2 * 600
        half = (v.max(0) - v.min(0)) / 2
        assert half.max() == 1.0 and np.allclose((v.max(0) + v.min(0)) / 2, 0, atol=1e-6)
        np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1, atol=1e-5)
        assert np.array_equal(e, unique_edges(f.astype(np.int64)))
        assert len(p) >= 3000 and (p[:, 0] != p[:, 1]).all() and p.max() < len(v)
        assert np.isfinite(d).all() and (d > 0).all()
        assert set(attrs["timings"]) == {"load", "watertight", "remesh", "simplify", "normalize", "geodesic"}
    failures = store.list_failures(out)
    assert sorted(a["source"] for a in failures.values()) == sorted(BAD)
    for a in failures.values():
        assert a["stage"] == "load" and a["error"] and "\n" not in a["error"]
    assert "Traceback" not in output
    assert "3 ok, 7 failed" in output


def test_stored_arrays_are_the_stages_output_and_exact_distances(reference, raw):
    """The store holds what the stages compute from the input file (the mesh, to float32), and each
    stored distance is the exact geodesic between its two stored vertices: at least the straight line,
    at most the shortest path along the edges (an independent upper bound), and equal to the exact
    solver's distance from the stored source on the stored mesh."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import dijkstra

    from geodata.geodesic import geodesic_solver
    from geodata.prepare import PrepareConfig, prepare_geometry
    from geodata.stages.load import load_mesh_bytes

    out, _ = reference
    for mesh_id, attrs in published(out).items():
        path = raw / attrs["source"]
        expected = prepare_geometry(load_mesh_bytes(path.read_bytes(), path.suffix),
                                    PrepareConfig(target_vertices=600))
        with store.read_mesh(out, mesh_id) as g:
            v, f = g["vertices"][:], g["faces"][:]
            p, d = g["geodesic/pairs"][:].astype(np.int64), g["geodesic/distances"][:]
        np.testing.assert_array_equal(v, expected.vertices.astype(np.float32))
        np.testing.assert_array_equal(f, expected.faces)
        e = unique_edges(f.astype(np.int64))
        lengths = np.linalg.norm(v[e[:, 0]].astype(np.float64) - v[e[:, 1]], axis=1)
        graph = coo_matrix((lengths, (e[:, 0], e[:, 1])), shape=(len(v), len(v))).tocsr()
        sources = np.unique(p[:, 0])
        path_length = dijkstra(graph, directed=False, indices=sources)
        row = np.searchsorted(sources, p[:, 0])
        straight = np.linalg.norm(v[p[:, 0]] - v[p[:, 1]], axis=1)
        assert (d >= straight * (1 - 1e-5)).all() and (d <= path_length[row, p[:, 1]] * (1 + 1e-5)).all()
        assert (d < 0.95 * path_length[row, p[:, 1]]).mean() > 0.2  # the bound is not the answer
        solve = geodesic_solver(Mesh(v.astype(np.float64), f.astype(np.int64)))
        exact = np.stack([solve(int(s)) for s in sources])
        np.testing.assert_allclose(d, exact[row, p[:, 1]], rtol=1e-5, atol=1e-6)


def test_info_lists_counts_and_failures(reference):
    out, _ = reference
    result = CliRunner().invoke(main, ["info", str(out)])
    assert result.exit_code == 0, result.output
    assert "inputs: 10 files: 3 ok, 0 duplicate, 7 failed, 0 pending" in result.output
    assert "meshes: 3 published, 7 failed" in result.output
    for name in BAD:
        assert name in result.output


def test_rerun_does_nothing_and_other_params_are_refused(reference, raw):
    out, _ = reference
    before = arrays(out)
    result = prepare(raw, out)
    assert "10 input files, 10 distinct, 3 published, 7 failed, 0 pending; 0 to do" in result.output
    assert_same(before, arrays(out))
    refused = CliRunner().invoke(main, ["prepare", str(raw), str(out), "--pairs", "10", "--target-vertices", "600"])
    assert refused.exit_code != 0 and "pairs" in refused.output


def test_jobs_and_shards_give_identical_arrays(reference, raw, tmp_path):
    ref = arrays(reference[0])
    prepare(raw, tmp_path / "jobs2", "--jobs", "2")
    assert_same(ref, arrays(tmp_path / "jobs2"))
    # Two shard processes writing one store at the same time.
    procs = [subprocess.Popen([sys.executable, "-m", "geodata.cli", "prepare", str(raw), str(tmp_path / "shards"),
                               *ARGS, "--shard", f"{k}/2"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
             for k in range(2)]
    for p in procs:
        assert p.wait(timeout=600) == 0, p.stdout.read().decode()
    assert_same(ref, arrays(tmp_path / "shards"))
    assert len(store.list_failures(tmp_path / "shards")) == len(BAD)


def test_sigkill_loses_nothing_and_rerun_finishes_exactly_the_rest(reference, raw, tmp_path):
    out = tmp_path / "killed.zarr"
    proc = subprocess.Popen([sys.executable, "-m", "geodata.cli", "prepare", str(raw), str(out), *ARGS],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline:  # kill the whole process group once the first mesh is committed
        if (out / "meshes").exists() and store.list_meshes(out):
            break
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    committed = sorted(store.list_meshes(out))
    assert 1 <= len(committed) < 3
    # A writer killed while writing a mesh leaves only its temporary file: make one such, truncated.
    published_zip = store.mesh_file(out, committed[0])
    leftover = published_zip.with_name(f".{published_zip.name}.host.1.tmp")
    leftover.write_bytes(published_zip.read_bytes()[:100])
    published_zip.unlink()
    result = prepare(raw, out)
    assert f"{len(committed) - 1} published" in result.output
    assert leftover.name in store.temporary_files(out)  # info counts it: a killed run's leftover
    assert_same(arrays(reference[0]), arrays(out))


def test_a_crashing_or_hanging_mesh_fails_alone(raw, tmp_path, monkeypatch):
    """A segfault in native code and a hang are recorded as that mesh's failure; the batch goes on."""
    import geodata.prepare
    from geodata.stages.load import load_mesh_bytes

    sizes = {load_mesh_bytes(p.read_bytes(), p.suffix).n_vertices: p.name
             for p in [raw / "lamp.ply", raw / "crate.glb"]}
    real = geodata.prepare.watertight

    def misbehaving(mesh):
        name = sizes.get(mesh.n_vertices)
        if name == "lamp.ply":
            os.kill(os.getpid(), signal.SIGSEGV)
        if name == "crate.glb":
            time.sleep(60)
        return real(mesh)

    monkeypatch.setattr(geodata.prepare, "watertight", misbehaving)
    result = prepare(raw, tmp_path / "out.zarr", "--timeout", "20")
    failures = {a["source"]: a for a in store.list_failures(tmp_path / "out.zarr").values()}
    assert failures["lamp.ply"]["stage"] == "watertight" and "SIGSEGV" in failures["lamp.ply"]["error"]
    assert failures["crate.glb"]["stage"] == "watertight" and "timed out" in failures["crate.glb"]["error"]
    ok = [a["source"] for a in published(tmp_path / "out.zarr").values()]
    assert ok == ["nested/table.obj"] and "Traceback" not in result.output


def test_out_path_problems_are_one_line_errors(raw, tmp_path):
    afile = tmp_path / "afile"
    afile.write_text("not a store")
    for out, words in [(afile, "is a file"), (afile / "sub", "cannot create the store: Not a directory")]:
        result = CliRunner().invoke(main, ["prepare", str(raw), str(out)])
        assert result.exit_code != 0 and "Traceback" not in result.output
        assert words in result.output.strip().splitlines()[-1]  # the error line, after click's usage lines


def test_failures_exit_0_unless_strict(tmp_path):
    raw = tmp_path / "raw"
    raw.mkdir()
    (raw / "empty.obj").write_bytes(b"")
    lenient = CliRunner().invoke(main, ["prepare", str(raw), str(tmp_path / "a.zarr")])
    assert lenient.exit_code == 0 and "0 ok, 1 failed" in lenient.output
    strict = CliRunner().invoke(main, ["prepare", str(raw), str(tmp_path / "b.zarr"), "--strict"])
    assert strict.exit_code == 1 and "--strict: 1 of 1 meshes failed" in strict.output


def test_flat_input_is_kept_with_a_warning_in_attrs_and_info(tmp_path):
    raw = tmp_path / "raw"
    raw.mkdir()
    (raw / "triangle.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    out = tmp_path / "out.zarr"
    result = CliRunner().invoke(main, ["prepare", str(raw), str(out), "--pairs", "2000", "--target-vertices", "600"])
    assert result.exit_code == 0 and "1 ok, 0 failed" in result.output, result.output
    (attrs,) = published(out).values()
    assert attrs["status"] == "ok"
    assert attrs["warnings"] == ["flat input thickened: all 3 vertices lie in one plane (1 faces); the "
                                 "watertight stage made a thin closed slab of it"]
    assert "note" in result.output and "flat input thickened" in result.output
    info = CliRunner().invoke(main, ["info", str(out)])
    assert "ok, with warnings:" in info.output and "triangle.obj  flat input thickened" in info.output


def test_input_notes_only_for_flat_input():
    from geodata.prepare import input_notes
    from geodata.stages.load import load_mesh_bytes

    assert input_notes(load_mesh_bytes(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\n", ".obj")) == []
    square = b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\nf 1 3 4\n"
    assert input_notes(load_mesh_bytes(square, ".obj"))[0].startswith("flat input thickened: all 4 vertices")


def test_realworld_kinds_prepare_without_traceback(tmp_path):
    """Every kind of issue 11 in one folder: the valid ones ok (warnings recorded), the broken ones
    failed with a reason in the file's own terms, exit 0, no traceback."""
    from realworld_files import write_fixtures

    expected = write_fixtures(tmp_path / "raw")
    out = tmp_path / "out.zarr"
    result = CliRunner().invoke(main, ["prepare", str(tmp_path / "raw"), str(out), "--pairs", "2000",
                                       "--target-vertices", "600", "--jobs", "2"])
    assert result.exit_code == 0 and "Traceback" not in result.output, result.output
    ok = {a["source"]: a for a in published(out).values()}
    failed = {a["source"]: a for a in store.list_failures(out).values()}
    for name, (status, words) in expected.items():
        if status == "ok":
            assert name in ok, failed.get(name)
            assert words in "; ".join(ok[name].get("warnings", [])) if words else not ok[name].get("warnings")
        else:
            assert name in failed and words in failed[name]["error"], (name, failed.get(name))


@pytest.mark.parametrize("backend, bound", [("vsp", 0.005), ("paths", 0.001)])
def test_the_approximate_backend_says_so_in_the_params_and_is_near_exact(raw, tmp_path, backend, bound):
    """--geodesic-backend vsp (virtual source propagation) or paths (vtp pruned within a tolerance): the store's
    params name it (values, no prose), a run with an exact backend is refused as the command line says it, and
    its distances are those of the exact solver to within its error (paths: never below them)."""
    from geodata.geodesic import geodesic_solver

    out = tmp_path / f"{backend}.zarr"
    result = CliRunner().invoke(main, ["prepare", str(raw / "nested"), str(out), *ARGS, "--geodesic-backend", backend])
    assert result.exit_code == 0 and "1 ok, 0 failed" in result.output, result.output
    params = zarr.open_group(str(out), mode="r").attrs["params"]
    assert params["geodesic_backend"] == backend and "geodesic_error" not in params
    refused = CliRunner().invoke(main, ["prepare", str(raw / "nested"), str(out), *ARGS])
    assert refused.exit_code != 0 and f"was made with --geodesic-backend {backend}, this run asks for vtp" in refused.output
    (mesh_id,) = published(out)
    with store.read_mesh(out, mesh_id) as g:
        mesh = Mesh(g["vertices"][:].astype(np.float64), g["faces"][:].astype(np.int64))
        p, d = g["geodesic/pairs"][:], g["geodesic/distances"][:]
    exact = geodesic_solver(mesh)
    errors = []
    for source in np.unique(p[:, 0])[:3]:
        rows = p[:, 0] == source
        truth = exact(int(source))[p[rows, 1]]
        errors.append((d[rows] - truth) / truth)
    errors = np.concatenate(errors)
    assert 0 < np.abs(errors).mean() < bound  # measured 0.09% (vsp), 0.02% (paths): approximate, not exact
    if backend == "paths":
        assert errors.min() > -1e-6  # real paths: below exact only by float32's rounding
    # each mesh records its own error, measured against exact fields of its first two sources
    first = p[np.sort(np.unique(p[:, 0], return_index=True)[1]), 0][:2]
    truth = np.concatenate([exact(int(s))[p[p[:, 0] == s, 1]] for s in first])
    expect = np.mean(np.abs(np.concatenate([d[p[:, 0] == s] for s in first]) - truth) / truth)
    recorded = store.mesh_attrs(out, mesh_id)["geodesic_error"]
    assert 0 < recorded < bound and recorded == pytest.approx(expect, rel=1e-4)


def test_the_approximate_backends_probes_stop_where_they_would_cost_more_than_the_pairs(monkeypatch):
    from geodata import geodesic
    from geodata.zoo import zoo_mesh

    mesh = Mesh(*zoo_mesh("torus-r0.3", 0.1))
    pairs, distances, _ = geodesic.exact_geodesic_pairs(mesh, 2000, np.random.default_rng(0), backend="vsp")
    assert 0 < geodesic.approximation_error(mesh, pairs, distances) < 0.01
    monkeypatch.setattr(geodesic, "PROBED_UP_TO", mesh.n_vertices - 1)
    assert geodesic.approximation_error(mesh, pairs, distances) is None
