"""`geodata upgrade`: a format-1 store (one zarr group per mesh) copied into format 2 with its ids, arrays,
attributes, subgroups and failures; incomplete meshes left out; a rerun copies nothing twice."""
import numpy as np
import zarr
from click.testing import CliRunner

from geodata import store
from geodata.cli import main


def format1_store(path) -> dict:
    """A store as geodata wrote it before 0.2.0: two committed meshes (one with biharmonic distances, one
    whose biharmonic step failed), an incomplete one, a failure record."""
    root = zarr.open_group(str(path), mode="w", attributes={"geodata_format": 1, "params": {"pairs": 5}})
    meshes, rng = root.create_group("meshes"), np.random.default_rng(0)
    data = {}
    for mesh_id in ("chair-0123abcd", "lamp-89abcdef", "half-00000000"):
        g = meshes.create_group(mesh_id)
        arrays = {"vertices": rng.random((6, 3), dtype=np.float32), "faces": rng.integers(0, 6, (4, 3), dtype=np.int32),
                  "normals": rng.random((6, 3), dtype=np.float32), "edges": rng.integers(0, 6, (7, 2), dtype=np.int32),
                  "geodesic/pairs": rng.integers(0, 6, (5, 2)).astype(np.uint32),
                  "geodesic/distances": rng.random(5, dtype=np.float32)}
        for name, a in arrays.items():
            g.create_array(name, data=a)
        data[mesh_id] = arrays
        if mesh_id == "chair-0123abcd":
            b = g.create_group("biharmonic", attributes={"seed": 0})
            b.create_array("pairs", data=arrays["geodesic/pairs"])
            b.create_array("distances", data=arrays["geodesic/distances"] * 2)
            b.attrs["status"] = "ok"
        if mesh_id == "lamp-89abcdef":
            g.create_group("biharmonic", attributes={"status": "failed", "stage": "biharmonic", "error": "singular"})
        if mesh_id != "half-00000000":
            g.attrs.update(source=f"{mesh_id.split('-')[0]}.obj", sha256="ab" * 32, status="ok")
    root.create_group("failed").create_group("bad-11111111").attrs.update(source="bad.obj", stage="load",
                                                                          error="empty file")
    return data


def test_upgrade_copies_a_format_1_store_with_its_ids(tmp_path):
    old, new = tmp_path / "old.zarr", tmp_path / "new.zarr"
    data = format1_store(old)
    result = CliRunner().invoke(main, ["upgrade", str(old), str(new)])
    assert result.exit_code == 0, result.output
    assert "2 meshes copied, 0 already there, 1 incomplete (not copied), 1 failure records" in result.output
    assert store.list_meshes(new) == {"chair-0123abcd": {"biharmonic"}, "lamp-89abcdef": set()}
    for mesh_id in store.list_meshes(new):
        with store.read_mesh(new, mesh_id) as g:
            for name, expected in data[mesh_id].items():
                np.testing.assert_array_equal(g[name][:], expected)
            assert g.attrs["geometry_key"] == store.geometry_key(data[mesh_id]["vertices"], data[mesh_id]["faces"])
            assert g.attrs["source"] == mesh_id.split("-")[0] + ".obj" and g.attrs["status"] == "ok"
    with store.read_mesh(new, "chair-0123abcd", "biharmonic") as b:
        np.testing.assert_array_equal(b["distances"][:], data["chair-0123abcd"]["geodesic/distances"] * 2)
    failures = store.list_failures(new)
    assert failures["bad-11111111"]["error"] == "empty file" and failures["lamp-89abcdef.biharmonic"]["error"] == "singular"
    info = CliRunner().invoke(main, ["info", str(new)]).output
    assert "inputs: 3 files: 2 ok, 0 duplicate, 1 failed, 0 pending" in info
    again = CliRunner().invoke(main, ["upgrade", str(old), str(new)])
    assert "0 meshes copied, 2 already there" in again.output
    refused = CliRunner().invoke(main, ["info", str(old)])
    assert refused.exit_code != 0 and "geodata upgrade" in refused.output
