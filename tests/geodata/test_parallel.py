import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

from geodata.mesh import MeshError
from geodata.parallel import current_stage, in_shard, parse_shard, run_isolated


def _gdist_on_non_manifold_edge():
    import gdist

    current_stage("geodesic")
    v = np.array([[0, 0, 0], [0, 0, 1], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]], float)
    f = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4], [1, 0, 5]], np.int32)
    return gdist.compute_gdist(v, f, np.array([2], np.int32))


def _segfault():
    current_stage("watertight")
    os.kill(os.getpid(), signal.SIGSEGV)


def _raise_mesh_error():
    raise MeshError("remesh", "too thin")


def _raise_bug():
    current_stage("simplify")
    return {}["missing"]


def _sleep():
    current_stage("geodesic")
    time.sleep(30)


def test_result_comes_back_intact():
    big = np.arange(3_000_000, dtype=np.float32)  # larger than a pipe buffer
    out = run_isolated(lambda a: (a * 2, "x"), big)
    assert np.array_equal(out[0], big * 2) and out[1] == "x"


def test_native_crash_becomes_a_failure_of_its_stage():
    with pytest.raises(MeshError) as info:
        run_isolated(_segfault)
    assert info.value.stage == "watertight" and "SIGSEGV" in info.value.reason


def test_exact_geodesic_library_crash_on_non_manifold_edge_is_contained():
    try:
        result = run_isolated(_gdist_on_non_manifold_edge)
    except MeshError as exc:
        assert exc.stage == "geodesic" and "native crash" in exc.reason
    else:  # if the library ever stops crashing, the answer must still be sane
        assert np.isfinite(result).all()


def test_errors_keep_their_stage_and_bugs_become_one_line():
    with pytest.raises(MeshError, match="remesh: too thin"):
        run_isolated(_raise_mesh_error)
    with pytest.raises(MeshError) as info:
        run_isolated(_raise_bug)
    assert info.value.stage == "unknown" and info.value.reason == "KeyError: 'missing'"


def test_timeout_kills_the_child():
    with pytest.raises(MeshError) as info:
        run_isolated(_sleep, timeout=0.5)  # the child would sleep 30 s
    assert info.value.stage == "geodesic" and info.value.reason == "timed out after 0.5 s"


def test_shards_partition_the_work():
    keys = [f"dir/mesh{i}.obj" for i in range(200)]
    owners = [[k for k in keys if in_shard(k, (s, 3))] for s in range(3)]
    assert sorted(sum(owners, [])) == sorted(keys)
    assert all(len(o) > 30 for o in owners)
    assert parse_shard("2/5") == (2, 5) and parse_shard(None) == (0, 1)
    for bad in ("5/5", "1", "-1/3", "a/b"):
        with pytest.raises(ValueError):
            parse_shard(bad)


def _warn_twice():
    import warnings

    current_stage("remesh")
    for _ in range(3):
        np.float64(1.0) / np.float64(0.0)  # numpy's RuntimeWarning: divide by zero
    warnings.warn("a library's own words", UserWarning)
    return 7


def test_library_warnings_come_back_once_and_not_on_stderr(capfd):
    seen = []
    assert run_isolated(_warn_twice, warnings_out=seen) == 7
    assert seen == ["[remesh] RuntimeWarning: divide by zero encountered in scalar divide",
                    "[remesh] UserWarning: a library's own words"]
    assert "Warning" not in capfd.readouterr().err


def test_library_warnings_go_to_the_log_file_only(tmp_path, capfd):
    from geodata import cli

    cli._setup_logging(str(tmp_path / "run.log"))
    cli.library_log.info("library warning (first seen on a.obj): [remesh] RuntimeWarning: x")
    cli.log.info("ok a a.obj 1.0s")
    text = (tmp_path / "run.log").read_text()
    assert "RuntimeWarning: x" in text and "ok a a.obj" in text
    err = capfd.readouterr().err
    assert "ok a a.obj" in err and "RuntimeWarning" not in err


# -- a per-mesh memory limit -------------------------------------------------------------------------
def _data_size() -> int:
    """This process's data size (VmData: heap and private anonymous mappings), what RLIMIT_DATA counts."""
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) << 10 for line in f if line.startswith("VmData:"))


def _allocate(nbytes):
    current_stage("remesh")
    return int(np.ones(nbytes // 8).sum())  # every page written


def _abort():
    current_stage("geodesic")
    os.abort()  # how native code ends on an uncaught std::bad_alloc


def _exact_solver(vertices, faces):
    from geodata._exact_geodesic import Surface  # imported by the parent first: no allocation here

    current_stage("geodesic")
    return Surface(vertices, faces).distances(np.arange(len(vertices), dtype=np.int64)).shape


@pytest.mark.skipif(not os.path.exists("/proc/self/status"), reason="RLIMIT_DATA counts mappings on Linux only")
def test_a_mesh_over_its_memory_limit_fails_as_out_of_memory_and_the_parent_lives_on():
    import resource

    before = resource.getrlimit(resource.RLIMIT_DATA)
    limit = 128 << 20  # beyond what the fork inherits (this test session's data: numpy, libigl, ..., 0.2 GiB)
    assert _data_size() > limit  # counted, the inherited alone would be over the limit
    assert run_isolated(_allocate, 64 << 20, max_memory=limit) == 8 << 20  # under it: as without a limit
    with pytest.raises(MeshError) as info:
        run_isolated(_allocate, 1 << 30, max_memory=limit)
    assert info.value.stage == "remesh"
    assert info.value.reason == f"out of memory: over the --max-memory limit of {limit / 2 ** 30:.3g} GiB"
    # the exact solver's own std::bad_alloc (pybind11 raises MemoryError): 2,562 sources x 2,562 vertices
    # are 52 MB of distances; with 16 MiB beyond the fork's, out of memory (64 MiB: enough, measured).
    # In a fresh process: a long-lived one (a test session) holds freed heap the child may reuse uncounted.
    script = (f"import sys; sys.path.insert(0, {os.path.dirname(__file__)!r}); import numpy as np, trimesh; "
              "from test_parallel import _exact_solver, _data_size; from geodata.parallel import run_isolated; "
              "from geodata.mesh import MeshError; from geodata._exact_geodesic import Surface; "
              "s = trimesh.creation.icosphere(4); m = np.asarray(s.vertices, np.float64), np.asarray(s.faces, np.int32)\n"
              "try:\n run_isolated(_exact_solver, *m, max_memory=16 << 20); print('no error')\n"
              "except MeshError as e:\n print(e.stage, e.reason)\n"
              "print(run_isolated(_exact_solver, *m))")
    lines = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300).stdout.splitlines()
    assert lines[0].startswith("geodesic out of memory: over the --max-memory limit") and lines[1] == "(2562, 2562)"
    assert resource.getrlimit(resource.RLIMIT_DATA) == before  # the limit was the child's alone
    assert run_isolated(_allocate, 1 << 30) == 1 << 27  # and no later child inherits it


def test_a_native_abort_under_a_limit_is_reported_as_out_of_memory():
    with pytest.raises(MeshError) as info:
        run_isolated(_abort, max_memory=3 << 30)
    assert info.value.stage == "geodesic"
    assert info.value.reason == "out of memory: over the --max-memory limit of 3 GiB (native abort, SIGABRT)"
    with pytest.raises(MeshError) as info:
        run_isolated(_abort)  # no limit: a crash like any other
    assert info.value.reason == "native crash (SIGABRT) in the worker process"
    with pytest.raises(MeshError) as info:
        run_isolated(_segfault, max_memory=3 << 30)  # another signal: a crash, the limit named beside it
    assert info.value.reason == "native crash (SIGSEGV) in the worker process, under a --max-memory limit of 3 GiB"


MB = 1 << 20


@pytest.mark.parametrize("env, expected", [
    ({"SLURM_MEM_PER_CPU": "4000", "SLURM_CPUS_PER_TASK": "8", "SLURM_MEM_PER_NODE": "1"}, 32000 * MB),
    ({"SLURM_MEM_PER_CPU": "4000"}, 4000 * MB),  # one CPU per task unless told
    ({"SLURM_MEM_PER_NODE": "64000"}, 64000 * MB),
])
def test_the_default_limit_is_the_slurm_allocation_over_the_jobs(monkeypatch, env, expected):
    from geodata.parallel import default_max_memory

    for name in ("SLURM_MEM_PER_CPU", "SLURM_CPUS_PER_TASK", "SLURM_MEM_PER_NODE"):
        monkeypatch.delenv(name, raising=False)
    for name, value in env.items():
        monkeypatch.setenv(name, value)
    assert default_max_memory(4) == int(expected * 0.9) // 4
    assert default_max_memory(1, fraction=1.0) == expected


def test_without_slurm_the_default_is_the_cgroup_limit_else_the_machine(monkeypatch, tmp_path):
    import geodata.parallel as parallel

    for name in ("SLURM_MEM_PER_CPU", "SLURM_CPUS_PER_TASK", "SLURM_MEM_PER_NODE"):
        monkeypatch.delenv(name, raising=False)
    # cgroup v2: the lowest memory.max on the path; "max" is none
    (tmp_path / "v2" / "job" / "step").mkdir(parents=True)
    (tmp_path / "v2" / "job" / "memory.max").write_text(f"{6 << 30}\n")
    (tmp_path / "v2" / "job" / "step" / "memory.max").write_text("max\n")
    (tmp_path / "v2.cgroup").write_text("0::/job/step\n")
    assert parallel._cgroup_memory(str(tmp_path / "v2.cgroup"), str(tmp_path / "v2")) == 6 << 30
    # cgroup v1: the memory controller's tree; 2^63 rounded to pages is none
    (tmp_path / "v1" / "memory" / "slurm" / "job").mkdir(parents=True)
    (tmp_path / "v1" / "memory" / "slurm" / "memory.limit_in_bytes").write_text("9223372036854771712\n")
    (tmp_path / "v1" / "memory" / "slurm" / "job" / "memory.limit_in_bytes").write_text(f"{3 << 30}\n")
    (tmp_path / "v1.cgroup").write_text("5:cpu,cpuacct:/slurm/job\n4:memory:/slurm/job\n0::/\n")
    assert parallel._cgroup_memory(str(tmp_path / "v1.cgroup"), str(tmp_path / "v1")) == 3 << 30
    (tmp_path / "v1" / "memory" / "slurm" / "job" / "memory.limit_in_bytes").write_text("9223372036854771712\n")
    assert parallel._cgroup_memory(str(tmp_path / "v1.cgroup"), str(tmp_path / "v1")) is None

    monkeypatch.setattr(parallel, "_cgroup_memory", lambda: 6 << 30)
    assert parallel.default_max_memory(3) == int((6 << 30) * 0.9) // 3
    monkeypatch.setattr(parallel, "_cgroup_memory", lambda: None)
    physical = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    assert parallel.default_max_memory(2) == int(physical * 0.9) // 2


def test_memory_sizes_read_as_a_user_writes_them():
    from geodata.parallel import parse_memory

    assert parse_memory("4G") == parse_memory("4GiB") == parse_memory("4gb") == 4 << 30
    assert parse_memory("512M") == 512 << 20 and parse_memory("1.5G") == 3 << 29
    assert parse_memory("123456") == 123456
    assert parse_memory(None) is None and parse_memory("none") is None and parse_memory("0") is None
    for bad in ("4X", "lots", "-1G"):
        with pytest.raises(ValueError):
            parse_memory(bad)


def test_without_fork_and_resource_as_on_windows_both_programs_import_and_a_mesh_is_solved():
    """Windows has neither the ``resource`` module nor ``os.fork``: both command lines import, a task runs in
    the caller (no isolation, as README says), and the exact solver's memory check finds no limit to apply."""
    script = textwrap.dedent("""
        import os, sys
        sys.modules["resource"] = None  # import resource raises ImportError, as on Windows
        del os.fork
        from geodata.cli import main as geodata_main
        from gegnn.cli import main as gegnn_main
        import numpy as np, trimesh
        from geodata.exact_memory import available_memory
        from geodata.geodesic import geodesic_solver
        from geodata.mesh import Mesh
        from geodata.parallel import run_isolated
        assert available_memory() > 0
        sphere = trimesh.creation.icosphere(2)
        mesh = Mesh(np.asarray(sphere.vertices), np.asarray(sphere.faces))
        d = run_isolated(lambda: geodesic_solver(mesh)(0), max_memory=1 << 30)
        assert d.shape == (len(mesh.vertices),) and d[0] == 0 and 3.0 < d.max() < 3.2
        print("ok")
    """)
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr[-2000:]
