"""Worker processes and single-threaded BLAS for the offline-optimum searches."""

from __future__ import annotations

import ctypes
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from typing import Any, TypeVar

import numpy as np
from numpy.typing import ArrayLike

from continuum_gym.validation import fraction, integer

Job = TypeVar("Job")
Result = TypeVar("Result")

# ====================================================================== BLAS threads
_BLAS_CONTROLS: dict = {}

_BLAS_SYMBOLS = (("openblas_get_num_threads", "openblas_set_num_threads"),
                 ("scipy_openblas_get_num_threads64_", "scipy_openblas_set_num_threads64_"),
                 ("scipy_openblas_get_num_threads", "scipy_openblas_set_num_threads"))


def _blas_controls():
    """(getter, setter) of the thread count of every OpenBLAS loaded in this process (Linux; else none)."""
    try:
        with open("/proc/self/maps") as maps:
            paths = tuple(sorted({line.split()[-1] for line in maps
                                  if "openblas" in line.lower() and line.rstrip().split()[-1].startswith("/")}))
    except OSError:
        return []
    if paths not in _BLAS_CONTROLS:
        controls = []
        for path in paths:
            try:
                library = ctypes.CDLL(path)
            except OSError:
                continue
            for get_name, set_name in _BLAS_SYMBOLS:
                getter = getattr(library, get_name, None)
                setter = getattr(library, set_name, None)
                if getter is not None and setter is not None:
                    controls.append((getter, setter))
                    break
        _BLAS_CONTROLS[paths] = controls
    return _BLAS_CONTROLS[paths]


@contextmanager
def single_threaded_blas() -> Iterator[None]:
    """Run the block with one OpenBLAS thread (restored afterwards).

    The searches make hundreds of thousands of tiny BLAS calls (L-BFGS-B, SVDs of 6x7 matrices); a
    threaded OpenBLAS spends milliseconds per call synchronising its threads, more than the call's own
    work, so the coverage optimum would take several times as long. Without OpenBLAS (or off Linux)
    this does nothing.
    """
    controls = _blas_controls()
    previous = [getter() for getter, _ in controls]
    for _, setter in controls:
        setter(1)
    try:
        yield
    finally:
        for (_, setter), count in zip(controls, previous):
            setter(count)


def map_jobs(function: Callable[[Job], Result], jobs: Sequence[Job], workers: int, progress: bool,
             description: str) -> list[Result]:
    """Run ``function`` over ``jobs`` (in order), in ``workers`` processes, with a tqdm bar."""
    from tqdm.auto import tqdm

    results: list[Any] = [None] * len(jobs)
    bar = tqdm(total=len(jobs), desc=description, disable=not progress, leave=False)
    if workers <= 1 or len(jobs) <= 1:
        with single_threaded_blas():
            for k, job in enumerate(jobs):
                results[k] = function(job)
                bar.update()
    else:
        from concurrent.futures import ProcessPoolExecutor, as_completed

        with ProcessPoolExecutor(max_workers=workers) as pool:
            futures = {pool.submit(_single_threaded, function, job): k for k, job in enumerate(jobs)}
            for future in as_completed(futures):
                results[futures[future]] = future.result()
                bar.update()
    bar.close()
    return results


def _single_threaded(function, job):
    with single_threaded_blas():
        return function(job)


def positive_int(value: object, name: str) -> int:
    """An integer >= 1 (``ValueError`` naming ``name`` otherwise)."""
    return integer(value, name, low=1)


def grid_size(grid: int) -> int:
    """Grid points per axis: an integer >= 2."""
    return integer(grid, "grid (points per axis)", low=2)


def visibility_fraction(visibility: float) -> float:
    """The visibility requirement: a fraction of the cone half-angle in (0, 1]."""
    return fraction(visibility, "visibility (fraction of the cone half-angle)")


def rounded(values: ArrayLike, digits: int = 6) -> list:
    return np.round(np.asarray(values, dtype=float), digits).tolist()
