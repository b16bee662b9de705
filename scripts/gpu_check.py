"""The GPU check: on a machine with CUDA, in about 9 minutes (an H200,
2026-11-27), everything this project claims of GPUs.

    scripts/gpu_check.sh [OUT] [--store STORE]     (OUT default gpu-check/; the report is OUT/REPORT.md)

Run from the repository root with the package and its test extra installed (``pip install -e ".[test]"``
over a CUDA build of torch). Steps, each a process of its own whose exit status decides PASS or FAIL
(no shell pipelines, so no failure is swallowed):

  environment   CUDA is there, the compiled kernels and pytest import; versions
  tests         the CUDA tests (no host sync in a training step, CUDA embedding and queries equal the CPU's
                at one precision), the GPU-path guards, and the trainer's tests, which train on the GPU there;
                in pytest-xdist workers where it is installed (4 on 16 cores: pytest_workers)
  bench-gpu     embed and 1M queries against the paper's RTX 3090 figures, fp32 against bf16, CUDA against
                the CPU, a training step with and without --deterministic (benchmarks/bench_gpu.py)
  data          the toolkit's sample meshes prepared (or --store, a store prepared elsewhere)
  train-paper, train-landmark
                150 steps of the paper model and of the landmark model (a decoder warm-up too), with
                loader workers, on the GPU
  eval          both models evaluated by `gegnn eval` on the GPU and on the CPU (fp32): every mesh's MRE
                must agree within EVAL_RTOL (relative) and every run must end well
  ddp           a two-rank torchrun of the landmark model (field cache filled by both ranks): gloo with the
                two ranks on one GPU, NCCL where there are two GPUs or more; both ranks must train
  throughput    the loader against the measured GPU step (benchmarks/bench_train_throughput.py)

Every step's output is kept in OUT/<step>.log; OUT/REPORT.md has a line per step and the verdict, which
is also the last line printed. The exit status is 0 only if every step passed. A failed environment step
ends the check there (no CUDA: every later result would be void), its reason in the verdict.
"""
from __future__ import annotations

import argparse
import csv
import datetime
import importlib.util
import os
import platform
import re
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

EVAL_RTOL = 2e-3  # GPU and CPU fp32 MRE of a mesh: sums in another order, nothing more
TRAIN = ["--batch-size", "1", "--pairs-per-mesh", "20000", "--lr", "1e-3", "--device", "cuda"]
COMPILED = ("geodata._exact_geodesic", "geodata._virtual_source_geodesic", "gegnn._pair_features", "gegnn._geoconv",
            "gegnn._heat_ops", "gegnn._farthest_points", "gegnn._cloud_ops", "gegnn._local_triangulation")
CORES_PER_TEST_WORKER = 4  # a trainer test runs loader processes of its own


def pytest_workers(cores: int, xdist: bool) -> list[str]:
    """pytest-xdist's arguments for the tests step: one worker per CORES_PER_TEST_WORKER cores, at most 4,
    where pytest-xdist is installed and that makes two or more (the tests run one after another otherwise)."""
    n = min(4, cores // CORES_PER_TEST_WORKER)
    return ["-n", str(n)] if xdist and n >= 2 else []


@dataclass
class Step:
    name: str
    argv: list[str]  # a command, or [] with ``call`` set
    call: object = None  # a Python function of the log file's handle: raises on failure
    required: bool = False  # the later steps mean nothing without it: its failure ends the check


def run_steps(steps: list[Step], out: Path) -> list[tuple[str, bool | None, float]]:
    """Run the steps, logging each to OUT/<name>.log: a failed step does not stop the others unless it is
    required, after which the rest are not run (their result None)."""
    results = []
    for i, step in enumerate(steps):
        print(f"== {step.name}: {' '.join(step.argv) or step.call.__name__}", flush=True)
        t0 = time.perf_counter()
        with open(out / f"{step.name}.log", "w") as log:
            try:
                if step.call is not None:
                    step.call(log)
                    ok = True
                else:
                    ok = subprocess.run(step.argv, stdout=log, stderr=subprocess.STDOUT).returncode == 0
            except Exception as e:  # noqa: BLE001 - a step's failure of any kind is its FAIL
                print(f"FAILED: {type(e).__name__}: {e}", file=log)
                ok = False
        results.append((step.name, ok, time.perf_counter() - t0))
        print(f"   {'PASS' if ok else 'FAIL'} ({time.perf_counter() - t0:.0f} s)", flush=True)
        if step.required and not ok:
            results += [(later.name, None, 0.0) for later in steps[i + 1:]]
            print(f"   {step.name} failed: the other steps are not run", flush=True)
            break
    return results


def failure_reason(out: Path, name: str) -> str:
    """The last line of a failed step's log: its error."""
    p = out / f"{name}.log"
    lines = [line.strip() for line in p.read_text().splitlines() if line.strip()] if p.exists() else []
    return lines[-1] if lines else "no output"


def verdict(results, out: Path | None = None) -> str:
    skipped = [name for name, ok, _ in results if ok is None]
    failed = [name for name, ok, _ in results if ok is False]
    if skipped:
        reason = f": {failure_reason(out, failed[-1])}" if out is not None else ""
        return (f"GPU check: FAIL ({failed[-1]} failed{reason}; {len(skipped)} later steps not run: "
                f"{', '.join(skipped)})")
    if failed:
        return f"GPU check: FAIL ({len(failed)} of {len(results)} steps: {', '.join(failed)})"
    return f"GPU check: PASS (all {len(results)} steps)"


def read_eval(path: Path) -> dict[str, float]:
    with open(path, newline="") as f:
        return {r["mesh_id"]: float(r["mre"]) for r in csv.DictReader(f)}


def compare_evals(gpu_csv: Path, cpu_csv: Path, rtol: float = EVAL_RTOL) -> list[str]:
    """Lines comparing two `gegnn eval --csv` tables; raises if a mesh is missing from one or differs by
    more than ``rtol`` (relative to the CPU's MRE)."""
    gpu, cpu = read_eval(gpu_csv), read_eval(cpu_csv)
    if not cpu or set(gpu) != set(cpu):
        raise AssertionError(f"{gpu_csv.name} and {cpu_csv.name} hold other meshes: {sorted(gpu)} vs {sorted(cpu)}")
    lines, bad = [], []
    for mesh in cpu:
        diff = abs(gpu[mesh] - cpu[mesh]) / max(cpu[mesh], 1e-12)
        lines.append(f"{mesh}: MRE {100 * gpu[mesh]:.4f}% (cuda) {100 * cpu[mesh]:.4f}% (cpu), relative difference "
                     f"{diff:.1e}")
        if not diff <= rtol:
            bad.append(mesh)
    if bad:
        raise AssertionError(f"CUDA and CPU differ by more than {rtol:.0e} (relative) on {', '.join(bad)}:\n"
                             + "\n".join(lines))
    return lines


def check_environment(log) -> None:
    import torch

    import pytest

    for name in COMPILED:
        importlib.import_module(name)  # the compiled kernels: pip install built them

    if not torch.cuda.is_available():
        raise RuntimeError("no CUDA device: nothing to check")
    print(f"torch {torch.__version__}, CUDA {torch.version.cuda}, pytest {pytest.__version__}, python "
          f"{platform.python_version()}", file=log)
    for i in range(torch.cuda.device_count()):
        p = torch.cuda.get_device_properties(i)
        print(f"GPU {i}: {p.name}, {p.total_memory / 2**30:.0f} GiB, {p.multi_processor_count} SMs", file=log)
    # what a command pays before its first step
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-c", "import gegnn.cli, gegnn.training.loop"], check=True)
    t1 = time.perf_counter()
    subprocess.run([sys.executable, "-c", "import torch; torch.zeros(1, device='cuda'); torch.cuda.synchronize()"],
                   check=True)
    t2 = time.perf_counter()
    subprocess.run([sys.executable, "-c", "from gegnn import GeGnn; GeGnn().to('cuda')"], check=True)
    print(f"start-up: import gegnn.cli {t1 - t0:.1f} s, CUDA context {t2 - t1:.1f} s, GeGnn() on CUDA "
          f"{time.perf_counter() - t2:.1f} s (each a process of its own)", file=log)


def make_steps(out: Path, store: Path | None, gegnn: list[str]) -> list[Step]:
    py = sys.executable
    given = store is not None
    store = store or out / "store"

    def data(log):
        if not given:
            for argv in ([*geodata, "examples", str(out / "raw")],
                         [*geodata, "prepare", str(out / "raw"), str(store), "--pairs", "20000", "--jobs",
                          str(len(os.sched_getaffinity(0)))]):
                subprocess.run(argv, stdout=log, stderr=subprocess.STDOUT, check=True)
        subprocess.run([*geodata, "info", str(store)], stdout=log, stderr=subprocess.STDOUT, check=True)

    def evaluate(log):
        for model in ("paper", "landmark"):
            for device in ("cuda", "cpu"):
                subprocess.run([*gegnn, "eval", str(out / model / "best.safetensors"), str(store), "--device", device,
                                "--csv", str(out / f"eval-{model}-{device}.csv")], stdout=log,
                               stderr=subprocess.STDOUT, check=True)
            print(f"## {model}", file=log)
            print("\n".join(compare_evals(out / f"eval-{model}-cuda.csv", out / f"eval-{model}-cpu.csv")), file=log)

    def ddp(log):
        ranks = 2
        subprocess.run([py, "-m", "torch.distributed.run", "--standalone", "--nproc-per-node", str(ranks),
                        "-m", "gegnn.cli", "train", str(store), "--run-dir", str(out / "ddp"), "--channels", "32",
                        "--landmarks", "16", "--epochs", "3", *TRAIN], stdout=log, stderr=subprocess.STDOUT,
                       check=True)
        text = (out / "ddp" / "train.log").read_text()
        if f"{ranks} process(es)" not in text or "epoch 2 " not in text:
            raise AssertionError(f"the run's log does not show {ranks} processes training 3 epochs")

    geodata = [py, "-m", "geodata.cli"]
    return [
        Step("environment", [], check_environment, required=True),
        Step("tests", [py, "-m", "pytest", "-q", "-p", "no:cacheprovider", "tests/gegnn/test_gpu_path.py",
                       "tests/gegnn/test_train.py", "--durations", "10",
                       *pytest_workers(len(os.sched_getaffinity(0)), importlib.util.find_spec("xdist") is not None)]),
        Step("bench-gpu", [py, "benchmarks/bench_gpu.py"]),
        Step("data", [], data),
        Step("train-paper", [*gegnn, "train", str(store), "--run", str(out / "paper"), "--channels", "64",
                             "--epochs", "30", *TRAIN]),
        Step("train-landmark", [*gegnn, "train", str(store), "--run", str(out / "landmark"), "--init",
                                str(out / "paper" / "best.safetensors"), "--landmarks", "128", "--decoder-warmup",
                                "300", "--epochs", "30", *TRAIN]),
        Step("eval", [], evaluate),
        Step("ddp", [], ddp),
        Step("throughput", [py, "benchmarks/bench_train_throughput.py", "--steps", "5"]),
    ]


def write_report(out: Path, results, path: Path) -> None:
    def log(name):
        p = out / f"{name}.log"
        return p.read_text() if p.exists() else "(no log)"

    def grep(path, *keys):
        p = Path(path)
        return "\n".join(line for line in p.read_text().splitlines() if any(k in line for k in keys)) \
            if p.exists() else "(no log)"

    gpu = subprocess.run(["nvidia-smi", "--query-gpu=name,memory.total,driver_version", "--format=csv,noheader"],
                         capture_output=True, text=True).stdout.strip() if shutil.which("nvidia-smi") else ""
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,  # '' outside a clone
                            text=True).stdout.strip() if shutil.which("git") else ""  # a node without git
    cpu = next((line.split(":", 1)[1].strip() for line in open("/proc/cpuinfo") if line.startswith("model name")), "?")
    lines = ["# GPU check", "",
             f"`scripts/gpu_check.sh` on {datetime.date.today()}, commit {commit or '?'}.", "",
             f"GPU: {gpu or '?'}  ", f"CPU: {cpu}, {len(os.sched_getaffinity(0))} cores", "",
             "| step | result | time |", "|---|---|---:|"]
    lines += [f"| {name} | {'not run' if ok is None else 'PASS' if ok else '**FAIL**'} | {seconds:.0f} s |"
              for name, ok, seconds in results]
    def summary(text):  # pytest's counts and its slowest tests, without the progress dots and warnings
        keep = [line for line in text.splitlines()
                if re.match(r"^[\d.]+s call ", line) or re.search(r"\d+ (passed|failed)", line)]
        return "\n".join(keep) or "(no summary)"

    def plain(text):  # without progress bars
        return "\n".join(line for line in text.splitlines() if "it/s" not in line and "%|" not in line and line.strip())

    lines += ["", f"**{verdict(results, out)}**", "", "## Environment", "```", log("environment").strip(), "```", "",
              "## Tests", "```", summary(log("tests")), "```", "",
              log("bench-gpu").strip(), "", "## Training (sample meshes)"]
    for run in ("paper", "landmark"):
        lines += ["", f"### {run}", "```",
                  grep(out / run / "train.log", "warm-up", "loader worker", "fields:", "epoch 0 ", "epoch 29 "), "```"]
    lines += ["", f"## Evaluation, CUDA against CPU (fp32; tolerance {EVAL_RTOL:.0e} relative)", "```",
              "\n".join(line for line in log("eval").splitlines() if line.startswith("##") or "relative difference" in line
                        or "FAILED" in line), "```", "", "## Two-rank DDP", "```",
              grep(out / "ddp" / "train.log", "process", "fields:", "epoch 2 "), "```", "",
              "## Loader throughput", "```", plain(log("throughput")), "```"]
    path.write_text("\n".join(lines) + "\n")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("out", nargs="?", default="gpu-check", type=Path)
    ap.add_argument("--store", type=Path, help="A prepared store to train on (skips preparing the sample meshes).")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    results = run_steps(make_steps(args.out, args.store, [sys.executable, "-m", "gegnn.cli"]), args.out)
    write_report(args.out, results, args.out / "REPORT.md")
    print(f"report: {args.out / 'REPORT.md'}")
    print(verdict(results, args.out))
    return 0 if all(ok for _, ok, _ in results) else 1


if __name__ == "__main__":
    sys.exit(main())
