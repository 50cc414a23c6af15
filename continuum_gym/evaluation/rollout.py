"""Run any ``predict`` (SB3 model, zero residual, random) on fixed task instances through a batched core.

One path for every method: the core of an environment steps all episodes at once; the policy sees
the flat observations as SB3 would. The core's per-step values are reduced to per-episode metrics as
its spec says (``EnvSpec.episode_metrics``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any, Protocol

import numpy as np
from numpy.typing import ArrayLike

from continuum_gym.envs.batched import BatchedCore
from continuum_gym.envs.helpers import apply_helpers
from continuum_gym.envs.spec import get_spec, registered_kwargs


class Progress(Protocol):
    """What :func:`run_episodes` updates once per step: a ``tqdm`` bar, for one."""

    def update(self, n: int = 1) -> object: ...


class ZeroResidual:
    """The analytic baseline inside a residual env: always a zero action (SB3 ``predict`` signature)."""

    def __init__(self, action_dim: int) -> None:
        self.action_dim = int(action_dim)

    def predict(self, observation: ArrayLike, state: tuple[np.ndarray, ...] | None = None,
                episode_start: np.ndarray | None = None, deterministic: bool = False
                ) -> tuple[np.ndarray, tuple[np.ndarray, ...] | None]:
        if isinstance(observation, dict):  # an image obs_mode: the measured state sets the batch shape
            observation = observation["state"]
        observation = np.asarray(observation)
        return np.zeros(observation.shape[:-1] + (self.action_dim,), dtype=np.float32), state


def make_core(env_id: str, num_envs: int, **env_kwargs: Any) -> BatchedCore:
    """A batched core of ``env_id`` with ``num_envs`` rows (any id registered to the library's entry points).

    A user's registered id is built as ``gym.make`` builds it: its registered keyword arguments, then
    ``env_kwargs`` over them.
    """
    return get_spec(env_id).make_core(num_envs, **{**registered_kwargs(env_id), **env_kwargs})


def run_episodes(core: BatchedCore, policy: Any, task_ids: ArrayLike, progress: Progress | None = None,
                 record: bool = False, helpers: Sequence[Callable[..., np.ndarray]] = (),
                 pixel_metrics: bool = False) -> dict[str, np.ndarray]:
    """Run one episode per task id (all in one batch) until each ends; returns per-episode metrics.

    Args:
        core: a batched core with ``num_envs == len(task_ids)``.
        policy: any policy :func:`~continuum_gym.evaluation.policies.as_predictor` takes (SB3 model,
            batched callable, ``torch.nn.Module``, object with ``predict``); its answers are checked.
        task_ids: task instance per row.
        progress: optional tqdm-like object updated once per step.
        record: also return per-step traces (``trace_<value>`` arrays of shape (steps, N), NaN after the end).
        helpers: helpers made for ``core``'s config (``envs.helpers.make_helpers``), applied in order to the
            clipped actions before each step.
        pixel_metrics: also measure the env's pixel metrics (``envs/pixels.py``; e.g. ``mean_image_occlusion``),
            rendering every step; a core whose ``obs_mode`` is an image mode always does, its policy sees the
            images.

    Returns:
        dict of metric name -> (N,) array (the spec's episode metrics), plus ``return``, ``length`` and
        ``action_clipped_fraction`` (the fraction of action components outside [-1, 1], clipped).
    """
    from continuum_gym.evaluation.policies import as_predictor

    predictor = as_predictor(policy)
    task_ids = np.asarray(task_ids, dtype=np.int64)
    n = len(task_ids)
    if core.num_envs != n:
        raise ValueError(f"core has {core.num_envs} rows for {n} task ids")
    spec = core.spec
    observer = _observer(core, pixel_metrics)
    core.reset_rows(np.arange(n), task_ids)
    active = np.ones(n, dtype=np.uint8)
    faulted = core.non_finite().copy()  # rows with a value that is not finite (on_non_finite="truncate")
    sums: dict = {}
    finals: dict = {}
    counts = np.zeros(n)
    returns = np.zeros(n)
    traces: dict = {}
    clipped = np.zeros(n)
    action_dim = core.single_action_space.shape[0]
    while active.any():
        observation = core.observations(copy=False)  # the images of an image obs_mode (core.pixels), or the state
        actions = predictor.act(observation, action_dim)
        outside = np.abs(actions) > 1.0
        clipped[active.astype(bool)] += outside.mean(axis=1)[active.astype(bool)]
        actions = apply_helpers(helpers, core.obs, np.clip(actions, -1.0, 1.0), active)
        rewards, terminated, truncated = core.step(np.ascontiguousarray(actions), active)
        alive = active.astype(bool)
        values = core.step_values()
        if observer is not None:
            if observer is not core.pixels:  # the metrics' own observer: the core marks only its own
                observer.stale(alive)
            values.update(observer.info())
        for key, value in values.items():
            sums.setdefault(key, np.zeros(n))[alive] += value[alive]
            finals.setdefault(key, np.zeros(n))[alive] = value[alive]
            if record:
                traces.setdefault(key, []).append(np.where(alive, value, np.nan))
        returns[alive] += rewards[alive]
        counts[alive] += 1
        faulted |= alive & core.non_finite()
        active[alive & (terminated | truncated)] = 0
        if progress is not None:
            progress.update(1)
    if faulted.any():
        from continuum_gym.envs.faults import NonFiniteError

        raise NonFiniteError(
            f"{spec.env_id}: {int(faulted.sum())} of {n} episode(s) (task ids {task_ids[faulted][:8].tolist()}) had a "
            "value that is not finite (info['non_finite']); their metrics are not numbers, and an average without "
            "them would hide the failure, so none is reported. Find the plug-in with on_non_finite='raise' (the "
            "default), which names it")
    out = {}
    reductions = spec.episode_metrics + (observer.spec.episode_metrics if observer is not None else ())
    for metric in reductions:
        if metric.reduce == "final":
            out[metric.name] = finals[metric.step_value]
        else:
            out[metric.name] = sums[metric.step_value] / np.maximum(counts, 1)
    out["return"] = returns
    out["length"] = counts
    out["action_clipped_fraction"] = clipped / np.maximum(counts, 1)
    if record:
        out.update({f"trace_{key}": np.array(value) for key, value in traces.items()})
    return out


def _observer(core: BatchedCore, pixel_metrics: bool) -> Any:
    """What measures the pixel metrics: the core's own observer (an image ``obs_mode``), one that renders only what
    the metrics need (``pixel_metrics`` of a state core), else None."""
    from continuum_gym.envs.pixels import PixelObserver

    if core.pixels is not None or not pixel_metrics:
        return core.pixels
    return PixelObserver(core)
