"""Golden files: what users rely on, recorded before the inside refactor and compared bit for bit after it.

Three records (``tests/data/golden/``):

- ``env_steps.npz``: a few hundred steps of both environments through every front end (single env,
  native vector env, SB3 adapter, threaded batches) at fixed seeds and seeded random actions: obs,
  reward, terminated, truncated and every info value;
- ``reproduce.json``: ``continuum-gym reproduce --json`` (both papers, full size);
- ``evaluate.json``: ``continuum-gym evaluate --json`` on the shipped policies.

``python tests/golden.py`` writes them (only ever before a refactor, or in a commit of its own that
says why they changed); ``tests/test_golden.py`` recomputes and compares. The info layout may change
(nested ``reward_terms`` or flat ``reward_<term>`` keys map to the same canonical name), the values may not.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path

import numpy as np

GOLDEN_DIR = Path(__file__).resolve().parent / "data" / "golden"
OCCLUSION = "ContinuumGym/OcclusionAvoidance-v0"
VIEW = "ContinuumGym/ViewTracking-v0"

#: (case name, env id, front end, number of rows, steps, env kwargs).
ENV_CASES = (
    ("occlusion_default", OCCLUSION, "single", 1, 320, {}),
    ("occlusion_min_norm_random_joint", OCCLUSION, "single", 1, 200,
     {"base_controller": "minimum_norm", "task": "random", "residual_space": "joint", "visibility_guard": None}),
    ("occlusion_pure_mixed", OCCLUSION, "single", 1, 200, {"base_controller": None, "task": "mixed"}),
    ("occlusion_circle_test", OCCLUSION, "single", 1, 120, {"task": "circle", "task_split": "test",
                                                            "lens_model": "physical", "max_bend": 1.2}),
    ("occlusion_vector", OCCLUSION, "vector", 4, 200, {"task": "mixed"}),
    ("occlusion_vector_threaded", OCCLUSION, "vector", 40, 25, {"task": "random"}),
    ("occlusion_sb3", OCCLUSION, "sb3", 3, 160, {}),
    ("view_default", VIEW, "single", 1, 320, {}),
    ("view_rmrc_static_target", VIEW, "single", 1, 200,
     {"base_controller": "resolved_rate", "task": "static", "observe_target": True}),
    ("view_target_space_pan_tilt", VIEW, "single", 1, 200,
     {"residual_space": "target", "task": "pan_tilt", "residual_scale": 1.0,
      "reward_weights": {"overlap_bonus": 1.0}}),
    ("view_pure", VIEW, "single", 1, 200, {"base_controller": None}),
    ("view_rate_limits_case2", VIEW, "single", 1, 150,
     {"task": "case2", "task_split": "test", "rate_limits": [0.05, 1.0, 1.0, 2.0, 1.0, 2.0]}),
    ("view_vector", VIEW, "vector", 4, 200, {"task": "static"}),
    ("view_vector_threaded", VIEW, "vector", 40, 40, {}),
    ("view_sb3", VIEW, "sb3", 3, 160, {}),
)


def canonical_info(info: dict, prefix: str = "") -> dict:
    """Flatten an info dict to {name: array}: nested dicts and named ``reward_terms`` joined by '.',
    flat ``reward_<term>`` keys (older layouts) renamed to ``reward_terms.<term>``; ``_<key>`` masks dropped."""
    out = {}
    for key, value in info.items():
        if key.startswith("_"):
            continue
        name = f"{prefix}{key}"
        if isinstance(value, dict) or callable(getattr(value, "items", None)):  # dicts, named RewardTerms
            out.update(canonical_info(dict(value.items()), f"{name}."))
            continue
        if not prefix and key.startswith("reward_") and key != "reward_terms":
            name = f"reward_terms.{key[len('reward_'):]}"
        out[name] = np.asarray(value)
    return out


def _make(env_id, front_end, rows, kwargs):
    import gymnasium as gym

    import continuum_gym  # noqa: F401

    if front_end == "single":
        return gym.make(env_id, **kwargs)
    if front_end == "vector":
        return gym.make_vec(env_id, num_envs=rows, vectorization_mode="vector_entry_point", **kwargs)
    from continuum_gym.envs.sb3 import ContinuumSB3VecEnv

    return ContinuumSB3VecEnv(env_id, rows, seed=7, **kwargs)


def record_case(env_id, front_end, rows, steps, kwargs, seed=11) -> dict:
    """{name: stacked array} of one case: obs, reward, terminated, truncated and info per step."""
    env = _make(env_id, front_end, rows, kwargs)
    rng = np.random.default_rng([seed, rows, steps])
    # SB3's VecEnv exposes the single action space; Gymnasium's vector env the batched one.
    action_shape = (rows, *env.action_space.shape) if front_end == "sb3" else env.action_space.shape
    record: dict[str, list] = {}

    def add(name, value):
        record.setdefault(name, []).append(np.asarray(value))

    if front_end == "sb3":
        obs = env.reset()
        add("reset_obs", obs)
    else:
        obs, info = env.reset(seed=seed)
        add("reset_obs", obs)
        for key, value in canonical_info(info).items():
            add(f"reset_info.{key}", value)
    for step in range(steps):
        # Beyond [-1, 1] now and then, so clipping is recorded too; an exact zero residual every 7th step.
        action = rng.uniform(-1.2, 1.2, action_shape).astype(np.float32)
        if step % 7 == 0:
            action[:] = 0.0
        if front_end == "sb3":
            env.step_async(action)
            obs, reward, done, infos = env.step_wait()
            add("obs", obs)
            add("reward", reward)
            add("done", done)
            for i, row_info in enumerate(infos):
                for key, value in canonical_info(row_info).items():
                    # terminal_observation and TimeLimit.truncated exist only on the step that ended an episode
                    sparse = key in ("terminal_observation", "TimeLimit.truncated")
                    add(f"row{i}.{key}@{step}" if sparse else f"row{i}.{key}", value)
            continue
        obs, reward, terminated, truncated, info = env.step(action)
        add("obs", obs)
        add("reward", reward)
        add("terminated", terminated)
        add("truncated", truncated)
        for key, value in canonical_info(info).items():
            add(f"info.{key}", value)
        if front_end == "single" and (terminated or truncated):
            obs, info = env.reset()
            add(f"reset_at_{step}", obs)
    env.close()
    return {name: np.stack(values) for name, values in record.items()}


def record_env_steps() -> dict:
    """{"<case>/<name>": array} over every case of ``ENV_CASES``."""
    out = {}
    for name, env_id, front_end, rows, steps, kwargs in ENV_CASES:
        for key, value in record_case(env_id, front_end, rows, steps, kwargs).items():
            out[f"{name}/{key}"] = value
    return out


def run_reproduce() -> dict:
    """``continuum-gym reproduce --json`` (full size), without its wall times."""
    from continuum_gym.cli import main

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "reproduce.json"
        if main(["reproduce", "--out", tmp, "--json", str(path)]) != 0:
            raise RuntimeError("continuum-gym reproduce failed")
        result = json.loads(path.read_text())
    result.pop("seconds", None)
    return result


def run_evaluate(extra=()) -> dict:
    """``continuum-gym evaluate --json`` on the shipped policies (default episodes and grid)."""
    from continuum_gym.cli import main

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "evaluate.json"
        if main(["evaluate", "--out", tmp, "--json", str(path), "--no-progress", *extra]) != 0:
            raise RuntimeError("continuum-gym evaluate failed")
        result = json.loads(path.read_text())
    result.pop("metadata", None)  # revision, versions and timings: not results
    return result


def differences(expected, actual, path="") -> list:
    """Paths where ``actual`` differs from ``expected`` (exact float equality; extra keys in ``actual`` are
    additions and allowed)."""
    if isinstance(expected, dict):
        if not isinstance(actual, dict):
            return [f"{path}: expected a dict, got {type(actual).__name__}"]
        found = []
        for key, value in expected.items():
            if key not in actual:
                found.append(f"{path}/{key}: missing")
            else:
                found.extend(differences(value, actual[key], f"{path}/{key}"))
        return found
    if isinstance(expected, list):
        if not isinstance(actual, list) or len(actual) != len(expected):
            return [f"{path}: expected a list of {len(expected)}"]
        found = []
        for k, (a, b) in enumerate(zip(expected, actual)):
            found.extend(differences(a, b, f"{path}[{k}]"))
        return found
    same = expected == actual or (isinstance(expected, float) and isinstance(actual, float)
                                   and np.isnan(expected) and np.isnan(actual))
    return [] if same else [f"{path}: {expected!r} != {actual!r}"]


def array_differences(expected: dict, actual: dict) -> list:
    """Keys of ``expected`` whose arrays differ from ``actual``'s in shape or any bit of any value."""
    found = []
    for key, value in expected.items():
        if key not in actual:
            found.append(f"{key}: missing")
            continue
        other = np.asarray(actual[key])
        value = np.asarray(value)
        if other.shape != value.shape:
            found.append(f"{key}: shape {value.shape} != {other.shape}")
        elif value.dtype.kind in "fc" or other.dtype.kind in "fc":
            a = value.astype(np.float64)
            b = other.astype(np.float64)
            if a.tobytes() != b.tobytes():
                worst = np.nanmax(np.abs(a - b)) if a.size else 0.0
                found.append(f"{key}: values differ (max |diff| {worst:.3g})")
        elif not np.array_equal(value, other):
            found.append(f"{key}: values differ")
    return found


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", choices=("env_steps", "reproduce", "evaluate"), nargs="+",
                        default=("env_steps", "reproduce", "evaluate"))
    parser.add_argument("--check", action="store_true", help="compare with the stored files instead of writing")
    args = parser.parse_args(argv)
    GOLDEN_DIR.mkdir(parents=True, exist_ok=True)
    failed = False
    for part in args.only:
        if part == "env_steps":
            result = record_env_steps()
            path = GOLDEN_DIR / "env_steps.npz"
            if args.check:
                with np.load(path) as stored:
                    problems = array_differences(dict(stored), result)
            else:
                np.savez_compressed(path, **result)
        else:
            result = run_reproduce() if part == "reproduce" else run_evaluate()
            path = GOLDEN_DIR / f"{part}.json"
            if args.check:
                problems = differences(json.loads(path.read_text()), result)
            else:
                path.write_text(json.dumps(result, indent=1) + "\n")
        if args.check:
            failed |= bool(problems)
            print(f"{part}: {'identical' if not problems else f'{len(problems)} differences'}")
            for line in problems[:20]:
                print("   ", line)
        else:
            print(f"wrote {path}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
