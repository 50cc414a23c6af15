"""States for the batched renderer's tests, drawn from the environments' own task pools.

Each environment is reset with 25 seeds and stepped 8 times with seeded random actions: 225 states per
environment (the start of every task and where random control takes it).
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import continuum_gym  # noqa: F401  (registers the environments)

SEEDS = 25
STEPS = 8


def _states(env_id: str, record) -> tuple:
    env = gym.make(env_id)
    core = env.unwrapped.core
    rows = []
    for seed in range(SEEDS):
        env.reset(seed=seed)
        rng = np.random.default_rng(seed)
        rows.append(record(core))
        for _ in range(STEPS):
            env.step(rng.uniform(-1.0, 1.0, env.action_space.shape))
            rows.append(record(core))
    env.close()
    return core, [np.array(column) for column in zip(*rows)]


@pytest.fixture(scope="session")
def occlusion_states():
    """(core, q (225, 7), gamma (225,)) of OcclusionAvoidance."""
    core, (q, gamma) = _states("ContinuumGym/OcclusionAvoidance-v0", lambda c: (c.q[0].copy(), float(c.gamma[0])))
    return core, q, gamma


@pytest.fixture(scope="session")
def view_tracking_states():
    """(core, q (225, 6), davinci_configuration (225, 4)) of ViewTracking."""
    core, (q, q_dv) = _states("ContinuumGym/ViewTracking-v0", lambda c: (c.q[0].copy(), c.davinci_configuration(0)))
    return core, q, q_dv
