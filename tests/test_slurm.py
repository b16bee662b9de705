"""SLURM launchers: syntax, the commands they would run under SLURM's variables, and a real emulated array."""
import os
import shlex
import subprocess
import sys
from pathlib import Path

import pytest
from storetools import ARGS, assert_same_arrays, store_arrays

SLURM = Path(__file__).resolve().parents[1] / "pipelines" / "slurm"


def fake_bin(tmp_path, names, stdout="") -> Path:
    """Executables that append their name and argv (one shell-quoted line) to calls.txt."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir(exist_ok=True)
    for name in names:
        script = bin_dir / name
        script.write_text(f'#!/usr/bin/env bash\necho "{name} $(printf "%q " "$@")" >> "{tmp_path}/calls.txt"\n'
                          f'printf "{stdout}"\n')
        script.chmod(0o755)
    return bin_dir


def run(script, args, env, tmp_path):
    full_env = {**os.environ, **env, "PATH": f"{tmp_path / 'bin'}:{os.environ['PATH']}"}
    proc = subprocess.run(["bash", str(SLURM / script), *args], env=full_env, cwd=tmp_path,
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    calls = (tmp_path / "calls.txt").read_text().splitlines() if (tmp_path / "calls.txt").exists() else []
    return [shlex.split(c) for c in calls]


@pytest.mark.parametrize("script", sorted(p.name for p in SLURM.iterdir()))
def test_scripts_parse(script):
    assert subprocess.run(["bash", "-n", str(SLURM / script)]).returncode == 0


@pytest.mark.parametrize("env, shard", [
    ({"SLURM_ARRAY_TASK_ID": "3", "SLURM_ARRAY_TASK_COUNT": "8", "SLURM_CPUS_PER_TASK": "4"}, "3/8"),
    # one shard resubmitted alone (--array=7): still shard 7 of 8, not shard 0 of 1
    ({"SLURM_ARRAY_TASK_ID": "7", "SLURM_ARRAY_TASK_MIN": "7", "SLURM_ARRAY_TASK_MAX": "7",
      "SLURM_ARRAY_TASK_COUNT": "1", "SLURM_CPUS_PER_TASK": "4"}, "7/8"),
    # an array with a step (--array=0-7:2): the ids are the shards
    ({"SLURM_ARRAY_TASK_ID": "6", "SLURM_ARRAY_TASK_MIN": "0", "SLURM_ARRAY_TASK_MAX": "6",
      "SLURM_ARRAY_TASK_STEP": "2", "SLURM_ARRAY_TASK_COUNT": "4", "SLURM_CPUS_PER_TASK": "4"}, "6/8"),
])
def test_prepare_array_task_runs_the_shard_its_id_names(tmp_path, env, shard):
    fake_bin(tmp_path, ["geodata"])
    calls = run("prepare.sbatch", ["raw dir", "s3://bucket/out", "8", "--pairs", "1000"], env, tmp_path)
    assert calls == [["geodata", "prepare", "raw dir", "s3://bucket/out", "--shard", shard, "--jobs", "4",
                      "--log", f"{tmp_path}/logs/prepare-{shard.split('/')[0]}.log", "--pairs", "1000"]]


def test_train_on_gpu_nodes_and_on_nodes_without_gpus(tmp_path):
    fake_bin(tmp_path, ["srun", "torchrun"])
    (tmp_path / "bin" / "scontrol").write_text("#!/usr/bin/env bash\nprintf 'node7\\nnode8\\n'\n")
    (tmp_path / "bin" / "scontrol").chmod(0o755)
    two_gpu_nodes = {"SLURM_JOB_NODELIST": "node[7-8]", "SLURM_NNODES": "2", "SLURM_JOB_ID": "42",
                     "SLURM_GPUS_ON_NODE": "4"}
    calls = run("train.sbatch", ["out", "run1", "--epochs", "3"], two_gpu_nodes, tmp_path)
    assert calls == [["srun", "torchrun", "--nnodes", "2", "--nproc-per-node", "4", "--rdzv-id", "42",
                      "--rdzv-backend", "c10d", "--rdzv-endpoint", "node7:20042",
                      "-m", "gegnn.cli", "train", "out", "--run-dir", "run1", "--epochs", "3"]]
    (tmp_path / "calls.txt").unlink()
    for env, nproc in [({}, "1"), ({"SLURM_GPUS_ON_NODE": "0"}, "1"), ({"NPROC_PER_NODE": "2"}, "2"),
                       ({"SLURM_GPUS_PER_NODE": "h100:2"}, "2")]:
        calls = run("train.sbatch", ["out", "run1"], {"SLURM_NNODES": "1", "SLURM_JOB_ID": "43", **env}, tmp_path)
        assert calls[-1][:7] == ["srun", "torchrun", "--nnodes", "1", "--nproc-per-node", nproc, "--standalone"]


def test_submit_chains_prepare_biharmonic_train_with_each_stages_options(tmp_path):
    fake_bin(tmp_path, ["sbatch"], stdout="1234")
    calls = run("submit.sh", ["raw", "out", "run", "16", "2", "--prepare", "--pairs 2000 --strict",
                              "--train", "--epochs 2", "--sbatch", "--partition=cpu --mem=4G"], {}, tmp_path)
    assert [c[:3] for c in calls] == [["sbatch", "--parsable", "--array=0-15"]] * 2 + [["sbatch", "--parsable", "--nodes=2"]]
    assert "--dependency=afterok:1234" in calls[1] and "--dependency=afterok:1234" in calls[2]
    assert all("--partition=cpu" in c and "--mem=4G" in c for c in calls)
    assert calls[0][-7:] == [str(SLURM / "prepare.sbatch"), "raw", "out", "16", "--pairs", "2000", "--strict"]
    assert calls[1][-3:] == [str(SLURM / "biharmonic.sbatch"), "out", "16"]
    assert calls[2][-5:] == [str(SLURM / "train.sbatch"), "out", "run", "--epochs", "2"]
    assert (tmp_path / "logs").is_dir()


def test_emulated_array_of_two_builds_the_reference_store(raw, reference, tmp_path):
    """Both array tasks really run (at once), with the real geodata, into one store."""
    out = tmp_path / "out.zarr"
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    (bin_dir / "geodata").write_text(f'#!/usr/bin/env bash\nexec {sys.executable} -m geodata.cli "$@"\n')
    (bin_dir / "geodata").chmod(0o755)
    env = {**os.environ, "PATH": f"{bin_dir}:{os.environ['PATH']}", "SLURM_CPUS_PER_TASK": "1",
           "SLURM_SUBMIT_DIR": str(tmp_path)}
    procs = [subprocess.Popen(["bash", str(SLURM / "prepare.sbatch"), str(raw), str(out), "2", *ARGS],
                              env={**env, "SLURM_ARRAY_TASK_ID": str(k)}, stdout=subprocess.PIPE,
                              stderr=subprocess.STDOUT) for k in range(2)]
    for p in procs:
        assert p.wait(timeout=600) == 0, p.stdout.read().decode()
    assert_same_arrays(store_arrays(reference[0]), store_arrays(out))
    assert (tmp_path / "logs" / "prepare-0.log").exists()
