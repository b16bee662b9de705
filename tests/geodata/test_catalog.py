"""A catalog as users bring it (ShapeNet: every file is model_normalized.obj): every input file accounted
for, ids that do not collide, shards that can tell whether they are done, a mesh over its memory limit
failed alone, and each input vertex's place on the stored surface (labels carried there and back)."""
import csv
import hashlib
import io
import re

import numpy as np
import pytest
import trimesh
from click.testing import CliRunner
from scipy.spatial import cKDTree

from geodata import store
from geodata.cli import main
from storetools import published

ARGS = ["--pairs", "2000", "--target-vertices", "600"]


def box_obj(extents, comment: str = "") -> bytes:
    box = trimesh.creation.box(extents=extents)
    return f"# {comment}\n".encode() + trimesh.exchange.obj.export_obj(box, include_normals=False).encode()


def colliding_prefix_pair() -> tuple[bytes, bytes]:
    """Two OBJ files of different geometry whose SHA-256 share the first 8 hex digits (the ids of
    format 1): a birthday search over boxes of slightly different heights, ~2^16 tries."""
    seen = {}
    for i in range(1 << 20):
        data = box_obj((1.0, 0.6, 0.3 + i * 1e-7), str(i))
        prefix = hashlib.sha256(data).hexdigest()[:8]
        if prefix in seen:
            return seen[prefix], data
        seen[prefix] = data
    raise AssertionError("no 32-bit prefix collision in 2^20 tries")


@pytest.fixture(scope="module")
def catalog(tmp_path_factory):
    """SYNSET/MODEL/models/model_normalized.obj: two files whose hashes share 8 hex digits, a byte copy, a
    file that fails to load; prepared as two shards."""
    raw = tmp_path_factory.mktemp("shapenet")
    first, second = colliding_prefix_pair()
    files = {"02/a/models/model_normalized.obj": first, "02/b/models/model_normalized.obj": second,
             "03/c/models/model_normalized.obj": first, "03/d/models/model_normalized.obj": b""}
    for name, data in files.items():
        (raw / name).parent.mkdir(parents=True)
        (raw / name).write_bytes(data)
    out = tmp_path_factory.mktemp("store") / "out.zarr"
    checks_before = [CliRunner().invoke(main, ["prepare", str(raw), str(out), *ARGS, "--shard", f"{k}/2", "--check"])
                     for k in range(2)]
    runs = [CliRunner().invoke(main, ["prepare", str(raw), str(out), *ARGS, "--shard", f"{k}/2"]) for k in range(2)]
    for run in runs:
        assert run.exit_code == 0, run.output
    return raw, out, checks_before


def test_every_input_file_has_one_record(catalog):
    """Colliding 8-digit prefixes are two meshes, the byte copy a duplicate of the first, the empty file a
    failure: `info --csv` maps each of the four sources to its fate."""
    raw, out, _ = catalog
    rows = list(csv.DictReader(io.StringIO(CliRunner().invoke(main, ["info", str(out), "--csv", "-"]).output)))
    fate = {r["source"]: r for r in rows}
    assert sorted(fate) == ["02/a/models/model_normalized.obj", "02/b/models/model_normalized.obj",
                            "03/c/models/model_normalized.obj", "03/d/models/model_normalized.obj"]
    a, b, c, d = (fate[s] for s in sorted(fate))
    if a["fate"] == "duplicate":  # the copy's shard published the mesh first
        a, c = c, a
    assert a["fate"] == b["fate"] == "ok" and a["mesh_id"] != b["mesh_id"]
    assert a["sha256"][:8] == b["sha256"][:8] and a["sha256"] != b["sha256"]
    assert re.fullmatch(r"model_normalized-[0-9a-f]{32}", a["mesh_id"]) and a["mesh_id"].endswith(a["sha256"][:32])
    assert c["fate"] == "duplicate" and c["mesh_id"] == a["mesh_id"] and a["mesh_id"] in c["detail"]
    assert d["fate"] == "failed" and "[load] empty file" in d["detail"]
    assert sorted(published(out)) == sorted([a["mesh_id"], b["mesh_id"]])
    info = CliRunner().invoke(main, ["info", str(out)]).output
    assert "inputs: 4 files: 2 ok, 1 duplicate, 1 failed, 0 pending" in info


def test_a_shard_tells_whether_its_inputs_are_all_accounted_for(catalog):
    raw, out, before = catalog
    assert [r.exit_code for r in before] == [3, 3] and all("pending" in r.output for r in before)
    for k in range(2):
        after = CliRunner().invoke(main, ["prepare", str(raw), str(out), *ARGS, "--shard", f"{k}/2", "--check"])
        assert after.exit_code == 0 and " 0 pending" in after.output, after.output


def test_a_rerun_reads_no_unchanged_file_again(catalog, monkeypatch):
    """A shard's ledger keeps each file's hash with its size, times and inode: its rerun hashes only changed
    files, and its check none (a changed file is pending until a run reads it)."""
    import geodata.prepare

    raw, out, _ = catalog
    contents = {p.read_bytes() for p in raw.rglob("*.obj")} - {b""}
    hashed, real = [], hashlib.sha256
    monkeypatch.setattr(geodata.prepare.hashlib, "sha256", lambda data=b"": hashed.append(data) or real(data))
    for k in range(2):
        CliRunner().invoke(main, ["prepare", str(raw), str(out), *ARGS, "--shard", f"{k}/2", "--check"])
    assert hashed and not contents.intersection(hashed)
    changed = raw / "02/b/models/model_normalized.obj"
    changed.write_bytes(changed.read_bytes() + b"# touched\n")
    checks = [CliRunner().invoke(main, ["prepare", str(raw), str(out), *ARGS, "--shard", f"{k}/2", "--check"])
              for k in range(2)]
    assert sorted(c.exit_code for c in checks) == [0, 3] and not contents.union({changed.read_bytes()}) & set(hashed)
    for k in range(2):
        CliRunner().invoke(main, ["prepare", str(raw), str(out), *ARGS, "--shard", f"{k}/2"])
    assert contents.union({changed.read_bytes()}).intersection(hashed) == {changed.read_bytes()}


def test_a_mesh_over_max_memory_is_a_failure_and_the_batch_exits_0(tmp_path, monkeypatch):
    import geodata.prepare

    raw = tmp_path / "raw"
    raw.mkdir()
    (raw / "small.obj").write_bytes(box_obj((1, 1, 1)))
    (raw / "huge.obj").write_bytes(box_obj((1, 2, 3)))
    real = geodata.prepare.watertight

    def greedy(mesh):
        if np.ptp(mesh.vertices[:, 2]) > 2.5:  # the "huge" one: 2 GiB at once
            np.ones(1 << 28)
        return real(mesh)

    monkeypatch.setattr(geodata.prepare, "watertight", greedy)
    limit = "512M"  # beyond what the children inherit from this process
    result = CliRunner().invoke(main, ["prepare", str(raw), str(tmp_path / "out.zarr"), *ARGS, "--max-memory", limit])
    assert result.exit_code == 0, result.output
    failures = store.list_failures(tmp_path / "out.zarr")
    (failure,) = failures.values()
    assert failure["source"] == "huge.obj" and failure["stage"] == "watertight"
    assert failure["error"].startswith("out of memory: over the --max-memory limit of")
    assert [a["source"] for a in published(tmp_path / "out.zarr").values()] == ["small.obj"]


def test_input_vertices_lie_on_the_stored_surface_and_labels_go_there_and_back(tmp_path):
    """Two boxes, labelled 0 and 1 on the input's vertices, through stages that move every vertex: each input
    vertex's recorded place is on the stored surface at its recorded offset from where the normalization maps
    it; a label carried to the stored vertices (the nearest place) and back (the place's nearest corner)
    returns unchanged."""
    raw = tmp_path / "raw"
    raw.mkdir()
    boxes = [trimesh.creation.box(extents=(1, 0.6, 0.4)), trimesh.creation.box(extents=(0.5, 0.5, 0.5))]
    boxes[1].apply_translation((2.5, 0.3, 0.1))
    both = trimesh.util.concatenate(boxes)
    (raw / "two.obj").write_text(trimesh.exchange.obj.export_obj(both, include_normals=False))
    out = tmp_path / "out.zarr"
    assert CliRunner().invoke(main, ["prepare", str(raw), str(out), *ARGS]).exit_code == 0
    (mesh_id,) = store.list_meshes(out)
    with store.read_mesh(out, mesh_id) as g:
        v, f = g["vertices"][:].astype(np.float64), g["faces"][:]
        face, bary, offset = g["input/face"][:], g["input/bary"][:].astype(np.float64), g["input/offset"][:]
        norm = g.attrs["normalization"]
    labels = np.repeat([0, 1], [len(b.vertices) for b in boxes])
    assert len(face) == len(labels) == len(both.vertices) and (face >= 0).all()
    place = np.einsum("pk,pkd->pd", bary, v[f[face]])
    mapped = (np.asarray(both.vertices) - norm["center"]) / norm["scale"]
    np.testing.assert_allclose(np.linalg.norm(place - mapped, axis=1), offset, atol=1e-5)
    assert offset.max() > 1e-3 and offset.max() < 0.05  # the stages moved the surface, a little
    assert np.abs(bary.sum(axis=1) - 1).max() < 1e-5 and bary.min() >= 0
    stored_labels = labels[cKDTree(place).query(v)[1]]                      # there: every stored vertex
    back = stored_labels[f[face, np.argmax(bary, axis=1)]]                  # and back: every input vertex
    np.testing.assert_array_equal(back, labels)
    assert set(stored_labels) == {0, 1}
