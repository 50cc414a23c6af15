"""Helpers: named parts that act after the policy, before the step (``dimension_reduced+overlap_polish``).

A helper changes the actions a policy gives, from what the system observes and the nominal model, before the env
steps them: ViewTracking's ``overlap_polish`` (a one-step lookahead on the overlap ratio) is one. It is never an env
option: a method that runs with one says so in its name (``residual_dimension_reduced+overlap_polish``), its base
beside it runs with the same helpers and a zero residual, and a training run lists its helpers in its
``config.yml`` (``helpers``). An environment files its helpers by name (``register_helper``); ``make_helpers``
builds them for an env's config, and ``HelperWrapper`` applies them in a Gymnasium env, as the evaluation and
training do.

A helper is made from the env's config and called as ``helper(obs (N, d), actions (N, k), active (N,) uint8) ->
actions (N, k)``, on the observation the policy saw and its actions after clipping to [-1, 1].
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np

from continuum_gym.validation import closest, describe

#: env id -> {helper name: factory(config) -> helper}
HELPERS: dict[str, dict[str, Callable[[Any], Callable[..., np.ndarray]]]] = {}


def register_helper(env_id: str, name: str, factory: Callable[[Any], Callable[..., np.ndarray]]) -> None:
    """File ``factory(config) -> helper`` as the helper ``name`` of ``env_id``."""
    if not isinstance(name, str) or not name.isidentifier():
        raise ValueError(f"a helper's name must be an identifier (it is written after '+' in row names); got "
                         f"{describe(name)}")
    HELPERS.setdefault(env_id, {})[name] = factory


def helper_names(env_id: str) -> tuple[str, ...]:
    """The helpers ``env_id``'s environment files (its package registers them when imported)."""
    from continuum_gym.envs.spec import get_spec

    spec = get_spec(env_id)
    spec.row_functions()  # the env's module, which registers its helpers
    return tuple(HELPERS.get(spec.env_id, {}))


def check_helpers(env_id: str, names: Any) -> tuple[str, ...]:
    """``names`` (a sequence of helper names, or None) checked against ``env_id``'s helpers."""
    if names is None:
        return ()
    if isinstance(names, str) or not isinstance(names, Iterable):
        raise ValueError(f"helpers must be a list of helper names; got {describe(names)}")
    known = helper_names(env_id)
    out = []
    for name in names:
        if name not in known:
            raise ValueError(f"helpers: {name!r} is not a helper of {env_id}{closest(str(name), known)}; its helpers: "
                             f"{list(known)}")
        out.append(name)
    return tuple(out)


def make_helpers(env_id: str, names: Sequence[str], config: Any) -> tuple[Callable[..., np.ndarray], ...]:
    """The helpers ``names`` of ``env_id`` made for ``config`` (an ``EnvConfig``), in order."""
    from continuum_gym.envs.spec import get_spec

    names = check_helpers(env_id, names)
    table = HELPERS[get_spec(env_id).env_id] if names else {}
    return tuple(table[name](config) for name in names)


def apply_helpers(helpers: Sequence[Callable[..., np.ndarray]], obs: np.ndarray, actions: np.ndarray,
                  active: np.ndarray) -> np.ndarray:
    """``actions`` (N, k), already clipped to [-1, 1], after each helper in turn, in their own dtype.

    The helpers compute in float64; the result is cast back to the dtype the policy gave (a float32 policy's
    actions stay float32, as the env would have stepped them), so a helper that changes nothing changes no bit.
    """
    if not helpers:
        return actions
    dtype = np.asarray(actions).dtype
    out = np.ascontiguousarray(actions, dtype=np.float64)
    obs = np.ascontiguousarray(obs, dtype=np.float64)
    active = np.ascontiguousarray(active, dtype=np.uint8)
    for helper in helpers:
        out = helper(obs, out, active)
    return np.ascontiguousarray(out.astype(dtype, copy=False))


def row_name(base: str, helpers: Sequence[str]) -> str:
    """``base`` with its helpers: ``dimension_reduced+overlap_polish``."""
    return "".join([base, *(f"+{name}" for name in helpers)])


class HelperWrapper(gym.ActionWrapper):
    """A single env whose actions pass through the named helpers before its step (as evaluation and training do).

        env = HelperWrapper(gym.make("ContinuumGym/ViewTracking-v0", residual_scale=3.0), ["overlap_polish"])
    """

    def __init__(self, env: gym.Env, helpers: Sequence[str]) -> None:
        super().__init__(env)
        inner: Any = env.unwrapped
        self.helper_names = check_helpers(inner.config.env_id, helpers)
        self._helpers = make_helpers(inner.config.env_id, self.helper_names, inner.config)
        self._active = np.ones(1, dtype=np.uint8)

    def action(self, action: Any) -> np.ndarray:
        # clipped first, as the evaluation clips before its helpers (the env's ``info["action_clipped"]`` then
        # reads False: the helpers saw the clipped action)
        clipped = np.clip(np.asarray(action), -1.0, 1.0).reshape(1, -1)
        inner: Any = self.env.unwrapped  # a continuum-gym env: its batched core holds the observation the policy saw
        return apply_helpers(self._helpers, inner.core.obs, clipped, self._active)[0]


__all__ = ["HELPERS", "register_helper", "helper_names", "check_helpers", "make_helpers", "apply_helpers", "row_name",
           "HelperWrapper"]
