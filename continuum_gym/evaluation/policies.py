"""Any policy a researcher has, as one batched ``act(obs) -> actions`` that the evaluation can trust.

``evaluate_policy`` and ``continuum-gym evaluate --policy`` accept four kinds of policy:

* a callable ``obs (N, d) -> actions (N, k)`` on batched numpy arrays (CleanRL, JAX, hand-written);
* a stable-baselines3 model (anything whose ``predict(obs, deterministic=True)`` returns ``(actions, state)``);
* a ``torch.nn.Module`` whose ``forward`` maps a float32 observation batch to the deterministic action;
* any other object with ``predict(obs)`` returning actions or ``(actions, state)``.

Whatever comes back is checked on every step: the shape must be (N, k) and every value finite, else
:class:`PolicyError` names the policy, the step and the first bad row. Actions outside [-1, 1] are
clipped like the environments' action space does, and the fraction clipped is reported with the results.
"""

from __future__ import annotations

import importlib
import inspect
import sys
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike


class PolicyError(ValueError):
    """A policy returned something the environment cannot act on (wrong shape, NaN or inf)."""


class Predictor:
    """A policy adapted to batched float32 numpy observations -> float64 actions of shape (N, k)."""

    def __init__(self, policy: Any, name: str = "policy", source: str | None = None) -> None:
        self.policy = policy
        self.name = str(name)
        self.source = source  #: where the policy came from (a model file, an entry point), named in errors
        self.kind, self._act = _adapt(policy)
        self.steps = 0

    @property
    def observation_shape(self) -> tuple | None:
        """The observation shape the policy declares (SB3 models do), or None."""
        space = getattr(self.policy, "observation_space", None)
        shape = getattr(space, "shape", None)
        return tuple(shape) if shape is not None else None

    @property
    def label(self) -> str:
        """``'name' (kind[, from source])``: how errors name this policy."""
        origin = f", from {self.source}" if self.source else ""
        return f"{self.name!r} ({self.kind}{origin})"

    def act(self, observation: Any, action_dim: int) -> np.ndarray:
        """Actions (N, action_dim) for observations (N, d) (or a dict of (N, ...) arrays: an image ``obs_mode``);
        raises :class:`PolicyError` on a bad answer."""
        n = len(next(iter(observation.values()))) if isinstance(observation, dict) else observation.shape[0]
        shape = {k: v.shape for k, v in observation.items()} if isinstance(observation, dict) else observation.shape
        raw = self._act(observation)
        if isinstance(raw, tuple):  # SB3-style (actions, state)
            raw = raw[0]
        if "torch" in sys.modules and isinstance(raw, sys.modules["torch"].Tensor):
            raw = raw.detach().cpu().numpy()
        try:
            actions = np.asarray(raw, dtype=np.float64)
        except (TypeError, ValueError) as error:
            raise PolicyError(f"policy {self.label} returned {type(raw).__name__}, not numbers "
                              f"(step {self.steps})") from error
        if actions.shape != (n, action_dim):
            raise PolicyError(f"policy {self.label} returned actions of shape {actions.shape} for "
                              f"observations of shape {shape}: expected ({n}, {action_dim}) "
                              f"(step {self.steps})")
        bad = ~np.isfinite(actions).all(axis=1)
        if bad.any():
            row = int(np.flatnonzero(bad)[0])
            raise PolicyError(f"policy {self.label} returned a non-finite action at step {self.steps}, "
                              f"row {row}: {actions[row].tolist()}")
        self.steps += 1
        return actions

    def predict(self, observation: ArrayLike, state: tuple[np.ndarray, ...] | None = None,
                episode_start: np.ndarray | None = None, deterministic: bool = True
                ) -> tuple[Any, tuple[np.ndarray, ...] | None]:
        """SB3's ``predict`` signature, for code that expects an SB3 policy."""
        if not isinstance(observation, dict):
            observation = np.asarray(observation, dtype=np.float32)
        return self._act(observation), state


def as_predictor(policy: Any, name: str = "policy", source: str | None = None) -> Predictor:
    """``policy`` (callable, SB3 model, ``torch.nn.Module`` or object with ``predict``) as a :class:`Predictor`;
    ``source`` (its file or entry point) is named in its errors."""
    return policy if isinstance(policy, Predictor) else Predictor(policy, name, source)


def _adapt(policy: Any) -> tuple[str, Callable[[np.ndarray], Any]]:
    torch = sys.modules.get("torch")
    if torch is not None and isinstance(policy, torch.nn.Module):
        def act_module(observation):
            with torch.no_grad():
                return policy(torch.as_tensor(observation, dtype=torch.float32))
        return "torch.nn.Module", act_module
    predict = getattr(policy, "predict", None)
    if callable(predict):
        try:
            takes_deterministic = "deterministic" in inspect.signature(predict).parameters
        except (TypeError, ValueError):
            takes_deterministic = False
        if takes_deterministic:
            return f"{type(policy).__name__}.predict", lambda observation: predict(observation, deterministic=True)
        return f"{type(policy).__name__}.predict", predict
    if callable(policy):
        return "callable", policy
    raise TypeError(f"policy: expected a callable obs -> actions, an SB3 model, a torch.nn.Module or an object "
                    f"with predict(obs); got {type(policy).__name__}")


def load_entry_point(reference: str, **kwargs: Any) -> Any:
    """The policy made by ``"package.module:function"`` (called with ``kwargs``), or that attribute itself.

    A function is called (``make_policy()`` returns the policy); a class is instantiated; anything else
    (an already built policy object) is returned as it is.
    """
    module_name, sep, attribute = str(reference).partition(":")
    if not sep or not module_name or not attribute:
        raise ValueError(f"--policy: expected 'package.module:function', got {reference!r}")
    try:
        module = importlib.import_module(module_name)
    except ImportError as error:
        raise ValueError(f"--policy: cannot import module {module_name!r} ({error})") from error
    target = module
    for part in attribute.split("."):
        if not hasattr(target, part):
            raise ValueError(f"--policy: module {module_name!r} has no attribute {attribute!r}")
        target = getattr(target, part)
    if inspect.isfunction(target) or inspect.isclass(target):
        return target(**kwargs)
    return target


__all__ = ["PolicyError", "Predictor", "as_predictor", "load_entry_point"]
