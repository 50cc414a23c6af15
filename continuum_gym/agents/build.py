"""A training run's model, wrapped env and callbacks (``train`` writes the run directory around them).

``build`` makes the SB3 model (new, zero-initialised as a residual, or loaded from a checkpoint unit), wraps the
native vector env in SB3's ``VecMonitor`` (and ``VecNormalize`` for rewards), and the callbacks in the order they
must run: the actor's burn-in, the checkpoints, the evaluation on validation tasks.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from continuum_gym.agents.evaluation_callback import history_until, make_eval_callback
from continuum_gym.agents.run_inputs import SCHEDULE_KEYS, schedule_initial


def algo_class(algo: str) -> type:
    """The stable-baselines3 class of ``ppo``, ``sac`` or ``td3``."""
    from stable_baselines3 import PPO, SAC, TD3

    return {"ppo": PPO, "sac": SAC, "td3": TD3}[algo]


def linear_schedule(value: float | str, name: str) -> float | Callable[[float], float]:
    """rl-zoo's ``lin_<x>``: decay linearly from x to 0 over the run (SB3 passes the remaining fraction)."""
    if not isinstance(value, str):
        return value
    if not value.startswith("lin_"):
        raise ValueError(f"{name} must be a number or 'lin_<initial value>'; got {value!r}")
    initial = schedule_initial(value, name)
    from stable_baselines3.common.utils import LinearSchedule

    return LinearSchedule(initial, 0.0, 1.0)


def build(env_id: str, algo: str, base: str | None, seed: int, total: int, run: dict, env_kwargs: dict, venv: Any,
          run_dir: Path, unit: Any, report: Callable[[int, float], None] | None) -> tuple[Any, Any, Any, list]:
    """Model (new or from ``unit``), wrapped env and callbacks [burn-in, checkpoints, evaluation]."""
    from stable_baselines3.common.noise import NormalActionNoise
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    from continuum_gym.agents.checkpoint import (
        BURN_IN_ACTOR,
        CHECKPOINTS,
        NORMALIZER,
        CheckpointCallback,
        load_model,
    )
    from continuum_gym.agents.residual import (
        ActorBurnIn,
        actor_parameters,
        zero_init_residual,
    )

    venv = VecMonitor(venv)
    venv.seed(seed)
    if run["normalize_reward"]:
        # Returns of long episodes reach the hundreds; the critic learns scaled returns. Observations are
        # already normalised by the environment, and the policy never needs these statistics at test time.
        saved = unit.file(NORMALIZER) if unit is not None else None
        venv = VecNormalize.load(str(saved), venv) if saved else VecNormalize(
            venv, norm_obs=False, norm_reward=True, gamma=float(run.get("gamma", 0.99)))
    cls = algo_class(algo)
    if unit is not None:
        model = load_model(unit, cls, venv, device="cpu", tensorboard_log=str(run_dir / "tb"))
        # SB3's load reseeds with the run's seed, which would replay step 0's task sequence: continue
        # with a stream of its own, the same for every resume from this unit.
        model.set_random_seed(int(np.random.SeedSequence([seed, unit.step]).generate_state(1)[0] % 2**31))
        state = {} if unit.legacy else unit.state()
    else:
        algo_kwargs = {k: algo_value(k, v) for k, v in run.items() if k in algo_keys(cls)}
        if algo == "td3" and run.get("action_noise_std"):
            dim = venv.action_space.shape[0]
            sigma = float(run["action_noise_std"]) * np.ones(dim)
            algo_kwargs["action_noise"] = NormalActionNoise(np.zeros(dim), sigma)
        model = cls(run.get("policy", "MlpPolicy"), venv, seed=seed, verbose=0, device="cpu",
                    tensorboard_log=str(run_dir / "tb"), **algo_kwargs)
        if base is not None:
            zero_init_residual(model)
        state = {}
    history = state.get("evaluations") if unit is None or not unit.legacy else history_until(
        run_dir / "evaluations.npz", unit.step)
    # what the run has cost so far, earlier sessions included (a checkpoint carries both): wall-clock seconds and
    # this process's CPU seconds (every thread: the learner's, the env's step threads, the evaluations). A checkpoint
    # written before a count was kept leaves it unknown (NaN) for the rest of the run, not restarted from zero.
    unknown = float("nan") if unit is not None else 0.0
    elapsed_before, cpu_before = (float(state.get(key, unknown)) for key in ("elapsed_s", "cpu_s"))
    started, cpu_started = time.monotonic(), time.process_time()

    def cost() -> tuple[float, float]:
        return elapsed_before + time.monotonic() - started, cpu_before + time.process_time() - cpu_started

    # its class is local to make_eval_callback (write(), records())
    evaluator: Any = make_eval_callback(env_id, dict(env_kwargs), run_dir, int(run["eval_freq"]),
                                        int(run["n_eval_episodes"]), report, history=history,
                                        helpers=run.get("helpers") or (), cost=cost)
    if unit is not None:
        evaluator.write()  # the curve as of the checkpoint: rows of the lost stretch go
    burn_steps = int(run["burn_in_steps"]) if base is not None else 0
    burn_in = None
    if burn_steps > 0:
        snapshot = None
        if unit is not None and unit.file(BURN_IN_ACTOR):
            snapshot = ActorBurnIn.load_snapshot(unit.file(BURN_IN_ACTOR))
        elif unit is not None and unit.legacy:
            snapshot = [p.detach().clone() for p in actor_parameters(model)]
        burn_in = ActorBurnIn(burn_steps, snapshot=snapshot)
    def extra_state() -> dict:
        elapsed_s, cpu_s = cost()
        return {"algo": algo, "seed": seed, "total_timesteps": total, "elapsed_s": elapsed_s, "cpu_s": cpu_s,
                "evaluations": evaluator.records(), "burn_in_steps": burn_steps}

    def extra_files() -> dict:
        if burn_in is not None and model.num_timesteps <= burn_steps:
            return {BURN_IN_ACTOR: burn_in.save_snapshot}
        return {}

    saver = CheckpointCallback(run_dir / CHECKPOINTS, int(run["checkpoint_freq"]), float(run["checkpoint_minutes"]),
                               int(run["keep_checkpoints"]), state=extra_state, files=extra_files)
    # Burn-in first: at a rollout start it restores the actor before the checkpoint is written.
    callbacks = ([burn_in] if burn_in is not None else []) + [saver, evaluator]
    return model, venv, saver, callbacks


def algo_value(key: str, value: Any) -> Any:
    """A checked hyperparameter as the algorithm takes it (YAML has lists, SB3 wants a train_freq tuple)."""
    if key in SCHEDULE_KEYS:
        return linear_schedule(value, key)
    if key == "train_freq" and isinstance(value, list):
        return tuple(value)
    if key == "policy_kwargs" and isinstance(value, dict) and isinstance(value.get("features_extractor_class"), str):
        from continuum_gym.plugins import load_object  # YAML names the class "module:Class" (pixel policies)

        return {**value, "features_extractor_class": load_object(value["features_extractor_class"])}
    return value


def algo_keys(cls: type) -> set:
    from continuum_gym.agents.run_inputs import algorithm_parameters

    return set(algorithm_parameters(cls)) - {"policy"}


__all__ = ["algo_class", "build", "linear_schedule", "algo_value", "algo_keys"]
