"""The keyword arguments of ``MyLab/EndoscopeReach-v0``, validated once (``EnvConfig`` does the rest)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

from continuum_gym.envs.config import EnvConfig, check_common, resolve_robot, spec
from continuum_gym.robots import ContinuumEndoscope


@dataclass(frozen=True)
class ReachConfig(EnvConfig):
    """Configuration of ``MyLab/EndoscopeReach-v0`` (SI units)."""

    env_id: ClassVar[str] = "MyLab/EndoscopeReach-v0"
    baselines: ClassVar[tuple] = ("jacobian_transpose",)
    default_weights: ClassVar[dict] = {"distance": 1.0, "action": 0.01}
    task_module: ClassVar[str] = "my_reach.tasks"
    trajectory_class: ClassVar[str] = "continuum_gym.envs.trajectories:TipTrajectory"  # a moving goal, recorded
    builtin_tasks: ClassVar[tuple] = ("reach",)
    object_keywords: ClassVar[tuple] = ("robot",)

    task: Any = field(default="reach", metadata=spec(doc="`reach` (a reachable goal point per episode) or a "
                                                         "`TipTrajectory` of the goal", type_name="str"))
    task_split: str = field(default="train", metadata=spec(doc="`train`, `validation` or `test`", type_name="str"))
    base_controller: str | None = field(default="jacobian_transpose", metadata=spec(
        doc="residual base: `jacobian_transpose` or `None` (pure RL)", type_name="str or None"))
    residual_scale: float = field(default=1.0, metadata=spec(unit="fraction of the action scale",
                                                             doc="residual at action 1.0 (in (0, 10])"))
    reward_weights: dict = field(default_factory=dict, metadata=spec(
        doc="weights of `distance` and `action` (defaults 1, 0.01)", type_name="dict"))
    control_dt: float = field(default=0.01, metadata=spec(unit="s", doc="control step (in (0, 0.1])"))
    substeps: int = field(default=1, metadata=spec(doc="Euler steps per control step"))
    max_episode_steps: int | None = field(default=None, metadata=spec(doc="cap on the episode length (steps)"))
    robot: Any = field(default=None, metadata=spec(doc="a `ContinuumEndoscope`; `None`: the paper's",
                                                   type_name="ContinuumEndoscope or None"))

    def __post_init__(self) -> None:
        object.__setattr__(self, "robot", resolve_robot(self.robot, ContinuumEndoscope, self.env_id))
        check_common(self)
