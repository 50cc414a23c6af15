"""``continuum-gym train``: residual (or pure) RL with stable-baselines3 on the native vector env.

Each run directory holds ``config.yml`` (fully resolved), ``args.yml``, ``command.txt``, TensorBoard
logs, ``evaluations.npz`` (held-out learning curve), ``checkpoints/latest.zip`` (+ replay buffer for
off-policy learners, written atomically) and ``model.zip`` at the end. ``--resume`` continues from the
latest checkpoint with optimizer (and replay) state and the step count; without it an existing run
is never overwritten.
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import yaml

from continuum_gym.envs.spec import ENV_SPECS, get_spec
from continuum_gym.evaluation.io import write_text_atomic

ALGOS = ("ppo", "sac", "td3")
HYPERPARAMS_DIR = Path(__file__).resolve().parent / "hyperparams"
# Keys of a hyperparameter block that are not arguments of the SB3 algorithm.
RUN_KEYS = ("n_timesteps", "n_envs", "env_kwargs", "residual_scale", "burn_in_steps", "eval_freq", "n_eval_episodes",
            "checkpoint_freq", "policy", "action_noise_std", "normalize_reward")
EVAL_TASK_OFFSET = 0
# Hyperparameters that may be given as rl-zoo's linear schedules, "lin_<initial value>".
SCHEDULE_KEYS = ("learning_rate", "clip_range")


def run_name(env_id: str, algo: str, base, seed: int) -> str:
    short = env_id.split("/")[-1].split("-")[0]
    return f"{short}_{algo}_{base or 'pure_rl'}_seed{seed}"


def load_hyperparams(algo: str, env_id: str, path=None) -> dict:
    """The block for ``env_id`` in ``<algo>.yml`` (anchors resolved); a missing id raises ``ValueError``."""
    path = Path(path) if path else HYPERPARAMS_DIR / f"{algo}.yml"
    if not path.exists():
        raise ValueError(f"no hyperparameter file {path}")
    table = yaml.safe_load(path.read_text())
    if env_id not in table:
        raise ValueError(f"{path.name} has no block for {env_id!r}; blocks: {sorted(k for k in table if k != 'default')}")
    return dict(table[env_id])


def linear_schedule(value, name):
    """rl-zoo's ``lin_<x>``: decay linearly from x to 0 over the run (SB3 passes the remaining fraction)."""
    if not isinstance(value, str):
        return value
    if not value.startswith("lin_"):
        raise ValueError(f"{name} must be a number or 'lin_<initial value>'; got {value!r}")
    try:
        initial = float(value[4:])
    except ValueError:
        raise ValueError(f"{name} must be a number or 'lin_<initial value>'; got {value!r}") from None
    if not initial > 0:
        raise ValueError(f"{name}: the initial value of {value!r} must be > 0")
    from stable_baselines3.common.utils import LinearSchedule

    return LinearSchedule(initial, 0.0, 1.0)


def validate(env_id, algo, base):
    spec = get_spec(env_id)
    if algo not in ALGOS:
        raise ValueError(f"unknown algo {algo!r}; valid: {list(ALGOS)}")
    if base is not None and base not in spec.baselines:
        raise ValueError(f"unknown base {base!r} for {env_id}; valid: {list(spec.baselines)} or none")


def _algo_class(algo):
    from stable_baselines3 import PPO, SAC, TD3

    return {"ppo": PPO, "sac": SAC, "td3": TD3}[algo]


def _git_commit():
    try:
        return subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True, check=True,
                              cwd=Path(__file__).resolve().parent).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None


def save_model_atomic(model, path: Path) -> None:
    tmp = path.with_name(f".{path.stem}.tmp.zip")
    model.save(tmp)
    os.replace(tmp, path)


class AtomicCheckpoint:
    """SB3 callback factory: every ``freq`` steps write ``checkpoints/latest.zip`` (+ replay buffer) atomically."""

    @staticmethod
    def make(run_dir: Path, freq: int):
        from stable_baselines3.common.callbacks import BaseCallback
        from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm

        class _Checkpoint(BaseCallback):
            def __init__(self):
                super().__init__()
                self.last = 0

            def _on_step(self) -> bool:
                if self.num_timesteps - self.last >= freq:
                    self.save()
                return True

            def save(self):
                self.last = self.num_timesteps
                folder = run_dir / "checkpoints"
                folder.mkdir(parents=True, exist_ok=True)
                if isinstance(self.model, OffPolicyAlgorithm):
                    tmp = folder / ".replay_buffer.tmp.pkl"
                    self.model.save_replay_buffer(tmp)
                    os.replace(tmp, folder / "replay_buffer.pkl")
                normalizer = self.model.get_vec_normalize_env()
                if normalizer is not None:
                    tmp = folder / ".vecnormalize.tmp.pkl"
                    normalizer.save(str(tmp))
                    os.replace(tmp, folder / "vecnormalize.pkl")
                save_model_atomic(self.model, folder / "latest.zip")
                write_text_atomic(folder / "state.json", json.dumps({"num_timesteps": int(self.num_timesteps),
                                                                     "time": time.time()}))

        return _Checkpoint()


def headline_metric(env_id: str) -> str:
    """The held-out metric a run is judged by (its spec's; lower is better for VOI, higher for OR)."""
    return get_spec(env_id).headline_metric


def make_eval_callback(env_id, env_kwargs, run_dir, freq, n_episodes, report=None):
    """Periodic evaluation on held-out test tasks (fixed ids), logged to TensorBoard and evaluations.npz.

    ``report(timesteps, value)`` is called after each evaluation (a sweep scheduler listens there).
    """
    from stable_baselines3.common.callbacks import BaseCallback

    from continuum_gym.evaluation.rollout import make_core, run_episodes

    kwargs = {**env_kwargs, "task_split": "test"}
    core = make_core(env_id, n_episodes, **kwargs)
    task_ids = np.arange(EVAL_TASK_OFFSET, EVAL_TASK_OFFSET + n_episodes) % max(core.task_count, 1)
    metric = headline_metric(env_id)
    path = run_dir / "evaluations.npz"

    class _Eval(BaseCallback):
        def __init__(self):
            super().__init__()
            self.last = -freq
            previous = np.load(path) if path.exists() else None
            self.history = {key: list(previous[key]) for key in previous.files} if previous is not None else {
                "timesteps": [], "mean_return": [], metric: []}

        def _on_step(self) -> bool:
            if self.num_timesteps - self.last >= freq:
                self.evaluate()
            return True

        def _on_training_end(self) -> None:
            if not self.history["timesteps"] or self.history["timesteps"][-1] != self.num_timesteps:
                self.evaluate()

        def evaluate(self):
            self.last = self.num_timesteps
            result = run_episodes(core, self.model, task_ids)
            self.history["timesteps"].append(self.num_timesteps)
            self.history["mean_return"].append(float(result["return"].mean()))
            self.history[metric].append(float(result[metric].mean()))
            self.logger.record("eval/mean_return", float(result["return"].mean()))
            self.logger.record(f"eval/{metric}", float(result[metric].mean()))
            tmp = run_dir / ".evaluations.tmp.npz"
            np.savez(tmp, **{k: np.asarray(v) for k, v in self.history.items()})
            os.replace(tmp, path)
            if report is not None:
                report(int(self.num_timesteps), float(result[metric].mean()))

    return _Eval()


def train(env_id, algo="ppo", base="__default__", seed=0, steps=None, out="runs", resume=False,
          hyperparams=None, progress=True, command=None, n_envs=None, report=None) -> Path:
    """Train one run; returns its directory. ``base=None`` trains pure RL; the default is the env's first base."""
    if base == "__default__":
        base = get_spec(env_id).headline_baseline
    validate(env_id, algo, base)
    import numba
    import torch
    from stable_baselines3.common.callbacks import CallbackList
    from stable_baselines3.common.noise import NormalActionNoise
    from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm
    from stable_baselines3.common.vec_env import VecMonitor, VecNormalize

    from continuum_gym.agents.residual import ActorBurnIn, zero_init_residual
    from continuum_gym.envs.sb3 import ContinuumSB3VecEnv

    # Runs are parallelised by process (--parallel); one thread each keeps them from fighting.
    torch.set_num_threads(1)
    numba.set_num_threads(1)
    hp = load_hyperparams(algo, env_id, hyperparams)
    total = int(float(steps if steps is not None else hp["n_timesteps"]))
    run_dir = Path(out) / run_name(env_id, algo, base, seed)
    checkpoint = run_dir / "checkpoints" / "latest.zip"
    if run_dir.exists() and any(run_dir.iterdir()) and not resume:
        raise FileExistsError(f"{run_dir} exists; pass --resume to continue it (nothing is overwritten)")
    if resume and not checkpoint.exists():
        raise FileNotFoundError(f"--resume: no checkpoint at {checkpoint}")
    run_dir.mkdir(parents=True, exist_ok=True)
    env_kwargs = dict(hp.get("env_kwargs") or {})
    env_kwargs.update(base_controller=base, residual_scale=float(hp.get("residual_scale", 0.3)))
    n = int(n_envs or hp.get("n_envs", 16))
    venv = VecMonitor(ContinuumSB3VecEnv(env_id, n, seed=seed, task_split="train", **env_kwargs))
    venv.seed(seed)
    normalizer_path = run_dir / "checkpoints" / "vecnormalize.pkl"
    if hp.get("normalize_reward", False):
        # Returns of long episodes reach the hundreds; the critic learns scaled returns. Observations are
        # already normalised by the environment, and the policy never needs these statistics at test time.
        if resume and normalizer_path.exists():
            venv = VecNormalize.load(str(normalizer_path), venv)
        else:
            venv = VecNormalize(venv, norm_obs=False, norm_reward=True, gamma=float(hp.get("gamma", 0.99)))
    algo_kwargs = {k: linear_schedule(v, k) if k in SCHEDULE_KEYS else v for k, v in hp.items() if k not in RUN_KEYS}
    if algo == "td3" and hp.get("action_noise_std"):
        dim = venv.action_space.shape[0]
        algo_kwargs["action_noise"] = NormalActionNoise(np.zeros(dim), float(hp["action_noise_std"]) * np.ones(dim))
    cls = _algo_class(algo)
    if resume:
        model = cls.load(checkpoint, env=venv, tensorboard_log=str(run_dir / "tb"))
        if isinstance(model, OffPolicyAlgorithm) and (run_dir / "checkpoints" / "replay_buffer.pkl").exists():
            model.load_replay_buffer(run_dir / "checkpoints" / "replay_buffer.pkl")
    else:
        model = cls(hp.get("policy", "MlpPolicy"), venv, seed=seed, verbose=0, device="cpu",
                    tensorboard_log=str(run_dir / "tb"), **algo_kwargs)
        if base is not None:
            zero_init_residual(model)
    config = {"env_id": env_id, "algo": algo, "base_controller": base, "seed": seed, "total_timesteps": total,
              "n_envs": n, "hyperparams": hp, "env_kwargs": env_kwargs,
              "env_config": _base_vec_env(venv).core.config.to_dict(),
              "continuum_gym_version": _version(), "git_commit": _git_commit(), "python": sys.version.split()[0]}
    write_text_atomic(run_dir / "config.yml", yaml.safe_dump(config, sort_keys=False))
    write_text_atomic(run_dir / "args.yml", yaml.safe_dump({"env": env_id, "algo": algo, "base": base or "none",
                                                            "seed": seed, "steps": total, "out": str(out),
                                                            "resume": resume}, sort_keys=False))
    command_line = command or " ".join(shlex.quote(a) for a in sys.argv)
    with open(run_dir / "command.txt", "a") as handle:
        handle.write(command_line + "\n")
    saver = AtomicCheckpoint.make(run_dir, int(hp.get("checkpoint_freq", 100000)))
    callbacks = [saver, make_eval_callback(env_id, dict(env_kwargs), run_dir, int(hp.get("eval_freq", 100000)),
                                           int(hp.get("n_eval_episodes", 16)), report)]
    if base is not None and int(hp.get("burn_in_steps", 0)) > 0 and not resume:
        callbacks.append(ActorBurnIn(int(hp["burn_in_steps"])))
    remaining = total - model.num_timesteps
    if remaining > 0:
        model.learn(total_timesteps=remaining, callback=CallbackList(callbacks), reset_num_timesteps=not resume,
                    tb_log_name="tb", progress_bar=progress)
        saver.save()
    save_model_atomic(model, run_dir / "model.zip")
    venv.close()
    return run_dir


def _base_vec_env(venv):
    """The ``ContinuumSB3VecEnv`` under SB3's wrappers (VecMonitor, VecNormalize)."""
    while hasattr(venv, "venv"):
        venv = venv.venv
    return venv


def _version():
    from continuum_gym import __version__

    return __version__


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--env", required=True, help=f"environment id: {sorted(ENV_SPECS)}")
    parser.add_argument("--algo", default="ppo", help=f"one of {list(ALGOS)} (default ppo)")
    parser.add_argument("--base", default=None,
                        help="base controller name, or 'none' for pure RL (default: the env's first baseline)")
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--seed", type=int, default=0)
    group.add_argument("--seeds", type=int, nargs="+", help="several seeds, one run each")
    parser.add_argument("--parallel", type=int, default=1, help="with --seeds: number of runs at once (processes)")
    parser.add_argument("--steps", type=float, default=None, help="total environment steps (default: the YAML's)")
    parser.add_argument("--n-envs", type=int, default=None, help="native vector env batch size (default: the YAML's)")
    parser.add_argument("--out", default="runs", help="parent directory of run directories (default: runs)")
    parser.add_argument("--resume", action="store_true", help="continue from the run's latest checkpoint")
    parser.add_argument("--hyperparams", default=None, help="YAML file keyed by env id (default: the packaged one)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args) -> int:
    base = None if (args.base or "").lower() == "none" else (args.base or "__default__")
    try:
        validate(args.env, args.algo, None if base == "__default__" else base)
    except ValueError as error:
        print(f"continuum-gym train: {error}", file=sys.stderr)
        return 2
    seeds = args.seeds if args.seeds else [args.seed]
    command = "continuum-gym " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    jobs = []
    for seed in seeds:
        jobs.append(dict(env_id=args.env, algo=args.algo, base=base, seed=seed, steps=args.steps, out=args.out,
                         resume=args.resume, hyperparams=args.hyperparams, progress=not args.no_progress,
                         command=command, n_envs=args.n_envs))
    try:
        if args.parallel > 1 and len(jobs) > 1:
            from concurrent.futures import ProcessPoolExecutor

            with ProcessPoolExecutor(args.parallel) as pool:
                for path in pool.map(_train_job, jobs):
                    print(f"finished {path}")
        else:
            for job in jobs:
                print(f"finished {_train_job(job)}")
    except (ValueError, FileExistsError, FileNotFoundError) as error:
        print(f"continuum-gym train: {error}", file=sys.stderr)
        return 2
    return 0


def _train_job(job):
    return train(**job)
