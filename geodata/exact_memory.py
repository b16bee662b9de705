"""What the exact solver (``vtp``, ``src/exact_geodesic.cpp``) needs in memory, and what this process may still
allocate: a solve that would not fit is refused before anything is allocated (:func:`require_memory`, which the
``vtp`` backend of :func:`geodata.geodesic.geodesic_solver` calls)."""
from __future__ import annotations

from geodata.mesh import MeshError

__all__ = ["exact_memory_estimate", "available_memory", "require_memory", "MEMORY_BASE", "MEMORY_SCALE",
           "MEMORY_POWER", "MEMORY_MARGIN", "THREAD_SCALE"]

# The vtp solver keeps the mesh's half-edge tables (~430 bytes a vertex) and only the wavefront of a source
# (the windows waiting to cross a face, in chunks that the next ones reuse: ~50 MiB at 1M vertices).
# The peak resident memory of building the solver and one solve, over what the process held before,
# 5k-1M vertices, regular and irregular meshes, grew linearly: 9 MiB at 10k, 162 MiB at 320k, 458 MiB at
# 1M, within 1% of MEMORY_BASE + MEMORY_SCALE N^MEMORY_POWER bytes or under it (benchmarks/
# bench_exact_scaling.py, docs/benchmarks.md); MEMORY_MARGIN over it for meshes whose wavefront is
# longer. (Keeping every window instead costs ~40 N^1.5 bytes, 47 GiB at 1M.)
MEMORY_BASE, MEMORY_SCALE, MEMORY_POWER, MEMORY_MARGIN = 8 << 20, 500.0, 1.0, 1.25
# Each further thread keeps its own wavefront and distances: 200-205 bytes a vertex more each (peak resident
# memory of 1, 2 and 4 sources at once on an icosphere of 164k vertices, the output rows aside).
THREAD_SCALE = 210.0


def exact_memory_estimate(n_vertices: int) -> int:
    """Bytes the vtp solver is expected to allocate for one source on a mesh of ``n_vertices`` (with
    MEMORY_MARGIN over the measured fit; meshes of other shapes and qualities vary around it)."""
    return int(MEMORY_MARGIN * (MEMORY_BASE + MEMORY_SCALE * float(n_vertices) ** MEMORY_POWER))


def available_memory() -> int:
    """Bytes this process may still allocate: its RLIMIT_DATA less its data segment (``run_isolated``
    under --max-memory sets it) where set; else the least of the cgroup's memory limit and the
    machine's MemAvailable (on Windows, without rlimits or /proc: no limit known)."""
    from geodata.parallel import _cgroup_memory, _status_kib

    try:
        import resource
    except ImportError:  # Windows
        resource = None
    soft = resource.getrlimit(resource.RLIMIT_DATA)[0] if resource else None
    if resource and soft != resource.RLIM_INFINITY:
        return max(0, soft - _status_kib("VmData:", "/proc/self/status") * 1024)
    limits = [m for m in (_cgroup_memory(), _status_kib("MemAvailable:", "/proc/meminfo") * 1024) if m]
    return min(limits) if limits else 1 << 62


def require_memory(n_vertices: int, threads: int = 1) -> int:
    """MeshError("geodesic", ...) before a solve whose estimate exceeds the memory available; else how many of
    ``threads`` may solve at once, each with its own wavefront (THREAD_SCALE bytes a vertex, MEMORY_MARGIN over
    it), in what is left (at least 1)."""
    need, have = exact_memory_estimate(n_vertices), available_memory()
    if need > have:
        raise MeshError("geodesic", f"the exact solver would need ~{need / 2 ** 30:.1f} GiB for one source on "
                                    f"{n_vertices} vertices; {have / 2 ** 30:.1f} GiB available")
    per_thread = MEMORY_MARGIN * THREAD_SCALE * max(n_vertices, 1)
    return int(max(1, min(threads, 1 + (have - need) // per_thread)))
