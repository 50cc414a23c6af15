"""The periodic held-out evaluation of a training run: TensorBoard scalars and ``evaluations.npz``."""

from __future__ import annotations

import io
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from continuum_gym.envs.benchmark import benchmark_of
from continuum_gym.envs.spec import get_spec
from continuum_gym.evaluation.io import write_bytes_atomic

if TYPE_CHECKING:
    from stable_baselines3.common.callbacks import BaseCallback

#: First validation-split task id of the training evaluation (ids EVAL_TASK_OFFSET .. + n_eval_episodes).
EVAL_TASK_OFFSET = 0
#: the run's cost at each evaluation: wall-clock and CPU seconds since it started, earlier sessions included
COST_COLUMNS = ("wall_s", "cpu_s")


def make_eval_callback(env_id: str, env_kwargs: Mapping[str, Any], run_dir: Path, freq: int, n_episodes: int,
                       report: Callable[[int, float], None] | None = None,
                       history: Mapping[str, Iterable[float]] | None = None,
                       helpers: Iterable[str] = (),
                       cost: Callable[[], tuple[float, float]] | None = None) -> BaseCallback:
    """Periodic evaluation on held-out validation tasks (fixed ids), logged to TensorBoard and evaluations.npz.

    The validation split, not the test split: a sweep selects its configuration on these numbers, and
    the test split is kept for final numbers only (``continuum-gym evaluate``).

    ``freq`` is in environment steps. ``history`` (``{column: list}``, from a checkpoint) continues an
    earlier learning curve: the next evaluation is ``freq`` steps after its last row, not at once.
    ``report(timesteps, value)`` is called after each evaluation (a sweep scheduler listens there).
    ``helpers`` act after the policy, as in training (``envs/helpers.py``). ``cost() -> (wall-clock s, CPU s)``,
    the run's cost so far, is recorded with each evaluation (columns ``wall_s`` and ``cpu_s``; NaN in the rows of a
    history that did not record them), so a run states what it cost without a scheduler's logs.
    """
    from stable_baselines3.common.callbacks import BaseCallback

    from continuum_gym.evaluation.rollout import make_core, run_episodes

    kwargs = {**env_kwargs, "task_split": "validation"}
    config_class = get_spec(env_id).config_class
    # a paper's fixed task has no validation instances (test_only_tasks: a ClassVar of the concrete configs)
    if kwargs.get("task") in config_class.test_only_tasks:
        kwargs["task"] = "random"
    core = make_core(env_id, n_episodes, **kwargs)
    from continuum_gym.envs.helpers import make_helpers

    made = make_helpers(env_id, tuple(helpers), core.config)
    task_ids = np.arange(EVAL_TASK_OFFSET, EVAL_TASK_OFFSET + n_episodes) % max(core.task_count, 1)
    metric = benchmark_of(env_id).headline_metric
    path = run_dir / "evaluations.npz"

    class _Eval(BaseCallback):
        def __init__(self):
            super().__init__()
            self.history = {"timesteps": [], "mean_return": [], metric: []}
            for key, values in (history or {}).items():
                self.history[key] = list(values)
            if cost is not None:
                for key in COST_COLUMNS:  # a history from before the cost was recorded: unknown, not zero
                    self.history[key] = self.history.get(key, [float("nan")] * len(self.history["timesteps"]))
            self.last = self.history["timesteps"][-1] if self.history["timesteps"] else -freq

        def _on_step(self) -> bool:
            if self.num_timesteps - self.last >= freq:
                self.evaluate()
            return True

        def _on_training_end(self) -> None:
            if not self.history["timesteps"] or self.history["timesteps"][-1] != self.num_timesteps:
                self.evaluate()

        def records(self) -> dict:
            """The curve so far as JSON-able lists (what a checkpoint stores)."""
            return {key: [int(v) if key == "timesteps" else float(v) for v in values]
                    for key, values in self.history.items()}

        def write(self) -> None:
            buffer = io.BytesIO()
            arrays: dict[str, Any] = {k: np.asarray(v) for k, v in self.history.items()}
            np.savez(buffer, **arrays)
            write_bytes_atomic(path, buffer.getvalue())

        def evaluate(self):
            self.last = self.num_timesteps
            result = run_episodes(core, self.model, task_ids, helpers=made)
            self.history["timesteps"].append(int(self.num_timesteps))
            self.history["mean_return"].append(float(result["return"].mean()))
            self.history[metric].append(float(result[metric].mean()))
            if cost is not None:
                for key, value in zip(COST_COLUMNS, cost()):
                    self.history[key].append(float(value))
            self.logger.record("eval/mean_return", float(result["return"].mean()))
            self.logger.record(f"eval/{metric}", float(result[metric].mean()))
            self.write()
            if report is not None:
                report(int(self.num_timesteps), float(result[metric].mean()))

    return _Eval()


def history_until(path: Path, step: int) -> dict:
    """Rows of an old-layout evaluations.npz up to ``step``, strictly increasing (old resumes duplicated rows)."""
    if not path.is_file():
        return {}
    data = np.load(path)
    keep, last = [], -np.inf
    for index, timestep in enumerate(data["timesteps"]):
        if last < timestep <= step:
            keep.append(index)
            last = timestep
    return {key: data[key][keep].tolist() for key in data.files}
