"""``ContinuumGym/OcclusionAvoidance-v0``: the MBCR beside the rotating angled-lens endoscope."""

from __future__ import annotations

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
from continuum_gym.envs.info import (
    AtMost,
    InfoField,
    attribute,
    bits,
    column,
    env_docstring,
)
from continuum_gym.envs.occlusion.config import OcclusionConfig
from continuum_gym.envs.occlusion.kernel import (
    OBS_LIMIT,
    REWARD_TERMS,
    OcclusionOutputs,
    OcclusionState,
    OcclusionStepParams,
    observation_dim,
    occlusion_step_batch,
)
from continuum_gym.envs.occlusion.outputs import OBSERVATION, Flag, Metric
from continuum_gym.envs.occlusion.plan_base import ArcPlanBase
from continuum_gym.envs.occlusion.spec import SPEC as OCCLUSION_SPEC
from continuum_gym.envs.occlusion.tasks import VISIBILITY_FRACTION
from continuum_gym.envs.single import ContinuumEnv
from continuum_gym.envs.tasks import TaskContext
from continuum_gym.envs.vector import ContinuumVectorEnv

if TYPE_CHECKING:
    from continuum_gym.baselines.occlusion import OcclusionController

#: ``info`` of every step, for the single env (one row) and the vector env (arrays) alike.
INFO_FIELDS = (
    InfoField("voi", column("metrics", Metric.VOI), float, "Visual Occlusion Index (eq 27) at the new state"),
    InfoField("tip_error_m", column("metrics", Metric.TIP_ERROR), float, "tip position error (m)"),
    InfoField("orientation_error_rad", column("metrics", Metric.ORIENTATION_ERROR), float,
              "tip orientation error (rad)"),
    InfoField("tip_view_fraction", column("metrics", Metric.VIEW_FRACTION), float,
              "tip angle from the view axis / cone half-angle"),
    InfoField("tip_in_view", AtMost("metrics", Metric.VIEW_FRACTION, VISIBILITY_FRACTION), bool,
              "tip within 0.7 of the half-angle"),
    InfoField("gamma", attribute("gamma"), float, "endoscope rotation (rad)"),
    InfoField("clamped_joints", bits("flags", Flag.CLAMPED), None, "joints clamped at a position limit (dof,)"),
    InfoField("rate_saturated", column("flags", Flag.RATE_SATURATED, bool), bool,
              "joint rates scaled down to the rate limits"),
    InfoField("gamma_rate_saturated", column("flags", Flag.GAMMA_SATURATED, bool), bool,
              "endoscope rate clipped to its limit"),
    InfoField("base_frozen_joints", bits("flags", Flag.BASE_FROZEN), None,
              "joints the baseline froze at a limit during the step (dof,)"),
    InfoField("base_rate_saturated", column("flags", Flag.BASE_SATURATED, bool), bool,
              "the baseline's rates were scaled down"),
    InfoField("visibility_guarded", column("flags", Flag.GUARDED, bool), bool,
              "the visibility guard cut the residual's endoscope rotation"),
    InfoField("non_finite", column("flags", Flag.NON_FINITE, bool), bool,
              "a value of the row was not finite (NaN or inf) and its episode ended as truncated (only with "
              "``on_non_finite='truncate'``; its metrics are NaN)"),
    InfoField("base_command", attribute("base_cmd"), None, "the baseline's command at the new state (dof + 1,)"),
    InfoField("task_id", attribute("tasks.task_id"), int, "task instance"),
    InfoField("elapsed_steps", attribute("steps"), int, "control steps since reset"),
)


class OcclusionCore(BatchedCore):
    """Batched state and step of the occlusion-avoidance environment (see ``OcclusionAvoidanceEnv``)."""

    spec = OCCLUSION_SPEC
    config_class = OcclusionConfig
    builtin_reward_names = REWARD_TERMS
    step_kernel = staticmethod(occlusion_step_batch)
    terminated_flag, truncated_flag, non_finite_flag = Flag.TERMINATED, Flag.TRUNCATED, Flag.NON_FINITE
    supports_pixel_occlusion = True
    info_fields = INFO_FIELDS
    metric_columns = {"voi": Metric.VOI, "tip_error_m": Metric.TIP_ERROR,
                      "orientation_error_rad": Metric.ORIENTATION_ERROR, "tip_view_fraction": Metric.VIEW_FRACTION}

    def __init__(self, num_envs: int = 1, config: OcclusionConfig | None = None, num_threads: int | None = None,
                 **kwargs: Any) -> None:
        self.config = config = self._config(config, kwargs)
        self.num_envs = self._num_envs(num_envs)
        self.task, self.task_split = config.task, config.task_split
        self.base_controller = config.base_controller
        self.residual_space = config.residual_space
        self.residual_scale = config.residual_scale
        self.weights = config.reward_weights
        self.control_dt, self.substeps = config.control_dt, config.substeps
        self.limits = config.limits
        self.visibility_guard = config.visibility_guard
        self.max_episode_steps = config.max_episode_steps
        self.cone = config.cone
        self.robot = config.robot
        # The built-in baseline always exists inside (its rate limits, cone and kernels); has_base says if a base
        # acts, and a registered controller's slot replaces its command when active.
        builtin = config.base_controller if config.base_controller in self.spec.baselines else "projected_gradient"
        self.controller = cast("OcclusionController",  # builtin is one of this env's baselines
                               make_controller(builtin, robot=self.robot, cone=self.cone, limits=self.limits))
        self.dof = dof = self.robot.dof
        lower, upper, rate_limit = self.limits.bounds(self.robot.n_segments)
        self.task_context = TaskContext(self.robot, self.control_dt, self.cone, self.limits)
        self.task_source = config.task_source
        self.task_count = self.task_source.count(self.task_split, self.task_context)
        self.rate_scale_vec = np.append(rate_limit, self.limits.gamma_rate)
        obs_dim = observation_dim(self.robot.n_segments)
        self.single_observation_space = spaces.Box(-OBS_LIMIT, OBS_LIMIT, (obs_dim,), np.float32)
        self.single_action_space = spaces.Box(-1.0, 1.0, (dof + 1,), np.float32)
        n = self.num_envs
        self._setup_mismatch("occlusion", self.robot.n_segments)
        self._setup_rewards()
        self.q = np.zeros((n, dof))
        self.gamma = np.zeros(n)
        self.steps = np.zeros(n, dtype=np.int64)
        self.obs = np.zeros((n, obs_dim))
        self.base_cmd = np.zeros((n, dof + 1))
        self.base_info = np.zeros((n, 2), dtype=np.int64)
        self.metrics = np.zeros((n, len(Metric)))
        self.terms = np.zeros((n, len(self.reward_names)))
        self.rewards = np.zeros(n)
        self.limit = np.zeros(n, dtype=np.int64)
        self.flags = np.zeros((n, len(Flag)), dtype=np.int64)
        self.num_threads = step_threads(num_threads)
        self.row_threads = row_threads(n, self.num_threads, self.parallel_min_rows)
        self.tasks = self.task_source.batch(self.task_split, np.zeros(n, dtype=np.int64), self.task_context)
        has_base = self.base_controller is not None
        guard = self.visibility_guard
        self._state = OcclusionState(self.q, self.gamma, self.steps)
        self._tasks = task_arrays(self.tasks, self.limit)
        self._env = OcclusionStepParams(
            control_dt=self.control_dt, substeps=self.substeps, has_base=has_base,
            nullspace=self.residual_space == "nullspace", residual_scale=self.residual_scale if has_base else 1.0,
            rate_scale_vec=self.rate_scale_vec, rate_limit=rate_limit, gamma_rate_limit=self.limits.gamma_rate,
            lower=lower, upper=upper, max_bend=self.limits.max_bend,
            weights=np.array([self.weights[key] for key in REWARD_TERMS]), visibility_fraction=VISIBILITY_FRACTION,
            visibility_guard=-1.0 if guard is None else float(guard))
        self._faults = np.zeros(1, dtype=np.int64)
        self._out = OcclusionOutputs(self.base_cmd, self.base_info, self.obs, self.metrics, self.terms, self.rewards,
                                     self.flags, self._faults)
        self._model = self.kernel_model()
        # no plans under a model error: they run along the guard's edge, which the true tip crosses (plan_base.py)
        planned = config.arc_plan and self._mismatch is None
        self._planner: ArcPlanBase | None = ArcPlanBase(self) if planned else None

    def kernel_model(self) -> tuple:
        return self.robot.kernel_args(), self.controller.params

    def mismatch_kernel(self) -> Any:
        from continuum_gym.envs.occlusion.mismatch import occlusion_mismatch_batch

        return occlusion_mismatch_batch

    def joint_values(self) -> np.ndarray:
        """Every row's joints and, last, the endoscope's rotation gamma (N, dof + 1): the action's layout."""
        return np.concatenate([self.q, self.gamma[:, None]], axis=1)

    #: gamma, the last column, is an angle on the circle.
    circular_joint_columns = (-1,)

    # ------------------------------------------------------------------ state
    def reset_rows(self, rows: np.ndarray, task_ids: np.ndarray) -> None:
        rows = np.asarray(rows, dtype=np.int64)
        fresh = self.task_source.batch(self.task_split, task_ids, self.task_context)
        self._install_tasks(rows, fresh)
        self.gamma[rows] = fresh.start_gamma
        self._reset_mismatch(rows, task_ids)
        self.observe_rows(rows)
        if self._planner is not None:
            self._planner.reset_rows(rows)

    def step(self, actions: np.ndarray, active: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if self._planner is None:
            return super().step(actions, active)
        sent, planned = self._planner.actions(actions, active)
        out = super().step(sent, active)
        self._planner.after_step(actions, planned)
        return out

    def step_values(self) -> dict:
        """Per-step values the evaluation reduces to episode metrics (``OCCLUSION_SPEC.episode_metrics``)."""
        return {"voi": self.metrics[:, Metric.VOI],
                "in_view": (self.metrics[:, Metric.VIEW_FRACTION] <= VISIBILITY_FRACTION) * 1.0,
                "tip_error": self.metrics[:, Metric.TIP_ERROR],
                "orientation_error": self.metrics[:, Metric.ORIENTATION_ERROR],
                "guarded": (self.flags[:, Flag.GUARDED] != 0) * 1.0}

    def controller_observation(self, row: int = 0) -> dict:
        """The dict observation an analytic controller's ``predict`` reads, for one row."""
        t = self.steps[row] * self.control_dt
        p, v = self.desired(row, t)
        return {"q": self.measured_joints(row), "gamma": float(self.gamma[row]), "p_des": p, "R_des": self.desired_rotation(row, t),
                "v_des": v, "dt": self.control_dt / self.substeps, "robot": self.robot, "cone": self.cone}


_DOC = env_docstring("""The multi-backbone continuum robot of Sarli & Simaan beside the rotating angled-lens endoscope.

    ## Description
    A 3-segment multi-backbone continuum robot with insertion (7 DoF) leaves its channel 4.47 mm beside
    a 30-degree angled-lens endoscope. Its tip must follow a desired pose while its body stays out of
    the endoscope's view cone (half-angle 27.5 deg) and the tip stays well inside the view. The
    endoscope rotation gamma is part of the control. Physics: paper 000 with paper-notes §1 (SI units).

    The action is a *residual* added to an analytic baseline (``base_controller``, default the
    projected gradient with the centring law for gamma), recomputed at every 1 ms substep; with
    ``base_controller=None`` the action is the whole command (pure RL). A zero action reproduces the
    baseline exactly.

    ## Action Space
    ``Box(-1, 1, (8,))``: rates of [theta1, delta1, theta2, delta2, theta3, delta3, q_ins, gamma] as
    fractions of the rate limits, times ``residual_scale`` (residual) or 1 (pure RL). Actions outside
    [-1, 1] are clipped (``info["action_clipped"]``); NaN/inf raise ``ValueError``. With
    ``residual_space="nullspace"`` the joint residual is projected into the tip Jacobian's null space
    at every substep, so it cannot disturb tracking; ``"joint"`` adds it as is.

    The visibility guard (``visibility_guard``, default 0.69 of the half-angle) limits **only the
    residual's endoscope rotation**: at every substep, the residual's share of the endoscope rate is
    scaled back (bisection) where it would carry the tip, at the joints that substep reaches, beyond the
    guard, or beyond where the baseline's own rotation leaves it if that is further. That is all it
    guarantees. It does not limit the baseline's command (never changed, so a zero action is still the
    baseline exactly), nor the joint residual: projected into the tip Jacobian's null space it moves the
    tip only at second order, through the uniform rate scaling and at joint limits, and with
    ``residual_space="joint"`` directly; and under a ``model_error`` it predicts the tip with the nominal
    model. On the paper's robot the shipped residuals keep the tip in view on every test step; on a
    4-segment variant a residual kept it in view on 84 % of steps (29-51 % under severe model error), so
    for a variant measure ``info["tip_in_view"]`` rather than rely on the guard. Each intervention sets
    ``info["visibility_guarded"]``; ``visibility_guard=None`` turns it off (visibility is then only a
    reward term).

    | Num | Action | Unit at 1.0 (default limits) |
    |-----|--------|------|
    | 0, 2, 4 | theta_j rate | 3 rad/s |
    | 1, 3, 5 | delta_j rate | 6 rad/s |
    | 6 | insertion rate | 0.02 m/s |
    | 7 | endoscope rotation rate | 3 rad/s |

    ## Observation Space
    ``Box(-10, 10, (32,), float32)``, each entry clipped to +-10:

{observation}

    ## Rewards
    Sum of weighted terms (``reward_weights``; each in ``info["reward_terms"][term]``):
    ``voi`` = -w VOI; ``tip_position`` = -w |e_p| / 1 mm; ``tip_orientation`` = -w |e_R| / 0.01 rad;
    ``visibility`` = -w max(0, f - 0.7)/0.3 with f the tip's angle from the view axis over the cone
    half-angle (looking away from the robot is not a way to avoid occlusion); ``action`` = -w mean(a^2).
    Defaults: voi 1.0, tip_position 0.05, tip_orientation 0.05, visibility 10.0, action 0.01.

    ## Starting State
    ``hold`` and ``random``: paper-like configurations (VOI 0.2-0.3 at gamma = 0, tip within 0.7 of the
    half-angle, >= 60 % of the psps in the cone; paper-notes §1.5's search) from a per-split pool; gamma 0.
    ``circle``: psi_b of paper-notes §1.5, gamma 0.

    ## Episode End
    ``terminated`` when the tip is more than 10 mm from its desired position (the tip is lost);
    ``truncated`` at the task's duration (hold 1.5 s, random 5 s, circle 10 s; mixed: its instance's).

    ## Info
    One layout for the single env, the native vector env and the SB3 adapter: numpy scalars
    (float64, bool_, int64) and arrays in the single env, (N, ...) arrays with Gymnasium's ``_<key>``
    masks in the vector env.
{info}
    - ``reward_terms``: the weighted reward terms, read by name like a dict (``info["reward_terms"]["voi"]``;
      their sum is the reward) and a float64 array in ``reward_terms.names`` order; ``action_clipped``: the
      action was clipped to [-1, 1].

    ## Arguments
    Keyword arguments of ``gym.make`` (or one ``config=OcclusionConfig(...)``), validated in one place
    (``continuum_gym.envs.config``); physics limits the paper lacks are assumptions (paper-notes §5).
    Front-end arguments: ``render_mode`` (``None`` or ``"rgb_array"``), ``camera`` (``"external"`` or
    ``"endoscope"``), ``pixel_occlusion`` (add the pixel-occlusion fraction to ``info``; slow).
    ``num_threads``: threads a batch of 32 rows or more is stepped on (1 to ``NUMBA_NUM_THREADS``;
    default 1 when torch is loaded in the process, so a learner's own threads are not oversubscribed,
    else all of numba's threads); results do not depend on it.

{arguments}

    ## Version History
    - v0 (continuum-gym 0.1): initial release. Later in 0.1, with the same dynamics and rewards: robots,
      tasks, controllers and reward terms as plug-ins; ``info`` holds numpy scalars, and the weighted
      reward terms ``reward_terms`` a named float64 array (still read like the former dict); the vector env
      takes ``autoreset_mode``, ``reset_mask``, ``render_mode``, ``camera`` and ``pixel_occlusion``.
    """, INFO_FIELDS, OcclusionConfig, OBSERVATION.table(3))


class OcclusionAvoidanceEnv(ContinuumEnv):
    core_class = OcclusionCore
    __doc__ = _DOC


class OcclusionAvoidanceVectorEnv(ContinuumVectorEnv, VectorEnv):  # VectorEnv listed: clients such as skrl detect it
                                                    # among the direct bases
    core_class = OcclusionCore
    __doc__ = "Native batched vector version of OcclusionAvoidance-v0 (one compiled call per step).\n\n    " + _DOC
