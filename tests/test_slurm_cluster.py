"""The SLURM recipes on a real single-node SLURM (scripts/slurm_single_node.sh: Debian's slurm-wlm and
munge, started here): the whole chain on the sample meshes with a shortened training on a node without
GPUs, a cancelled shard recovered by recover.sh, a .sbatch submitted directly from a folder without logs/,
and two training jobs on one node. Skipped where SLURM cannot start; under CI=true that is a failure."""
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import zarr

ROOT = Path(__file__).resolve().parents[1]
SLURM = ROOT / "pipelines" / "slurm"
SITE = "--cpus-per-task=1 --mem=1500M"  # the site's resource flags: this node has 2 cores


@pytest.fixture(scope="module")
def cluster():
    why = None
    path = f"{os.environ.get('PATH', '')}:/usr/sbin:/sbin"  # the daemons live in sbin
    if not shutil.which("slurmctld", path=path) or not shutil.which("munged", path=path):
        why = "slurm-wlm and munge are not installed (apt-get install slurm-wlm munge)"
    elif os.geteuid() != 0:
        why = "starting SLURM's daemons needs root"
    else:
        start = subprocess.run([str(ROOT / "scripts" / "slurm_single_node.sh"), "start"], capture_output=True,
                               text=True)
        why = None if start.returncode == 0 else f"SLURM did not start: {start.stderr.strip()}"
    if why:
        if os.environ.get("CI") == "true":
            pytest.fail(why)
        pytest.skip(why)
    yield


def _env():
    """Jobs inherit the submitter's environment: this interpreter's geodata, gegnn and torchrun first."""
    return {**os.environ, "PATH": f"{Path(sys.executable).parent}:{os.environ['PATH']}"}


def _wait(jobs, timeout=900):
    """Until none of ``jobs`` is pending or running; their final states by id."""
    t0 = time.time()
    while time.time() - t0 < timeout:
        out = subprocess.run(["squeue", "-h", "-o", "%i %T", "-j", ",".join(jobs)], capture_output=True,
                             text=True).stdout
        if not out.strip():
            break
        time.sleep(3)
    else:
        raise AssertionError(f"jobs {jobs} still queued after {timeout} s")
    states = {}
    for job in jobs:
        info = subprocess.run(["scontrol", "-o", "show", "job", job], capture_output=True, text=True).stdout
        states[job] = sorted(set(re.findall(r"JobState=(\w+)", info)))
    return states


def test_the_chain_with_a_cancelled_shard_recovered_then_two_training_jobs(cluster, tmp_path):
    env = _env()
    subprocess.run([sys.executable, "-m", "geodata.cli", "examples", "raw"], cwd=tmp_path, check=True,
                   capture_output=True)
    submitted = subprocess.run(
        ["bash", str(SLURM / "submit.sh"), "raw", "out.zarr", "run", "2", "1", "--prepare", "--pairs 3000",
         "--biharmonic", "--pairs 3000", "--train", "--epochs 2 --channels 16 --pairs-per-mesh 2000",
         "--sbatch", SITE], cwd=tmp_path, env=env, capture_output=True, text=True, check=True).stdout
    prepare, biharmonic, train = re.search(r"prepare (\d+) -> biharmonic (\d+) -> train (\d+)", submitted).groups()
    t0 = time.time()  # a shard lost while it runs (cancelled, as a node failure would): the chain is stuck
    while "RUNNING" not in subprocess.run(["squeue", "-h", "-j", f"{prepare}_1", "-o", "%T"], capture_output=True,
                                          text=True).stdout:
        assert time.time() - t0 < 300, "shard 1 never started"
        time.sleep(0.5)
    subprocess.run(["scancel", f"{prepare}_1"], check=True)
    t0 = time.time()
    while "DependencyNeverSatisfied" not in subprocess.run(["scontrol", "-o", "show", "job", biharmonic],
                                                           capture_output=True, text=True).stdout:
        assert time.time() - t0 < 300, "the stage after a cancelled shard never gave up waiting"
        time.sleep(2)
    recovered = subprocess.run(["bash", str(SLURM / "recover.sh"), prepare, biharmonic, train], env=env,
                               capture_output=True, text=True, check=True).stdout
    assert f"requeued {prepare}" in recovered and f"released {biharmonic}" in recovered
    states = _wait([prepare, biharmonic, train])
    assert all(s == ["COMPLETED"] for s in states.values()), (states, list((tmp_path / "logs").iterdir()))

    root = zarr.open_group(str(tmp_path / "out.zarr"), mode="r")
    meshes = [g for _, g in root["meshes"].groups()]
    assert len(meshes) == 6 and all(g.attrs["status"] == "ok" for g in meshes)
    for g in meshes:  # exact biharmonic distances of their own pairs, positive off the diagonal
        assert g["biharmonic"].attrs["status"] == "ok"
        d = np.asarray(g["biharmonic"]["distances"][:])
        assert len(d) >= 3000 and np.isfinite(d).all() and (d > 0).all()  # whole rows of sources
    log = (tmp_path / "run" / "train.log").read_text()
    assert "1 process(es) on cpu" in log and "epoch 1 " in log and (tmp_path / "run" / "best.safetensors").exists()

    # Two training jobs on one node, each .sbatch submitted directly from a folder without logs/.
    direct = tmp_path / "direct"
    direct.mkdir()
    ids = [subprocess.run(["sbatch", "--parsable", *SITE.split(), str(SLURM / "train.sbatch"),
                           str(tmp_path / "out.zarr"), f"run{k}", "--epochs", "1", "--channels", "16",
                           "--pairs-per-mesh", "1000"], cwd=direct, env=env, capture_output=True, text=True,
                          check=True).stdout.strip() for k in (1, 2)]
    assert all(s == ["COMPLETED"] for s in _wait(ids).values())
    for k, job in zip((1, 2), ids):
        assert "epoch 0 " in (direct / f"run{k}" / "train.log").read_text()
        assert (direct / f"gegnn-train-{job}.log").exists()
