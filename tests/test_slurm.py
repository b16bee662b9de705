"""SLURM launchers: syntax, the commands they would run under SLURM's variables, and a real emulated array."""
import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from storetools import ARGS, assert_same_arrays, store_arrays

ROOT = Path(__file__).resolve().parents[1]
SLURM = ROOT / "pipelines" / "slurm"
# The recipes' tests with stand-ins run under this bash and, where BASH_4_2 names one, under bash 4.2 (RHEL 7's:
# "${a[@]}" of an empty array is unbound there under set -u); a bash 4.2 builds from GNU's bash-4.2 sources.
SHELLS = ["bash", os.environ.get("BASH_4_2", "bash-4.2")]
RECIPES = sorted([*SLURM.iterdir(), *ROOT.glob("scripts/slurm_*.sh"), ROOT / "scripts" / "gpu_check.sh"])


def skip_without(shell):
    if not shutil.which(shell):
        pytest.skip(f"no {shell} (BASH_4_2=/path/to/bash-4.2 runs the recipes' tests under it)")


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


def run(script, args, env, tmp_path, shell="bash", rc=0):
    full_env = {**os.environ, **env, "PATH": f"{tmp_path / 'bin'}:{os.environ['PATH']}"}
    proc = subprocess.run([shell, str(SLURM / script), *args], env=full_env, cwd=tmp_path,
                          capture_output=True, text=True)
    assert proc.returncode == rc, proc.stderr
    calls = (tmp_path / "calls.txt").read_text().splitlines() if (tmp_path / "calls.txt").exists() else []
    return [shlex.split(c) for c in calls]


def fake_ids(tmp_path):
    """A stand-in sbatch that logs its call and answers job ids 100, 101, ... (as --parsable does)."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir(exist_ok=True)
    (bin_dir / "sbatch").write_text(f'''#!/usr/bin/env bash
echo "sbatch $(printf "%q " "$@")" >> "{tmp_path}/calls.txt"
[ -e "{tmp_path}/sbatch-fails" ] && exit 1
n=$(cat "{tmp_path}/next-id" 2>/dev/null || echo 100)
echo $((n + 1)) > "{tmp_path}/next-id"
echo "$n"
''')
    (bin_dir / "sbatch").chmod(0o755)


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


@pytest.mark.parametrize("shell", SHELLS)
def test_array_tasks_without_extra_options(tmp_path, shell):
    skip_without(shell)
    fake_bin(tmp_path, ["geodata"])
    env = {"SLURM_ARRAY_TASK_ID": "1", "SLURM_CPUS_PER_TASK": "2"}
    calls = run("prepare.sbatch", ["raw", "out", "2"], env, tmp_path, shell=shell)
    calls += run("biharmonic.sbatch", ["out", "2"], env, tmp_path, shell=shell)[1:]
    assert calls == [["geodata", "prepare", "raw", "out", "--shard", "1/2", "--jobs", "2", "--log",
                      f"{tmp_path}/logs/prepare-1.log"],
                     ["geodata", "biharmonic", "out", "--shard", "1/2", "--jobs", "2", "--log",
                      f"{tmp_path}/logs/biharmonic-1.log"]]


def unguarded_arrays(text):
    """Expansions of every element of an array, ${a[@]} or ${a[*]}, outside bash 4.2's guard for an empty
    one (${a[@]+"${a[@]}"}, ${a[*]-}), in the lines of a script that are not comments."""
    found = []
    for number, line in enumerate(text.splitlines(), 1):
        if line.lstrip().startswith("#"):
            continue
        for m in re.finditer(r"\$\{(\w+)\[([@*])\]\}", line):
            guard = f'${{{m.group(1)}[{m.group(2)}]+"'
            if line[max(0, m.start() - len(guard)):m.start()] != guard:
                found.append(f"{number}: {m.group(0)}")
    return found


def test_no_array_expansion_that_bash_4_2_calls_unbound():
    assert unguarded_arrays('set -u\nx=("${a[@]}")\n# "${b[@]}"\ny=(${c[@]+"${c[@]}"} ${d[*]-})\necho ${e[*]}\n') \
        == ['2: ${a[@]}', '5: ${e[*]}']
    for script in RECIPES:
        assert unguarded_arrays(script.read_text()) == [], script.name


def test_shellcheck_passes_on_the_recipes():
    if not shutil.which("shellcheck"):
        if os.environ.get("CI") == "true":
            pytest.fail("shellcheck is not installed (apt-get install shellcheck)")
        pytest.skip("shellcheck is not installed (apt-get install shellcheck)")
    proc = subprocess.run(["shellcheck", "--shell=bash", *map(str, RECIPES)], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout


@pytest.mark.parametrize("shell", SHELLS)
def test_train_on_gpu_nodes_and_on_nodes_without_gpus(tmp_path, shell):
    """One torchrun per node, its processes the node's GPUs or NPROC_PER_NODE; srun told the task's cores (it
    does not inherit them on SLURM 22.05-23.02, and CPU binding would pin the node's ranks to one core)."""
    skip_without(shell)
    fake_bin(tmp_path, ["srun", "torchrun"])
    (tmp_path / "bin" / "scontrol").write_text("#!/usr/bin/env bash\nprintf 'node7\\nnode8\\n'\n")
    (tmp_path / "bin" / "scontrol").chmod(0o755)
    two_gpu_nodes = {"SLURM_JOB_NODELIST": "node[7-8]", "SLURM_NNODES": "2", "SLURM_JOB_ID": "42",
                     "SLURM_GPUS_ON_NODE": "4"}
    calls = run("train.sbatch", ["out", "run1", "--epochs", "3"], {**two_gpu_nodes, "SLURM_CPUS_PER_TASK": "32"},
                tmp_path, shell=shell)
    assert calls == [["srun", "--ntasks-per-node=1", "--cpus-per-task=32", "torchrun", "--nnodes", "2",
                      "--nproc-per-node", "4", "--rdzv-id", "42", "--rdzv-backend", "c10d", "--rdzv-endpoint",
                      "node7:20042", "-m", "gegnn.cli", "train", "out", "--run-dir", "run1", "--epochs", "3"]]
    (tmp_path / "calls.txt").unlink()
    for env, nproc in [({}, "1"), ({"SLURM_GPUS_ON_NODE": "0"}, "1"), ({"NPROC_PER_NODE": "2"}, "2"),
                       ({"SLURM_GPUS_PER_NODE": "h100:2"}, "2")]:
        calls = run("train.sbatch", ["out", "run1"], {"SLURM_NNODES": "1", "SLURM_JOB_ID": "43", **env}, tmp_path,
                    shell=shell)
        assert calls[-1] == ["srun", "--ntasks-per-node=1", "torchrun", "--nnodes", "1", "--nproc-per-node", nproc,
                             "--standalone", "-m", "gegnn.cli", "train", "out", "--run-dir", "run1"]
    (tmp_path / "run1").mkdir()
    (tmp_path / "run1" / "last.safetensors").write_bytes(b"")
    calls = run("train.sbatch", ["out", "run1"], {"SLURM_JOB_ID": "44"}, tmp_path, shell=shell)
    assert calls[-1][-1] == "--resume"


SITE_WITH_SPACES = ["--prepare", "--pairs", "2000", "--exclude", "/data/my list.txt", "--strict",
                    "--train", "--epochs", "2", "--run-note=it's \"quoted\"",
                    "--sbatch", "--partition=cpu", "--comment=a b",
                    "--sbatch-prepare", "--mem=4G", "--sbatch-train", "--gpus-per-node=4", "--partition=gpu"]


def submitted(tmp_path, args=SITE_WITH_SPACES, shell="bash"):
    fake_ids(tmp_path)
    return run("submit.sh", ["raw", "out", "run", "16", "2", *args], {}, tmp_path, shell=shell)


@pytest.mark.parametrize("shell", SHELLS)
def test_submit_chains_prepare_biharmonic_train_with_each_stages_options_and_flags(tmp_path, shell):
    """Each word after a section goes to its stage as that one word (spaces and quotes intact); a stage's
    own sbatch flags go to it alone, after the common ones (so they win)."""
    skip_without(shell)
    calls = submitted(tmp_path, shell=shell)
    assert [c[:3] for c in calls] == [["sbatch", "--parsable", "--array=0-15"]] * 2 + [["sbatch", "--parsable", "--nodes=2"]]
    assert "--dependency=afterok:100" in calls[1] and "--dependency=afterok:101" in calls[2]
    assert all("--partition=cpu" in c and "--comment=a b" in c for c in calls)
    assert "--mem=4G" in calls[0] and "--mem=4G" not in calls[1] + calls[2]
    assert all("--gpus-per-node=4" not in c for c in calls[:2]) and "--gpus-per-node=4" in calls[2]
    assert calls[2].index("--partition=gpu") > calls[2].index("--partition=cpu")
    assert calls[0][-9:] == [str(SLURM / "prepare.sbatch"), "raw", "out", "16", "--pairs", "2000", "--exclude",
                             "/data/my list.txt", "--strict"]
    assert calls[1][-3:] == [str(SLURM / "biharmonic.sbatch"), "out", "16"]
    assert calls[2][-6:] == [str(SLURM / "train.sbatch"), "out", "run", "--epochs", "2", "--run-note=it's \"quoted\""]
    assert (tmp_path / "logs").is_dir()


def test_submit_records_the_chain_for_recover_exactly(tmp_path):
    submitted(tmp_path)
    chain = tmp_path / "logs" / "chain-100.sh"
    (tmp_path / "show.sh").write_text(
        '. "$1"\nfor a in prepare_opts train_opts prepare_flags train_flags; do\n'
        '    eval \'printf "%s|" "${\'"$a"\'[@]}"\'; echo\ndone\n'
        'echo "$raw $out $run $shards $nodes $submit_dir"\necho "${prepare_jobs[*]} ${biharmonic_jobs[*]} ${train_jobs[*]}"\n')
    script = ["bash", str(tmp_path / "show.sh"), str(chain)]
    lines = subprocess.run(script, capture_output=True, text=True, check=True).stdout.splitlines()
    assert lines == ["--pairs|2000|--exclude|/data/my list.txt|--strict|", "--epochs|2|--run-note=it's \"quoted\"|",
                     "--partition=cpu|--comment=a b|--mem=4G|",
                     "--partition=cpu|--comment=a b|--gpus-per-node=4|--partition=gpu|",
                     f"raw out run 16 2 {tmp_path}", "100 101 102"]


@pytest.mark.parametrize("args", [["--prepare", "--pairs 2000 --strict"], ["--sbatch", "--partition=cpu --mem=4G"],
                                  ["--unknown"], ["--train"] * 0 + ["only-two"]])
def test_submit_refuses_an_option_string_and_bad_arguments(tmp_path, args):
    """The old form, several options in one quoted word, is refused rather than passed on as one argument."""
    fake_ids(tmp_path)
    positional = ["raw", "out"] if args == ["only-two"] else ["raw", "out", "run"]
    proc = subprocess.run(["bash", str(SLURM / "submit.sh"), *positional, *(a for a in args if a != "only-two")],
                          env={**os.environ, "PATH": f"{tmp_path / 'bin'}:{os.environ['PATH']}"}, cwd=tmp_path,
                          capture_output=True, text=True)
    assert proc.returncode == 2 and not (tmp_path / "calls.txt").exists()
    if " " in args[-1]:
        assert "give each its own" in proc.stderr


def chain_with_stand_ins(tmp_path, queue, checks=(), shards=4):
    """A chain submitted (prepare 100 -> biharmonic 101 -> train 102, options with spaces) to stand-ins:
    squeue answers ``queue`` ("JOB TASK STATE" lines), geodata's --check exits as ``checks`` says
    ({(stage, shard): code}, else 0), scontrol and sbatch log their calls. Returns the chain's record."""
    fake_ids(tmp_path)
    run("submit.sh", ["raw", "out", "run", str(shards), "2", *SITE_WITH_SPACES], {}, tmp_path)
    (tmp_path / "calls.txt").unlink()
    (tmp_path / "queue.txt").write_text("".join(f"{line}\n" for line in queue))
    for (stage, shard), code in dict(checks).items():
        (tmp_path / f"check-{stage}-{shard}").write_text(str(code))
    log = f'echo "$(basename "$0") $(printf "%q " "$@")" >> "{tmp_path}/calls.txt"'
    stand_ins = {
        "squeue": f'[ -e "{tmp_path}/squeue-fails" ] && exit 1\ncat "{tmp_path}/queue.txt"',
        "scontrol": f'{log}\n[ "$1" = -o ] && cat "{tmp_path}/show-$4.txt" 2>/dev/null\ntrue',
        "geodata": (f'{log}\nwhile (( $# )); do [ "$1" = --shard ] && shard=${{2%/*}}; shift; done\n'
                    f'code=$(cat "{tmp_path}/check-$stage-$shard" 2>/dev/null || echo 0)\necho "counts of $shard"\n'
                    'exit "$code"').replace("$(basename", "$(basename").replace('{log}', log),
    }
    stand_ins["geodata"] = f'stage=$1\n{stand_ins["geodata"]}'
    for name, body in stand_ins.items():
        (tmp_path / "bin" / name).write_text(f"#!/usr/bin/env bash\n{body}\n")
        (tmp_path / "bin" / name).chmod(0o755)
    return str(tmp_path / "logs" / "chain-100.sh")


def recover(tmp_path, chain, rc=0, shell="bash"):
    calls = run("recover.sh", [chain], {}, tmp_path, shell=shell, rc=rc)
    return ([c for c in calls if c[0] == "geodata"], [c for c in calls if c[0] == "sbatch"],
            [c for c in calls if c[0] == "scontrol" and c[1] == "update"])


BLOCKED = ["101 0 PENDING", "101 1 PENDING", "101 2 PENDING", "101 3 PENDING", "102 N/A PENDING"]


def test_recover_leaves_a_dependency_that_is_already_right(tmp_path):
    """Training already waits on the biharmonic array (SLURM shows it so): only the biharmonic array's
    dependency is updated (SLURM 22.05 refused to update such a job unchanged on the test cluster)."""
    chain = chain_with_stand_ins(tmp_path, BLOCKED, {("prepare", 1): 3})
    (tmp_path / "show-102.txt").write_text("JobId=102 JobName=geo Dependency=afterok:101_*(unfulfilled) Nodes=2\n")
    (tmp_path / "show-101.txt").write_text("JobId=101 JobName=bih Dependency=afterok:100_*(failed) Nodes=1\n")
    _, _, scontrol = recover(tmp_path, chain)
    assert scontrol == [["scontrol", "update", "JobId=101", "Dependency=afterok:103"]]


@pytest.mark.parametrize("shell", SHELLS)
def test_recover_after_the_records_are_purged_resubmits_the_missing_shard_alone(tmp_path, shell):
    """SLURM knows nothing of the prepare array (purged); the store says shard 1 is not done: shard 1 alone is
    resubmitted with the stage's flags and options as submitted, the biharmonic array waits on it, training
    on the biharmonic array; the biharmonic shards are not asked (they would look done on a store missing
    meshes); nothing is requeued or cancelled. Also under bash 4.2 where BASH_4_2 names one."""
    skip_without(shell)
    chain = chain_with_stand_ins(tmp_path, BLOCKED, {("prepare", 1): 3})
    checks, sbatch, scontrol = recover(tmp_path, chain, shell=shell)
    assert sorted(c[:2] + c[-3:] for c in checks) == [["geodata", "prepare", "--shard", f"{k}/4", "--check"]
                                                       for k in range(4)]  # asked at once: in any order
    assert checks[0][2:-3] == ["raw", "out", "--pairs", "2000", "--exclude", "/data/my list.txt", "--strict"]
    assert sbatch == [["sbatch", "--parsable", "--array=1", "--output=logs/%x-%A_%a.log", "--partition=cpu",
                       "--comment=a b", "--mem=4G", str(SLURM / "prepare.sbatch"), "raw", "out", "4", "--pairs",
                       "2000", "--exclude", "/data/my list.txt", "--strict"]]
    assert scontrol == [["scontrol", "update", "JobId=101", "Dependency=afterok:103"],
                        ["scontrol", "update", "JobId=102", "Dependency=afterok:101"]]
    assert "prepare_jobs+=(103)" in Path(chain).read_text()


def test_recover_never_touches_a_running_shard_and_waits_on_it(tmp_path):
    """Shard 2 runs and shard 3 is queued, both not done yet; shard 1 failed: only shard 1 is resubmitted and
    the next stage waits on the three."""
    chain = chain_with_stand_ins(tmp_path, ["100 2 RUNNING", "100 3 PENDING", *BLOCKED],
                                 {("prepare", 1): 3, ("prepare", 2): 3, ("prepare", 3): 3})
    _, sbatch, scontrol = recover(tmp_path, chain)
    assert [c[2] for c in sbatch] == ["--array=1"]
    assert scontrol[0] == ["scontrol", "update", "JobId=101", "Dependency=afterok:100_2:100_3:103"]
    assert all(c[1] == "update" for c in scontrol)  # no requeue, no hold


def test_recover_a_biharmonic_shard_once_prepare_is_done(tmp_path):
    """Every prepare shard done (records purged): the biharmonic shards are asked, the one not done and not
    queued is resubmitted with the biharmonic stage's flags, and training waits on it."""
    chain = chain_with_stand_ins(tmp_path, ["102 N/A PENDING"], {("biharmonic", 2): 3})
    checks, sbatch, scontrol = recover(tmp_path, chain)
    assert [c[1] for c in checks] == ["prepare"] * 4 + ["biharmonic"] * 4
    assert checks[4][:3] == ["geodata", "biharmonic", "out"]
    assert sbatch == [["sbatch", "--parsable", "--array=2", "--output=logs/%x-%A_%a.log", "--partition=cpu",
                       "--comment=a b", str(SLURM / "biharmonic.sbatch"), "out", "4"]]
    assert scontrol == [["scontrol", "update", "JobId=102", "Dependency=afterok:103"]]


def test_recover_releases_what_waits_once_the_store_has_everything(tmp_path):
    chain = chain_with_stand_ins(tmp_path, BLOCKED)
    _, sbatch, scontrol = recover(tmp_path, chain)
    assert sbatch == [] and scontrol == [["scontrol", "update", "JobId=101", "Dependency="],
                                         ["scontrol", "update", "JobId=102", "Dependency="]]


@pytest.mark.parametrize("broken", ["check", "squeue", "sbatch"])
def test_recover_fails_loudly_and_releases_nothing_when_it_cannot_tell(tmp_path, broken):
    """A --check that neither says done (0) nor not done (3), e.g. a store it cannot read or a geodata
    without --check; squeue failing; the resubmission failing: non-zero exit, the shard or the cause named,
    no stage after it released."""
    checks = {("prepare", 1): 3, ("prepare", 2): 2 if broken == "check" else 0}
    chain = chain_with_stand_ins(tmp_path, BLOCKED, checks)
    if broken != "check":
        (tmp_path / f"{broken}-fails").write_text("")
    proc = subprocess.run(["bash", str(SLURM / "recover.sh"), chain], cwd=tmp_path, capture_output=True, text=True,
                          env={**os.environ, "PATH": f"{tmp_path / 'bin'}:{os.environ['PATH']}"})
    assert proc.returncode == 1
    expected = {"check": "cannot say whether prepare shards 2 are done", "squeue": "squeue failed",
                "sbatch": "resubmitting prepare shards 1 failed"}[broken]
    assert expected in proc.stderr
    calls = (tmp_path / "calls.txt").read_text() if (tmp_path / "calls.txt").exists() else ""
    assert "scontrol" not in calls and ("sbatch" not in calls) == (broken != "sbatch")


def test_recover_refuses_to_guess_about_a_forgotten_training_job(tmp_path):
    """Data complete, training not queued and its record purged: whether it finished is not SLURM's to say
    any more; recover.sh says so and how to resubmit, with a non-zero exit, instead of training again."""
    chain = chain_with_stand_ins(tmp_path, [])
    proc = subprocess.run(["bash", str(SLURM / "recover.sh"), chain], cwd=tmp_path, capture_output=True, text=True,
                          env={**os.environ, "PATH": f"{tmp_path / 'bin'}:{os.environ['PATH']}"})
    assert proc.returncode == 1 and "no longer knows training job 102" in proc.stderr
    (tmp_path / "show-102.txt").write_text("JobId=102 JobState=FAILED Reason=NonZeroExitCode\n")
    _, sbatch, _ = recover(tmp_path, chain)
    assert sbatch == [["sbatch", "--parsable", "--nodes=2", "--output=logs/%x-%j.log", "--partition=cpu",
                       "--comment=a b", "--gpus-per-node=4", "--partition=gpu", str(SLURM / "train.sbatch"), "out",
                       "run", "--epochs", "2", "--run-note=it's \"quoted\""]]


@pytest.mark.parametrize("shell", SHELLS)
def test_recover_submits_a_training_job_the_chain_never_got(tmp_path, shell):
    """submit.sh's sbatch for training failed (a typo in --sbatch-train): the record has no training job, which
    ended recover.sh in "bad array subscript". It says so and submits training behind the stage still
    running; where that sbatch fails too (the data now complete), it names the flags to correct in the
    record."""
    skip_without(shell)
    chain = chain_with_stand_ins(tmp_path, BLOCKED[:-1], {("prepare", 1): 3})
    text = Path(chain).read_text()
    Path(chain).write_text("".join(line for line in text.splitlines(True) if not line.startswith("train_jobs")))
    run_env = {**os.environ, "PATH": f"{tmp_path / 'bin'}:{os.environ['PATH']}"}
    proc = subprocess.run([shell, str(SLURM / "recover.sh"), chain], cwd=tmp_path, capture_output=True, text=True,
                          env=run_env)
    assert proc.returncode == 0, proc.stderr
    assert "the chain's record has no training job" in proc.stderr
    sbatch = [shlex.split(c) for c in (tmp_path / "calls.txt").read_text().splitlines() if c.startswith("sbatch")]
    assert [c[2] for c in sbatch] == ["--array=1", "--nodes=2"]
    assert "--dependency=afterok:101" in sbatch[1] and sbatch[1][-6:-4] == [str(SLURM / "train.sbatch"), "out"]
    assert "train_jobs+=(104)" in Path(chain).read_text()
    Path(chain).write_text("".join(line for line in Path(chain).read_text().splitlines(True)
                                   if not line.startswith("train_jobs")))
    (tmp_path / "check-prepare-1").unlink()  # the store now complete
    (tmp_path / "sbatch-fails").write_text("")
    proc = subprocess.run([shell, str(SLURM / "recover.sh"), chain], cwd=tmp_path, capture_output=True, text=True,
                          env=run_env)
    assert proc.returncode == 1 and "correct its sbatch flags" in proc.stderr and "bad array" not in proc.stderr


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


def single_node(tmp_path, action, **env):
    return subprocess.run(["bash", str(ROOT / "scripts" / "slurm_single_node.sh"), action], capture_output=True,
                          text=True, env={**os.environ, "SLURM_SINGLE_NODE_CONF": str(tmp_path / "slurm.conf"),
                                          "SLURM_SINGLE_NODE_STATE": str(tmp_path / "state"), **env})


def test_the_single_node_script_leaves_a_sites_slurm_alone(tmp_path):
    """A slurm.conf it did not write is neither overwritten nor removed; a slurmd it did not start (here a
    process that is only called so) makes it refuse to start, and its stop does not end it, nor a process
    whose pid its pid file names but that is not that daemon (a pid reused)."""
    (tmp_path / "slurm.conf").write_text("ClusterName=site\n")
    (tmp_path / "state").mkdir()
    refused = single_node(tmp_path, "start")
    assert refused.returncode == 1 and "is not this script's" in refused.stderr
    assert single_node(tmp_path, "stop").returncode == 0
    assert (tmp_path / "slurm.conf").read_text() == "ClusterName=site\n"
    (tmp_path / "slurm.conf").unlink()

    fake = tmp_path / "slurmd"
    shutil.copy(shutil.which("sleep"), fake)
    daemon = subprocess.Popen([str(fake), "600"])
    other = subprocess.Popen(["sleep", "600"])
    try:
        (tmp_path / "state" / "slurmctld.pid").write_text(f"{other.pid}\n")
        refused = single_node(tmp_path, "start")
        assert refused.returncode == 1 and "daemons this script did not start run" in refused.stderr
        assert re.search(rf"slurmd \(pid ([0-9]+ )*{daemon.pid}[ )]", refused.stderr), refused.stderr
        assert single_node(tmp_path, "stop").returncode == 0
        assert daemon.poll() is None and other.poll() is None
    finally:
        daemon.kill()
        other.kill()
