"""Offline-RL datasets: episodes of the analytic baselines as Minari datasets (``continuum-gym dataset``).

A dataset is the registered environment run with ``base_controller=<controller>`` on task ids
``0 .. episodes - 1`` of one split, every episode seeded from ``seed``. The recorded actions are the
residuals the env received: zeros for the baseline itself (``noise=0``), or the baseline perturbed by
Gaussian residuals of standard deviation ``noise`` (clipped to the action box, as the env clips) for
datasets with action coverage. The observations already carry the baseline's command, so a policy
cloned from a noisy dataset learns a residual on it. Every ``info`` entry is stored (numpy scalars and
arrays; ``reward_terms`` as its float64 vector), and the dataset's ``env_spec`` carries the env kwargs,
so ``dataset.recover_environment()`` rebuilds the same env.

Ids follow Minari's ``namespace/env/name-v0``: ``continuum-gym/ViewTracking/dimension_reduced-train-v0``,
with ``-noise0p3`` (σ = 0.3) before the version for a noisy dataset. They are written under Minari's data
path (``$MINARI_DATASETS_PATH``, default ``~/.minari/datasets``, or ``root``) and loaded with
``minari.load_dataset(id)``.

The offline optimum is not recorded: it is a per-instant bound (the best configuration at every
sample time, found independently of the others), not a rate-limited trajectory, so it has no
environment transitions to store.

Needs the ``[offline]`` extra (``pip install "continuum-gym[offline]"``: Minari with its HDF5 storage).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from continuum_gym.envs.spec import ENV_SPECS, get_spec
from continuum_gym.validation import choice, integer, number

if TYPE_CHECKING:
    import gymnasium
    from minari import MinariDataset

NAMESPACE = "continuum-gym"
DATASET_SPLITS = ("train", "validation", "test")


def dataset_id(env_id: str, controller: str, split: str, noise: float = 0.0, version: int = 0,
               obs_mode: str = "state") -> str:
    """Minari id of a dataset: ``continuum-gym/<env name>/<controller>-<split>[-noise<σ>][-<obs_mode>]-v<version>``
    (σ with ``p`` for the decimal point; an image ``obs_mode`` with ``_`` for ``+``)."""
    env_name = env_id.split("/")[-1].rsplit("-v", 1)[0]
    suffix = f"-noise{noise:g}".replace(".", "p") if noise > 0 else ""  # Minari ids allow no "." in a name
    suffix += "" if obs_mode == "state" else f"-{obs_mode.replace('+', '_')}"
    return f"{NAMESPACE}/{env_name}/{controller}-{split}{suffix}-v{version}"


def check_dataset_arguments(env_id: str, controller: str, split: str, episodes: Any, noise: Any,
                            seed: Any) -> tuple[str, str, str, int, float, int]:
    """The arguments, validated with the parameter's name and valid range."""
    spec = get_spec(env_id)
    if controller not in spec.baselines and isinstance(controller, str) and controller in own_controllers(env_id):
        from continuum_gym import registry

        controller = registry.resolve("controller", spec.env_id, controller)  # the user's controller, by name
    else:
        controller = choice(controller, (*spec.baselines, *own_controllers(env_id)), "controller")
    split = choice(split, DATASET_SPLITS, "split")
    episodes = integer(episodes, "episodes", low=1, high=100_000)
    noise = number(noise, "noise", low=0.0, high=10.0)
    seed = integer(seed, "seed", low=0, high=2**32 - 1)
    return env_id, controller, split, episodes, noise, seed


def own_controllers(env_id: str) -> tuple:
    """The registered controllers of ``env_id``'s environment (the id's own base first)."""
    from continuum_gym import registry
    from continuum_gym.envs.spec import registered_base

    base = registered_base(env_id)
    return tuple(dict.fromkeys([*([base] if base else []), *registry.controller_names(get_spec(env_id).env_id)]))


def collect_episodes(env_id: str, controller: str, *, split: str = "train", episodes: int = 10,
                     noise: float = 0.0, seed: int = 0, env_kwargs: dict | None = None,
                     progress: bool = False) -> list:
    """Run ``controller`` on task ids ``0 .. episodes - 1`` of ``split``: a list of Minari ``EpisodeBuffer``.

    Episode ``k`` is reset with ``seed + k`` and ``options={"task_id": k}``; residual noise is drawn from
    ``np.random.default_rng(seed)``. Observations hold the reset observation plus one per step.
    """
    import gymnasium as gym
    from minari.data_collector import EpisodeBuffer
    from tqdm.auto import tqdm

    env_id, controller, split, episodes, noise, seed = check_dataset_arguments(
        env_id, controller, split, episodes, noise, seed)
    env = gym.make(env_id, **dataset_env_kwargs(controller, split, env_kwargs))
    rng = np.random.default_rng(seed)
    buffers = []
    for k in tqdm(range(episodes), desc=f"{controller} episodes", disable=not progress):
        obs, info = env.reset(seed=seed + k, options={"task_id": k})
        observations, actions, rewards, terminations, truncations = [obs], [], [], [], []
        infos = {key: [value] for key, value in _storable(info).items()}
        done = False
        while not done:
            action = np.zeros(cast(gym.spaces.Box, env.action_space).shape, dtype=np.float32)
            if noise > 0:
                action = np.clip(noise * rng.standard_normal(action.shape), -1.0, 1.0).astype(np.float32)
            obs, reward, terminated, truncated, info = env.step(action)
            observations.append(obs)
            actions.append(action)
            rewards.append(reward)
            terminations.append(terminated)
            truncations.append(truncated)
            for key, value in _storable(info).items():
                infos[key].append(value)
            done = terminated or truncated
        buffers.append(EpisodeBuffer(id=k, seed=seed + k, options={"task_id": k},
                                     observations=_stacked(observations), actions=np.asarray(actions),
                                     rewards=rewards, terminations=terminations, truncations=truncations,
                                     infos={key: np.asarray(values) for key, values in infos.items()}))
    env.close()
    return buffers


def _stacked(observations: list) -> Any:
    """An episode's observations as one array, or a dict of arrays for a ``Dict`` observation (goal front ends)."""
    if isinstance(observations[0], dict):
        return {key: np.asarray([o[key] for o in observations]) for key in observations[0]}
    return np.asarray(observations)


def dataset_env_kwargs(controller: str, split: str, env_kwargs: dict | None = None) -> dict:
    """The env kwargs a dataset is recorded with (and stored in its ``env_spec``)."""
    return {**(env_kwargs or {}), "base_controller": controller, "task_split": split}


#: ``info`` keys a wrapper adds on an episode's last step only: rl_zoo3, once imported, patches Gymnasium's
#: ``TimeLimit`` (``gym.make(..., max_episode_steps=...)``) to add this one; the truncations record it already.
_LAST_STEP_KEYS = ("TimeLimit.truncated",)


def _storable(info: dict) -> dict:
    # Same keys every step (Minari needs it); plain float64 arrays (reward_terms is an ndarray subclass).
    return {key: np.asarray(value).view(np.ndarray) for key, value in info.items() if key not in _LAST_STEP_KEYS}


def create_dataset(env_id: str, controller: str, *, split: str = "train", episodes: int = 10,
                   noise: float = 0.0, seed: int = 0, env_kwargs: dict | None = None, root: str | Path | None = None,
                   overwrite: bool = False, progress: bool = False) -> MinariDataset:
    """Record and write one dataset (see the module docstring); returns the ``minari.MinariDataset``.

    Args:
        env_id: a ``ContinuumGym/`` id.
        controller: one of the env's baselines (the behaviour policy).
        split: ``"train"``, ``"validation"`` or ``"test"`` task split.
        episodes: number of episodes (task ids ``0 .. episodes - 1``), 1..100000.
        noise: standard deviation of the Gaussian residual added to the baseline (action units, 0..10).
        seed: seed of the episodes and of the noise.
        env_kwargs: further env keyword arguments (physics, tasks; SI units as in the env docstrings).
        root: Minari data path to write under (default ``$MINARI_DATASETS_PATH`` or ``~/.minari/datasets``).
        overwrite: replace an existing dataset of the same id (else a ``FileExistsError``).
    """

    env_id, controller, split, episodes, noise, seed = check_dataset_arguments(
        env_id, controller, split, episodes, noise, seed)
    if root is not None:
        os.environ["MINARI_DATASETS_PATH"] = str(Path(root).resolve())
    import minari

    name = dataset_id(env_id, controller, split, noise, obs_mode=str((env_kwargs or {}).get("obs_mode", "state")))
    if name in minari.list_local_datasets():
        if not overwrite:
            raise FileExistsError(f"dataset {name} exists under {minari_root()}; pass overwrite=True (--overwrite)")
        minari.delete_dataset(name)
    buffers = collect_episodes(env_id, controller, split=split, episodes=episodes, noise=noise, seed=seed,
                               env_kwargs=env_kwargs, progress=progress)
    env_spec = recorded_env_spec(env_id, dataset_env_kwargs(controller, split, env_kwargs))
    description = (f"{episodes} episodes of the {controller} baseline of {env_id} on task ids 0..{episodes - 1} of "
                   f"the {split} split" + (f", with Gaussian residuals of std {noise:g}" if noise else "")
                   + f"; seeds {seed}..{seed + episodes - 1}. Recorded by continuum-gym dataset.")
    try:
        with warnings.catch_warnings():
            # No code_permalink or author_email: the project has no public repository or contact address to
            # record, and Minari's reminder that they are unset would print with every dataset.
            warnings.filterwarnings("ignore", "`(code_permalink|author_email)` is set to None", UserWarning)
            dataset = minari.create_dataset_from_buffers(
                dataset_id=name, buffer=buffers, env=env_spec, eval_env=env_spec, algorithm_name=controller,
                author="continuum-gym", description=description, data_format="hdf5", requirements=["continuum-gym"])
    except BaseException:  # a half-written dataset would shadow the id: remove it
        if name in minari.list_local_datasets():
            minari.delete_dataset(name)
        raise
    return dataset


def recorded_env_spec(env_id: str, env_kwargs: dict) -> gymnasium.envs.registration.EnvSpec:
    """The spec a dataset stores, from which ``recover_environment()`` rebuilds the env, in any process.

    Its kwargs hold the whole configuration as ``EnvConfig.to_dict`` writes it (``{"config": ...}``): plain JSON
    that Minari can store (a robot or a cone object it would flatten to a dict of fields that no constructor
    takes), plug-ins as ``"module:name"`` references with the modules that register them (a bare name means
    nothing in a fresh process) and recorded tasks with their samples. Its id, entry point and time limit are the
    registered id's (a researcher's variant keeps its own id), and ``gym.make`` of the spec needs no registration.
    """
    import gymnasium as gym

    env = gym.make(env_id, **env_kwargs)
    try:
        inner: Any = env.unwrapped  # a continuum-gym env: single or goal front end
        config = inner.config.to_dict(recorded="inline")
        extra = inner.goal_kwargs() if hasattr(inner, "goal_kwargs") else {}  # the goal front end's own keywords
    finally:
        env.close()
    return dataclasses.replace(gym.spec(env_id), kwargs={"config": config, **extra})


def observation_kwargs(obs_mode: str, image_size: int) -> dict:
    """The env keywords of ``--obs-mode`` / ``--image-size`` (none for the state), checked."""
    from continuum_gym.envs.pixels import check_image_size, check_obs_mode

    if check_obs_mode(obs_mode) == "state":
        return {}
    return {"obs_mode": obs_mode, "image_size": check_image_size(image_size)}


def minari_root() -> Path:
    """Where Minari reads and writes datasets."""
    return Path(os.environ.get("MINARI_DATASETS_PATH", Path.home() / ".minari" / "datasets"))


# ---------------------------------------------------------------------- CLI
def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--env", nargs="+", default=list(ENV_SPECS), help="environment ids (default: all)")
    parser.add_argument("--controller", nargs="+", default=None,
                        help="baselines to record (default: every baseline of each env)")
    parser.add_argument("--split", nargs="+", default=["train"], choices=DATASET_SPLITS,
                        help="task splits (default: train)")
    parser.add_argument("--episodes", type=int, default=20, help="episodes per dataset (default 20)")
    parser.add_argument("--noise", type=float, default=0.0,
                        help="std of Gaussian residuals added to the baseline, in action units (default 0)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--obs-mode", default="state", help="observation: state (default) or an image mode, e.g. "
                                                            "rgbd (docs/rendering.md); images of --image-size")
    parser.add_argument("--image-size", type=int, default=64, help="image side in pixels (image modes; default 64)")
    parser.add_argument("--root", default=None, help="Minari data path (default $MINARI_DATASETS_PATH "
                                                     "or ~/.minari/datasets)")
    parser.add_argument("--overwrite", action="store_true", help="replace datasets that exist")
    parser.add_argument("--no-progress", action="store_true")


def run(args: argparse.Namespace) -> int:
    try:
        import minari  # noqa: F401
    except ImportError:
        print('continuum-gym dataset: needs Minari: pip install "continuum-gym[offline]"', file=sys.stderr)
        return 2
    try:
        jobs = []
        for env_id in args.env:
            spec = get_spec(env_id)
            own = own_controllers(env_id)[:1] if get_spec(env_id).env_id != env_id else ()  # a registered id's base
            for controller in args.controller or (*spec.baselines, *own):
                for split in args.split:
                    jobs.append(check_dataset_arguments(env_id, controller, split, args.episodes, args.noise,
                                                        args.seed))
        observation_kwargs(args.obs_mode, args.image_size)
    except (ValueError, TypeError) as error:
        print(f"continuum-gym dataset: {error}", file=sys.stderr)
        return 2
    for env_id, controller, split, episodes, noise, seed in jobs:
        try:
            dataset = create_dataset(env_id, controller, split=split, episodes=episodes, noise=noise, seed=seed,
                                     root=args.root, overwrite=args.overwrite, progress=not args.no_progress,
                                     env_kwargs=observation_kwargs(args.obs_mode, args.image_size))
        except FileExistsError as error:
            print(f"continuum-gym dataset: {error}", file=sys.stderr)
            return 2
        print(f"wrote {dataset.spec.dataset_id}: {dataset.total_episodes} episodes, {dataset.total_steps} steps "
              f"under {minari_root()}")
    return 0
