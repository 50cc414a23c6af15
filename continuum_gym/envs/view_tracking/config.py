"""The configuration of ``ContinuumGym/ViewTracking-v0``: every keyword argument, validated once (see ``envs/config.py``)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, ClassVar

from continuum_gym.envs.config import (
    EnvConfig,
    check_common,
    check_model_error,
    model_error_field,
    randomize_field,
    resolve_robot,
    spec,
)
from continuum_gym.validation import boolean, choice, describe, integer, number

#: The built-in task families' names (the paper's case studies and coverage grid exist only in the test split),
#: here rather than in ``tasks.py`` so that the config (and ``continuum-gym --help``) does not import the generators.
TASKS = ("random", "static", "pan_tilt", "mixed", "case1", "case2", "coverage")
TEST_ONLY = ("case1", "case2", "coverage")

#: Largest coverage grid (points per axis).
MAX_GRID = 401


@dataclass(frozen=True)
class ViewTrackingConfig(EnvConfig):
    """Configuration of ``ContinuumGym/ViewTracking-v0`` (SI units)."""

    env_id: ClassVar[str] = "ContinuumGym/ViewTracking-v0"
    baselines: ClassVar[tuple] = ("resolved_rate", "dimension_reduced")
    packaged_controllers: ClassVar[tuple] = ("continuum_gym.envs.view_tracking.distilled:distilled_optimum",)
    default_weights: ClassVar[dict] = {"overlap": 1.0, "position": 0.1, "orientation": 0.1, "action": 0.01,
                                       "overlap_bonus": 0.0}
    residual_spaces: ClassVar[tuple] = ("joint", "target")
    object_keywords: ClassVar[tuple] = ("robot", "davinci", "model_error")
    task_module: ClassVar[str] = "continuum_gym.envs.view_tracking.tasks"
    #: the robots this env takes (``registry.register_robot`` checks a plug-in against it)
    robot_class: ClassVar[str] = "continuum_gym.robots.endoscope:ContinuumEndoscope"
    trajectory_class: ClassVar[str] = "continuum_gym.envs.trajectories:DaVinciTrajectory"
    builtin_tasks: ClassVar[tuple] = TASKS
    test_only_tasks: ClassVar[tuple] = TEST_ONLY

    task: Any = field(default="random", metadata=spec(
        doc="`random` (smooth random da Vinci motions), `static` (random fixed views), `pan_tilt` (the coverage "
            "map's distribution off its grid), `mixed` (even ids `pan_tilt`, odd ids `random`), the paper's `case1`, "
            "`case2`, `coverage` (test split only), a "
            "registered family's name, or recorded data: a `DaVinciTrajectory` or a list of them",
        type_name="str or DaVinciTrajectory(s)"))
    task_split: str = field(default="train", metadata=spec(
        doc="`train`, `validation` (for model selection) or `test`: disjoint task instances", type_name="str"))
    base_controller: str | None = field(default="dimension_reduced", metadata=spec(
        doc="residual base: `dimension_reduced`, `resolved_rate`, a registered controller (the package ships "
            "`distilled_optimum`), or `None` (pure RL)", type_name="str or None"))
    residual_scale: float = field(default=0.3, metadata=spec(
        unit="fraction of the action scale", doc="residual at action 1.0 (in (0, 10])", type_name="float"))
    residual_space: str = field(default="joint", metadata=spec(
        doc="`joint` (added to the baseline's joint rates) or `target` (moves the target the baseline's IK "
            "tracks)", type_name="str"))
    reward_weights: dict = field(default_factory=dict, metadata=spec(
        doc="weights of `overlap`, `position`, `orientation`, `action`, `overlap_bonus` (defaults 1, 0.1, 0.1, "
            "0.01, 0; each in [0, 1e6])", type_name="dict"))
    control_dt: float = field(default=0.01, metadata=spec(unit="s", doc="policy step = the IK step (in (0, 0.1])",
                                                          type_name="float"))
    substeps: int = field(default=1, metadata=spec(doc="must be 1: the paper's IK step is the control step",
                                                   type_name="int"))
    rate_limits: tuple | None = field(default=None, metadata=spec(
        unit="m/s, rad/s", doc="6 joint-rate limits (`None`: the paper has none)", type_name="6 floats or None"))
    grid: int = field(default=21, metadata=spec(doc="coverage grid points per axis (in [2, 401])", type_name="int"))
    max_episode_steps: int | None = field(default=None, metadata=spec(
        doc="cap on the episode length in steps (`None`: the task's own duration)", type_name="int or None"))
    observe_target: bool = field(default=False, metadata=spec(
        doc="append the da Vinci configuration [L_dV, yaw, pitch, sin roll, cos roll] to the observation",
        type_name="bool"))
    robot: Any = field(default=None, metadata=spec(
        doc="a `ContinuumEndoscope` (lengths, joint limits) or a registered robot's name; `None`: the paper's",
        type_name="ContinuumEndoscope, str or None"))
    davinci: Any = field(default=None, metadata=spec(
        doc="a `DaVinciEndoscope` (viewing angle alpha, view distance Le); `None`: the paper's 30-degree one",
        type_name="DaVinciEndoscope or None"))
    model_error: Any = model_error_field()
    randomize_model_error: bool = randomize_field()

    def __post_init__(self) -> None:
        from continuum_gym.robots import ContinuumEndoscope, DaVinciEndoscope

        set_ = object.__setattr__
        set_(self, "robot", resolve_robot(self.robot, ContinuumEndoscope, self.env_id))
        if self.davinci is None:
            set_(self, "davinci", DaVinciEndoscope())
        elif not isinstance(self.davinci, DaVinciEndoscope):
            raise ValueError(f"davinci must be a DaVinciEndoscope or None; got {describe(self.davinci)}")
        check_common(self)
        check_model_error(self, "view", 2)
        choice(self.residual_space, self.residual_spaces, "residual_space")
        if self.residual_space == "target" and self.base_controller is None:
            raise ValueError("residual_space='target' moves the baseline's target: it needs a base_controller")
        if self.substeps != 1:
            raise ValueError(f"substeps must be 1 for ViewTracking (the paper's IK step is the control step); "
                             f"got {self.substeps!r}")
        if self.rate_limits is not None:
            try:
                values = tuple(self.rate_limits)
            except TypeError:
                values = ()
            if len(values) != 6:
                raise ValueError("rate_limits must be 6 positive joint-rate limits (m/s for L0, rad/s) or None; got "
                                 f"{describe(self.rate_limits)}")
            set_(self, "rate_limits", tuple(
                math.inf if v == math.inf else number(v, f"rate_limits[{k}]", low=0.0, low_open=True,
                                                      unit="m/s or rad/s (inf: unlimited)")
                for k, v in enumerate(values)))
        set_(self, "grid", integer(self.grid, "grid (points per axis)", low=2, high=MAX_GRID))
        set_(self, "observe_target", boolean(self.observe_target, "observe_target"))


__all__ = ["ViewTrackingConfig", "TASKS", "TEST_ONLY", "MAX_GRID"]
