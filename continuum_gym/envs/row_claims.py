"""Rows of a batch step shared out among threads as they go: each thread claims the next block of rows.

A fixed split (one contiguous chunk per thread) waits for the slowest chunk, and on a virtual machine a
pool thread that slept between steps starts 30-75 us after it is handed its chunk, and the caller, had
it slept on the chunk's future, would wake as late again. Claimed rows even that out: a thread that
starts late claims fewer rows. The step kernels claim blocks with an atomic add on a small int64 array
of the call (``claims``), and the caller waits for the last rows in compiled code, for at most the time
of one block unless the other thread was descheduled (then it falls back to blocking on the futures).
The caller never depends on a pool thread to finish: if none comes, it steps every row itself.
Which thread steps a row changes no result: rows are independent and each is computed by the same row
function, bit for bit. ``KernelCall`` is how a batched core calls its step kernel: on the calling thread, or
claimed among threads through ``run_claimed``.
"""

from __future__ import annotations

import concurrent.futures
import os
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

from continuum_gym.robots.compiled import kernel

if TYPE_CHECKING:
    from numba.core.typing.context import BaseContext
    from numba.core.typing.templates import Signature

    #: What an intrinsic's typing function returns: its signature and code generator, or None (no match).
    IntrinsicTyping = tuple[Signature, Callable[..., Any]] | None

#: ``claims`` layout: [rows claimed so far, rows finished, rows per claim]
CLAIMED, FINISHED, BLOCK = 0, 1, 2
#: The serial call's ``claims``: no shared counter, the kernel steps [start, stop) in one pass.
# Writeable although never written: a read-only array is another numba type, and the step kernels would
# compile twice.
SERIAL = np.zeros(0, dtype=np.int64)
#: Polls of the finished count between the caller's checks of its helpers' futures (a pause instruction
#: each, tens of ns on current x86 cores, so a round lasts tens of microseconds).
WAIT_SPINS = 2_000
#: Longest busy wait, in s: a block takes 3-30 us, so a longer wait means a descheduled thread (the cores
#: are shared), and the caller then blocks on the futures instead of taking a core from it.
WAIT_SPIN_SECONDS = 1e-3


def _item_pointer(context, builder, array_type, array, index):
    return cgutils.get_item_pointer(context, builder, array_type, context.make_array(array_type)(context, builder,
                                                                                                array), [index])


@intrinsic
def atomic_add(typingctx: BaseContext, array: types.Type, index: types.Type, value: types.Type) -> IntrinsicTyping:
    """``array[index] += value`` as one atomic read-modify-write (sequentially consistent); returns the old value."""
    if not (isinstance(array, types.Array) and array.dtype == types.int64 and array.ndim == 1):
        return None

    def codegen(context, builder, signature, args):
        index_value = context.cast(builder, args[1], signature.args[1], types.intp)
        value = context.cast(builder, args[2], signature.args[2], types.int64)
        pointer = _item_pointer(context, builder, signature.args[0], args[0], index_value)
        return builder.atomic_rmw("add", pointer, value, "seq_cst")

    return types.int64(array, index, value), codegen


@intrinsic
def atomic_load(typingctx: BaseContext, array: types.Type, index: types.Type) -> IntrinsicTyping:
    """``array[index]`` read atomically (sequentially consistent), so a write of another thread is seen."""
    if not (isinstance(array, types.Array) and array.dtype == types.int64 and array.ndim == 1):
        return None

    def codegen(context, builder, signature, args):
        index_value = context.cast(builder, args[1], signature.args[1], types.intp)
        pointer = _item_pointer(context, builder, signature.args[0], args[0], index_value)
        return builder.load_atomic(pointer, "seq_cst", 8)

    return types.int64(array, index), codegen


@intrinsic
def spin_pause(typingctx: BaseContext) -> IntrinsicTyping:
    """x86's ``pause`` (a no-op elsewhere): a busy wait that leaves the core's pipeline to its sibling."""

    def codegen(context, builder, signature, args):
        import platform

        import llvmlite.ir as ir

        if platform.machine().lower() in ("x86_64", "amd64", "i386", "i686"):
            pause = builder.module.declare_intrinsic("llvm.x86.sse2.pause", fnty=ir.FunctionType(ir.VoidType(), []))
            builder.call(pause, [])
        return context.get_dummy_value()

    return types.none(), codegen


@kernel(inline="always", borrows=True)
def first_rows(claims, start, stop):
    """The first rows [first, last) the calling thread steps: all of [start, stop) on a serial call."""
    if claims.shape[0] == 0:
        return start, stop
    first = start + atomic_add(claims, CLAIMED, claims[BLOCK])
    return first, min(first + claims[BLOCK], stop)


@kernel(inline="always", borrows=True)
def next_rows(claims, start, stop, first, last):
    """Count [first, last) as finished and claim the next block; an empty range when none is left."""
    if claims.shape[0] == 0:
        return stop, stop
    atomic_add(claims, FINISHED, last - first)
    return first_rows(claims, start, stop)


@kernel(nogil=True, borrows=True)
def wait_rows(claims, rows, spins):
    """Busy-wait (without the GIL) until ``rows`` rows are finished, for at most ``spins`` polls."""
    for _ in range(spins):
        if atomic_load(claims, FINISHED) >= rows:
            return True
        spin_pause()
    return atomic_load(claims, FINISHED) >= rows


@kernel(nogil=True, borrows=True)
def close_claims(claims, rows):
    """Claim every row that is left, for nobody: threads that come to the call afterwards step nothing."""
    atomic_add(claims, CLAIMED, rows)


_EXECUTORS: dict = {}


def _executor(helpers: int) -> concurrent.futures.ThreadPoolExecutor:
    executor = _EXECUTORS.get(helpers)
    if executor is None:
        executor = _EXECUTORS[helpers] = concurrent.futures.ThreadPoolExecutor(
            max_workers=helpers, thread_name_prefix="continuum-gym-step")
    return executor


# A forked child has none of its parent's pool threads, but its copy of the pool believes it has them
# and would queue every call's work for nobody (the caller steps all rows itself, so nothing hangs, but
# the queue grows by one call per step): the child starts its own pool.
os.register_at_fork(after_in_child=_EXECUTORS.clear)


def run_claimed(kernel_entry: Callable[..., Any], args: tuple, num_rows: int, threads: int, block: int) -> None:
    """``kernel_entry(*args, claims, 0, num_rows)`` on the calling thread and ``threads - 1`` pool threads.

    The kernel claims ``block`` rows at a time from ``claims`` (a fresh array per call, so a pool thread
    that starts after the call returned finds every row claimed and does nothing) until all are claimed;
    this returns when every row is finished and re-raises a pool thread's exception.
    """
    claims = np.array([0, 0, block], dtype=np.int64)
    helpers = threads - 1
    executor = _executor(helpers)
    futures = [executor.submit(kernel_entry, *args, claims, 0, num_rows) for _ in range(helpers)]
    try:
        kernel_entry(*args, claims, 0, num_rows)
        deadline = time.perf_counter() + WAIT_SPIN_SECONDS
        while not wait_rows(claims, num_rows, WAIT_SPINS):
            for future in futures:
                if future.done():
                    future.result()  # a pool thread's exception (its claimed rows will never finish)
            if time.perf_counter() > deadline:
                break
        else:
            return
    except BaseException:
        close_claims(claims, num_rows)  # a pool thread that comes now steps nothing
        # Rows claimed before are being stepped: return only when no pool thread writes the arrays any more.
        concurrent.futures.wait(futures)
        raise
    for future in futures:
        future.result()
    if claims[FINISHED] < num_rows:  # pragma: no cover - every thread returned without finishing its rows
        raise RuntimeError(f"batch step finished {claims[FINISHED]} of {num_rows} rows")


_FLOAT64 = np.dtype(np.float64)
_UINT8 = np.dtype(np.uint8)


def _is_kernel_array(array, dtype: np.dtype, ndim: int) -> bool:
    # ``is``: numpy's native dtypes are singletons (any other dtype object takes the dispatcher's path);
    # flags.carray: C-contiguous, aligned and writeable, one flags object instead of three
    return type(array) is np.ndarray and array.dtype is dtype and array.ndim == ndim and array.flags.carray


class KernelCall:
    """A compiled step kernel called without numba's per-call type dispatch.

    Resolving the types of the step's named bundles costs ~9 us per call (more than ViewTracking's
    arithmetic for one robot). The bundles keep their types for the life of a core, so the compiled
    entry point for them is looked up once; a call whose per-step arrays (actions (N, k) float64,
    active (N,) uint8) have another type, layout or flag goes through numba's dispatcher.
    """

    def __init__(self, kernel: Any) -> None:  # a numba dispatcher (``@kernel``, typed as Any)
        self.kernel = kernel
        self.entry: Callable[..., Any] | None = None

    def __call__(self, args: tuple, actions: np.ndarray, active: np.ndarray, num_rows: int, threads: int = 1,
                 block: int = 1) -> None:
        """Step rows [0, num_rows) on ``threads`` threads, which claim ``block`` rows at a time."""
        kernel = self.kernel
        if _is_kernel_array(actions, _FLOAT64, 2) and _is_kernel_array(active, _UINT8, 1):
            if self.entry is None:
                signature = tuple(self.kernel.typeof_pyval(value) for value in (*args, SERIAL, 0, 0))
                self.kernel.compile(signature)
                self.entry = self.kernel.overloads[signature].entry_point
            kernel = self.entry
        if threads <= 1:  # the single env's and small batches' path: no further Python call
            kernel(*args, SERIAL, 0, num_rows)
        else:
            run_claimed(kernel, args, num_rows, threads, block)


__all__ = ["KernelCall", "SERIAL", "first_rows", "next_rows", "wait_rows", "run_claimed", "atomic_add", "atomic_load"]
