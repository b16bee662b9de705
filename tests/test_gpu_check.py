"""scripts/gpu_check.py cannot report PASS over a failed step: its runner and its CUDA-against-CPU comparison,
with steps broken on purpose."""
import importlib.util
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
spec = importlib.util.spec_from_file_location("gpu_check", ROOT / "scripts" / "gpu_check.py")
gpu_check = sys.modules["gpu_check"] = importlib.util.module_from_spec(spec)  # dataclasses look it up there
spec.loader.exec_module(gpu_check)
Step = gpu_check.Step


def _eval_csv(path, rows):
    path.write_text("mesh_id,vertices,pairs,mre\n" + "".join(f"{m},100,1000,{mre}\n" for m, mre in rows))
    return path


def test_a_failing_step_fails_the_check_and_the_others_still_run(tmp_path):
    """A step that exits non-zero, one that raises and one that crashes mid-way each FAIL, the steps after
    them still run (the report is complete), and the verdict names exactly the failed ones."""
    py = sys.executable

    def raises(log):
        raise AssertionError("CUDA and CPU differ")

    steps = [Step("good", [py, "-c", "print('fine')"]),
             Step("exits", [py, "-c", "import sys; print('partial'); sys.exit(3)"]),
             Step("raises", [], raises),
             Step("crashes", [py, "-c", "import os; os.abort()"]),
             Step("after", [py, "-c", "print('still ran')"])]
    results = gpu_check.run_steps(steps, tmp_path)
    assert [(name, ok) for name, ok, _ in results] == [("good", True), ("exits", False), ("raises", False),
                                                       ("crashes", False), ("after", True)]
    assert gpu_check.verdict(results) == "GPU check: FAIL (3 of 5 steps: exits, raises, crashes)"
    assert "still ran" in (tmp_path / "after.log").read_text()
    assert "CUDA and CPU differ" in (tmp_path / "raises.log").read_text()
    ok = gpu_check.run_steps([steps[0], steps[-1]], tmp_path)
    assert gpu_check.verdict(ok) == "GPU check: PASS (all 2 steps)"


def test_a_failed_required_step_ends_the_check_with_its_reason(tmp_path):
    """A required step (the environment) that fails stops the check: the steps after it do not run, are
    reported as not run, and the verdict says which step failed and why."""
    py = sys.executable
    steps = [Step("good", [py, "-c", "print('fine')"]),
             Step("gate", [py, "-c", "import sys; print('no CUDA device: nothing to check'); sys.exit(1)"],
                  required=True),
             Step("later", [py, "-c", f"open({str(tmp_path / 'ran')!r}, 'w')"]),
             Step("last", [py, "-c", f"open({str(tmp_path / 'ran')!r}, 'w')"])]
    results = gpu_check.run_steps(steps, tmp_path)
    assert [(name, ok) for name, ok, _ in results] == [("good", True), ("gate", False), ("later", None),
                                                       ("last", None)]
    assert not (tmp_path / "later.log").exists() and not (tmp_path / "ran").exists()
    assert gpu_check.verdict(results, tmp_path) == ("GPU check: FAIL (gate failed: no CUDA device: nothing to "
                                                    "check; 2 later steps not run: later, last)")
    passing = gpu_check.run_steps([steps[0], Step("gate", [py, "-c", "pass"], required=True), steps[0]], tmp_path)
    assert [ok for _, ok, _ in passing] == [True, True, True]


def test_eval_comparison_holds_cuda_to_the_cpu(tmp_path):
    cpu = _eval_csv(tmp_path / "cpu.csv", [("a", 0.0100), ("b", 0.0200), ("overall", 0.0150)])
    near = _eval_csv(tmp_path / "near.csv", [("a", 0.010001), ("b", 0.0200), ("overall", 0.015)])
    lines = gpu_check.compare_evals(near, cpu)
    assert len(lines) == 3 and "1.0e-04" in lines[0]
    far = _eval_csv(tmp_path / "far.csv", [("a", 0.0100), ("b", 0.0201), ("overall", 0.0150)])  # 5e-3 apart
    with pytest.raises(AssertionError, match="on b"):
        gpu_check.compare_evals(far, cpu)
    missing = _eval_csv(tmp_path / "missing.csv", [("a", 0.0100), ("overall", 0.0150)])
    with pytest.raises(AssertionError, match="other meshes"):
        gpu_check.compare_evals(missing, cpu)
    nan = _eval_csv(tmp_path / "nan.csv", [("a", "nan"), ("b", 0.0200), ("overall", 0.0150)])
    with pytest.raises(AssertionError, match="on a"):
        gpu_check.compare_evals(nan, cpu)


def test_the_check_without_cuda_fails_at_once(tmp_path):
    """The environment step itself fails on a machine without CUDA (this one, in CI), and so the check."""
    import torch

    if torch.cuda.is_available():
        pytest.skip("a CUDA device is here")
    results = gpu_check.run_steps([Step("environment", [], gpu_check.check_environment)], tmp_path)
    assert not results[0][1] and "no CUDA device" in (tmp_path / "environment.log").read_text()


def test_the_whole_check_without_cuda_stops_after_the_environment(tmp_path, capsys):
    """scripts/gpu_check.py on a machine without CUDA runs no test, benchmark or training: its verdict, on the
    last line and in the report, names the environment step and the reason."""
    import torch

    if torch.cuda.is_available():
        pytest.skip("a CUDA device is here")
    assert gpu_check.main([str(tmp_path / "check")]) == 1
    last = capsys.readouterr().out.strip().splitlines()[-1]
    assert last.startswith("GPU check: FAIL (environment failed: FAILED: RuntimeError: no CUDA device")
    assert "8 later steps not run: tests, bench-gpu, data," in last
    assert sorted(p.name for p in (tmp_path / "check").iterdir()) == ["REPORT.md", "environment.log"]
    report = (tmp_path / "check" / "REPORT.md").read_text()
    assert "| tests | not run |" in report and f"**{last}**" in report


def test_the_tests_step_runs_in_xdist_workers_only_where_there_are_cores_and_xdist():
    """The tests step (the check's long pole: 392 s of 663 on an H100, one test at a time) runs in one
    pytest-xdist worker per 4 cores, at most 4; one after another without xdist or on a small machine."""
    assert gpu_check.pytest_workers(16, True) == ["-n", "4"]
    assert gpu_check.pytest_workers(64, True) == ["-n", "4"]
    assert gpu_check.pytest_workers(8, True) == ["-n", "2"]
    assert gpu_check.pytest_workers(4, True) == [] and gpu_check.pytest_workers(2, True) == []
    assert gpu_check.pytest_workers(16, False) == []
    tests = next(s for s in gpu_check.make_steps(Path("out"), None, ["gegnn"]) if s.name == "tests")
    assert tests.argv[:3] == [sys.executable, "-m", "pytest"] and "tests/gegnn/test_train.py" in tests.argv


def test_the_environment_step_imports_every_compiled_module_cmake_builds():
    """The environment step imports each module CMakeLists.txt builds (eight: the virtual source solver's too)."""
    import re

    built = re.findall(r"^geogegnn_module\((\w+) \S+ (\w+)", (ROOT / "CMakeLists.txt").read_text(), re.M)
    assert sorted(gpu_check.COMPILED) == sorted(f"{package}.{name}" for name, package in built)
    assert len(built) == 8


def test_the_report_is_written_on_a_machine_without_git_or_nvidia_smi(tmp_path, monkeypatch):
    """A GPU node may run the check from an unpacked snapshot with no git (nor nvidia-smi) on its PATH: the
    report is still written, its commit '?', after all the steps have run."""
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))
    gpu_check.write_report(tmp_path, [("environment", True, 1.0)], tmp_path / "REPORT.md")
    report = (tmp_path / "REPORT.md").read_text()
    assert "commit ?." in report and "| environment | PASS | 1 s |" in report
    assert "**GPU check: PASS (all 1 steps)**" in report
