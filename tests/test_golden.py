"""Nothing users rely on changes: env steps, the reproduction and the evaluation equal their golden files
bit for bit (recorded before the inside refactor; see ``tests/golden.py``)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.golden import (
    GOLDEN_DIR,
    array_differences,
    differences,
    record_env_steps,
    run_evaluate,
    run_reproduce,
)


def test_env_steps_equal_their_golden_file():
    with np.load(GOLDEN_DIR / "env_steps.npz") as stored:
        expected = dict(stored)
    assert len(expected) > 100
    problems = array_differences(expected, record_env_steps())
    assert not problems, "\n".join(problems[:30])


def test_reproduction_equals_its_golden_file():
    expected = json.loads((GOLDEN_DIR / "reproduce.json").read_text())
    problems = differences(expected, run_reproduce())
    assert not problems, "\n".join(problems[:30])


@pytest.mark.slow
def test_evaluation_of_the_shipped_policies_equals_its_golden_file():
    expected = json.loads((GOLDEN_DIR / "evaluate.json").read_text())
    assert {"ContinuumGym/OcclusionAvoidance-v0", "ContinuumGym/ViewTracking-v0"} <= set(expected)
    problems = differences(expected, run_evaluate())
    assert not problems, "\n".join(problems[:30])


def test_comparison_sees_a_one_bit_change():
    """The comparison itself: a value one ulp away, a missing key and a changed array are all caught."""
    value = 0.1234
    assert differences({"a": {"b": value}}, {"a": {"b": np.nextafter(value, 1.0)}})
    assert differences({"a": 1}, {})
    assert not differences({"a": [1.0, float("nan")]}, {"a": [1.0, float("nan")], "extra": 2})
    x = np.linspace(0, 1, 5)
    y = x.copy()
    y[3] = np.nextafter(y[3], 2.0)
    assert array_differences({"k": x}, {"k": y})
    assert not array_differences({"k": x}, {"k": x.copy()})
