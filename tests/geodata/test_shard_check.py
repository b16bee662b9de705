"""What a scheduler's recovery asks of a shard (`--check`, issue 56 items 6, 7, 9): it says done once the
shard's work is done, whatever the stage's options; a shard's points step covers the meshes it prepared; a
check reads no input file."""
import hashlib

import numpy as np
from click.testing import CliRunner

from geodata import store
from geodata.cli import main
from storetools import ball_obj

ARGS = ["--pairs", "300", "--target-vertices", "150"]


def run(*args, code=0):
    result = CliRunner().invoke(main, [str(a) for a in args])
    assert result.exit_code == code, result.output
    return result


def test_retry_failed_check_says_done_with_a_failure_recorded(tmp_path):
    """A mesh whose biharmonic step always fails is accounted for: `--retry-failed --check` exits 0 as `--check`
    does (recover.sh passes the stage's options into its check)."""
    store.create_store(tmp_path, {})
    for mesh_id in ("a", "b"):
        store.write_mesh(tmp_path, mesh_id, {"vertices": np.zeros((3, 3), np.float32)}, {})
    store.write_mesh(tmp_path, "a", {"pairs": np.zeros((1, 2), np.uint32)}, {}, "biharmonic")
    store.record_failure(tmp_path, "b.biharmonic", "b.obj", "biharmonic", "singular")
    for extra in ([], ["--retry-failed"]):
        result = run("biharmonic", tmp_path, "--check", *extra)
        assert "1 done, 1 failed, 0 pending" in result.output


def test_each_shard_adds_points_to_the_meshes_it_prepared_and_check_counts_them(tmp_path):
    """`prepare --shard K/N --points`: the points of exactly the meshes shard K prepared (their ids hash
    elsewhere), and `--check --points` is done only when those have them."""
    raw, out = tmp_path / "raw", tmp_path / "out.zarr"
    raw.mkdir()
    for i in range(6):
        (raw / f"ball{i}.obj").write_bytes(ball_obj(0.4 + 0.1 * i))
    for k in range(2):
        run("prepare", raw, out, *ARGS, "--points", "20", "--shard", f"{k}/2")
    meshes = store.list_meshes(out)
    assert len(meshes) == 6 and all(subs == {"points"} for subs in meshes.values())
    for k in range(2):
        run("prepare", raw, out, *ARGS, "--points", "20", "--shard", f"{k}/2", "--check")
    store.mesh_file(out, next(iter(meshes)), "points").unlink()
    codes = [CliRunner().invoke(main, ["prepare", str(raw), str(out), *ARGS, "--points", "20", "--shard",
                                       f"{k}/2", "--check"]).exit_code for k in range(2)]
    assert sorted(codes) == [0, 3]
    assert sorted(CliRunner().invoke(main, ["prepare", str(raw), str(out), *ARGS, "--shard", f"{k}/2",
                                            "--check"]).exit_code for k in range(2)) == [0, 0]  # no --points


def test_check_of_a_shard_that_never_ran_reads_no_input(tmp_path, monkeypatch):
    """A shard's check hashes no file: what its ledger does not vouch for is pending until a run reads it (a
    recovery checks every shard while array tasks wait: it must not read the catalog each time)."""
    import geodata.prepare

    raw = tmp_path / "raw"
    raw.mkdir()
    contents = {ball_obj(0.5 + 0.1 * i) for i in range(3)}
    for i, data in enumerate(sorted(contents)):
        (raw / f"ball{i}.obj").write_bytes(data)
    hashed, real = [], hashlib.sha256
    monkeypatch.setattr(geodata.prepare.hashlib, "sha256", lambda data=b"": hashed.append(data) or real(data))
    out = tmp_path / "out.zarr"
    for _ in range(2):
        result = run("prepare", raw, out, *ARGS, "--check", code=3)
        assert "3 pending (3 not read yet)" in result.output
    run("prepare", raw, out, *ARGS, "--check", "--rehash", code=3)
    assert not contents.intersection(hashed)
    run("prepare", raw, out, *ARGS)
    run("prepare", raw, out, *ARGS, "--check", "--rehash")  # --rehash is a run's: a check says done


def test_a_shards_work_is_one_function_a_scheduler_can_call(tmp_path):
    """geodata.shard.prepare_shard: the check's answer, then the run (ledger, meshes, points) and its rows, with
    no command line; subgroup_shard likewise for a later stage."""
    from geodata.points_runner import PointsConfig
    from geodata.prepare import PrepareConfig
    from geodata.shard import prepare_shard, subgroup_shard

    raw, out = tmp_path / "raw", tmp_path / "out.zarr"
    raw.mkdir()
    (raw / "ball.obj").write_bytes(ball_obj())
    config, points = PrepareConfig(300, 150), PointsConfig(20, 300)
    before = prepare_shard(raw, out, config, points=points, check=True)
    assert before.pending == 1 and "1 pending (1 not read yet)" in before.counts and not out.exists()
    ran = prepare_shard(raw, out, config, points=points)
    assert [(r["source"], r["status"]) for r in ran.rows] == [("ball.obj", "ok")] * 2
    after = prepare_shard(raw, out, config, points=points, check=True)
    assert after.pending == 0 and after.counts.endswith("points: 1 done, 0 failed, 0 pending")
    assert subgroup_shard(out, "points", None, points, check=True).counts() == "1 done, 0 failed, 0 pending"


def test_a_check_on_a_ledger_of_0_3_0_judges_by_size_and_mtime(tmp_path):
    """Ledgers of 0.3.0 keep no ctime or inode: a check still says a finished shard is done (a recovery after the
    update must not resubmit every shard); a run hashes the files once."""
    import json

    raw, out = tmp_path / "raw", tmp_path / "out.zarr"
    raw.mkdir()
    (raw / "ball.obj").write_bytes(ball_obj())
    run("prepare", raw, out, *ARGS)
    (path,) = (out / "sources").glob("*.json")
    ledger = json.loads(path.read_text())
    for entry in ledger["inputs"].values():
        for key in ("ctime_ns", "inode", "checked_ns"):
            del entry[key]
    path.write_text(json.dumps(ledger))
    run("prepare", raw, out, *ARGS, "--check")
    assert "0 to do" in run("prepare", raw, out, *ARGS).output
    assert "ctime_ns" in json.loads(path.read_text())["inputs"]["ball.obj"]
