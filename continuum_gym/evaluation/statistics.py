"""Aggregate statistics with rliable: mean and interquartile mean with stratified-bootstrap 95 % CIs.

Scores are arranged as (runs x tasks): one row per training seed (a deterministic baseline is one
row), one column per held-out task instance. rliable's stratified bootstrap resamples runs within
each task; with ``task_bootstrap=True`` it also resamples the task instances, so a method evaluated
with one seed still gets an interval that reflects the spread over episodes.
"""

from __future__ import annotations

import warnings

import numpy as np
from numpy.typing import ArrayLike

DEFAULT_REPS = 2000


def _aggregates(scores: np.ndarray) -> np.ndarray:
    from rliable import metrics

    return np.array([metrics.aggregate_mean(scores), metrics.aggregate_iqm(scores)])


def summarize(scores: ArrayLike, reps: int = DEFAULT_REPS, seed: int = 0) -> dict[str, float]:
    """{mean, iqm, ci_low, ci_high, iqm_ci_low, iqm_ci_high, n_runs, n_tasks} of a (runs, tasks) score array."""
    from rliable import library

    scores = np.atleast_2d(np.asarray(scores, dtype=float))
    if scores.size == 0 or not np.all(np.isfinite(scores)):
        raise ValueError("scores must be a non-empty finite (runs, tasks) array")
    point = _aggregates(scores)
    if scores.size == 1:
        low = high = point
    else:
        # rliable 1.2 draws its resampling indices from numpy's *global* generator (update_indices calls
        # np.random.choice) and ignores random_state, so a CI would depend on whatever ran before. Seed the
        # global generator for the draw and give the caller's state back afterwards.
        caller_state = np.random.get_state()
        np.random.seed(seed)
        try:
            with warnings.catch_warnings():
                # arch deprecates the RandomState rliable hands it; the draws come from the seeded global state.
                warnings.filterwarnings("ignore", message="random_state is deprecated", category=FutureWarning)
                estimates, intervals = library.get_interval_estimates(
                    {"m": scores}, _aggregates, reps=reps, task_bootstrap=True,
                    random_state=np.random.RandomState(seed))
        finally:
            np.random.set_state(caller_state)
        low, high = intervals["m"][0], intervals["m"][1]
    return {"mean": float(point[0]), "iqm": float(point[1]), "ci_low": float(low[0]), "ci_high": float(high[0]),
            "iqm_ci_low": float(low[1]), "iqm_ci_high": float(high[1]),
            "n_runs": int(scores.shape[0]), "n_tasks": int(scores.shape[1])}
