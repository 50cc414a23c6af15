"""Run any ``predict`` (SB3 model, zero residual, random) on fixed task instances through a batched core.

One path for every method: the core of an environment steps all episodes at once; the policy sees
the flat observations as SB3 would. Per-step metrics are accumulated into per-episode metrics.
"""

from __future__ import annotations

import numpy as np

from continuum_gym.envs.tasks import VISIBILITY_FRACTION

OCCLUSION_METRICS = ("mean_voi", "tip_in_view_fraction", "mean_tip_error_m", "mean_orientation_error_rad")
VIEW_METRICS = ("mean_or", "or_above_0.8_fraction", "mean_position_error_m", "final_or")


class ZeroResidual:
    """The analytic baseline inside a residual env: always a zero action (SB3 ``predict`` signature)."""

    def __init__(self, action_dim: int):
        self.action_dim = int(action_dim)

    def predict(self, observation, state=None, episode_start=None, deterministic=False):
        observation = np.asarray(observation)
        return np.zeros(observation.shape[:-1] + (self.action_dim,), dtype=np.float32), state


def make_core(env_id: str, num_envs: int, **env_kwargs):
    from continuum_gym.envs.sb3 import core_class

    return core_class(env_id)(num_envs=num_envs, **env_kwargs)


def run_episodes(core, policy, task_ids, progress=None, record=False) -> dict:
    """Run one episode per task id (all in one batch) until each ends; returns per-episode metrics.

    Args:
        core: a batched core with ``num_envs == len(task_ids)``.
        policy: anything with SB3's ``predict(obs, deterministic=True)``.
        task_ids: task instance per row.
        progress: optional tqdm-like object updated once per step.
        record: also return per-step traces (``trace_<metric>`` arrays of shape (steps, N), NaN after the end).

    Returns:
        dict of metric name -> (N,) array, plus ``return`` and ``length``.
    """
    task_ids = np.asarray(task_ids, dtype=np.int64)
    n = len(task_ids)
    if core.num_envs != n:
        raise ValueError(f"core has {core.num_envs} rows for {n} task ids")
    core.reset_rows(np.arange(n), task_ids)
    occlusion = "voi" in core.info()
    active = np.ones(n, dtype=np.uint8)
    sums = {}
    counts = np.zeros(n)
    returns = np.zeros(n)
    traces = {}
    final = {}
    while active.any():
        actions, _ = policy.predict(core.obs.astype(np.float32), deterministic=True)
        actions = np.clip(np.asarray(actions, dtype=np.float64).reshape(n, -1), -1.0, 1.0)
        rewards, terminated, truncated = core.step(np.ascontiguousarray(actions), active)
        alive = active.astype(bool)
        info = core.info()
        if occlusion:
            step_metrics = {"voi": info["voi"], "in_view": (info["tip_view_fraction"] <= VISIBILITY_FRACTION) * 1.0,
                            "tip_error": info["tip_error_m"], "orientation_error": info["orientation_error_rad"],
                            "guarded": info["visibility_guarded"] * 1.0}
        else:
            step_metrics = {"or": info["overlap_ratio"], "or_above": (info["overlap_ratio"] > 0.8) * 1.0,
                            "position_error": info["position_error_m"]}
        for key, value in step_metrics.items():
            sums.setdefault(key, np.zeros(n))[alive] += value[alive]
            if record:
                traces.setdefault(key, []).append(np.where(alive, value, np.nan))
        if not occlusion:
            final_or = final.setdefault("or", np.zeros(n))
            final_or[alive] = info["overlap_ratio"][alive]
        returns[alive] += rewards[alive]
        counts[alive] += 1
        active[alive & (terminated | truncated)] = 0
        if progress is not None:
            progress.update(1)
    mean = {key: value / np.maximum(counts, 1) for key, value in sums.items()}
    if occlusion:
        out = {"mean_voi": mean["voi"], "tip_in_view_fraction": mean["in_view"], "mean_tip_error_m": mean["tip_error"],
               "mean_orientation_error_rad": mean["orientation_error"],
               "visibility_guarded_fraction": mean["guarded"]}
    else:
        out = {"mean_or": mean["or"], "or_above_0.8_fraction": mean["or_above"],
               "mean_position_error_m": mean["position_error"], "final_or": final["or"]}
    out["return"] = returns
    out["length"] = counts
    if record:
        out.update({f"trace_{key}": np.array(value) for key, value in traces.items()})
    return out
