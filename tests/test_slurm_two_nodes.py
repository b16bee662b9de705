"""The SLURM recipes on a real two-node SLURM on this one machine (scripts/slurm_two_nodes.sh: slurmctld and
two slurmd, each in a network namespace with its own address and hostname, CPU binding on, MinJobAge=30; its
settings and which are SLURM's defaults: docs/notes/slurm-test-clusters.md): the chain with 4 shards spread over both nodes,
per-stage flags and an option holding a space, a running shard cancelled and its record purged, recovered by
recover.sh from the store, then training on 2 nodes x 1 process (gloo, c10d rendezvous across the
namespaces). Skipped where the cluster cannot start; under CI=true that is a failure."""
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
STATE = "/var/spool/slurm-two-nodes"
CLIENT = ["nsenter", "--net=/run/netns/geo-ctl"]  # SLURM's clients, in the controller's namespace

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def cluster():
    yield from running_cluster("slurm_two_nodes.sh", ("slurmctld", "slurmd", "munged", "ip", "nsenter"),
                               "slurm-wlm, munge or iproute2 are not installed",
                               "network namespaces and SLURM's daemons need root", "the two-node SLURM")


def _env(tmp_path):
    """The submitter's environment, which jobs inherit: the cluster's slurm.conf, this interpreter's tools,
    behind a geodata and a torchrun that first write down the node they run on (and torchrun its cores)."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    # A prepare task of the shard named in the file "hold" waits there (a shard at work when its node fails) and
    # never goes on to the real prepare: cancelled, SLURM may kill the sleep before the shell, which would
    # otherwise run the shard to the end (seen once: the shard's meshes all done when the test expected none).
    hold = (f'[ "$1" = prepare ] && [[ " $* " != *" --check "* && -e "{tmp_path}/hold" && " $* " == *" --shard '
            f'$(cat "{tmp_path}/hold") "* ]] && {{ sleep 3600; exit 143; }}\n')
    for name, extra in (("geodata", ""), ("torchrun", ' $(python3 -c "import os; print(len(os.sched_getaffinity(0)))")')):
        real = shutil.which(name, path=str(Path(sys.executable).parent))
        (bin_dir / name).write_text(f'#!/usr/bin/env bash\necho "$(hostname) ${{SLURM_JOB_ID:-}}{extra} $*" >> '
                                    f'"{tmp_path}/{name}-where.txt"\n{hold if name == "geodata" else ""}'
                                    f'exec {real} "$@"\n')
        (bin_dir / name).chmod(0o755)
    return {**os.environ, "SLURM_CONF": f"{STATE}/slurm.conf",
            "PATH": f"{bin_dir}:{Path(sys.executable).parent}:{os.environ['PATH']}"}


def _client(args, env, **kw):
    return subprocess.run([*CLIENT, *args], env=env, capture_output=True, text=True, **kw)


def _check(tmp_path, stage, shard):
    """The exit status of the store's own account of one shard of 4 (0 done, 3 not yet)."""
    return subprocess.run([sys.executable, "-m", "geodata.cli", *stage, "--shard", f"{shard}/4", "--check"],
                          cwd=tmp_path, capture_output=True, text=True).returncode


def test_the_chain_on_two_nodes_with_a_purged_shard_recovered(cluster, tmp_path):
    env = _env(tmp_path)
    subprocess.run([sys.executable, "-m", "geodata.cli", "examples", "raw"], cwd=tmp_path, check=True,
                   capture_output=True)
    skip = tmp_path / "skip list.txt"
    skip.write_text("crate.glb\n")
    prepare_options = ["raw", "out.zarr", "--pairs", "3000", "--exclude", str(skip)]
    shard = next(k for k in range(4) if _check(tmp_path, ["prepare", *prepare_options], k) == 3)  # has inputs
    (tmp_path / "hold").write_text(f"{shard}/4")
    submitted = _client(["bash", str(SLURM / "submit.sh"), "raw", "out.zarr", "run", "4", "2",
                         "--prepare", "--pairs", "3000", "--exclude", str(skip), "--biharmonic", "--pairs", "3000",
                         "--train", "--epochs", "2", "--channels", "16", "--pairs-per-mesh", "2000",
                         "--sbatch", "--cpus-per-task=1", "--mem=1500M",
                         "--sbatch-train", "--cpus-per-task=2", "--mem=3000M"], env, cwd=tmp_path, check=True).stdout
    ids = submitted.split("\n")[0].split()
    prepare, train = ids[1], ids[7]
    chain = submitted.split("recover.sh ")[1].strip()
    t0 = time.time()  # the held shard lost while it runs (cancelled, as a node failure would)
    while "RUNNING" not in _client(["squeue", "-h", "-j", f"{prepare}_{shard}", "-o", "%T"], env).stdout:
        assert time.time() - t0 < 300, "the shard never started"
        time.sleep(0.5)
    _client(["scancel", f"{prepare}_{shard}"], env, check=True)
    (tmp_path / "hold").unlink()
    t0 = time.time()  # until SLURM has forgotten the prepare array: only the store can tell now
    while _client(["scontrol", "show", "job", prepare], env).returncode == 0:
        assert time.time() - t0 < 400, "the prepare array's records were never purged"
        time.sleep(5)
    assert _check(tmp_path, ["prepare", *prepare_options], shard) == 3  # its meshes are missing
    recovered = _client(["bash", str(SLURM / "recover.sh"), chain], env)
    assert recovered.returncode == 0, recovered.stderr
    assert f"prepare shards {shard} resubmitted" in recovered.stderr, recovered.stderr
    t0 = time.time()
    while _client(["squeue", "-h"], env, check=True).stdout.strip():
        assert time.time() - t0 < 1200, _client(["squeue"], env).stdout
        time.sleep(3)

    for k in range(4):  # the store accounts for every input of every shard, both stages
        for stage in (["prepare", *prepare_options], ["biharmonic", "out.zarr", "--pairs", "3000"]):
            assert _check(tmp_path, stage, k) == 0, (stage, k)
    shards = [line.split() for line in (tmp_path / "geodata-where.txt").read_text().splitlines()]
    tasks = [line for line in shards if line[2] == "prepare" and "--check" not in line]  # not recover.sh's
    assert {line[0] for line in tasks} == {"geo-n1", "geo-n2"}, tasks  # both nodes
    ranks = [line.split() for line in (tmp_path / "torchrun-where.txt").read_text().splitlines()]
    assert sorted((line[0], line[1], line[2]) for line in ranks) == [("geo-n1", train, "2"), ("geo-n2", train, "2")]
    log = (tmp_path / "run" / "train.log").read_text()
    assert "2 process(es) on cpu" in log and "epoch 1 " in log, log
    from gegnn import GeGnn
    GeGnn.from_checkpoint(tmp_path / "run" / "best.safetensors")
