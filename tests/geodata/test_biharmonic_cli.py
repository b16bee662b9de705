"""`geodata biharmonic` on a store: contract, agreement with the function, rerun and resume."""
import shutil

import numpy as np
from click.testing import CliRunner

from geodata import store
from geodata.biharmonic import biharmonic_distances
from geodata.cli import main
from geodata.mesh import Mesh


def biharmonic(out, *extra):
    result = CliRunner().invoke(main, ["biharmonic", str(out), "--pairs", "2000", *extra])
    assert result.exit_code == 0, result.output
    return result.output


def bh_arrays(out):
    data = {}
    for k, subs in store.list_meshes(out).items():
        if "biharmonic" in subs:
            with store.read_mesh(out, k, "biharmonic") as g:
                data[k] = g["pairs"][:], g["distances"][:]
    return data


def test_biharmonic_adds_exact_pairs_and_resumes(reference, tmp_path):
    out = tmp_path / "out.zarr"
    shutil.copytree(reference[0], out)
    assert "3 to do" in biharmonic(out)
    data = bh_arrays(out)
    assert len(data) == 3
    for mesh_id, (pairs, dist) in data.items():
        assert store.mesh_attrs(out, mesh_id, "biharmonic")["status"] == "ok"
        assert pairs.dtype == np.uint32 and dist.dtype == np.float32 and len(pairs) >= 2000
        with store.read_mesh(out, mesh_id) as g:
            mesh = Mesh(g["vertices"][:], g["faces"][:])
        source = int(pairs[0, 0])
        rows = pairs[:, 0] == source
        expected = biharmonic_distances(mesh, np.array([source]))[0, pairs[rows, 1]]
        np.testing.assert_allclose(dist[rows], expected, rtol=1e-6)
    assert "0 to do, 3 already done" in biharmonic(out)
    assert CliRunner().invoke(main, ["biharmonic", str(out), "--check"]).exit_code == 0
    # A subgroup a kill stopped before its publication (only the temporary file left) is redone, to the same values.
    first = sorted(data)[0]
    bh_zip = store.mesh_file(out, first, "biharmonic")
    bh_zip.rename(bh_zip.with_name(f".{bh_zip.name}.host.1.tmp"))
    check = CliRunner().invoke(main, ["biharmonic", str(out), "--check"])
    assert check.exit_code == 3 and "2 done, 0 failed, 1 pending" in check.output
    assert "1 to do, 2 already done" in biharmonic(out, "--jobs", "2")
    again = bh_arrays(out)
    for k in data:
        assert all(np.array_equal(a, b) for a, b in zip(data[k], again[k]))
    info = CliRunner().invoke(main, ["info", str(out)])
    assert "biharmonic: 3 ok, 0 failed" in info.output
