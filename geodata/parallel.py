"""Running per-mesh work: each mesh in its own forked process, meshes spread by joblib.

Native mesh code (Kirsanov's exact geodesics, pymeshlab) can segfault or leak; a dead joblib worker
fails the whole `Parallel` call (joblib#812). So the joblib worker only supervises: it forks a child
per mesh, and a child that dies or hangs becomes that mesh's failure, never the batch's.

A child may also be given a memory limit (`max_memory`): a mesh that would need more fails as "out of
memory" instead of growing until the kernel's OOM killer ends it, which a scheduler counts against the
whole job (SLURM marks the array task OUT_OF_MEMORY, and every `afterok` dependency fails with it).
"""
from __future__ import annotations

import contextlib
import faulthandler
import hashlib
import io
import os
import pickle
import select
import signal
import sys
import time
import warnings
from typing import Any, Callable, Iterable, Iterator

from geodata.mesh import MeshError, one_line

__all__ = ["BACKENDS", "run_isolated", "parallel_map", "parse_shard", "in_shard", "default_max_memory",
           "parse_memory", "MEMORY_FRACTION"]

BACKENDS = ("loky", "dask", "ray")
MEMORY_FRACTION = 0.9  # of a task's memory, shared by its per-mesh processes; the rest for their supervisors
GiB = 1 << 30


def run_isolated(fn: Callable[..., Any], *args, timeout: float | None = None,
                 warnings_out: list[str] | None = None, max_memory: int | None = None) -> Any:
    """fn(*args) in a forked child; MeshError when it raises one, dies, or exceeds `timeout` seconds.

    The child reports the stage it enters through `stage(name)` (see `current_stage`), so a crash is
    blamed on the right stage. Python warnings raised in the child (libraries' RuntimeWarnings...)
    never reach the console: each distinct one is appended to `warnings_out` as "[stage] Category:
    message", for the caller to log.

    `max_memory` (bytes, None: no limit) caps what the child allocates: its heap and private anonymous
    mappings (RLIMIT_DATA, Linux >= 4.7) beyond those it inherited from this process (0.2-0.5 GiB measured
    with geodata's libraries and torch loaded, shared with this process until written, not counted: the
    limit is the child's data size at the fork plus `max_memory`). An allocation beyond it fails in the child and
    the mesh fails with MeshError(stage, "out of memory: over the --max-memory limit of X GiB"): NumPy's
    MemoryError, the exact solver's std::bad_alloc (pybind11 raises MemoryError) and pymeshlab's (a
    PyMeshLabException naming std::bad_alloc) all do, measured; a native abort under a limit (an
    uncaught std::bad_alloc ends in SIGABRT) is reported so too. RLIMIT_AS, the address space, is not
    used: torch's import alone reserves 1.0 GiB of it, none of it memory.
    """
    if not hasattr(os, "fork"):  # no process isolation on this platform
        return fn(*args)
    read_fd, write_fd = os.pipe()
    pid = os.fork()
    if pid == 0:  # child
        os.close(read_fd)
        _child(fn, args, write_fd, max_memory)
    os.close(write_fd)
    data, timed_out = _read_all(read_fd, timeout, pid)
    _, wait_status = os.waitpid(pid, 0)
    messages = _unpickle_all(data)
    if warnings_out is not None:
        warnings_out.extend(m[1] for m in messages if m[0] == "warning")
    stage = next((m[1] for m in reversed(messages) if m[0] == "stage"), "unknown")
    last = messages[-1] if messages else (None, None)
    if last[0] == "result":
        return last[1]
    if last[0] == "error":
        raise MeshError(*last[1])
    if timed_out:
        raise MeshError(stage, f"timed out after {timeout:g} s")
    if os.WIFSIGNALED(wait_status):
        name = signal.Signals(os.WTERMSIG(wait_status)).name
        if max_memory is not None and name == "SIGABRT":  # how native code ends on an uncaught bad_alloc
            raise MeshError(stage, f"{_over_limit(max_memory)} (native abort, SIGABRT)")
        under = f", under a --max-memory limit of {max_memory / GiB:.3g} GiB" if max_memory is not None else ""
        raise MeshError(stage, f"native crash ({name}) in the worker process{under}")
    raise MeshError(stage, f"worker process exited with code {os.waitstatus_to_exitcode(wait_status)}")


_report_fd: int | None = None
_stage, _warned = "unknown", set()


def current_stage(name: str) -> None:
    """Tell the supervising process which stage runs now (no-op outside `run_isolated`)."""
    global _stage
    _stage = name
    if _report_fd is not None:
        os.write(_report_fd, pickle.dumps(("stage", name)))


def _report_warning(message, category, filename, lineno, file=None, line=None) -> None:
    text = f"[{_stage}] {category.__name__}: {' '.join(str(message).split())[:200]}"
    if text not in _warned:
        _warned.add(text)
        os.write(_report_fd, pickle.dumps(("warning", text)))


def _over_limit(max_memory: int) -> str:
    return f"out of memory: over the --max-memory limit of {max_memory / GiB:.3g} GiB"


def _child(fn, args, write_fd: int, max_memory: int | None) -> None:
    global _report_fd, _stage
    _report_fd, _stage = write_fd, "unknown"
    faulthandler.disable()  # a crash is reported by the parent in one line, not as a dump here
    warnings.simplefilter("default")  # each distinct warning once, through the pipe
    warnings.showwarning = _report_warning
    code = 0
    try:
        out_of_memory = "out of memory"
        if max_memory is not None:
            import resource  # Unix only, as os.fork: a platform without fork never gets here

            hard = resource.getrlimit(resource.RLIMIT_DATA)[1]
            allowed = _status_kib("VmData:", "/proc/self/status") * 1024 + max_memory  # the inherited not counted
            limit = allowed if hard == resource.RLIM_INFINITY else min(allowed, hard)
            with contextlib.suppress(ValueError, OSError):  # a platform that refuses it: the mesh runs unlimited
                resource.setrlimit(resource.RLIMIT_DATA, (limit, hard))
                out_of_memory = _over_limit(max_memory)
        try:
            message = ("result", fn(*args))
        except MeshError as exc:
            reason = out_of_memory if "bad_alloc" in exc.reason else exc.reason
            message = ("error", (exc.stage, reason))
        except MemoryError:
            message = ("error", (_stage, out_of_memory))
        except Exception as exc:  # any bug must still become a one-line failure of this mesh
            if "bad_alloc" in str(exc):  # pymeshlab wraps a failed allocation: "... Details: std::bad_alloc"
                message = ("error", (_stage, out_of_memory))
            else:
                message = ("error", ("unknown", one_line(exc)))
        try:
            data = pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL)
        except MemoryError:  # a result too large for the limit
            data = pickle.dumps(("error", (_stage, out_of_memory)))
        view = memoryview(data)
        while view:
            view = view[os.write(write_fd, view):]
    except BaseException:
        code = 1
    finally:
        sys.stdout.flush()
        os._exit(code)


def _read_all(fd: int, timeout: float | None, pid: int) -> tuple[bytes, bool]:
    chunks, deadline = [], None if timeout is None else time.monotonic() + timeout
    with os.fdopen(fd, "rb", buffering=0) as pipe:
        while True:
            wait = None if deadline is None else max(0.0, deadline - time.monotonic())
            ready, _, _ = select.select([pipe], [], [], wait)
            if not ready:
                os.kill(pid, signal.SIGKILL)
                return b"".join(chunks), True
            chunk = pipe.read(1 << 20)
            if not chunk:
                return b"".join(chunks), False
            chunks.append(chunk)


def _unpickle_all(data: bytes) -> list[tuple]:
    """The messages of a child, in order; a message cut short by the child's death ends the list."""
    stream, messages = io.BytesIO(data), []
    while stream.tell() < len(data):
        try:
            messages.append(pickle.load(stream))
        except Exception:
            break
    return messages


def parse_shard(text: str | None) -> tuple[int, int]:
    """'K/N' (0 <= K < N) to (K, N); None means the whole batch."""
    if text is None:
        return 0, 1
    try:
        k, n = (int(x) for x in text.split("/"))
    except ValueError:
        raise ValueError(f"--shard must look like K/N, got {text!r}") from None
    if not (n >= 1 and 0 <= k < n):
        raise ValueError(f"--shard K/N needs 0 <= K < N, got {text!r}")
    return k, n


def in_shard(key: str, shard: tuple[int, int]) -> bool:
    """Stable assignment of a work item to one of N shards by a hash of its key."""
    k, n = shard
    return int.from_bytes(hashlib.sha1(key.encode()).digest()[:8], "big") % n == k


def default_max_memory(jobs: int, fraction: float = MEMORY_FRACTION) -> int | None:
    """A per-mesh process's share of this task's memory, in bytes: ``fraction`` of the allocation over
    ``jobs`` processes. The allocation is, the first found: SLURM's ``SLURM_MEM_PER_CPU`` x
    ``SLURM_CPUS_PER_TASK`` or ``SLURM_MEM_PER_NODE`` (MB, as SLURM writes them); the memory limit of
    this process's cgroup (v2 ``memory.max``, v1 ``memory.limit_in_bytes``, the lowest on its path);
    the machine's physical memory. None where none can be read."""
    total = _slurm_memory() or _cgroup_memory()
    try:
        physical = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        physical = None
    total = total or physical
    if total is None:
        return None
    return int(total * fraction) // max(jobs, 1)


def _slurm_memory() -> int | None:
    def megabytes(name: str) -> int | None:
        try:
            return int(os.environ[name]) << 20
        except (KeyError, ValueError):
            return None

    per_cpu = megabytes("SLURM_MEM_PER_CPU")
    if per_cpu:
        cpus = os.environ.get("SLURM_CPUS_PER_TASK", "1")
        return per_cpu * (int(cpus) if cpus.isdigit() else 1)
    return megabytes("SLURM_MEM_PER_NODE") or None


def _status_kib(key: str, path: str) -> int:
    """A ``key: <n> kB`` line of a /proc file, in KiB (0 where absent)."""
    try:
        with open(path) as file:
            line = next((line for line in file if line.startswith(key)), "")
    except OSError:
        return 0
    return int(line.split()[1]) if line else 0


def _cgroup_memory(proc_cgroup: str = "/proc/self/cgroup", mount: str = "/sys/fs/cgroup") -> int | None:
    """The lowest memory limit on this process's cgroup path (None: unlimited or unknown). Inside a
    container with its own cgroup namespace the path may name the host's tree: the mount's own files count."""
    try:
        lines = open(proc_cgroup).read().splitlines()
    except OSError:
        return None
    limits = []
    for line in lines:
        _, controllers, path = line.split(":", 2)
        if controllers == "":  # v2: one unified tree
            folder, file = mount, "memory.max"
        elif "memory" in controllers.split(","):
            folder, file = os.path.join(mount, "memory"), "memory.limit_in_bytes"
        else:
            continue
        parts = [p for p in path.split("/") if p]
        for depth in range(len(parts) + 1):
            try:
                text = open(os.path.join(folder, *parts[:depth], file)).read().strip()
            except OSError:
                continue
            if text.isdigit() and int(text) < 1 << 60:  # v2 "max", v1 a page-rounded 2^63: no limit
                limits.append(int(text))
    return min(limits) if limits else None


def parse_memory(text: str | None) -> int | None:
    """'4G', '512M', '1.5GiB', '2000000000' (bytes) to bytes; None, 'none' or '0' to None (no limit)."""
    if text is None or text.strip().lower() in ("none", "0", ""):
        return None
    units = {"": 1, "k": 1 << 10, "m": 1 << 20, "g": 1 << 30, "t": 1 << 40}
    number = text.strip().lower().removesuffix("ib").removesuffix("b")
    unit = number[-1] if number[-1:].isalpha() else ""
    try:
        value = float(number[:-1] if unit else number) * units[unit]
    except (KeyError, ValueError):
        raise ValueError(f"a memory size looks like 4G, 512M or a number of bytes, got {text!r}") from None
    if value <= 0:
        raise ValueError(f"a memory size must be positive, got {text!r}")
    return int(value)


@contextlib.contextmanager
def joblib_backend(backend: str, jobs: int, scheduler: str | None):
    """joblib's parallel_config for loky, or a Dask/Ray cluster (local one of `jobs` workers if no address)."""
    import joblib

    if backend == "loky":
        with joblib.parallel_config(backend="loky", n_jobs=jobs):
            yield
    elif backend == "dask":
        try:
            from dask.distributed import Client, LocalCluster
        except ImportError:
            raise RuntimeError("--backend dask needs the dask extra: pip install 'geogegnn[dask]'") from None
        cluster = None if scheduler else LocalCluster(n_workers=jobs, threads_per_worker=1, processes=True,
                                                      dashboard_address=None)
        try:
            with Client(scheduler or cluster), joblib.parallel_config(backend="dask", n_jobs=-1):
                yield
        finally:
            if cluster is not None:
                cluster.close()
    elif backend == "ray":
        try:
            import ray
            from ray.util.joblib import register_ray
        except ImportError:
            raise RuntimeError("--backend ray needs the ray extra: pip install 'geogegnn[ray]'") from None
        register_ray()
        ray.init(address=scheduler, num_cpus=None if scheduler else jobs, include_dashboard=False,
                 ignore_reinit_error=True, log_to_driver=False)
        try:
            with joblib.parallel_config(backend="ray", n_jobs=-1 if scheduler else jobs):
                yield
        finally:
            ray.shutdown()
    else:
        raise ValueError(f"unknown backend {backend!r}; choose from {BACKENDS}")


def parallel_map(fn: Callable, items: Iterable, jobs: int = 1, backend: str = "loky",
                 scheduler: str | None = None) -> Iterator:
    """fn(item) for every item, results in completion order. jobs=1 with loky runs in this process."""
    import joblib

    items = list(items)
    if not items:
        return
    if backend == "loky" and jobs == 1:
        yield from map(fn, items)
        return
    with joblib_backend(backend, jobs, scheduler):
        # max_nbytes=None: no read-only memmaps in the workers; items are small anyway.
        if backend != "ray":
            yield from joblib.Parallel(return_as="generator_unordered", max_nbytes=None)(
                joblib.delayed(fn)(item) for item in items)
            return
        # Ray's joblib backend returns lists only: run in rounds so progress still shows.
        parallel = joblib.Parallel(max_nbytes=None)
        step = 4 * max(jobs, 1)
        for start in range(0, len(items), step):
            yield from parallel(joblib.delayed(fn)(item) for item in items[start:start + step])
