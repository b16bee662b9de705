"""The SLURM recipes on a real single-node SLURM (scripts/slurm_single_node.sh: Debian's slurm-wlm and munge,
started here, with CPU binding and MinJobAge=30): the whole chain on the sample meshes with per-stage flags and
an option holding a space, a running shard cancelled and its record purged, then recovered by recover.sh from
the store; a .sbatch submitted directly from a folder without logs/, and two training jobs on one node.
Skipped where SLURM cannot start; under CI=true that is a failure."""
import csv
import io
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest
from slurmtools import running_cluster

ROOT = Path(__file__).resolve().parents[1]
SLURM = ROOT / "pipelines" / "slurm"
SITE = ["--cpus-per-task=1", "--mem=1500M"]  # the site's resource flags: this node has 2 cores


@pytest.fixture(scope="module")
def cluster():
    yield from running_cluster("slurm_single_node.sh", ("slurmctld", "munged"),
                               "slurm-wlm and munge are not installed (apt-get install slurm-wlm munge)",
                               "starting SLURM's daemons needs root", "SLURM")


def _env(tmp_path):
    """Jobs inherit the submitter's environment: this interpreter's geodata, gegnn and torchrun first, behind
    a torchrun that first writes down the cores its task may use."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir(exist_ok=True)
    real = shutil.which("torchrun", path=str(Path(sys.executable).parent))
    (bin_dir / "torchrun").write_text(
        "#!/usr/bin/env bash\n"
        f'{sys.executable} -c "import os; print(len(os.sched_getaffinity(0)))" > "$SLURM_SUBMIT_DIR/cores-$SLURM_JOB_ID"\n'
        f'exec {real} "$@"\n')
    (bin_dir / "torchrun").chmod(0o755)
    # A prepare task of the shard named in the file "hold" waits there (a shard at work when its node fails).
    (bin_dir / "geodata").write_text(
        "#!/usr/bin/env bash\n"
        f'[ "$1" = prepare ] && [[ " $* " != *" --check "* && -e "{tmp_path}/hold" && " $* " == *" --shard '
        f'$(cat "{tmp_path}/hold") "* ]] && sleep 3600\n'
        f'exec {shutil.which("geodata", path=str(Path(sys.executable).parent))} "$@"\n')
    (bin_dir / "geodata").chmod(0o755)
    return {**os.environ, "PATH": f"{bin_dir}:{Path(sys.executable).parent}:{os.environ['PATH']}"}


def _queued():
    return subprocess.run(["squeue", "-h", "-r", "-o", "%i %T %r"], capture_output=True, text=True,
                          check=True).stdout.split("\n")


def _wait_gone(jobs, timeout=900):
    """Until SLURM has none of ``jobs`` (array ids) queued or running."""
    t0 = time.time()
    while any(line.split("_")[0].split(" ")[0] in jobs for line in _queued() if line):
        assert time.time() - t0 < timeout, f"jobs {jobs} still queued after {timeout} s: {_queued()}"
        time.sleep(3)


def _forgotten(job):
    return subprocess.run(["scontrol", "show", "job", job], capture_output=True, text=True).returncode != 0


def _check(tmp_path, stage, shard):
    """The exit status of the store's own account of one shard of 2 (0 done, 3 not yet)."""
    return subprocess.run([sys.executable, "-m", "geodata.cli", *stage, "--shard", f"{shard}/2", "--check"],
                          cwd=tmp_path, capture_output=True, text=True).returncode


def fates(out):
    """Each input file's fate in the store, by `geodata info --csv -`."""
    table = subprocess.run([sys.executable, "-m", "geodata.cli", "info", str(out), "--csv", "-"], check=True,
                           capture_output=True, text=True).stdout
    return {row["source"]: row["fate"] for row in csv.DictReader(io.StringIO(table))}


def test_the_chain_with_a_purged_shard_recovered_then_two_training_jobs(cluster, tmp_path):
    env = _env(tmp_path)
    subprocess.run([sys.executable, "-m", "geodata.cli", "examples", "raw"], cwd=tmp_path, check=True,
                   capture_output=True)
    skip = tmp_path / "skip list.txt"  # an option holding a space, to its stage intact
    skip.write_text("crate.glb\n")
    prepare_options = ["prepare", "raw", "out.zarr", "--pairs", "3000", "--exclude", str(skip)]
    shard = next(k for k in range(2) if _check(tmp_path, prepare_options, k) == 3)  # one with inputs
    (tmp_path / "hold").write_text(f"{shard}/2")
    submitted = subprocess.run(
        ["bash", str(SLURM / "submit.sh"), "raw", "out.zarr", "run", "2", "1",
         "--prepare", "--pairs", "3000", "--exclude", str(skip), "--biharmonic", "--pairs", "3000",
         "--train", "--epochs", "2", "--channels", "16", "--pairs-per-mesh", "2000",
         "--sbatch", *SITE, "--sbatch-train", "--cpus-per-task=2", "--job-name=geo train"],
        cwd=tmp_path, env=env, capture_output=True, text=True, check=True).stdout
    ids = submitted.split("\n")[0].split()
    prepare, biharmonic, train = ids[1], ids[4], ids[7]
    chain = submitted.split("recover.sh ")[1].strip()
    t0 = time.time()  # the held shard lost while it runs (cancelled, as a node failure would): the chain is stuck
    while "RUNNING" not in subprocess.run(["squeue", "-h", "-j", f"{prepare}_{shard}", "-o", "%T"],
                                          capture_output=True, text=True).stdout:
        assert time.time() - t0 < 300, "the shard never started"
        time.sleep(0.5)
    subprocess.run(["scancel", f"{prepare}_{shard}"], check=True)
    (tmp_path / "hold").unlink()
    t0 = time.time()  # until SLURM has forgotten the prepare array (MinJobAge): only the store can tell now
    while not _forgotten(prepare):
        assert time.time() - t0 < 400, "the prepare array's records were never purged"
        time.sleep(5)
    assert _check(tmp_path, prepare_options, shard) == 3  # its meshes are missing
    recovered = subprocess.run(["bash", str(SLURM / "recover.sh"), chain], env=env, capture_output=True,
                               text=True)
    assert recovered.returncode == 0, recovered.stderr
    assert f"prepare shards {shard} resubmitted" in recovered.stderr, recovered.stderr
    assert f"{biharmonic} waits on" in recovered.stdout, recovered.stdout
    _wait_gone([prepare, biharmonic, train, *[line.split("+=(")[1].rstrip(")") for line in
                                            Path(chain).read_text().splitlines() if "_jobs+=(" in line]])

    found = fates(tmp_path / "out.zarr")
    assert sorted(found) == ["chair.ply", "lamp.stl", "mug.obj", "shelf.off", "table.obj"], found  # no crate
    assert set(found.values()) == {"ok"}, found
    for k in range(2):  # the store says both stages are done, shard by shard
        for stage in (["prepare", "raw", "out.zarr", "--pairs", "3000", "--exclude", str(skip)],
                      ["biharmonic", "out.zarr", "--pairs", "3000"]):
            assert _check(tmp_path, stage, k) == 0, (stage, k)
    log = (tmp_path / "run" / "train.log").read_text()
    assert "1 process(es) on cpu" in log and "epoch 1 " in log, list((tmp_path / "logs").iterdir())
    assert (tmp_path / f"cores-{train}").read_text().strip() == "2"  # the task's 2 cores, not one
    assert (tmp_path / "logs" / f"geo train-{train}.log").exists()  # the training job's own flags
    from gegnn import GeGnn
    GeGnn.from_checkpoint(tmp_path / "run" / "best.safetensors")

    # Two training jobs on one node, each .sbatch submitted directly from a folder without logs/.
    direct = tmp_path / "direct"
    direct.mkdir()
    ids = [subprocess.run(["sbatch", "--parsable", *SITE, str(SLURM / "train.sbatch"),
                           str(tmp_path / "out.zarr"), f"run{k}", "--epochs", "1", "--channels", "16",
                           "--pairs-per-mesh", "1000"], cwd=direct, env=env, capture_output=True, text=True,
                          check=True).stdout.strip() for k in (1, 2)]
    _wait_gone(ids)
    for k, job in zip((1, 2), ids):
        assert "epoch 0 " in (direct / f"run{k}" / "train.log").read_text()
        assert (direct / f"gegnn-train-{job}.log").exists()
