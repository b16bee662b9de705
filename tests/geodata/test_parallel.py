import os
import signal
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
