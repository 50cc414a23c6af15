"""Save an environment's configuration to a file and make the same environment from it, in any process.

    continuum_gym.save_config(env, "my_env.yml")      # + my_env.tasks.npz when the task is recorded data
    env = continuum_gym.make_from_config("my_env.yml")  # the same env, bit for bit

The YAML file holds the env id it was made as (a user's registered id included) and the library's
env it runs, the configuration as
``EnvConfig.to_dict()`` writes it (robots and cones as their fields; plug-ins as ``"module:name"``
references and the modules that register them) and a format version. Recorded tasks are samples, not
names: they go to a ``.tasks.npz`` file beside the YAML file (the samples each trajectory was built
from), so the rebuilt env interpolates the same splines.
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from continuum_gym.evaluation.io import write_bytes_atomic, write_text_atomic
from continuum_gym.validation import describe

if TYPE_CHECKING:

    from continuum_gym.envs.config import EnvConfig

#: Version of the file layout (bumped when a key changes meaning).
FORMAT = 1


#: The front ends a config file remakes: ``gym.make`` of a plain or a goal env, ``gym.make_vec`` of the native vector env.
FRONT_ENDS = ("single", "goal", "vector")


def _describe_env(env: Any) -> dict:
    """What a config file records of any front end (single, vector, SB3, goal, wrapped): its ``EnvConfig``, the id
    it was made as, which front end it is (with the goal front end's own keywords, the vector env's row count)
    and its time limit."""
    from continuum_gym.envs.goal import ContinuumGoalEnv

    inner = getattr(env, "unwrapped", env)
    config = getattr(inner, "config", None)  # every front end has it (envs.single.CoreOwner, the goal envs)
    if config is None:
        raise ValueError(f"env must be a continuum-gym environment (single, vector, SB3 or goal); got {describe(env)}")
    spec = getattr(env, "spec", None) or getattr(inner, "spec", None)
    env_id = getattr(spec, "id", None) if spec is not None and hasattr(spec, "entry_point") else None
    out: dict[str, Any] = {"env_id": env_id or config.env_id, "front_end": "single", "front_end_kwargs": {},
                           "max_episode_steps": getattr(spec, "max_episode_steps", None)}
    if isinstance(inner, ContinuumGoalEnv):
        out.update(front_end="goal", front_end_kwargs=inner.goal_kwargs())
    elif getattr(inner, "num_envs", None) is not None and hasattr(inner, "core"):  # the vector env, the SB3 adapter
        out.update(front_end="vector", num_envs=int(inner.num_envs), max_episode_steps=None)
    return out


def tasks_path(path: Path) -> Path:
    """Where the recorded tasks of the config file ``path`` are stored."""
    return path.with_name(path.stem + ".tasks.npz")


def _save_tasks(trajectories: list, path: Path) -> None:
    from continuum_gym.envs.trajectories import samples_of

    arrays: dict[str, Any] = {"count": np.array(len(trajectories))}  # Any: np.savez's **kwds (not its keywords)
    for k, trajectory in enumerate(trajectories):
        for name, value in samples_of(trajectory).items():
            if name != "type":
                arrays[f"{k}/{name}"] = value
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    write_bytes_atomic(path, buffer.getvalue())


def _load_tasks(path: Path) -> list:
    from continuum_gym.envs.trajectories import SAMPLE_FIELDS, from_samples

    if not path.is_file():
        raise ValueError(f"the config's recorded tasks are missing: {path} (written beside the config file by "
                         "save_config; copy both files)")
    with np.load(path) as data:
        out = []
        for k in range(int(data["count"])):
            kind = "TipTrajectory" if f"{k}/positions" in data else "DaVinciTrajectory"
            out.append(from_samples({"type": kind, **{name: data[f"{k}/{name}"] for name in SAMPLE_FIELDS[kind]
                                                       if f"{k}/{name}" in data}}))
    return out


def save_config(env: Any, path: str | Path) -> Path:
    """Write ``env``'s id, front end and configuration to the YAML file ``path`` (recorded tasks beside it).

    ``make_from_config(path)`` makes the same front end (plain, goal or native vector env; the SB3 adapter is
    saved as the vector env of its core) with the same id and the same configuration. Returns ``path``.
    """
    import yaml

    from continuum_gym.envs.task_sources import RecordedTasks

    made = _describe_env(env)
    config = getattr(env, "unwrapped", env).config
    path = Path(path)
    data = config.to_dict()
    source = config.task_source
    if isinstance(source, RecordedTasks):
        _save_tasks(source.trajectories, tasks_path(path))
        data["task"] = {"type": "recorded", "file": tasks_path(path).name, **source.describe()}
    path.parent.mkdir(parents=True, exist_ok=True)
    record = {"format": FORMAT, "env_id": made["env_id"], "base_env_id": config.env_id,
              "front_end": made["front_end"], "front_end_kwargs": made["front_end_kwargs"],
              "max_episode_steps": made["max_episode_steps"], "config": data}
    if "num_envs" in made:
        record["num_envs"] = made["num_envs"]
    write_text_atomic(path, yaml.safe_dump(record, sort_keys=False))
    return path


def _read(path: str | Path) -> tuple[dict, EnvConfig]:
    """The file's record and its ``EnvConfig`` (plug-in modules imported, recorded tasks loaded)."""
    import yaml

    from continuum_gym.envs.spec import get_spec
    from continuum_gym.validation import choice

    path = Path(path)
    if not path.is_file():
        raise ValueError(f"path: no config file at {path}")
    data = yaml.safe_load(path.read_text())
    if not isinstance(data, dict) or not {"config", "env_id", "base_env_id"} <= set(data):
        raise ValueError(f"path: {path} is not a config file of save_config (keys format, env_id, base_env_id, "
                         "config)")
    if data.get("format") != FORMAT:
        raise ValueError(f"path: {path} has format {data.get('format')!r}; this version reads format {FORMAT}")
    choice(data.setdefault("front_end", "single"), FRONT_ENDS, f"front_end (of {path})")
    config = dict(data["config"])
    task = config.get("task")
    if isinstance(task, dict) and task.get("type") == "recorded":
        if "file" not in task:
            raise ValueError(f"path: {path} records its task only as a digest; save it again with save_config")
        config["task"] = _load_tasks(path.with_name(task["file"]))
    return data, get_spec(data["base_env_id"]).config_class.from_dict(config)


def load_config(path: str | Path) -> tuple[str, EnvConfig, int | None]:
    """``(env_id, EnvConfig, max_episode_steps)`` from a file written by ``save_config``.

    ``max_episode_steps`` is the Gymnasium time limit the saved env was made with (None: the task's own).
    """
    data, config = _read(path)
    return data["env_id"], config, data.get("max_episode_steps")


def saved_spec(env_id: str, base_env_id: str, front_end: str, time_limit: int | None) -> Any:
    """A Gymnasium ``EnvSpec`` named ``env_id`` without keyword arguments (the config holds them all).

    The id's own registration when this process has it (the plug-in modules the config names are imported by
    then, and with them a researcher's ids); else the library's entry point of the front end under that id, so
    that ``env.spec.id`` is still the saved one. A registered id's keyword defaults are left out: they would
    override what the saved env was made with.
    """
    import dataclasses

    import gymnasium as gym
    from gymnasium.envs.registration import EnvSpec as GymEnvSpec
    from gymnasium.envs.registration import registry

    from continuum_gym import plugins
    from continuum_gym.envs.spec import get_spec

    if env_id not in registry:
        plugins.load_known()
    if env_id in registry:
        return dataclasses.replace(gym.spec(env_id), kwargs={}, max_episode_steps=time_limit)
    spec = get_spec(base_env_id)
    entry = spec.goal_entry_point if front_end == "goal" else spec.entry_point
    return GymEnvSpec(id=env_id, entry_point=entry, vector_entry_point=spec.vector_entry_point,
                      max_episode_steps=time_limit)


def make_from_config(path: str | Path, **kwargs: Any) -> Any:
    """The env saved at ``path``: the same front end, id and configuration; ``kwargs`` go to ``gym.make`` (e.g.
    ``render_mode``), or ``gym.make_vec`` for a saved vector env (e.g. ``num_envs`` to change its size)."""
    import gymnasium as gym

    data, config = _read(path)
    front_end = data["front_end"]
    spec = saved_spec(data["env_id"], data["base_env_id"], front_end, data.get("max_episode_steps"))
    if front_end == "vector":
        kwargs.setdefault("num_envs", data.get("num_envs", 1))
        return gym.make_vec(spec, vectorization_mode="vector_entry_point", config=config, **kwargs)
    return gym.make(spec, config=config, **{**(data.get("front_end_kwargs") or {}), **kwargs})


__all__ = ["save_config", "load_config", "make_from_config", "tasks_path", "saved_spec", "FORMAT", "FRONT_ENDS"]
