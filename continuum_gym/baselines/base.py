"""What every analytic controller shares: SB3's ``predict`` protocol and input checks."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike


def broadcast_rows(shape: tuple[int, ...], *arrays_and_tails: tuple[ArrayLike, tuple[int, ...]]
                   ) -> tuple[np.ndarray, ...]:
    """Broadcast each (array, tail) to ``shape + tail`` and flatten the batch: C-contiguous (-1, *tail) rows."""
    return tuple(np.ascontiguousarray(np.broadcast_to(x, shape + tail).reshape((-1,) + tail))
                 for x, tail in arrays_and_tails)


def as_rotation_field(value: ArrayLike) -> np.ndarray:
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

    @property
    def action_dim(self) -> int:
        """Length of the command (a subclass overrides it)."""
        return 0

    def joint_rates(self, q: ArrayLike, target: Any, *args: Any, **kwargs: Any
                    ) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def predict(self, observation: np.ndarray | dict[str, np.ndarray], state: tuple[np.ndarray, ...] | None = None,
                episode_start: np.ndarray | None = None, deterministic: bool = False
                ) -> tuple[np.ndarray, tuple[np.ndarray, ...] | None]:  # pragma: no cover
        raise NotImplementedError

    @staticmethod
    def _observation_dict(observation: object, required: Sequence[str]) -> dict[str, Any]:
        if not isinstance(observation, dict):
            raise ValueError(
                "analytic controllers read a dict observation with keys "
                f"{list(required)}; got {type(observation).__name__}")
        missing = [key for key in required if key not in observation]
        if missing:
            raise ValueError(f"observation lacks keys {missing}; required: {list(required)}")
        return observation

    def __repr__(self) -> str:
        return f"{type(self).__name__}()"
