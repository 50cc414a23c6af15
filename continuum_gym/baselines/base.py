"""What every analytic controller shares: SB3's ``predict`` protocol and input checks."""

from __future__ import annotations

import numpy as np


def broadcast_rows(shape: tuple, *arrays_and_tails):
    """Broadcast each (array, tail) to ``shape + tail`` and flatten the batch: C-contiguous (-1, *tail) rows."""
    return tuple(np.ascontiguousarray(np.broadcast_to(x, shape + tail).reshape((-1,) + tail))
                 for x, tail in arrays_and_tails)


def as_rotation_field(value) -> np.ndarray:
    """A rotation from an observation dict: (..., 3, 3) or flattened (..., 9)."""
    R = np.asarray(value, dtype=float)
    return R.reshape(R.shape[:-1] + (3, 3)) if R.shape[-1] == 9 else R


class Controller:
    """Base of the analytic baselines.

    Subclasses implement ``joint_rates(q, target, ...)`` (the plain kinematic call) and ``predict``
    with SB3's exact signature, so one evaluation path serves baselines and learned agents.
    ``name`` is the registry name; ``action_dim`` the length of the command.
    """

    name = "controller"
    action_dim = 0

    def joint_rates(self, q, target, *args, **kwargs):  # pragma: no cover - abstract
        raise NotImplementedError

    def predict(self, observation, state=None, episode_start=None, deterministic=False):  # pragma: no cover
        raise NotImplementedError

    @staticmethod
    def _observation_dict(observation, required):
        if not isinstance(observation, dict):
            raise ValueError(
                "analytic controllers read a dict observation with keys "
                f"{list(required)}; got {type(observation).__name__}")
        missing = [key for key in required if key not in observation]
        if missing:
            raise ValueError(f"observation lacks keys {missing}; required: {list(required)}")
        return observation

    def __repr__(self):
        return f"{type(self).__name__}()"
