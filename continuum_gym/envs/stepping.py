"""What a core's step takes besides its state: the actions, checked and clipped once for every front end, and
the threads its rows run on (``BatchedCore.num_threads``, ``row_threads``)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from continuum_gym.robots.compiled import kernel
from continuum_gym.validation import integer


@kernel
def _clip_rows(array, clipped):
    """Clip (N, d) to [-1, 1] in place, marking clipped rows; False if anything is non-finite."""
    for i in range(array.shape[0]):
        clipped[i] = False
        for k in range(array.shape[1]):
            value = array[i, k]
            if not math.isfinite(value):
                return False
            if value > 1.0:
                array[i, k] = 1.0
                clipped[i] = True
            elif value < -1.0:
                array[i, k] = -1.0
                clipped[i] = True
    return True


def check_actions(actions: Any, shape: tuple[int, ...], name: str = "action") -> tuple[np.ndarray, np.ndarray]:
    """Validate actions: exact shape, finite; clip to [-1, 1] and report which rows were clipped.

    Returns a fresh C-ordered (N, d) float64 array (the caller's array is never modified) and a bool
    mask (N,). C order whatever the input's layout (a transposed torch tensor, a Fortran-ordered batch):
    an array of another layout would take numba's dispatcher and compile the step kernel again for it.
    """
    try:
        array = np.array(actions, dtype=np.float64, ndmin=1, order="C")
    except (TypeError, ValueError) as error:
        raise ValueError(f"{name} must be a numeric array of shape {shape}") from error
    if array.shape != shape:
        raise ValueError(f"{name} must have shape {shape}; got {array.shape}")
    rows = array.reshape(-1, shape[-1])
    clipped = np.empty(rows.shape[0], dtype=bool)
    if not _clip_rows(rows, clipped):
        raise ValueError(f"{name} must be finite (no NaN or inf); got {actions}")
    return rows, clipped


#: Batches at least this large are stepped on all cores (rows are independent, results identical); a core
#: whose rows are cheap sets a larger ``parallel_min_rows``.
PARALLEL_MIN_ROWS = 32


def step_threads(num_threads: int | None = None) -> int:
    """Threads a core steps its rows on: ``num_threads`` in [1, NUMBA_NUM_THREADS], or the default.

    The default avoids oversubscription: 1 when torch is loaded in the process (a learner such as SB3,
    torchrl or skrl computes there with its own threads; two thread pools on the same cores collapse
    both), else numba's thread count (``NUMBA_NUM_THREADS`` or ``numba.set_num_threads``). The caller's
    OpenMP and torch settings are never changed: the rows run on a pool of Python threads.
    """
    import sys

    import numba

    if num_threads is None:
        if "torch" in sys.modules:
            return 1
        # numba.get_num_threads() starts numba's threading layer, whose OpenMP backend then sets the
        # process's OpenMP thread count (a torch imported later would inherit it, OMP_NUM_THREADS or not).
        # Ask it only if it runs already (a caller's numba.set_num_threads); else read NUMBA_NUM_THREADS.
        from numba.np.ufunc import parallel

        if getattr(parallel, "_is_initialized", False):
            return numba.get_num_threads()
        return numba.config.NUMBA_NUM_THREADS  # type: ignore[attr-defined]  # set by numba.config at import
    return integer(num_threads, "num_threads", low=1,
                   high=numba.config.NUMBA_NUM_THREADS)  # type: ignore[attr-defined]  # (as above)


def row_threads(num_envs: int, threads: int, min_rows: int = PARALLEL_MIN_ROWS) -> int:
    """Threads a batch of ``num_envs`` rows is stepped on: ``threads``, or 1 below ``min_rows`` rows."""
    return 1 if num_envs < min_rows else threads


__all__ = ["check_actions", "step_threads", "row_threads", "PARALLEL_MIN_ROWS"]
