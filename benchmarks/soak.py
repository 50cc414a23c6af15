"""Soak: 10^7 random robot-steps per environment over every controller, task family and limit setting.

Every configuration runs on the native vector env (autoreset on) with uniform random actions in
[-1, 1] drawn from one seeded generator; every step's observations, rewards and floating-point info
entries are checked finite and the observations inside the observation space. The run fails (exit 1)
on the first violation and reports the configuration and row.

    python benchmarks/soak.py --steps 1e7 --json results/bench/soak.json
    python benchmarks/soak.py --steps 1e6 --model-error mild severe  # per preset (issue 37)

With ``--model-error`` every configuration runs under each preset given (every other one with
``randomize_model_error=True``), ``--steps`` robot-steps per environment and preset.
"""

from __future__ import annotations

import argparse
import itertools
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import finish, machine, peak_rss_mib  # noqa: E402

import continuum_gym  # noqa: E402, F401  (registers the ids)

OCCLUSION = "ContinuumGym/OcclusionAvoidance-v0"
VIEW = "ContinuumGym/ViewTracking-v0"
CONFIGS = {
    OCCLUSION: [dict(base_controller=base, task=task, **limits, residual_space=space)
                for base, task, limits, space in itertools.product(
                    ["projected_gradient", "minimum_norm", None], ["random", "hold", "mixed"],
                    [{}, {"max_bend": 0.6, "insertion": (0.0, 0.01)}, {"bend_rate": 0.2, "gamma_rate": 0.1}],
                    ["nullspace", "joint"])
                if not (base is None and space == "nullspace")],
    VIEW: [dict(base_controller=base, task=task, **limits, residual_space=space)
           for base, task, limits, space in itertools.product(
               ["dimension_reduced", "resolved_rate", None], ["random", "static", "pan_tilt"],
               [{}, {"rate_limits": (0.02, 0.5, 0.5, 0.5, 0.5, 0.5)}], ["joint", "target"])
           if not (base is None and space == "target")],
}


def soak(env_id: str, config: dict, steps: int, rows: int, rng: np.random.Generator) -> dict:
    import gymnasium as gym

    env = gym.make_vec(env_id, num_envs=rows, vectorization_mode="vector_entry_point", **config)
    space = env.single_observation_space
    obs, _ = env.reset(seed=int(rng.integers(2**31)))
    episodes = 0
    for _ in range(max(1, steps // rows)):
        actions = rng.uniform(-1, 1, env.action_space.shape).astype(np.float32)
        obs, reward, terminated, truncated, info = env.step(actions)
        outside = ((obs < space.low) | (obs > space.high)).any(axis=1)
        bad = ~np.isfinite(obs).all(axis=1) | ~np.isfinite(reward) | outside
        for key, value in info.items():
            value = np.asarray(value)
            if not key.startswith("_") and value.dtype.kind == "f":
                bad |= ~np.isfinite(value.reshape(rows, -1)).all(axis=1)
        if bad.any():
            raise AssertionError(f"{env_id} {config}: row {int(np.flatnonzero(bad)[0])} non-finite or out of space")
        episodes += int((terminated | truncated).sum())
    env.close()
    return {"robot_steps": max(1, steps // rows) * rows, "episodes": episodes}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=float, default=1e7, help="robot-steps per environment (default 1e7)")
    parser.add_argument("--rows", type=int, default=256, help="rows of the vector env")
    parser.add_argument("--env", nargs="+", default=list(CONFIGS))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", default=None)
    parser.add_argument("--model-error", nargs="+", default=None, choices=("none", "mild", "severe"),
                        help="run every configuration under these model-error presets (--steps per preset)")
    args = parser.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    results = {"machine": machine(), "steps_per_env": int(args.steps)}
    for env_id, preset in itertools.product(args.env, args.model_error or [None]):
        configs = CONFIGS[env_id] if preset is None else [
            dict(config, model_error=preset, randomize_model_error=preset != "none" and k % 2 == 1)
            for k, config in enumerate(CONFIGS[env_id])]
        per_config = int(args.steps) // len(configs)
        started = time.perf_counter()
        total = {"robot_steps": 0, "episodes": 0, "configurations": len(configs), "non_finite": 0}
        for config in configs:
            out = soak(env_id, config, per_config, args.rows, rng)
            total["robot_steps"] += out["robot_steps"]
            total["episodes"] += out["episodes"]
        total["seconds"] = round(time.perf_counter() - started, 1)
        label = env_id if preset is None else f"{env_id} model_error={preset}"
        print(f"{label}: {total['robot_steps']:,} robot-steps, {total['episodes']:,} episodes over "
              f"{len(configs)} configurations, 0 non-finite, {total['seconds']} s", flush=True)
        results[env_id if preset is None else f"{env_id} {preset}"] = total
    results["peak_rss_mib"] = round(peak_rss_mib(), 1)
    return finish(results, args.json)


if __name__ == "__main__":
    sys.exit(main())
