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
"""
from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor

import numpy as np

__all__ = ["count", "beside", "by_rows", "MIN_ROWS"]

MIN_ROWS = 2048  # fewer rows are not split: a thread costs ~0.1 ms, a block of 1k rows of a cloud ~1 ms


def count() -> int:
    """torch's thread count."""
    import torch

    return torch.get_num_threads()


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
