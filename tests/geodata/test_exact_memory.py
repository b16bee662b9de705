"""The exact solver refuses, before allocating, a solve whose memory estimate exceeds what is available."""
import numpy as np
import pytest

from geodata import exact_memory
from geodata.exact_memory import available_memory, exact_memory_estimate
from geodata.geodesic import geodesic_solver
from geodata.mesh import Mesh, MeshError
from geodata.parallel import run_isolated


def sphere(subdivisions=3):
    import trimesh

    m = trimesh.creation.icosphere(subdivisions)
    return Mesh(np.asarray(m.vertices), np.asarray(m.faces))


def vm_data() -> int:
    line = next(line for line in open("/proc/self/status") if line.startswith("VmData:"))
    return int(line.split()[1]) * 1024


def test_a_solve_over_the_available_memory_is_refused_before_the_solver_is_built(monkeypatch):
    import geodata._exact_geodesic as native

    mesh = sphere()
    need = exact_memory_estimate(mesh.n_vertices)
    monkeypatch.setattr(exact_memory, "available_memory", lambda: need - 1)
    monkeypatch.setattr(native, "Surface", lambda *a: pytest.fail("the solver was built"))
    with pytest.raises(MeshError) as err:
        geodesic_solver(mesh)
    assert err.value.stage == "geodesic"
    assert f"~{need / 2 ** 30:.1f} GiB for one source on {mesh.n_vertices} vertices" in err.value.reason
    assert f"{(need - 1) / 2 ** 30:.1f} GiB available" in err.value.reason
    assert "\n" not in str(err.value)


def test_a_solve_within_the_available_memory_runs(monkeypatch):
    mesh = sphere()
    monkeypatch.setattr(exact_memory, "available_memory", lambda: exact_memory_estimate(mesh.n_vertices))
    d = geodesic_solver(mesh)(0)
    assert np.isfinite(d).all() and d[0] == 0 and d.max() > 2.5  # half a great circle of the unit sphere: pi


def test_the_estimate_grows_linearly_with_the_mesh():
    """Only the wavefront is kept (issue 58): linear, as measured, and a million vertices fit in 3 GiB."""
    sizes = [1_000, 10_000, 100_000, 1_000_000]
    estimates = [exact_memory_estimate(n) for n in sizes]
    assert all(a < b <= 10 * a for a, b in zip(estimates, estimates[1:]))
    assert 8 * estimates[-2] < estimates[-1] < 3 << 30  # 10x the vertices, ~10x the bytes (a fixed 8 MiB aside)


def test_available_memory_is_the_rlimit_data_left_under_a_max_memory_limit():
    """Under run_isolated's --max-memory (RLIMIT_DATA in a forked child) the probe reads the limit less the
    child's data segment; outside it, at most the machine's MemAvailable."""
    headroom = 256 << 20
    left = run_isolated(available_memory, max_memory=headroom)
    assert headroom // 2 < left <= headroom + (64 << 20)
    meminfo = next(line for line in open("/proc/meminfo") if line.startswith("MemAvailable:"))
    assert 0 < available_memory() <= int(meminfo.split()[1]) * 1024 * 1.1


def test_under_a_small_max_memory_the_child_refuses_with_the_estimate_instead_of_dying():
    mesh = sphere(6)  # 40,962 vertices: ~29 MiB estimated
    with pytest.raises(MeshError, match=r"geodesic: the exact solver would need ~.* GiB available"):
        run_isolated(lambda: geodesic_solver(mesh)(0), max_memory=8 << 20)


def test_threads_are_as_many_as_the_memory_left_holds(monkeypatch):
    """Each thread beyond the first needs its own wavefront (THREAD_SCALE bytes a vertex, with the margin): the
    threads granted are those that fit beside one solve, at least 1, never more than asked for."""
    from geodata.exact_memory import MEMORY_MARGIN, THREAD_SCALE, require_memory

    n = 100_000
    need, per_thread = exact_memory_estimate(n), MEMORY_MARGIN * THREAD_SCALE * n
    for room, asked, granted in [(0, 8, 1), (per_thread - 1, 8, 1), (per_thread, 8, 2), (3.5 * per_thread, 8, 4),
                                 (100 * per_thread, 8, 8), (100 * per_thread, 1, 1)]:
        monkeypatch.setattr(exact_memory, "available_memory", lambda room=room: need + int(room))
        assert require_memory(n, asked) == granted, (room, asked)
