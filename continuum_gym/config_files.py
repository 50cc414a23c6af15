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
    import gymnasium

    from continuum_gym.envs.config import EnvConfig

#: Version of the file layout (bumped when a key changes meaning).
FORMAT = 1
_TIP_FIELDS = ("times", "positions", "rotations", "start_q", "start_gamma")
_DAVINCI_FIELDS = ("times", "configurations")


def _config_and_id(env: Any):
    """The ``EnvConfig`` of any front end (single, vector, SB3, goal, wrapped) and the id it was made as."""
    inner = getattr(env, "unwrapped", env)
    config = getattr(inner, "config", None)  # every front end has it (envs.single.CoreOwner, the goal envs)
    if config is None:
        raise ValueError(f"env must be a continuum-gym environment (single, vector, SB3 or goal); got {describe(env)}")
    spec = getattr(env, "spec", None) or getattr(inner, "spec", None)
    env_id = getattr(spec, "id", None) if spec is not None and hasattr(spec, "entry_point") else None
    return config, env_id or config.env_id, getattr(spec, "max_episode_steps", None)


def tasks_path(path: Path) -> Path:
    """Where the recorded tasks of the config file ``path`` are stored."""
    return path.with_name(path.stem + ".tasks.npz")


def _save_tasks(trajectories: list, path: Path) -> None:
    arrays: dict[str, Any] = {"count": np.array(len(trajectories))}  # Any: np.savez's **kwds (not its keywords)
    for k, trajectory in enumerate(trajectories):
        names = _TIP_FIELDS if hasattr(trajectory, "positions") else _DAVINCI_FIELDS
        for name in names:
            value = getattr(trajectory, name)
            if value is not None:
                arrays[f"{k}/{name}"] = np.asarray(value, dtype=np.float64)
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    write_bytes_atomic(path, buffer.getvalue())


def _load_tasks(path: Path) -> list:
    from continuum_gym.envs.trajectories import DaVinciTrajectory, TipTrajectory

    if not path.is_file():
        raise ValueError(f"the config's recorded tasks are missing: {path} (written beside the config file by "
                         "save_config; copy both files)")
    with np.load(path) as data:
        out = []
        for k in range(int(data["count"])):
            tip = f"{k}/positions" in data
            names = _TIP_FIELDS if tip else _DAVINCI_FIELDS
            kwargs: dict[str, Any] = {name: data[f"{k}/{name}"] for name in names if f"{k}/{name}" in data}
            if "start_gamma" in kwargs:
                kwargs["start_gamma"] = float(kwargs["start_gamma"])
            out.append((TipTrajectory if tip else DaVinciTrajectory)(**kwargs))
    return out


def save_config(env: Any, path: str | Path) -> Path:
    """Write ``env``'s id and configuration to the YAML file ``path`` (recorded tasks beside it); returns it."""
    import yaml

    from continuum_gym.envs.task_sources import RecordedTasks

    config, env_id, time_limit = _config_and_id(env)
    path = Path(path)
    data = config.to_dict()
    source = config.task_source
    if isinstance(source, RecordedTasks):
        _save_tasks(source.trajectories, tasks_path(path))
        data["task"] = {"type": "recorded", "file": tasks_path(path).name, **source.describe()}
    path.parent.mkdir(parents=True, exist_ok=True)
    write_text_atomic(path, yaml.safe_dump({"format": FORMAT, "env_id": env_id, "base_env_id": config.env_id,
                                            "max_episode_steps": time_limit, "config": data}, sort_keys=False))
    return path


def load_config(path: str | Path) -> tuple[str, EnvConfig, int | None]:
    """``(env_id, EnvConfig, max_episode_steps)`` from a file written by ``save_config``.

    ``max_episode_steps`` is the Gymnasium time limit the saved env was made with (None: the task's own).
    """
    import yaml

    from continuum_gym.envs.spec import get_spec

    path = Path(path)
    if not path.is_file():
        raise ValueError(f"path: no config file at {path}")
    data = yaml.safe_load(path.read_text())
    if not isinstance(data, dict) or not {"config", "env_id", "base_env_id"} <= set(data):
        raise ValueError(f"path: {path} is not a config file of save_config (keys format, env_id, base_env_id, "
                         "config)")
    if data.get("format") != FORMAT:
        raise ValueError(f"path: {path} has format {data.get('format')!r}; this version reads format {FORMAT}")
    env_id, config = data["env_id"], dict(data["config"])
    task = config.get("task")
    if isinstance(task, dict) and task.get("type") == "recorded":
        if "file" not in task:
            raise ValueError(f"path: {path} records its task only as a digest; save it again with save_config")
        config["task"] = _load_tasks(path.with_name(task["file"]))
    return env_id, get_spec(data["base_env_id"]).config_class.from_dict(config), data.get("max_episode_steps")


def make_from_config(path: str | Path, **kwargs: Any) -> gymnasium.Env:
    """``gym.make`` of the env saved at ``path``; ``kwargs`` go to ``gym.make`` (e.g. ``render_mode``)."""
    import gymnasium as gym

    env_id, config, time_limit = load_config(path)
    # The config holds every keyword: made from the library's own id, so that a registered id's defaults
    # cannot override what the saved env was made with; the time limit is the saved env's.
    if time_limit is not None:
        kwargs.setdefault("max_episode_steps", time_limit)
    return gym.make(config.env_id, config=config, **kwargs)


__all__ = ["save_config", "load_config", "make_from_config", "tasks_path", "FORMAT"]
