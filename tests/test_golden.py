"""Nothing users rely on changes: env steps, the reproduction and the evaluation equal their golden files
bit for bit (``tests/golden.py`` says when they are recorded, and what a numerics platform is)."""

from __future__ import annotations

import numpy as np
import pytest

from tests.golden import (
    CROSS_PLATFORM_TOLERANCE,
    compute_record,
    golden_set,
    holds_own,
    load_record,
    record_problems,
    tolerance_of,
)


def check_record(part: str, minimum_size: int) -> None:
    directory, own = golden_set()
    expected = load_record(directory, part)
    assert len(expected) >= minimum_size
    problems, how = record_problems(part, expected, compute_record(part), holds_own(directory, own, part))
    assert not problems, f"{part} compared with {directory} {how}:\n" + "\n".join(problems[:30])


def test_env_steps_equal_their_golden_file():
    check_record("env_steps", minimum_size=100)


def test_reproduction_equals_its_golden_file():
    check_record("reproduce", minimum_size=4)


@pytest.mark.slow
def test_evaluation_of_the_shipped_policies_equals_its_golden_file():
    check_record("evaluate", minimum_size=2)


def test_a_record_a_platform_set_leaves_out_is_compared_as_the_reference_sets(tmp_path):
    (tmp_path / "evaluate.json").write_text("{}")
    assert holds_own(tmp_path, True, "evaluate")
    assert not holds_own(tmp_path, True, "reproduce")  # read from the reference set: tolerances after the bits
    assert not holds_own(tmp_path, False, "evaluate")


def test_the_cross_platform_comparison_still_catches_changed_results():
    rtol, atol = tolerance_of(CROSS_PLATFORM_TOLERANCE["evaluate"], "/env/method/mean_or/mean", 0.8)
    assert 0 < rtol < 0.1 and 0 < atol < 1e-3
    expected = {"method": {"mean_or": [0.798, 0.5], "episodes": 40, "ended": True}}
    last_bits = {"method": {"mean_or": [0.798 * (1 + rtol / 10), 0.5], "episodes": 40, "ended": True}}
    problems, how = record_problems("evaluate", expected, last_bits, own=False)
    assert problems == [] and "within" in how
    assert record_problems("evaluate", expected, last_bits, own=True)[0]  # a platform's own set: bit for bit
    changed = {"method": {"mean_or": [0.798 * (1 + 10 * rtol), 0.5], "episodes": 40, "ended": True}}
    assert record_problems("evaluate", expected, changed, own=False)[0] == [
        f"/method/mean_or[0]: 0.798 != {0.798 * (1 + 10 * rtol)!r}"]
    # The target-point error has a wider tolerance of its own, which still catches a doubled error.
    error_rtol, _ = tolerance_of(CROSS_PLATFORM_TOLERANCE["evaluate"], "/env/method/mean_position_error_m/mean", 0.01)
    assert rtol < error_rtol < 0.5
    error = {"method": {"mean_position_error_m": [0.014]}}
    assert record_problems("evaluate", error, {"method": {"mean_position_error_m": [0.0128]}}, own=False)[0] == []
    assert record_problems("evaluate", error, {"method": {"mean_position_error_m": [0.028]}}, own=False)[0]
    one_more_episode = {"method": {"mean_or": [0.798, 0.5], "episodes": 41, "ended": True}}
    assert record_problems("evaluate", expected, one_more_episode, own=False)[0]
    # The resolved-rate trajectories of the reproduction are not compared across platforms; its scalars are.
    reproduction = {"case2": {"resolved_rate": {"or": 0.6786, "q_history": [[0.1, 0.2]]}}}
    other_trajectory = {"case2": {"resolved_rate": {"or": 0.6764, "q_history": [[0.3, 0.2]]}}}
    assert record_problems("reproduce", reproduction, other_trajectory, own=False)[0] == []
    other_result = {"case2": {"resolved_rate": {"or": 0.60, "q_history": [[0.1, 0.2]]}}}
    assert record_problems("reproduce", reproduction, other_result, own=False)[0] == [
        "/case2/resolved_rate/or: 0.6786 != 0.6"]

    steps = {"case/obs": np.linspace(0.0, 1.0, 7), "case/terminated": np.array([False, True])}
    nudged = {"case/obs": steps["case/obs"] + 1e-14, "case/terminated": steps["case/terminated"]}
    assert record_problems("env_steps", steps, nudged, own=False)[0] == []
    flipped = {"case/obs": steps["case/obs"], "case/terminated": np.array([True, True])}
    assert record_problems("env_steps", steps, flipped, own=False)[0] == ["case/terminated: values differ"]
    moved = {"case/obs": steps["case/obs"] + 1e-6, "case/terminated": steps["case/terminated"]}
    assert record_problems("env_steps", steps, moved, own=False)[0]
