"""The batched core of ``MyLab/EndoscopeReach-v0`` and its Gymnasium front ends.

``BatchedCore`` declares what a core must define (a missing hook fails at the class statement); the
front ends ``ContinuumEnv`` and ``ContinuumVectorEnv`` are the library's own, unchanged.
"""

from __future__ import annotations

import math

import numpy as np
from gymnasium import spaces

from continuum_gym.envs.batched import BatchedCore, row_threads, step_threads
from continuum_gym.envs.common_kernels import task_arrays
from continuum_gym.envs.info import InfoField, attribute, bits, column
from continuum_gym.envs.single import ContinuumEnv
from continuum_gym.envs.tasks import TaskContext
from continuum_gym.envs.vector import ContinuumVectorEnv
from my_reach.config import ReachConfig
from my_reach.kernel import (
    OBS_DIM,
    OBS_LIMIT,
    OBSERVATION,
    REWARD_TERMS,
    Flag,
    Metric,
    ReachOutputs,
    ReachParams,
    ReachState,
    reach_step_batch,
)
from my_reach.spec import SPEC

#: Joint rates at action 1.0: m/s for L0, rad/s for the angles.
ACTION_SCALE = np.array([0.05, math.pi / 4, math.pi / 4, math.pi / 2, math.pi / 4, math.pi / 2])

INFO_FIELDS = (
    InfoField("distance_m", column("metrics", Metric.DISTANCE), float, "distance of the view's target point "
              "from the goal (m)"),
    InfoField("clamped_joints", bits("flags", Flag.CLAMPED), None, "joints clamped at a limit (6,)"),
    InfoField("task_id", attribute("tasks.task_id"), int, "task instance"),
    InfoField("elapsed_steps", attribute("steps"), int, "control steps since reset"),
)


class ReachCore(BatchedCore):
    """N endoscopes reaching N goals, stepped by one compiled call."""

    spec = SPEC
    config_class = ReachConfig
    step_kernel = staticmethod(reach_step_batch)
    terminated_flag, truncated_flag, non_finite_flag = Flag.TERMINATED, Flag.TRUNCATED, Flag.NON_FINITE
    builtin_reward_names = REWARD_TERMS
    info_fields = INFO_FIELDS
    metric_columns = {"distance_m": Metric.DISTANCE}
    circular_joint_columns = (1, 3, 5)
    dof = 6

    def __init__(self, num_envs: int = 1, config: ReachConfig | None = None, num_threads: int | None = None,
                 **kwargs) -> None:
        self.config = config = self._config(config, kwargs)
        n = self.num_envs = self._num_envs(num_envs)
        self.task_split, self.base_controller = config.task_split, config.base_controller
        self.weights, self.control_dt, self.substeps = config.reward_weights, config.control_dt, config.substeps
        self.max_episode_steps = config.max_episode_steps
        self.robot = config.robot
        self.task_context = TaskContext(self.robot, self.control_dt)
        self.task_source = config.task_source
        self.task_count = self.task_source.count(self.task_split, self.task_context)
        self.single_observation_space = spaces.Box(-OBS_LIMIT, OBS_LIMIT, (OBS_DIM,), np.float32)
        self.single_action_space = spaces.Box(-1.0, 1.0, (6,), np.float32)
        self._setup_rewards()
        self.q, self.steps, self.limit = np.zeros((n, 6)), np.zeros(n, dtype=np.int64), np.zeros(n, dtype=np.int64)
        self.obs, self.base_cmd = np.zeros((n, OBS_DIM)), np.zeros((n, 6))
        self.metrics, self.flags = np.zeros((n, len(Metric))), np.zeros((n, len(Flag)), dtype=np.int64)
        self.terms, self.rewards = np.zeros((n, len(self.reward_names))), np.zeros(n)
        self.num_threads = step_threads(num_threads)
        self.row_threads = row_threads(n, self.num_threads, self.parallel_min_rows)
        self.tasks = self.task_source.batch(self.task_split, np.zeros(n, dtype=np.int64), self.task_context)
        lower, upper = self.robot.joint_limits
        self._state = ReachState(self.q, self.steps)
        self._tasks = task_arrays(self.tasks, self.limit)
        self._env = ReachParams(self.control_dt, self.substeps, self.base_controller is not None,
                                config.residual_scale, ACTION_SCALE, lower, upper,
                                np.array([self.weights[name] for name in REWARD_TERMS]))
        self._faults = np.zeros(1, dtype=np.int64)
        self._out = ReachOutputs(self.base_cmd, self.obs, self.metrics, self.terms, self.rewards, self.flags,
                                 self._faults)
        self._model = self.kernel_model()

    def kernel_model(self) -> tuple:
        return (self.robot.kernel_args(),)

    def reset_rows(self, rows, task_ids) -> None:
        rows = np.asarray(rows, dtype=np.int64)
        self._install_tasks(rows, self.task_source.batch(self.task_split, task_ids, self.task_context))
        self.observe_rows(rows)

    def step_values(self) -> dict:
        return {"distance": self.metrics[:, Metric.DISTANCE]}

    def controller_observation(self, row: int = 0) -> dict:
        goal, _ = self.desired(row, self.steps[row] * self.control_dt)
        return {"q": self.measured_joints(row), "goal": goal, "dt": self.control_dt, "robot": self.robot}


class EndoscopeReachEnv(ContinuumEnv):
    __doc__ = f"""The continuum endoscope points its view at a goal point (a toy third environment; see ``my_reach``).

    ## Observation Space
    ``Box(-10, 10, ({OBS_DIM},), float32)``, each entry clipped to +-10:

{OBSERVATION.table()}
    """

    core_class = ReachCore
    metadata = {"render_modes": [], "render_fps": 100}  # no pybullet scene (``EnvSpec.scene``) for this toy


class EndoscopeReachVectorEnv(ContinuumVectorEnv):
    """Native batched version of ``EndoscopeReachEnv`` (one compiled call per step)."""

    core_class = ReachCore
    metadata = {**ContinuumVectorEnv.metadata, "render_modes": []}
