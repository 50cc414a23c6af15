"""The step kernels' columns, declared once (``continuum_gym.envs.columns`` and each env's ``outputs``).

Each observation block is read by its declared name and compared with the same quantity computed
independently of the observation code: from the core's joints, the ``info`` metrics and the baseline
command. A block declared at the wrong place, or a kernel writing past it, fails here; so does a docs
table that is not the declaration's.
"""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

from continuum_gym.envs.columns import Block, Columns, Layout
from continuum_gym.envs.occlusion import outputs as occ
from continuum_gym.envs.view_tracking import outputs as view
from continuum_gym.robots import MultiBackboneRobot

OCCLUSION = "ContinuumGym/OcclusionAvoidance-v0"
VIEW = "ContinuumGym/ViewTracking-v0"


def block(layout: Layout, obs: np.ndarray, name: str, n: int = 0) -> np.ndarray:
    """The entries of block ``name``, found by walking the declared blocks (not through ``offsets``)."""
    start = 0
    for b in layout.blocks:
        if b.name == name:
            return obs[start:start + b.length(n)]
        start += b.length(n)
    raise KeyError(name)


@pytest.mark.parametrize("n", [1, 2, 3, 4])
def test_a_layout_s_offsets_widths_and_table_agree_with_its_blocks(n):
    offsets, width = occ.OBSERVATION.offsets(), 0
    rows = occ.OBSERVATION.table(n, indent="").splitlines()[2:]
    for b, row in zip(occ.OBSERVATION.blocks, rows, strict=True):
        per, const = getattr(offsets, b.name)
        assert per * n + const == width
        first, _, last = row.split(" | ")[0].strip("| ").partition("-")
        assert (int(first), int(last or first)) == (width, width + b.length(n) - 1)
        width += b.length(n)
    assert occ.OBSERVATION.width(n) == width == 5 * n + 17  # the env's observation space (tests/envs/test_variants)
    assert view.OBS_DIM == 22 and view.TARGET_OBS_DIM == 5
    assert view.OBSERVATION.starts().overlap == 14 and view.OBSERVATION.starts().target_insertion == 22


def test_layouts_and_columns_reject_what_they_cannot_declare():
    with pytest.raises(ValueError, match="unique identifiers"):
        Layout("Bad", Block("a", "x", "-"), Block("a", "y", "-"))
    with pytest.raises(ValueError, match="grow with the robot"):
        occ.OBSERVATION.starts()
    with pytest.raises(ValueError, match="upto"):
        view.OBSERVATION.width(upto="nope")

    class Two(Columns):
        FIRST = "the first"
        SECOND = "the second"

    assert [int(c) for c in Two] == [0, 1] and Two.SECOND.doc == "the second"
    assert Two.table("X_") == "- 0: `X_FIRST` - the first\n- 1: `X_SECOND` - the second"


@pytest.mark.parametrize("n", [2, 3])
def test_every_occlusion_block_holds_what_it_declares(n):
    robot = MultiBackboneRobot(lengths=(0.03, 0.025, 0.02)[:n]) if n != 3 else None
    env = gym.make(OCCLUSION, **({"robot": robot} if robot else {}), task="random")
    obs, info = env.reset(seed=3)
    rng = np.random.default_rng(0)
    for step in range(6):
        obs, _, _, _, info = env.step(rng.uniform(-0.3, 0.3, env.action_space.shape).astype(np.float32))
        core = env.unwrapped.core
        q, gamma = core.q[0], core.gamma[0]
        lo, hi, _ = core.limits.bounds(n)

        def get(name, obs=obs):
            return block(occ.OBSERVATION, obs, name, n)

        np.testing.assert_allclose(get("bend"), (math.pi / 2 - q[0:2 * n:2]) / core.limits.max_bend, atol=1e-6)
        np.testing.assert_allclose(get("delta"), np.ravel([(np.sin(d), np.cos(d)) for d in q[1:2 * n:2]]), atol=1e-6)
        np.testing.assert_allclose(get("insertion"), [2 * (q[2 * n] - lo[2 * n]) / (hi[2 * n] - lo[2 * n]) - 1],
                                   atol=1e-6)
        np.testing.assert_allclose(get("gamma"), [math.sin(gamma), math.cos(gamma)], atol=1e-6)
        assert np.linalg.norm(get("tip_position_error")) * occ.POSITION_ERROR_SCALE == pytest.approx(
            info["tip_error_m"], rel=1e-5, abs=1e-9)
        assert np.linalg.norm(get("tip_orientation_error")) * occ.ORIENTATION_ERROR_SCALE == pytest.approx(
            info["orientation_error_rad"], rel=1e-5, abs=1e-9)
        assert get("view_fraction")[0] == pytest.approx(info["tip_view_fraction"], rel=1e-6)
        assert get("voi")[0] == pytest.approx(info["voi"], rel=1e-6, abs=1e-9)
        np.testing.assert_allclose(get("base_command") * core.rate_scale_vec, np.clip(
            info["base_command"], -10 * core.rate_scale_vec, 10 * core.rate_scale_vec), rtol=1e-6, atol=1e-9)
        assert get("time")[0] == pytest.approx((step + 1) / core.tasks.duration[0], rel=1e-6)


def test_every_view_tracking_block_holds_what_it_declares():
    env = gym.make(VIEW, task="random", observe_target=True)
    obs, info = env.reset(seed=5)
    rng = np.random.default_rng(1)
    for step in range(6):
        obs, _, _, _, info = env.step(rng.uniform(-0.3, 0.3, 6).astype(np.float32))
        core = env.unwrapped.core
        q, (lo, hi) = core.q[0], core.robot.joint_limits

        def get(name, obs=obs):
            return block(view.OBSERVATION, obs, name)

        assert get("l0")[0] == pytest.approx(2 * (q[0] - lo[0]) / (hi[0] - lo[0]) - 1, abs=1e-6)
        assert get("phi")[0] == pytest.approx(q[1] / math.pi, abs=1e-6)
        for name, k in (("theta1", 2), ("theta2", 4)):
            assert get(name)[0] == pytest.approx(2 * (q[k] - lo[k]) / (hi[k] - lo[k]) - 1, abs=1e-6)
        np.testing.assert_allclose(get("delta1"), [math.sin(q[3]), math.cos(q[3])], atol=1e-6)
        np.testing.assert_allclose(get("delta2"), [math.sin(q[5]), math.cos(q[5])], atol=1e-6)
        assert get("overlap")[0] == pytest.approx(info["overlap_ratio"], rel=1e-6)
        assert np.linalg.norm(get("orientation_error")) == pytest.approx(info["orientation_error_rad"], rel=1e-5)
        assert np.linalg.norm(get("target_error")) * view.POSITION_ERROR_SCALE == pytest.approx(
            info["position_error_m"], rel=1e-5, abs=1e-9)
        assert get("time")[0] == pytest.approx((step + 1) / core.tasks.duration[0], rel=1e-6)
        roll = block(view.OBSERVATION, obs, "target_roll")
        assert roll[0] ** 2 + roll[1] ** 2 == pytest.approx(1.0, abs=1e-6)  # sin, cos of one angle
    assert len(obs) == view.OBSERVATION.width()


def test_the_env_docstrings_carry_the_declared_tables():
    from continuum_gym.envs.occlusion.env import OcclusionAvoidanceEnv
    from continuum_gym.envs.view_tracking.env import ViewTrackingEnv

    assert occ.OBSERVATION.table(3) in OcclusionAvoidanceEnv.__doc__
    assert view.OBSERVATION.table() in ViewTrackingEnv.__doc__
