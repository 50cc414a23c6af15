"""``ContinuumGym/ViewTracking-v0``: the continuum endoscope reproducing a moving da Vinci 30-degree view."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any, cast

import numpy as np
from gymnasium import spaces
from gymnasium.vector import VectorEnv

from continuum_gym.baselines.registry import make_controller
from continuum_gym.envs.batched import (
    BatchedCore,
    row_threads,
    step_threads,
)
from continuum_gym.envs.common_kernels import task_arrays
from continuum_gym.envs.info import InfoField, attribute, bits, column, env_docstring
from continuum_gym.envs.single import ContinuumEnv
from continuum_gym.envs.tasks import TaskContext
from continuum_gym.envs.vector import ContinuumVectorEnv
from continuum_gym.envs.view_tracking.config import ViewTrackingConfig
from continuum_gym.envs.view_tracking.kernel import (
    ACTION_DIM,
    OBS_LIMIT,
    OVERLAP_BONUS_THRESHOLD,
    REWARD_TERMS,
    TARGET_SHIFT_SCALE,
    ViewOutputs,
    ViewState,
    ViewStepParams,
    view_step_batch,
)
from continuum_gym.envs.view_tracking.outputs import OBS_DIM, OBSERVATION, TARGET_OBS_DIM, Flag, Metric
from continuum_gym.envs.view_tracking.spec import SPEC as VIEW_SPEC
from continuum_gym.geometry.frustum import Frustum

if TYPE_CHECKING:
    from continuum_gym.baselines.view_tracking import ViewTrackingController

#: Joint-rate command at action 1.0 (pure RL) and the unit of the residual: m/s for L0, rad/s.
ACTION_SCALE = np.array([0.1, math.pi / 2, math.pi / 2, math.pi, math.pi / 2, math.pi])

#: ``info`` of every step, for the single env (one row) and the vector env (arrays) alike.
INFO_FIELDS = (
    InfoField("overlap_ratio", column("metrics", Metric.OR), float,
              "exact overlap ratio of the two view frustums at the new state"),
    InfoField("position_error_m", column("metrics", Metric.POSITION_ERROR), float,
              "distance of the target point from the da Vinci's (m)"),
    InfoField("orientation_error_rad", column("metrics", Metric.ORIENTATION_ERROR), float,
              "orientation error of the camera frame (rad)"),
    InfoField("clamped_joints", bits("flags", Flag.CLAMPED), None, "joints clamped at a limit (6,)"),
    InfoField("rate_saturated", column("flags", Flag.RATE_SATURATED, bool), bool,
              "joint rates scaled down to ``rate_limits``"),
    InfoField("non_finite", column("flags", Flag.NON_FINITE, bool), bool,
              "a value of the row was not finite (NaN or inf) and its episode ended as truncated (only with "
              "``on_non_finite='truncate'``; its metrics are NaN)"),
    InfoField("base_command", attribute("base_cmd"), None, "the baseline's joint rates at the new state (6,)"),
    InfoField("task_id", attribute("tasks.task_id"), int, "task instance"),
    InfoField("elapsed_steps", attribute("steps"), int, "control steps since reset"),
)


class ViewTrackingCore(BatchedCore):
    """Batched state and step of the view-tracking environment (see ``ViewTrackingEnv``)."""

    spec = VIEW_SPEC
    config_class = ViewTrackingConfig
    builtin_reward_names = REWARD_TERMS
    step_kernel = staticmethod(view_step_batch)
    terminated_flag, truncated_flag, non_finite_flag = Flag.TERMINATED, Flag.TRUNCATED, Flag.NON_FINITE
    # A row costs ~3 us: at N = 64 waking a second thread costs more than it saves (benchmarks/batch.py times
    # one thread against all cores); from N = 128 it pays.
    parallel_min_rows = 128
    # Threads claim 8 rows (~25 us) at a time: one claim per row would add an atomic add on a cache line
    # both cores write, and a call of the row loop, to every ~3 us row.
    claim_block = 8
    info_fields = INFO_FIELDS
    metric_columns = {"overlap_ratio": Metric.OR, "position_error_m": Metric.POSITION_ERROR,
                      "orientation_error_rad": Metric.ORIENTATION_ERROR}
    dof = ACTION_DIM

    def __init__(self, num_envs: int = 1, config: ViewTrackingConfig | None = None, num_threads: int | None = None,
                 **kwargs: Any) -> None:
        self.config = config = self._config(config, kwargs)
        self.num_envs = self._num_envs(num_envs)
        self.task, self.task_split = config.task, config.task_split
        self.base_controller = config.base_controller
        self.residual_space = config.residual_space
        self.residual_scale = config.residual_scale
        self.weights = config.reward_weights
        self.control_dt = config.control_dt
        self.substeps = 1
        self.grid = config.grid
        builtin = config.base_controller if config.base_controller in self.spec.baselines else "dimension_reduced"
        self.controller = cast("ViewTrackingController",  # builtin is one of this env's baselines
                               make_controller(builtin, robot=config.robot))
        self.robot = self.controller.robot
        self.davinci = config.davinci
        self.frustum = Frustum()
        self.rate_limits = np.full(ACTION_DIM, np.inf) if config.rate_limits is None else \
            np.array(config.rate_limits, dtype=float)
        self.max_episode_steps = config.max_episode_steps
        self.task_context = TaskContext(self.robot, self.control_dt, grid=self.grid)
        self.task_source = config.task_source
        self.task_count = self.task_source.count(self.task_split, self.task_context)
        self.observe_target = config.observe_target
        obs_dim = OBS_DIM + (TARGET_OBS_DIM if self.observe_target else 0)
        self.single_observation_space = spaces.Box(-OBS_LIMIT, OBS_LIMIT, (obs_dim,), np.float32)
        self.single_action_space = spaces.Box(-1.0, 1.0, (ACTION_DIM,), np.float32)
        n = self.num_envs
        self._setup_mismatch("view", 2)
        self._setup_rewards()
        self.q = np.zeros((n, 6))
        self.steps = np.zeros(n, dtype=np.int64)
        self.obs = np.zeros((n, obs_dim))
        self.base_cmd = np.zeros((n, ACTION_DIM))
        self.metrics = np.zeros((n, len(Metric)))
        self.terms = np.zeros((n, len(self.reward_names)))
        self.rewards = np.zeros(n)
        self.limit = np.zeros(n, dtype=np.int64)
        self.num_threads = step_threads(num_threads)
        self.row_threads = row_threads(n, self.num_threads, self.parallel_min_rows)
        self.flags = np.zeros((n, len(Flag)), dtype=np.int64)
        self.tasks = self.task_source.batch(self.task_split, np.zeros(n, dtype=np.int64), self.task_context)
        has_base = self.base_controller is not None
        self._state = ViewState(self.q, self.steps)
        self._tasks = task_arrays(self.tasks, self.limit)
        self._env = ViewStepParams(
            control_dt=self.control_dt, has_base=has_base, residual_scale=self.residual_scale if has_base else 1.0,
            target_space=self.residual_space == "target", target_scale=TARGET_SHIFT_SCALE, action_scale=ACTION_SCALE,
            rate_limit=self.rate_limits, weights=np.array([self.weights[key] for key in REWARD_TERMS]))
        self._faults = np.zeros(1, dtype=np.int64)
        self._out = ViewOutputs(self.base_cmd, self.obs, self.metrics, self.terms, self.rewards, self.flags,
                                self._faults)
        self._model = self.kernel_model()
        self.overlap_polish = config.overlap_polish
        lower, upper = self.robot.joint_limits
        # what the lookahead reads besides the observation and the actions, and its output (``polish``)
        self._polish_model = (self.control_dt, self._env.residual_scale * ACTION_SCALE, ACTION_SCALE, lower, upper,
                              self.robot.kernel_args(), self.davinci.Le,
                              np.array([self.frustum.tan_half, self.frustum.near, self.frustum.far]))
        self._polished = np.empty((n, ACTION_DIM))

    def step(self, actions: np.ndarray, active: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if self.overlap_polish is not None:  # the lookahead on the OR (``polish``) before the compiled step
            from continuum_gym.envs.view_tracking.polish import polish_actions

            polish_actions(self.obs, np.asarray(actions, dtype=np.float64), np.asarray(active), self.overlap_polish,
                           *self._polish_model, self._polished)
            actions = self._polished.astype(np.asarray(actions).dtype)
        return super().step(actions, active)

    def kernel_model(self) -> tuple:
        return self.robot.kernel_args(), self.controller.params, self.davinci.kernel_args(), self.frustum.kernel_args()

    def mismatch_kernel(self) -> Any:
        from continuum_gym.envs.view_tracking.mismatch import view_mismatch_batch

        return view_mismatch_batch

    def reset_rows(self, rows: np.ndarray, task_ids: np.ndarray) -> None:
        rows = np.asarray(rows, dtype=np.int64)
        fresh = self.task_source.batch(self.task_split, task_ids, self.task_context)
        self._install_tasks(rows, fresh)
        self._reset_mismatch(rows, task_ids)
        self.observe_rows(rows)

    def step_values(self) -> dict:
        """Per-step values the evaluation reduces to episode metrics (``VIEW_SPEC.episode_metrics``)."""
        ratio = self.metrics[:, Metric.OR]
        return {"or": ratio, "or_above": (ratio > OVERLAP_BONUS_THRESHOLD) * 1.0,
                "position_error": self.metrics[:, Metric.POSITION_ERROR]}

    def davinci_configuration(self, row: int = 0) -> np.ndarray:
        """q_davinci [L_dV (m), yaw, pitch, roll] of the target at the row's current time (clipped to its ranges)."""
        x, _ = self.desired(row, self.steps[row] * self.control_dt)
        lower, upper = self.davinci.joint_limits
        return np.clip(x, lower, upper)

    def controller_observation(self, row: int = 0) -> dict:
        p, R = self.davinci.target_pose(self.davinci_configuration(row))
        return {"q": self.measured_joints(row), "p_target": p, "R_target": R, "dt": self.control_dt, "robot": self.robot}


_DOC = env_docstring("""The 2-segment continuum endoscope of Deng, Xu et al. reproducing a moving da Vinci 30-degree view.

    ## Description
    A 6-DoF continuum endoscope (stem insertion L0, stem rotation phi, two bending segments) must place
    its view where a da Vinci 30-degree endoscope pivoting about the remote centre looks: its visual
    target point ct and camera frame must match the da Vinci's target frame. Kinematics: paper 001 with
    paper-notes §2 (SI at the interface; the paper's IK arithmetic in mm inside). Scored by the exact
    overlap ratio (OR) of the two square 90-degree view frustums (near 0.03 m, far 0.12 m).

    The action is a residual added to an analytic baseline (``base_controller``, default
    dimension-reduced IK) at the paper's IK step of 0.01 s; a zero action reproduces the baseline's
    iterations exactly. With ``base_controller=None`` the action is the whole command.

    ## Action Space
    ``Box(-1, 1, (6,))``: rates of [L0, phi, theta1, delta1, theta2, delta2] as fractions of
    (0.1 m/s, pi/2, pi/2, pi, pi/2, pi rad/s), times ``residual_scale`` (residual) or 1 (pure RL).
    Out-of-range actions are clipped (``info["action_clipped"]``); NaN/inf raise ``ValueError``.

    With ``residual_space="target"`` the action moves the target the baseline tracks instead: the da
    Vinci target point shifts by a[0:3] x 0.02 m and the target frame turns by the rotation vector
    a[3:6] x 0.5 rad (both in {w}, times ``residual_scale``); the baseline's IK step then runs towards
    that moved target. Dimension-reduced IK corrects its whole pose error every step, so a joint-rate
    residual moves its equilibrium by only about residual_scale x 0.02 rad; a target residual can hold
    the robot at any pose the baseline can reach. A zero action is the baseline exactly in both spaces.

    ## Observation Space
    ``Box(-10, 10, (22,), float32)`` (27 with ``observe_target=True``), each entry clipped to +-10:

{observation}

    ## Rewards
    Sum of weighted terms (``reward_weights``; each in ``info["reward_terms"][term]``): ``overlap`` = +w OR;
    ``position`` = -w eps_p / 0.01 m; ``orientation`` = -w eps_R (rad); ``action`` = -w mean(a^2);
    ``overlap_bonus`` = +w when OR > 0.8 (the coverage map's criterion).
    Defaults: overlap 1.0, position 0.1, orientation 0.1, action 0.01, overlap_bonus 0.

    ## Starting State
    The case-study configuration Psi0 = [8 mm, 0, 0.3857, -1.57, 0.7828, 1.57] of the paper.

    ## Episode End
    ``truncated`` at the task's duration (random 6 s; static, pan_tilt, case studies and coverage 10 s, the
    paper's T_max; mixed: its instance's); ``terminated`` only if the state becomes non-finite.

    ## Info
    One layout for the single env, the native vector env and the SB3 adapter: numpy scalars
    (float64, bool_, int64) and arrays in the single env, (N, ...) arrays with Gymnasium's ``_<key>``
    masks in the vector env.
{info}
    - ``reward_terms``: the weighted reward terms, read by name like a dict (``info["reward_terms"]["voi"]``;
      their sum is the reward) and a float64 array in ``reward_terms.names`` order; ``action_clipped``: the
      action was clipped to [-1, 1].

    ## Arguments
    Keyword arguments of ``gym.make`` (or one ``config=ViewTrackingConfig(...)``), validated in one place
    (``continuum_gym.envs.config``). The coverage task's id is the grid index (yaw-major). Joint limits of
    the paper (Table II): L0 in [0, 0.1] m, phi in [-pi, pi] (hard), theta1 in [0, pi/4], theta2 in
    [0, pi/2]; deltas wrapped to [-pi, pi); clamping is reported in ``info["clamped_joints"]``.
    Front-end arguments: ``render_mode`` (``None`` or ``"rgb_array"``), ``camera`` (``"external"``,
    ``"endoscope"`` or ``"davinci"``).
    ``num_threads``: threads a batch of 128 rows or more is stepped on (1 to ``NUMBA_NUM_THREADS``;
    default 1 when torch is loaded in the process, so a learner's own threads are not oversubscribed,
    else all of numba's threads); results do not depend on it.

{arguments}

    ## Version History
    - v0 (continuum-gym 0.1): initial release. Later in 0.1, with the same dynamics and rewards: robots,
      tasks, controllers and reward terms as plug-ins; ``info`` holds numpy scalars, and the weighted
      reward terms ``reward_terms`` a named float64 array (still read like the former dict); the vector env
      takes ``autoreset_mode``, ``reset_mask``, ``render_mode``, ``camera`` and ``pixel_occlusion``.
    """, INFO_FIELDS, ViewTrackingConfig, OBSERVATION.table())


class ViewTrackingEnv(ContinuumEnv):
    core_class = ViewTrackingCore
    __doc__ = _DOC


class ViewTrackingVectorEnv(ContinuumVectorEnv, VectorEnv):  # VectorEnv listed: clients such as skrl detect it
                                                    # among the direct bases
    core_class = ViewTrackingCore
    __doc__ = "Native batched vector version of ViewTracking-v0 (one compiled call per step).\n\n    " + _DOC
