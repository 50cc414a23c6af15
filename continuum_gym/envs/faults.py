"""What happens to a value that is not finite: it is never a score.

A researcher's plug-in (a controller, a reward term, a robot, a recorded task) can write a NaN or an inf
on some state it was never tried on. Left alone, the NaN spreads through the row's state and is read as
a result: a NaN configuration has a VOI of 0, the best value, and a NaN pose error terminated the
episode as if the task had failed. So the step kernels flag every row whose joints, cached baseline
command, observation, metrics or reward are not finite (``common_kernels.mark_non_finite``, a
``NON_FINITE`` column of ``flags``), the registered controller's slot records whether the controller
wrote the first such value (``custom.record_fault``), and the core then does one of two things,
chosen by the env keyword ``on_non_finite``:

- ``"raise"`` (default): ``NonFiniteError`` naming the env, the plug-in(s) that can have written it,
  the row, its step and task instance, and the values;
- ``"truncate"``: the row's episode ends as truncated (``terminated`` False, ``truncated`` True) with
  ``info["non_finite"] = True``; its metrics become NaN (no metric value is reported for it), its
  reward and reward terms 0, and the non-finite entries of its observation 0, so that a learner's
  buffers stay finite. A row whose first observation is already non-finite is reported at reset
  (``info["non_finite"]``) and truncated by its first step. ``continuum-gym evaluate`` refuses to
  average an episode that carries the flag (``evaluation.rollout``).
"""

from __future__ import annotations

from typing import Any

import numpy as np

#: A batched core (``envs.batched.BatchedCore``, which imports this module: named, not imported)
BatchedCore = Any

#: The values of the env keyword ``on_non_finite``.
ON_NON_FINITE = ("raise", "truncate")
#: Rows a message lists before it says "and k more".
_LISTED = 4


class NonFiniteError(FloatingPointError, ValueError):
    """A plug-in or the robot's model produced a NaN or an inf: the row's result is not a number to score."""


def blamed(core: BatchedCore, rows: np.ndarray) -> str:
    """Words naming what can have written the non-finite values of ``rows``: the plug-ins the env runs."""
    from continuum_gym.envs import registered

    config = core.config
    env = core.spec.env_id
    culprits = []
    slot = getattr(core, "_custom", None)
    if slot is not None and slot.fault[0]:
        culprits.append(f"the registered controller {_reference('controller', env, core.base_controller)} wrote a "
                        "non-finite command")
    first = len(core.builtin_reward_names)
    bad_terms = [name for k, name in enumerate(core.reward_names[first:], start=first)
                 if not np.all(np.isfinite(core.terms[rows, k]))]
    if bad_terms:
        culprits.append(f"the registered reward term(s) {bad_terms} returned a non-finite value")
    if culprits:
        return "; ".join(culprits)
    suspects = [f"the robot ({_robot_words(config.robot)})"]
    task = config.task
    if isinstance(task, str) and task in registered.TASKS[env]:
        suspects.append(f"the task family {_reference('task', env, task)}")
    elif not isinstance(task, str):
        suspects.append("the recorded task")
    if core.base_controller is not None:
        suspects.append(f"the base controller {core.base_controller!r}")
    return ("no registered controller or reward term wrote a non-finite value; the state became non-finite "
            f"through {', '.join(suspects[:-1])}{' or ' if len(suspects) > 1 else ''}{suspects[-1]}")


def _reference(kind: str, env: str, name: str | None) -> str:
    from continuum_gym.envs import registered

    if name is None:
        return "None"
    try:
        return repr(registered.reference_of(kind, env, name))
    except (KeyError, ValueError):
        return repr(name)


def _robot_words(robot: object) -> str:
    lengths = getattr(robot, "lengths", None)
    kind = type(robot).__name__
    if lengths is None:
        return kind
    return f"{kind} of {len(lengths)} segment(s), lengths {np.round(np.asarray(lengths) * 1e3, 3).tolist()} mm"


def message(core: BatchedCore, rows: np.ndarray, when: str) -> str:
    """The error of ``rows`` whose values are not finite ``when`` ("step" or "reset")."""
    listed = []
    for row in rows[:_LISTED]:
        values = {"joints": core.joint_values()[row], "observation": core.obs[row], "metrics": core.metrics[row]}
        bad = {name: np.flatnonzero(~np.isfinite(array)).tolist() for name, array in values.items()}
        bad = {name: index for name, index in bad.items() if index}
        if not np.isfinite(core.rewards[row]):
            bad["reward"] = [float(core.rewards[row])]
        where = ", ".join(f"{name} entries {index}" for name, index in bad.items()) or "its reward terms"
        listed.append(f"row {int(row)} at step {int(core.steps[row])} (task id {int(core.tasks.task_id[row])} of the "
                      f"{core.config.task_split} split): non-finite {where}")
    more = f" and {len(rows) - _LISTED} more row(s)" if len(rows) > _LISTED else ""
    return (f"{core.spec.env_id}: a value is not finite (NaN or inf) after the {when}, in {'; '.join(listed)}{more}. "
            f"Cause: {blamed(core, rows)}. No result of such a row is valid, so none is reported; fix the plug-in "
            "(a command must be finite at every state the robot can reach), or pass on_non_finite='truncate' to end "
            "such episodes as truncated with info['non_finite'] = True and go on")


def handle(core: BatchedCore, stepped: np.ndarray, when: str) -> None:
    """Raise, or end as truncated, the rows of ``stepped`` (bool (N,)) that the kernels flagged non-finite."""
    column = core.non_finite_flag
    rows = np.flatnonzero((core.flags[:, column] != 0) & stepped)
    core._faults[0] = 0
    slot = getattr(core, "_custom", None)
    try:
        if len(rows) == 0:
            return
        if core.config.on_non_finite == "raise":
            raise NonFiniteError(message(core, rows, when))
        obs = core.obs[rows]
        obs[~np.isfinite(obs)] = 0.0
        core.obs[rows] = obs
        core.metrics[rows] = np.nan
        core.terms[rows] = 0.0
        core.rewards[rows] = 0.0
        core.flags[rows, core.terminated_flag] = 0
        core.flags[rows, core.truncated_flag] = 1 if when == "step" else 0
    finally:
        if slot is not None:
            slot.fault[0] = 0


__all__ = ["ON_NON_FINITE", "NonFiniteError", "handle", "message", "blamed"]
