"""The env step with image observations (issue 56) beside the state step: rows per second of the native vector
env and steps per second of the single env, per observation mode.

    python benchmarks/pixel_envs.py [--json PATH] [--quick] [--num-envs 256] [--threads 2] [--size 64]

For each environment and ``obs_mode`` in (state, rgbd, rgb+depth+segmentation): ``gym.make_vec(id,
num_envs=N, obs_mode=..., image_size=size, num_threads=threads)`` stepped with random actions (autoreset on),
best of several timed windows, by wall clock and per CPU second of this process (what one core does: on a
shared machine the wall rate falls with the cores the threads get; the CPU rate does not); then the single env
(``gym.make``) the same way. An image step is the state step, the scene built from every row's state and one
render call per view (ViewTracking renders two), and fresh arrays of the observation.

JSON keys: ``vector.<env>.<mode>.{rows_per_second,rows_per_cpu_second}``, ``single.<env>.<mode>.steps_per_second``,
``ratio.<env>.<mode>`` (state rows per CPU second / this mode's).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

import gymnasium as gym
import numpy as np

import continuum_gym  # noqa: F401

ENVS = ("ContinuumGym/OcclusionAvoidance-v0", "ContinuumGym/ViewTracking-v0")
MODES = ("state", "rgbd", "rgb+depth+segmentation")


def best_rate(fn, count: int, seconds: float, windows: int = 3) -> tuple[float, float]:
    """(count per wall second, count per CPU second), each the best of ``windows`` windows."""
    fn()
    wall = cpu = 0.0
    for _ in range(windows):
        calls, w, c = 0, time.perf_counter(), time.process_time()
        while time.perf_counter() - w < seconds:
            fn()
            calls += 1
        wall = max(wall, calls * count / (time.perf_counter() - w))
        cpu = max(cpu, calls * count / max(time.process_time() - c, 1e-9))
    return wall, cpu


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json")
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--num-envs", type=int, default=256)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--size", type=int, default=64)
    args = parser.parse_args(argv)
    seconds = 0.3 if args.quick else 2.0
    n = args.num_envs
    results: dict = {"num_envs": n, "threads": args.threads, "size": args.size, "load_average": os.getloadavg()}
    print(f"N = {n}, {args.size} x {args.size}, {args.threads} threads, load average {os.getloadavg()[0]:.2f}")
    print("| env | obs_mode | vector rows/s (wall) | rows per CPU s | state / mode (CPU) | single env steps/s |")
    print("|---|---|---|---|---|---|")
    for env_id in ENVS:
        name = env_id.split("/")[1].split("-")[0]
        for mode in MODES:
            kwargs = {} if mode == "state" else {"obs_mode": mode, "image_size": args.size}
            venv = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point",
                                num_threads=args.threads, **kwargs)
            venv.reset(seed=0)
            actions = np.random.default_rng(0).uniform(-1, 1, (8, n) + venv.single_action_space.shape)
            k = iter(range(10**9))
            wall, cpu = best_rate(lambda: venv.step(actions[next(k) % 8]), n, seconds)
            venv.close()
            env = gym.make(env_id, **kwargs)
            env.reset(seed=0)

            def single():
                _, _, terminated, truncated, _ = env.step(env.action_space.sample())
                if terminated or truncated:
                    env.reset()

            single_rate, _ = best_rate(single, 1, seconds)
            results[f"vector.{name}.{mode}"] = {"rows_per_second": wall, "rows_per_cpu_second": cpu}
            results[f"single.{name}.{mode}.steps_per_second"] = single_rate
            state = results[f"vector.{name}.state"]["rows_per_cpu_second"]
            results[f"ratio.{name}.{mode}"] = state / cpu
            print(f"| {name} | {mode} | {wall:,.0f} | {cpu:,.0f} | {state / cpu:.1f}x | {single_rate:,.0f} |")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(results, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
