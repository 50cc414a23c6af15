"""``continuum-gym train``: residual (or pure) RL with stable-baselines3 on the native vector env.

Each run directory holds ``config.yml`` (fully resolved), ``args.yml``, ``command.txt``, TensorBoard
logs, ``evaluations.npz`` (held-out learning curve), ``checkpoints/step_<n>/`` units (model, replay
buffer, normaliser, burn-in actor, state; see ``checkpoint.py``) and ``model.zip`` at the end.

A run directory is always finished, resumable or restartable:

* finished (``model.zip``): never overwritten; ``--resume`` continues it to a larger ``--steps``.
* with a verified checkpoint: ``--resume`` continues from the newest intact unit (an older one if the
  newest is damaged); without ``--resume`` nothing is touched.
* without one (stopped before its first checkpoint): a re-run, with or without ``--resume``, starts
  it again from step 0 and says so.

Units are written every ``checkpoint_freq`` steps or ``checkpoint_minutes`` (default 5) of wall time,
whichever comes first, always where every counted step has been trained on; the newest
``keep_checkpoints`` (default 2) are kept. Everything is checked (hyperparameters
against the algorithm's constructor, the command line) before anything is written.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import shlex
import shutil
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import yaml

from continuum_gym.agents.build import algo_class, build
from continuum_gym.agents.run_inputs import (
    check_budget,
    check_combination,
    check_hyperparams,
    load_hyperparams,
    output_directory,
    seed_number,
    whole_number,
)
from continuum_gym.envs.benchmark import benchmark_of
from continuum_gym.envs.spec import ENV_SPECS, get_spec, registered_kwargs
from continuum_gym.evaluation.io import (
    temporary_files,
    write_bytes_atomic,
    write_text_atomic,
)

if TYPE_CHECKING:
    from stable_baselines3.common.base_class import BaseAlgorithm

ALGOS = ("ppo", "sac", "td3")
# Values of the run keys when a block leaves them out.
RUN_DEFAULTS = {"n_envs": 16, "env_kwargs": {}, "residual_scale": 0.3, "burn_in_steps": 0, "eval_freq": 100000,
                "n_eval_episodes": 16, "checkpoint_freq": 100000, "checkpoint_minutes": 5.0, "keep_checkpoints": 2,
                "normalize_reward": False}


class RunBusyError(RuntimeError):
    """Another process is training the same run directory."""


def run_name(env_id: str, algo: str, base: str | None, seed: int, helpers: list | tuple = (),
             obs_mode: str | None = None) -> str:
    """``<Env>_<algo>_<base>[_<obs_mode>][+<helper>...]_seed<n>``: the run's folder, which says what acts and what
    the policy sees (``OcclusionAvoidance_ppo_projected_gradient_rgbd_seed0``; ``+`` of a mode written ``_``)."""
    from continuum_gym.envs.helpers import row_name

    short = env_id.split("/")[-1].split("-")[0]
    mode = "" if obs_mode in (None, "state") else f"_{str(obs_mode).replace('+', '_')}"
    return f"{short}_{algo}_{row_name((base or 'pure_rl') + mode, helpers)}_seed{seed}"


def resolve_hyperparams(algo: str, env_id: str, path: Path | str | None = None) -> dict:
    """``load_hyperparams`` checked against the algorithm (``validation.check_hyperparams``)."""
    block = load_hyperparams(algo, env_id, path)
    source = f"{Path(path).name if path else f'{algo}.yml'} [{env_id}]"
    return check_hyperparams(block, algo_class(algo), algo, source)


def validate(env_id: str, algo: str, base: str | None) -> str | None:
    """The base controller's name; ``ValueError`` unless env_id is known, algo one of ``ALGOS`` and base a
    baseline of the env, a registered controller (a name or ``"module:name"``) or None."""
    from continuum_gym import registry

    spec = get_spec(env_id)
    if algo not in ALGOS:
        raise ValueError(f"unknown algo {algo!r}; valid: {list(ALGOS)}")
    if base is None or base in spec.baselines:
        return base
    try:
        return registry.resolve("controller", spec.env_id, base)
    except ValueError as error:
        raise ValueError(f"unknown base {base!r} for {env_id}; valid: {list(spec.baselines)}, a registered "
                         f"controller or none. {error}") from None


def check_steps(algo: str, env_id: str, base: str | None, steps: int | None,
                hyperparams: Path | str | None = None) -> str | None:
    """``run_inputs.check_budget`` for the block ``train`` would read: ``ValueError`` if ``steps`` (None: the
    block's ``n_timesteps``) trains nothing, a warning if it trains the actor little, else None."""
    hp = resolve_hyperparams(algo, env_id, hyperparams)
    if steps is None and "n_timesteps" not in hp:
        return None
    source = f"{Path(hyperparams).name if hyperparams else f'{algo}.yml'} [{env_id}]"
    return check_budget(algo_class(algo), hp, steps if steps is not None else hp["n_timesteps"], base is not None,
                        source, "--steps" if steps is not None else "n_timesteps")


def default_base(env_id: str) -> str | None:
    """The base an id trains on by default: the one it was registered with, else its env's headline baseline."""
    registered = registered_kwargs(env_id)
    return registered["base_controller"] if "base_controller" in registered else \
        benchmark_of(env_id).headline_baseline


def _git_commit():
    try:
        return subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True, check=True,
                              cwd=Path(__file__).resolve().parent).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None


#: What a finished model.zip leaves out: the last observation batch (an image policy's is 20 MB of a 22 MB zip;
#: SB3's ``learn`` resets the env when it is missing, and checkpoints keep it for a resume).
FINAL_EXCLUDE = ("_last_obs", "_last_original_obs")


def save_model_atomic(model: BaseAlgorithm, path: Path) -> None:
    buffer = io.BytesIO()
    model.save(buffer, exclude=list(FINAL_EXCLUDE))
    write_bytes_atomic(path, buffer.getvalue())


def notice(message: str) -> None:
    """What the trainer decided about a run directory (restart, resume, fallback), on stderr."""
    print(f"continuum-gym train: {message}", file=sys.stderr, flush=True)


def headline_metric(env_id: str) -> str:
    """The held-out metric a run is judged by (its spec's; lower is better for VOI, higher for OR)."""
    return benchmark_of(env_id).headline_metric


@contextlib.contextmanager
def _exclusive(run_dir: Path):
    """Hold an advisory lock on the run directory (released by the kernel if the process dies)."""
    try:
        import fcntl
    except ImportError:  # no flock on this platform: run unguarded
        yield
        return
    fd = os.open(run_dir, os.O_RDONLY)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise RunBusyError(f"{run_dir} is being trained by another process") from None
        yield
    finally:
        os.close(fd)


def _starting_point(run_dir: Path, resume: bool, total: int):
    """``(unit, done)``: the checkpoint unit to start from (``None``: step 0) after refusing what must not
    be overwritten; ``done`` when a finished run already has ``total`` steps."""
    from continuum_gym.agents.checkpoint import (
        CHECKPOINTS,
        discard,
        find_resumable,
        legacy_unit,
    )

    folder = run_dir / CHECKPOINTS
    finished = (run_dir / "model.zip").is_file()
    unit, damaged = find_resumable(folder)
    unit = unit or legacy_unit(folder)
    if not resume and finished:
        raise FileExistsError(f"{run_dir} is a finished run (model.zip); nothing is overwritten "
                              "(--resume continues it to a larger --steps)")
    if not resume and unit is not None:
        raise FileExistsError(f"{run_dir} exists with a checkpoint at step {unit.step}; pass --resume to continue "
                              "it (nothing is overwritten)")
    if finished and unit is None:
        raise FileNotFoundError(f"--resume: {run_dir} is finished and has no intact checkpoint to continue from")
    for bad, problem in damaged:
        then = f"falling back to {unit.path.name}" if unit is not None else "removing it"
        notice(f"checkpoint {bad.path} is damaged ({problem}); {then}")
        discard(bad)
    if unit is not None and finished and unit.step >= total:
        notice(f"{run_dir} is finished at step {unit.step} (>= {total} steps); nothing to do")
        return unit, True
    if unit is not None:
        notice(f"resuming {run_dir} from step {unit.step} ({unit.path.name})")
        return unit, False
    if any(run_dir.iterdir()):
        notice(f"{run_dir} has no checkpoint (stopped before its first one); starting it again from step 0")
        # What the stopped attempt produced; config, args and command.txt are rewritten or appended to.
        for name in ("evaluations.npz", "tb", CHECKPOINTS):
            target = run_dir / name
            if target.is_dir():
                shutil.rmtree(target)
            else:
                target.unlink(missing_ok=True)
    elif resume:
        notice(f"--resume: {run_dir} has no checkpoint yet; starting from step 0")
    return None, False


def learner_threads() -> dict:
    """Set this training process's torch thread count; returns the thread use (recorded in config.yml).

    One torch thread, whatever the cores: a trainer alternates env steps and gradient steps, never
    both at once, on small networks (two layers of 64-256 units, batches of 64-256), and ``--parallel``
    and ``sweep`` run one process per run, each of which then has a core of its own. A second thread
    buys a single run little or nothing (benchmarks/training.py times one thread against two). The
    vector env steps on the calling thread (its default when torch is loaded). numba's own threading
    layer is left unstarted: started (as ``numba.set_num_threads`` does), its OpenMP pool competes for
    the cores the other runs need, and two runs side by side lose about a third of their speed.
    """
    import os

    import torch

    torch.set_num_threads(1)
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return {"torch": torch.get_num_threads(), "cores_visible": cores}


def train(env_id: str, algo: str = "ppo", base: str | None = "__default__", seed: int = 0, steps: int | None = None,
          out: Path | str = "runs", resume: bool = False, hyperparams: Path | str | None = None, progress: bool = True,
          command: str | None = None, n_envs: int | None = None,
          report: Callable[[int, float], None] | None = None) -> Path:
    """Train one run; returns its directory. ``base=None`` trains pure RL; the default is the env's first base.

    ``steps`` is the total number of environment steps (summed over the vector env). Raises
    ``ValueError`` for bad input, ``FileExistsError`` rather than overwriting, before writing anything.
    """
    if base == "__default__":
        base = default_base(env_id)
    base = validate(env_id, algo, base)
    seed = seed_number("seed", seed)
    source = f"{Path(hyperparams).name if hyperparams else f'{algo}.yml'} [{env_id}]"
    hp = resolve_hyperparams(algo, env_id, hyperparams)
    if steps is None and "n_timesteps" not in hp:
        raise ValueError(f"no --steps given and {source} has no n_timesteps")
    total = whole_number("steps", steps) if steps is not None else hp["n_timesteps"]
    n = whole_number("n_envs", n_envs) if n_envs is not None else hp.get("n_envs", RUN_DEFAULTS["n_envs"])
    check_combination(algo, hp, n, source)
    little = check_budget(algo_class(algo), hp, total, base is not None, source,
                          "--steps" if steps is not None else "n_timesteps")
    from continuum_gym.envs.helpers import check_helpers

    try:
        helpers = list(check_helpers(env_id, hp.get("helpers")))
    except ValueError as error:
        raise ValueError(f"{source}: {error}") from None
    run_dir = output_directory("out", out) / run_name(env_id, algo, base, seed, helpers,
                                                      (hp.get("env_kwargs") or {}).get("obs_mode"))
    if run_dir.exists() and not run_dir.is_dir():
        raise ValueError(f"out: {run_dir} is an existing file, not a run directory")
    run = {**RUN_DEFAULTS, **hp}
    from continuum_gym.agents.checkpoint import (
        CHECKPOINTS,
        clean_temporary,
        model_files,
        remove_legacy_files,
        write_unit,
    )
    from continuum_gym.envs.sb3 import ContinuumSB3VecEnv

    threads = learner_threads()
    env_kwargs = dict(run["env_kwargs"] or {})
    if env_kwargs.get("obs_mode", "state") != "state":  # image batches: no page faults per step (allocator.py)
        from continuum_gym.agents.allocator import keep_large_blocks

        threads["large_blocks_kept"] = keep_large_blocks()
    env_kwargs.update(base_controller=base, residual_scale=float(run["residual_scale"]))
    try:  # the environment checks its own keywords; still nothing written
        venv = ContinuumSB3VecEnv(env_id, n, seed=seed, task_split="train", helpers=helpers, **env_kwargs)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{source}: env_kwargs: {error}") from None
    if little:
        notice(little)
    run_dir.mkdir(parents=True, exist_ok=True)
    with _exclusive(run_dir):
        unit, done = _starting_point(run_dir, resume, total)
        if done:
            return run_dir
        clean_temporary(run_dir / CHECKPOINTS)
        for stale in temporary_files(run_dir):
            stale.unlink()
        model, venv, saver, callbacks = build(env_id, algo, base, seed, total, run, env_kwargs, venv, run_dir,
                                               unit, report)
        config = {"env_id": env_id, "algo": algo, "base_controller": base, **({"helpers": helpers} if helpers else {}),
                  "seed": seed, "total_timesteps": total,
                  "n_envs": n, "hyperparams": hp, "env_kwargs": env_kwargs,
                  "env_config": _base_vec_env(venv).core.config.to_dict(), "continuum_gym_version": _version(),
                  "git_commit": _git_commit(), "python": sys.version.split()[0],
                  "threads": {**threads, "env_step_threads": _base_vec_env(venv).core.num_threads}}
        write_text_atomic(run_dir / "config.yml", yaml.safe_dump(config, sort_keys=False))
        start = f"resume from step {unit.step}" if unit is not None else "step 0"
        write_text_atomic(run_dir / "args.yml", yaml.safe_dump({"env": env_id, "algo": algo, "base": base or "none",
                                                                "seed": seed, "steps": total, "out": str(out),
                                                                "resume": resume, "start": start}, sort_keys=False))
        command_line = command or " ".join(shlex.quote(a) for a in sys.argv)
        previous = (run_dir / "command.txt").read_text() if (run_dir / "command.txt").is_file() else ""
        write_text_atomic(run_dir / "command.txt", previous + command_line + "\n")
        if unit is not None and unit.legacy:
            # Re-publish the old single-file checkpoint as a verified unit, then drop the old files.
            files = {**model_files(model), **saver.extra_files()}
            write_unit(run_dir / CHECKPOINTS, unit.step, files, saver.extra_state())
            remove_legacy_files(run_dir / CHECKPOINTS)
        try:
            remaining = total - model.num_timesteps
            if remaining > 0:
                from stable_baselines3.common.callbacks import CallbackList

                from continuum_gym.agents.progress import ProgressBar, rollout_steps, training_end

                end = training_end(model, total)
                if end != total:
                    notice(f"training ends at step {end}: {total} steps rounded up to whole rollouts of "
                           f"{rollout_steps(model)} steps (n_envs x {'n_steps' if algo == 'ppo' else 'train_freq'})")
                model.learn(total_timesteps=remaining, reset_num_timesteps=unit is None, tb_log_name="tb",
                            callback=CallbackList(callbacks + ([ProgressBar(total)] if progress else [])))
                saver.save()
            save_model_atomic(model, run_dir / "model.zip")
        finally:
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
    # Numbers are parsed in run(), so that a bad one gets the same one-line message as a bad hyperparameter.
    parser.add_argument("--env", required=True, help=f"environment id: {sorted(ENV_SPECS)}")
    parser.add_argument("--algo", default="ppo", help=f"one of {list(ALGOS)} (default ppo)")
    parser.add_argument("--base", default=None,
                        help="base controller name, or 'none' for pure RL (default: the env's first baseline)")
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--seed", default="0", help="random seed, an integer >= 0 (default 0)")
    group.add_argument("--seeds", nargs="+", help="several seeds, one run each")
    parser.add_argument("--parallel", default="1", help="with --seeds: number of runs at once (processes)")
    parser.add_argument("--steps", default=None, help="total environment steps, >= 1 (default: the YAML's)")
    parser.add_argument("--n-envs", default=None, help="native vector env batch size, >= 1 (default: the YAML's)")
    parser.add_argument("--out", default="runs", help="parent directory of run directories (default: runs)")
    parser.add_argument("--resume", action="store_true",
                        help="continue from the run's newest intact checkpoint (a run without one starts again)")
    parser.add_argument("--hyperparams", default=None, help="YAML file keyed by env id (default: the packaged one)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    base = None if (args.base or "").lower() == "none" else (args.base or "__default__")
    try:
        validate(args.env, args.algo, None if base == "__default__" else base)
        seeds = [seed_number("--seeds", s) for s in args.seeds] if args.seeds else [seed_number("--seed", args.seed)]
        if len(set(seeds)) != len(seeds):
            raise ValueError(f"--seeds must be distinct (one run directory each); got {args.seeds}")
        parallel = whole_number("--parallel", args.parallel)
        steps = whole_number("--steps", args.steps) if args.steps is not None else None
        n_envs = whole_number("--n-envs", args.n_envs) if args.n_envs is not None else None
        output_directory("--out", args.out)
        resolve_hyperparams(args.algo, args.env, args.hyperparams)  # once, before any run starts
    except ValueError as error:
        print(f"continuum-gym train: {error}", file=sys.stderr)
        return 2
    command = "continuum-gym " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    jobs = [dict(env_id=args.env, algo=args.algo, base=base, seed=seed, steps=steps, out=args.out, resume=args.resume,
                 hyperparams=args.hyperparams, progress=not args.no_progress, command=command, n_envs=n_envs)
            for seed in seeds]
    try:
        if parallel > 1 and len(jobs) > 1:
            from concurrent.futures import ProcessPoolExecutor

            with ProcessPoolExecutor(parallel) as pool:
                for path in pool.map(_train_job, jobs):
                    print(f"finished {path}")
        else:
            for job in jobs:
                print(f"finished {_train_job(job)}")
    except (ValueError, FileExistsError, FileNotFoundError, RunBusyError) as error:
        print(f"continuum-gym train: {error}", file=sys.stderr)
        return 2
    return 0


def _train_job(job):
    return train(**job)
