"""ViewTracking's ``overlap_polish``: the lookahead on the overlap ratio never lowers the next step's OR on a static
target, changes nothing below its OR threshold, and rejects bad values by name."""

from __future__ import annotations

import numpy as np
import pytest

from continuum_gym.envs.view_tracking.config import ViewTrackingConfig
from continuum_gym.envs.view_tracking.env import ViewTrackingCore
from continuum_gym.envs.view_tracking.outputs import Metric
from continuum_gym.envs.view_tracking.polish import POLISH_MIN_OR

N = 48


def test_polish_never_lowers_the_next_overlap_and_acts_only_above_its_threshold():
    kwargs = dict(task="static", task_split="validation", residual_scale=3.0)
    polished, plain = ViewTrackingCore(N, overlap_polish=0.05, **kwargs), ViewTrackingCore(N, **kwargs)
    ids = np.arange(N)
    largest = polished.overlap_polish
    for core in (polished, plain):
        core.reset_rows(ids, ids)
    polished.overlap_polish = None  # the same warm-up on the base alone: identical states
    active = np.ones(N, dtype=np.uint8)
    zero = np.zeros((N, 6))
    for _ in range(150):
        polished.step(zero, active)
        plain.step(zero, active)
    np.testing.assert_array_equal(polished.q, plain.q)
    polished.overlap_polish = largest
    rng = np.random.default_rng(7)
    improved = 0
    for _ in range(5):
        actions = np.clip(rng.normal(0.0, 0.3, (N, 6)), -1.0, 1.0)
        before = polished.metrics[:, Metric.OR].copy()
        polished.step(actions, active)
        plain.step(actions, active)
        after, reference = polished.metrics[:, Metric.OR], plain.metrics[:, Metric.OR]
        assert np.all(after >= reference - 1e-9)
        below = before < POLISH_MIN_OR
        np.testing.assert_array_equal(after[below], reference[below])  # untouched below the threshold
        improved += int(np.sum(after > reference + 1e-6))
        # the next step starts from the same states again
        plain.q[:] = polished.q
        plain.steps[:] = polished.steps
        plain.observe_rows(ids)
    assert improved > 0  # it does act: an active lookahead that never changed anything would pass the rest


@pytest.mark.parametrize("value", [0.0, -0.1, 1.5, float("nan"), "big", True])
def test_bad_polish_is_named(value):
    with pytest.raises(ValueError, match="overlap_polish"):
        ViewTrackingConfig(overlap_polish=value)


def test_polish_needs_a_joint_residual():
    with pytest.raises(ValueError, match="overlap_polish.*residual_space"):
        ViewTrackingConfig(overlap_polish=0.05, residual_space="target")
