"""Work spread over torch's thread count (``OMP_NUM_THREADS``, ``torch.set_num_threads``), so that the
limits a user sets for torch (joblib workers, SLURM cores) also hold for the NumPy, SciPy and libigl work
around the network: with one thread everything runs in the caller, as before.

Two shapes of parallel work, both on Python threads (NumPy's array loops, SciPy's k-d tree and sparse
products and torch's kernels release the interpreter; results do not depend on the thread count):

* :func:`beside`: one task on a thread of its own while the caller goes on (the U-Net while the
  landmark fields are computed: the network reads them only at its codes);
* :func:`by_rows`: a row-wise computation cut into one block of rows per thread, the blocks' results
  stacked in row order (bitwise what one call on all rows gives, for computations that treat every row
  on its own).

Threads are made per call, never kept: a pool kept in a module would be dead in the children that
``geodata`` forks.

While the network runs beside work of our own, torch's kernels keep to one thread fewer
(:func:`fewer_for_torch`): its OpenMP threads would otherwise wait, spinning, for cores that the other
work holds (a cloud's embed at 8k points on two threads: the network and the landmark fields side by
side 0.43-0.48 s with the network's kernels on two threads, 0.27-0.30 s on one; alone the network takes
the same on one thread as on two at that size).
"""
from __future__ import annotations

from collections.abc import Callable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import contextmanager

import numpy as np

__all__ = ["count", "beside", "by_rows", "indices", "fewer_for_torch", "MIN_ROWS"]

MIN_ROWS = 2048  # fewer rows are not split: a thread costs ~0.1 ms, a block of 1k rows of a cloud ~1 ms


_kept: int | None = None  # torch's thread count from before fewer_for_torch, while within it


def count() -> int:
    """The threads our work may use: torch's thread count (within :func:`fewer_for_torch`, the count from
    before it)."""
    import torch

    return _kept or torch.get_num_threads()


@contextmanager
def fewer_for_torch() -> Iterator[None]:
    """Within: torch's kernels on one thread fewer than :func:`count` (at least one), for a network run
    :func:`beside` work of our own, which keeps all of :func:`count`; torch's count restored after. torch's
    count is the process's: the same limit holds for any torch work of other threads meanwhile."""
    global _kept
    import torch

    n = count()
    if n == 1 or _kept is not None:
        yield
        return
    _kept = n
    torch.set_num_threads(n - 1)
    try:
        yield
    finally:
        torch.set_num_threads(n)
        _kept = None


def beside(compute: Callable[[], object]) -> Future:
    """``compute()`` on a thread of its own when torch may use more than one thread, at once otherwise; its
    result, or the error it raised, comes from the Future's ``result()``."""
    if count() > 1:
        pool = ThreadPoolExecutor(1, thread_name_prefix="gegnn-beside")
        future = pool.submit(compute)
        pool.shutdown(wait=False)  # the thread ends with the work; the Future holds its result
        return future
    done = Future()
    try:
        done.set_result(compute())
    except Exception as exc:  # noqa: BLE001 -- raised again by result(), as it would be from the thread
        done.set_exception(exc)
    return done


def by_rows(compute: Callable[[slice], np.ndarray | tuple], n: int):
    """``compute(rows)`` for one block ``rows`` (a slice of ``range(n)``) per thread (a single call on
    ``slice(0, n)`` with one thread or fewer than 2 * MIN_ROWS rows); the blocks' arrays (or each of their
    tuples' arrays) concatenated along the first axis."""
    blocks = min(count(), n // MIN_ROWS)
    if blocks <= 1:
        return compute(slice(0, n))
    bounds = np.linspace(0, n, blocks + 1).astype(int)
    with ThreadPoolExecutor(blocks, thread_name_prefix="gegnn-rows") as pool:
        parts = list(pool.map(compute, [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:])]))
    if isinstance(parts[0], tuple):
        return tuple(np.concatenate(column) for column in zip(*parts))
    return np.concatenate(parts)


def indices(rows: slice) -> np.ndarray:
    """The row numbers (int64) of a block of :func:`by_rows`, for compiled kernels that take them."""
    return np.arange(rows.start, rows.stop, dtype=np.int64)
