"""The configuration of ``ContinuumGym/OcclusionAvoidance-v0``: every keyword argument, validated once (see ``envs/config.py``)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar

from continuum_gym.envs.config import (
    EnvConfig,
    check_common,
    check_model_error,
    model_error_field,
    randomize_field,
    resolve_robot,
    spec,
)
from continuum_gym.validation import choice, describe, fraction

#: The built-in task families' names (the paper's ``circle`` exists only in the test split), here rather than
#: in ``tasks.py`` so that the config (and ``continuum-gym --help``) does not import the task generators.
TASKS = ("hold", "circle", "random", "mixed")
TEST_ONLY = ("circle",)

if TYPE_CHECKING:
    from continuum_gym.baselines.occlusion import OcclusionLimits


@dataclass(frozen=True)
class OcclusionConfig(EnvConfig):
    """Configuration of ``ContinuumGym/OcclusionAvoidance-v0`` (SI units)."""

    env_id: ClassVar[str] = "ContinuumGym/OcclusionAvoidance-v0"
    #: The analytic controllers a residual can be built on (the env spec lists them from here).
    #: ``arc_plan`` is the projected gradient that, on hold tasks, tracks a trajectory along the self-motion arc
    #: planned when the episode starts (``plan_base.py``).
    baselines: ClassVar[tuple] = ("minimum_norm", "projected_gradient", "arc_plan")
    #: The residual scale a base takes when ``residual_scale`` is not given (any other base: 0.3).
    base_residual_scales: ClassVar[dict] = {"arc_plan": 2.0}
    default_weights: ClassVar[dict] = {"voi": 1.0, "tip_position": 0.05, "tip_orientation": 0.05, "visibility": 10.0,
                                       "action": 0.01}
    residual_spaces: ClassVar[tuple] = ("nullspace", "joint")
    object_keywords: ClassVar[tuple] = ("robot", "cone", "model_error")
    task_module: ClassVar[str] = "continuum_gym.envs.occlusion.tasks"
    #: the robots this env takes (``registry.register_robot`` checks a plug-in against it)
    robot_class: ClassVar[str] = "continuum_gym.robots.mbcr:MultiBackboneRobot"
    trajectory_class: ClassVar[str] = "continuum_gym.envs.trajectories:TipTrajectory"
    builtin_tasks: ClassVar[tuple] = TASKS
    test_only_tasks: ClassVar[tuple] = TEST_ONLY

    task: Any = field(default="hold", metadata=spec(
        doc="`hold` (hold a paper-like start pose), `random` (smooth random tip trajectories, <= 12 mm), `mixed` "
            "(even task ids hold, odd ids random), `circle` (the paper's task b; test split only), a registered "
            "family's name, or recorded data: a `TipTrajectory` or a list of them", type_name="str or TipTrajectory(s)"))
    task_split: str = field(default="train", metadata=spec(
        doc="`train`, `validation` (for model selection) or `test`: disjoint task instances", type_name="str"))
    base_controller: str | None = field(default="projected_gradient", metadata=spec(
        doc="residual base: `projected_gradient`, `minimum_norm`, `arc_plan` (on hold tasks the projected gradient "
            "tracks a trajectory along the self-motion arc planned when the episode starts, about 1 s per start, "
            "cached per process; other tasks, and every task under a `model_error`, keep the projected gradient), "
            "a registered controller, or `None` (pure RL)", type_name="str or None"))
    residual_scale: float = field(default=None, metadata=spec(  # type: ignore[assignment]  # None: resolved below
        unit="fraction of the rate limits", doc="residual at action 1.0 (in (0, 10]); `None`: 0.3, or 2 with the "
        "`arc_plan` base (which needs >= 2: its correction of the projected gradient, up to twice the rate limits, "
        "travels in the residual)", type_name="float or None"))
    residual_space: str = field(default="nullspace", metadata=spec(
        doc="`nullspace` (projected into the tip Jacobian's null space at every substep) or `joint`",
        type_name="str"))
    reward_weights: dict = field(default_factory=dict, metadata=spec(
        doc="weights of the terms `voi`, `tip_position`, `tip_orientation`, `visibility`, `action` (defaults 1, "
            "0.05, 0.05, 10, 0.01; each in [0, 1e6])", type_name="dict"))
    visibility_guard: float | None = field(default=0.69, metadata=spec(
        unit="fraction of the cone half-angle", doc="the residual's endoscope rotation is cut where it would carry "
        "the tip beyond this angle from the view axis (in (0, 1); `None`: off); it does not limit the joint residual "
        "or the baseline, so it guarantees visibility only as far as the rotation goes (env docstring)",
        type_name="float or None"))
    control_dt: float = field(default=0.01, metadata=spec(unit="s", doc="policy step (in (0, 0.1])",
                                                          type_name="float"))
    substeps: int = field(default=10, metadata=spec(doc="kinematic substeps per policy step (the paper's 1 ms "
                                                        "loop at the default)", type_name="int"))
    max_bend: float = field(default=math.pi / 2, metadata=spec(
        unit="rad", doc="per-segment bend limit, two-sided |pi/2 - theta_j| <= max_bend (in (0, pi])",
        type_name="float"))
    insertion: tuple = field(default=(0.0, 0.04), metadata=spec(unit="m", doc="(min, max) insertion q_ins, within "
                                                                "[0, 0.2]", type_name="(float, float)"))
    bend_rate: float = field(default=3.0, metadata=spec(unit="rad/s", doc="|theta_dot| limit", type_name="float"))
    plane_rate: float = field(default=6.0, metadata=spec(unit="rad/s", doc="|delta_dot| limit", type_name="float"))
    insertion_rate: float = field(default=0.02, metadata=spec(unit="m/s", doc="|q_ins_dot| limit",
                                                              type_name="float"))
    gamma_rate: float = field(default=3.0, metadata=spec(unit="rad/s", doc="|gamma_dot| limit (endoscope rotation)",
                                                         type_name="float"))
    lens_model: str | None = field(default=None, metadata=spec(
        doc="`literal` or `physical` reading of the lens origin (paper-notes §1.3 item 7); `None`: the cone's "
            "(literal for the paper's)", type_name="str or None"))
    max_episode_steps: int | None = field(default=None, metadata=spec(
        doc="cap on the episode length in steps (`None`: the task's own duration)", type_name="int or None"))
    robot: Any = field(default=None, metadata=spec(
        doc="a `MultiBackboneRobot` (1-4 segments, any lengths and stiffness) or a registered robot's name; `None`: "
            "the paper's 3 segments", type_name="MultiBackboneRobot, str or None"))
    cone: Any = field(default=None, metadata=spec(
        doc="a `LensCone` (channel offset d_o, lens tilt alpha, half-angle beta, lens model); `None`: the paper's",
        type_name="LensCone or None"))
    model_error: Any = model_error_field()
    randomize_model_error: bool = randomize_field()

    def __post_init__(self) -> None:
        from continuum_gym.baselines.occlusion import OcclusionLimits
        from continuum_gym.geometry.lens_cone import LensCone
        from continuum_gym.robots import MultiBackboneRobot

        set_ = object.__setattr__
        set_(self, "robot", resolve_robot(self.robot, MultiBackboneRobot, self.env_id))
        if self.cone is not None and not isinstance(self.cone, LensCone):
            raise ValueError(f"cone must be a LensCone or None; got {describe(self.cone)}")
        if self.lens_model is not None:
            choice(self.lens_model, ("literal", "physical"), "lens_model")
            if self.cone is not None and self.cone.lens_model != self.lens_model:
                raise ValueError(f"lens_model={self.lens_model!r} contradicts cone.lens_model="
                                 f"{self.cone.lens_model!r}: give one of them")
        if self.cone is None:
            set_(self, "cone", LensCone(lens_model=self.lens_model or "literal"))
        assert self.cone is not None  # set just above when it was not given (mypy does not see object.__setattr__)
        set_(self, "lens_model", self.cone.lens_model)
        if self.residual_scale is None:
            own = self.base_residual_scales.get(self.base_controller) if isinstance(self.base_controller, str) else None
            set_(self, "residual_scale", 0.3 if own is None else own)  # a bad base is named by check_common
        check_common(self)
        check_model_error(self, "occlusion", self.robot.n_segments)
        choice(self.residual_space, self.residual_spaces, "residual_space")
        if self.base_controller == "arc_plan" and self.robot.dof != 7:
            raise ValueError(f"base_controller='arc_plan' plans along the one-dimensional self-motion arc of a robot "
                             f"with 7 DoF (3 segments and insertion); got a robot with dof={self.robot.dof}")
        if self.base_controller == "arc_plan" and self.residual_scale < 2.0:
            # the plan's correction (plan rate - base rate) reaches twice the rate limits, and is sent as residual
            raise ValueError(f"base_controller='arc_plan' needs residual_scale >= 2 (the plan's correction of the "
                             f"projected gradient, up to twice the rate limits, must fit in the residual's reach); "
                             f"got {self.residual_scale!r}")
        if self.visibility_guard is not None:
            if isinstance(self.visibility_guard, str):
                raise ValueError(f"visibility_guard must be a number in (0, 1) (fraction of the cone half-angle) "
                                 f"or None; got {self.visibility_guard!r}")
            set_(self, "visibility_guard", fraction(self.visibility_guard, "visibility_guard", allow_one=False))
        limits = OcclusionLimits(max_bend=self.max_bend, insertion=self.insertion, bend_rate=self.bend_rate,
                                 plane_rate=self.plane_rate, insertion_rate=self.insertion_rate,
                                 gamma_rate=self.gamma_rate)
        for name in ("max_bend", "insertion", "bend_rate", "plane_rate", "insertion_rate", "gamma_rate"):
            set_(self, name, getattr(limits, name))

    @property
    def limits(self) -> OcclusionLimits:
        """The ``OcclusionLimits`` these fields define."""
        from continuum_gym.baselines.occlusion import OcclusionLimits

        return OcclusionLimits(max_bend=self.max_bend, insertion=self.insertion, bend_rate=self.bend_rate,
                               plane_rate=self.plane_rate, insertion_rate=self.insertion_rate,
                               gamma_rate=self.gamma_rate)


__all__ = ["OcclusionConfig", "TASKS", "TEST_ONLY"]
