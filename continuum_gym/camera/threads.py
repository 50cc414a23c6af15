"""Rows of a batch shared out among a pool of Python threads that call a ``nogil`` kernel on blocks of rows.

The environments' cores step their rows the same way (a pool of Python threads, not numba's ``parallel``,
whose OpenMP layer would fight torch's for the cores). Each thread claims the next block of rows until none
is left, so a thread that starts late (a shared machine) takes fewer; which thread renders a row changes
no result.
"""

from __future__ import annotations

import concurrent.futures
import itertools
import os
import sys
from collections.abc import Callable
from typing import Any

from continuum_gym.validation import integer

__all__ = ["default_threads", "run_blocks"]

_EXECUTORS: dict[int, concurrent.futures.ThreadPoolExecutor] = {}
os.register_at_fork(after_in_child=_EXECUTORS.clear)  # a forked child has none of its parent's pool threads


def default_threads(threads: int | None = None) -> int:
    """``threads`` in [1, 256], or the default: 1 when torch is loaded (a learner computes with its own threads
    there), else numba's thread count (NUMBA_NUM_THREADS, the cores), read without starting its threading layer."""
    import numba

    if threads is None:
        return 1 if "torch" in sys.modules else int(numba.config.NUMBA_NUM_THREADS)  # type: ignore[attr-defined]
    return integer(threads, "threads", low=1, high=256)


def _executor(helpers: int) -> concurrent.futures.ThreadPoolExecutor:
    executor = _EXECUTORS.get(helpers)
    if executor is None:
        executor = _EXECUTORS[helpers] = concurrent.futures.ThreadPoolExecutor(
            max_workers=helpers, thread_name_prefix="continuum-gym-render")
    return executor


def run_blocks(kernel_entry: Callable[..., Any], args: tuple, num_rows: int, threads: int, block: int) -> None:
    """``kernel_entry(start, stop, *args)`` over [0, num_rows) in blocks of ``block`` rows on ``threads`` threads.

    The calling thread works too; it returns when every block is done and re-raises a thread's exception.
    """
    blocks = (num_rows + block - 1) // block
    if threads <= 1 or blocks <= 1:
        kernel_entry(0, num_rows, *args)
        return
    counter = itertools.count()  # next() is atomic under the GIL: each block is claimed once

    def work() -> None:
        while True:
            k = next(counter)
            if k >= blocks:
                return
            kernel_entry(k * block, min((k + 1) * block, num_rows), *args)

    futures = [_executor(threads - 1).submit(work) for _ in range(min(threads, blocks) - 1)]
    try:
        work()
    finally:
        for future in concurrent.futures.as_completed(futures):
            future.result()
