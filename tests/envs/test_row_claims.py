"""Rows shared out among threads by claiming (``envs/row_claims``): every row stepped exactly once, by
whichever thread, and a pool thread's error reaches the caller instead of a hang."""

from __future__ import annotations

import threading

import numba
import numpy as np
import pytest

from continuum_gym.envs.row_claims import SERIAL, atomic_add, first_rows, next_rows, run_claimed


@numba.njit(nogil=True)
def _count_rows(counts, spin, thread_ids, claims, start, stop):
    """counts[i] += 1 for each row this thread claims; a little work per row so that both threads claim."""
    me = atomic_add(thread_ids, 0, 1)
    first, last = first_rows(claims, start, stop)
    while first < last:
        for i in range(first, last):
            acc = 0.0
            # the last rows are slow: the thread that finishes first must wait for the other's
            for k in range(spin * 500 if i >= stop - 2 else spin):
                acc += np.sqrt(k + i)
            counts[i, 0] += 1
            counts[i, 1] = me
            counts[i, 2] += acc > -1.0
        first, last = next_rows(claims, start, stop, first, last)


@numba.njit(nogil=True)
def _fail_at(bad_row, counts, claims, start, stop):
    first, last = first_rows(claims, start, stop)
    while first < last:
        for i in range(first, last):
            acc = 0.0
            for k in range(2_000):  # ~2 us a row: both threads claim rows
                acc += np.sqrt(k + i)
            if i == bad_row:
                raise ValueError("row failed")
            counts[i] += 1 if acc > -1.0 else 2
        first, last = next_rows(claims, start, stop, first, last)


def _threads() -> int:
    return max(2, min(4, numba.config.NUMBA_NUM_THREADS))


@pytest.mark.parametrize("rows, block", [(1, 1), (7, 3), (64, 1), (20_001, 1), (20_001, 8), (5_000, 5_000)])
def test_every_row_is_stepped_once_and_both_threads_claim(rows, block):
    counts = np.zeros((rows, 3), dtype=np.int64)
    thread_ids = np.zeros(1, dtype=np.int64)
    # ~5 us a row on the large batches (~50 ms on two threads): long enough for the pool thread to come
    # even when the machine is busy with other tests (a thread may wait a few ms for a core)
    spin = 5_000 if rows >= 20_000 else 200 if rows >= 64 else 0
    run_claimed(_count_rows, (counts, spin, thread_ids), rows, _threads(), block)
    # Returned only once every row is finished: no row missing or stepped twice (a lost atomic update
    # would hand a block to both threads), and nothing written after the return.
    assert (counts[:, 0] == 1).all() and (counts[:, 2] == 1).all()
    if rows >= 20_000 and block == 1:
        assert len(np.unique(counts[:, 1])) >= 2, "the pool thread stepped no row"
    counts_after = counts.copy()
    threading.Event().wait(0.01)
    np.testing.assert_array_equal(counts, counts_after)


def test_serial_claims_step_the_whole_range_on_the_caller():
    counts = np.zeros((10, 3), dtype=np.int64)
    _count_rows(counts, 0, np.zeros(1, dtype=np.int64), SERIAL, 2, 9)
    np.testing.assert_array_equal(counts[:, 0], [0, 0, 1, 1, 1, 1, 1, 1, 1, 0])


def test_atomic_add_loses_no_update_under_contention():
    @numba.njit(nogil=True)
    def add_many(total, times):
        for _ in range(times):
            atomic_add(total, 0, 1)

    total = np.zeros(1, dtype=np.int64)
    add_many(total, 1)
    total[0] = 0
    workers = [threading.Thread(target=add_many, args=(total, 200_000)) for _ in range(2)]
    for worker in workers:
        worker.start()
    for worker in workers:
        worker.join()
    assert total[0] == 400_000


@pytest.mark.parametrize("bad_row", [0, 999])
def test_an_error_in_any_thread_reaches_the_caller(bad_row):
    counts = np.zeros(1_000, dtype=np.int64)
    # bad_row 0 is claimed first, usually by the caller; 999 last, by either thread: in 20 runs both.
    for _ in range(20):
        counts[:] = 0
        with pytest.raises(ValueError, match="row failed"):
            run_claimed(_fail_at, (bad_row, counts), 1_000, _threads(), 1)
    assert counts.max() <= 1


def _step_in_child(queue) -> None:
    counts = np.zeros((20_000, 3), dtype=np.int64)  # ~50 ms: time for the child's pool thread to come
    run_claimed(_count_rows, (counts, 5_000, np.zeros(1, dtype=np.int64)), 20_000, _threads(), 1)
    queue.put((int(counts[:, 0].sum()), len(np.unique(counts[:, 1]))))


def test_a_forked_child_steps_without_its_parents_pool_threads():
    """The parent's pool threads do not exist in a forked child (multiprocessing's fork workers): the
    caller must not wait for them (they never come, so it would hang), and the child starts a pool of its
    own rather than queueing every call's work for threads that are not there."""
    import multiprocessing

    counts = np.zeros((2_000, 3), dtype=np.int64)
    run_claimed(_count_rows, (counts, 200, np.zeros(1, dtype=np.int64)), 2_000, _threads(), 1)  # pool started
    context = multiprocessing.get_context("fork")
    queue = context.Queue()
    child = context.Process(target=_step_in_child, args=(queue,))
    child.start()
    child.join(timeout=120)
    assert child.exitcode == 0, "the forked child hung or failed"
    rows, threads_that_stepped = queue.get(timeout=5)
    assert rows == 20_000 and threads_that_stepped >= 2
