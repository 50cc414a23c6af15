"""Environment speed: single envs beside CartPole-v1, SyncVectorEnv beside the native vector env.

    python benchmarks/envs.py [--json PATH] [--quick]

JSON keys (steps per second): ``single.<id>``, ``cartpole``, ``sync64.<id>``, ``native.<id>.<N>``, plus
``profile.<id>`` (microseconds per step spent in the compiled kernel, the core wrapper, the env API and
Gymnasium's wrappers) and ``guard.off`` / ``guard.on`` (OcclusionAvoidance N=64 under random residual actions,
visibility guard off / on).
``units`` maps each key (pattern) to its unit; ``source`` is the ``continuum_gym`` that was timed.
The memory of a 4096-robot vector env is ``memory.py``'s: measured here, after the rows above, it would
include what the allocator kept from them.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import gymnasium as gym
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import finish, machine, print_table  # noqa: E402

import continuum_gym  # noqa: E402

#: Unit of every numeric result key (fnmatch patterns over the flattened, dot-joined keys), so that a
#: comparison across revisions (benchmarks/compare.py) knows which direction is better. "(derived)"
#: marks differences of separately timed quantities: they are shown, never judged.
UNITS = {
    "cartpole": "steps/s (control)",  # Gymnasium's own env: the same code in every revision
    "single.*": "steps/s",
    "sync64.*": "steps/s",
    "native.*": "steps/s",
    "guard.*": "steps/s",
    "profile.*.core_step_us": "us",
    "profile.*.env_step_us": "us",
    "profile.*.wrapped_step_us": "us",
    "profile.*.wrappers_us": "us (derived)",
    "profile.*.env_api_us": "us (derived)",
    "peak_rss_mib": "MiB",
    "machine.*": "info",
}


def rate(step, seconds, warmup=20):
    for _ in range(warmup):
        step()
    count = 0
    start = time.perf_counter()
    while time.perf_counter() - start < seconds:
        step()
        count += 1
    return count / (time.perf_counter() - start)


def single_env_rate(env_id, seconds):
    env = gym.make(env_id)
    env.reset(seed=0)
    zero = 0 if isinstance(env.action_space, gym.spaces.Discrete) else np.zeros(env.action_space.shape, np.float32)

    def step():
        _, _, terminated, truncated, _ = env.step(zero)
        if terminated or truncated:
            env.reset()

    return rate(step, seconds), env


def vector_rate(venv, n, seconds):
    venv.reset(seed=0)
    zero = np.zeros((n,) + venv.single_action_space.shape, dtype=np.float32)
    return rate(lambda: venv.step(zero), seconds) * n


def guard_cost(seconds, n=64):
    """OcclusionAvoidance native N=64 under random residual actions, visibility guard on vs off (same run).

    Zero actions never reach the guard; a residual that turns the endoscope does, at every substep.
    """
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1, 1, (256, n, 8)).astype(np.float32)
    out = {}
    for guard in (None, 0.69):
        venv = gym.make_vec("ContinuumGym/OcclusionAvoidance-v0", num_envs=n, vectorization_mode="vector_entry_point",
                            visibility_guard=guard)
        venv.reset(seed=0)
        counter = iter(range(10**9))
        out[guard] = rate(lambda: venv.step(actions[next(counter) % 256]), seconds) * n
    return out[None], out[0.69]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--json", help="write results to this JSON file")
    parser.add_argument("--quick", action="store_true", help="short timings (smoke test)")
    args = parser.parse_args(argv)
    seconds = 0.5 if args.quick else 3.0
    results = {"machine": machine(), "unit": "environment steps per second", "units": UNITS,
               "source": continuum_gym.__file__}
    rows = []
    cartpole, _ = single_env_rate("CartPole-v1", seconds)
    results["cartpole"] = cartpole
    rows.append(("CartPole-v1", "single", f"{cartpole:,.0f}", "1.00x"))
    for env_id in continuum_gym.ENV_IDS:
        single, env = single_env_rate(env_id, seconds)
        results[f"single.{env_id}"] = single
        rows.append((env_id, "single", f"{single:,.0f}", f"{single / cartpole:.2f}x CartPole"))
        # Where one step goes.
        core = env.unwrapped.core
        action = np.zeros((1,) + env.action_space.shape)
        active = np.ones(1, dtype=np.uint8)
        env.reset(seed=0)
        kernel = 1e6 / rate(lambda: core.step(action, active) if core.steps[0] < 50 else core.reset_rows(
            np.array([0]), np.array([0])), seconds)
        unwrapped = env.unwrapped
        unwrapped.reset(seed=0)
        zero = np.zeros(env.action_space.shape, dtype=np.float32)

        def raw_step():
            _, _, te, tr, _ = unwrapped.step(zero)
            if te or tr:
                unwrapped.reset()

        api = 1e6 / rate(raw_step, seconds)
        results[f"profile.{env_id}"] = {"core_step_us": kernel, "env_step_us": api, "wrapped_step_us": 1e6 / single,
                                        "wrappers_us": 1e6 / single - api, "env_api_us": api - kernel}
        sync = gym.make_vec(env_id, num_envs=64, vectorization_mode="sync")
        sync_rate = vector_rate(sync, 64, seconds)
        results[f"sync64.{env_id}"] = sync_rate
        rows.append((env_id, "SyncVectorEnv N=64", f"{sync_rate:,.0f}", "1.00x sync"))
        for n in (1, 64, 1024):
            native = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point")
            value = vector_rate(native, n, seconds)
            results[f"native.{env_id}.{n}"] = value
            rows.append((env_id, f"native N={n}", f"{value:,.0f}", f"{value / sync_rate:.2f}x sync"))
    unguarded, guarded = guard_cost(seconds)
    results["guard.off"], results["guard.on"] = unguarded, guarded
    rows.append(("ContinuumGym/OcclusionAvoidance-v0", "N=64 random actions, guard off", f"{unguarded:,.0f}", "1.00x"))
    rows.append(("ContinuumGym/OcclusionAvoidance-v0", "N=64 random actions, guard on", f"{guarded:,.0f}",
                 f"{guarded / unguarded:.2f}x"))
    print_table(rows, ["environment", "mode", "steps/s", "relative"])
    for env_id in continuum_gym.ENV_IDS:
        p = results[f"profile.{env_id}"]
        print(f"{env_id}: one step {p['wrapped_step_us']:.0f} us = kernel+core {p['core_step_us']:.0f} us + env API "
              f"{p['env_api_us']:.0f} us + Gymnasium wrappers {p['wrappers_us']:.0f} us")
    return finish(results, args.json)


if __name__ == "__main__":
    sys.exit(main())
