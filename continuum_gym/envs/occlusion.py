"""``ContinuumGym/OcclusionAvoidance-v0``: the MBCR beside the rotating angled-lens endoscope."""

from __future__ import annotations

import math

import numpy as np
from gymnasium import spaces

from continuum_gym.baselines.occlusion import OcclusionLimits
from continuum_gym.baselines.registry import OCCLUSION_CONTROLLERS, make_controller
from continuum_gym.envs.batched import (
    BIT_TABLE,
    TASK_SPLITS,
    BatchedCore,
    ContinuumEnv,
    ContinuumVectorEnv,
    choose,
    parallel_chunks,
    validate_weights,
)
from continuum_gym.envs.occlusion_kernel import (
    ACTION_DIM,
    OBS_DIM,
    OBS_LIMIT,
    REWARD_TERMS,
    occlusion_observe_batch,
    occlusion_step_batch,
    occlusion_step_batch_parallel,
)
from continuum_gym.envs.tasks import (
    OCCLUSION_TASKS,
    VISIBILITY_FRACTION,
    occlusion_task_count,
    occlusion_tasks,
)
from continuum_gym.geometry.lens_cone import LENS_MODELS, LensCone
from continuum_gym.robots.validation import positive

# Visibility is weighted so that leaving 0.7 of the half-angle costs more than any VOI it could save:
# otherwise occlusion is "solved" by looking away from the tip.
DEFAULT_WEIGHTS = {"voi": 1.0, "tip_position": 0.05, "tip_orientation": 0.05, "visibility": 10.0, "action": 0.01}
RESIDUAL_SPACES = ("nullspace", "joint")
# A hair inside the 0.7 half-angles of the visibility criterion: the tip still moves within a substep.
DEFAULT_VISIBILITY_GUARD = 0.69


class OcclusionCore(BatchedCore):
    """Batched state and step of the occlusion-avoidance environment (see ``OcclusionAvoidanceEnv``)."""

    reward_names = REWARD_TERMS

    def __init__(self, num_envs=1, task="hold", task_split="train", base_controller="projected_gradient",
                 residual_scale=0.3, residual_space="nullspace", reward_weights=None, control_dt=0.01, substeps=10,
                 max_bend=math.pi / 2, insertion=(0.0, 0.04), bend_rate=3.0, plane_rate=6.0, insertion_rate=0.02,
                 gamma_rate=3.0, lens_model="literal", max_episode_steps=None,
                 visibility_guard=DEFAULT_VISIBILITY_GUARD):
        self.num_envs = int(num_envs)
        self.task = choose(task, OCCLUSION_TASKS, "task")
        self.task_split = choose(task_split, TASK_SPLITS, "task_split")
        if self.task == "circle" and self.task_split == "train":
            raise ValueError("task='circle' is a fixed evaluation task: use task_split='test' "
                             "(training draws from 'hold' or 'random')")
        if base_controller is not None:
            choose(base_controller, OCCLUSION_CONTROLLERS, "base_controller")
        self.base_controller = base_controller
        self.residual_space = choose(residual_space, RESIDUAL_SPACES, "residual_space")
        self.residual_scale = positive(residual_scale, "residual_scale", "fraction of the rate limits")
        self.weights = validate_weights(reward_weights, DEFAULT_WEIGHTS)
        self.control_dt = positive(control_dt, "control_dt", "s")
        if int(substeps) != substeps or substeps < 1:
            raise ValueError(f"substeps must be an integer >= 1; got {substeps!r}")
        self.substeps = int(substeps)
        choose(lens_model, LENS_MODELS, "lens_model")
        self.limits = OcclusionLimits(max_bend=max_bend, insertion=tuple(insertion), bend_rate=bend_rate,
                                      plane_rate=plane_rate, insertion_rate=insertion_rate, gamma_rate=gamma_rate)
        self.cone = LensCone(lens_model=lens_model)
        # The baseline always exists inside (for its rate limits and kernels); has_base says if it acts.
        self.controller = make_controller(base_controller or "projected_gradient", cone=self.cone,
                                          limits=self.limits)
        self.robot = self.controller.robot
        self.max_episode_steps = None if max_episode_steps is None else int(max_episode_steps)
        if visibility_guard is not None and not (0.0 < visibility_guard < 1.0):
            raise ValueError(f"visibility_guard must be a fraction of the cone half-angle in (0, 1), or None to turn "
                             f"the guard off; got {visibility_guard!r}")
        self.visibility_guard = visibility_guard
        self.task_count = occlusion_task_count(self.task, self.task_split)
        self.rate_scale_vec = np.append(self.limits.rate_limit, self.limits.gamma_rate)
        self.single_observation_space = spaces.Box(-OBS_LIMIT, OBS_LIMIT, (OBS_DIM,), np.float32)
        self.single_action_space = spaces.Box(-1.0, 1.0, (ACTION_DIM,), np.float32)
        n = self.num_envs
        self.q = np.zeros((n, 7))
        self.gamma = np.zeros(n)
        self.steps = np.zeros(n, dtype=np.int64)
        self.obs = np.zeros((n, OBS_DIM))
        self.base_cmd = np.zeros((n, ACTION_DIM))
        self.base_info = np.zeros((n, 2), dtype=np.int64)
        self.metrics = np.zeros((n, 4))
        self.terms = np.zeros((n, len(REWARD_TERMS)))
        self.rewards = np.zeros(n)
        self.limit = np.zeros(n, dtype=np.int64)
        self.n_chunks = parallel_chunks(n)
        self.flags = np.zeros((n, 8), dtype=np.int64)
        self.tasks = occlusion_tasks(self.task, self.task_split, np.zeros(n, dtype=np.int64), self.control_dt,
                                     self.limits.max_bend, self.limits.insertion)
        self._weights = np.array([self.weights[key] for key in REWARD_TERMS])
        lengths, stiffness, segments, fractions, prm, has_base = self._model_args()
        self._step_args = (
            self.tasks.centre, self.tasks.amp, self.tasks.omega, self.tasks.phase, self.tasks.R_des,
            self.tasks.duration, self.limit, self.control_dt, self.substeps, lengths, stiffness, segments, fractions, prm,
            has_base, self.residual_space == "nullspace", self.residual_scale if has_base else 1.0,
            self.rate_scale_vec, self.limits.rate_limit, self.limits.gamma_rate, self.limits.lower,
            self.limits.upper, self.limits.max_bend, self._weights, VISIBILITY_FRACTION,
            -1.0 if visibility_guard is None else float(visibility_guard), self.base_cmd,
            self.base_info, self.obs, self.metrics, self.terms, self.rewards, self.flags)

    # ------------------------------------------------------------------ state
    def reset_rows(self, rows, task_ids):
        rows = np.asarray(rows, dtype=np.int64)
        fresh = occlusion_tasks(self.task, self.task_split, task_ids, self.control_dt, self.limits.max_bend,
                                self.limits.insertion)
        self._install_tasks(rows, fresh)
        self.gamma[rows] = fresh.start_gamma
        occlusion_observe_batch(rows, self.q, self.gamma, self.steps, self.tasks.centre, self.tasks.amp,
                                self.tasks.omega, self.tasks.phase, self.tasks.R_des, self.tasks.duration,
                                self.control_dt, self.substeps, *self._model_args(), self.limits.lower,
                                self.limits.upper, self.limits.max_bend, self.rate_scale_vec, self.base_cmd,
                                self.base_info, self.obs, self.metrics)

    def _model_args(self):
        c = self.controller
        return (c.robot._lengths_array, c.robot.stiffness, c._segments, c._fractions, c.params,
                self.base_controller is not None)

    def step(self, actions, active):
        if self.n_chunks > 1:
            occlusion_step_batch_parallel(self.q, self.gamma, self.steps, actions, active, *self._step_args,
                                          self.n_chunks)
        else:
            occlusion_step_batch(self.q, self.gamma, self.steps, actions, active, *self._step_args)
        return self.rewards, self.flags[:, 3] != 0, self.flags[:, 4] != 0

    # ------------------------------------------------------------------ info
    def info_row(self, row):
        m = self.metrics[row]
        f = self.flags[row]
        return {
            "voi": float(m[0]),
            "tip_error_m": float(m[1]),
            "orientation_error_rad": float(m[2]),
            "tip_view_fraction": float(m[3]),
            "tip_in_view": bool(m[3] <= VISIBILITY_FRACTION),
            "gamma": float(self.gamma[row]),
            "clamped_joints": BIT_TABLE[f[0] & 127, :7].copy(),
            "rate_saturated": bool(f[1]),
            "gamma_rate_saturated": bool(f[2]),
            "base_frozen_joints": BIT_TABLE[f[5] & 127, :7].copy(),
            "base_rate_saturated": bool(f[6]),
            "visibility_guarded": bool(f[7]),
            "base_command": self.base_cmd[row].copy(),
            "task_id": int(self.tasks.task_id[row]),
            "elapsed_steps": int(self.steps[row]),
        }

    def info(self):
        bits = np.arange(7)
        return {
            "voi": self.metrics[:, 0].copy(),
            "tip_error_m": self.metrics[:, 1].copy(),
            "orientation_error_rad": self.metrics[:, 2].copy(),
            "tip_view_fraction": self.metrics[:, 3].copy(),
            "tip_in_view": self.metrics[:, 3] <= VISIBILITY_FRACTION,
            "gamma": self.gamma.copy(),
            "clamped_joints": ((self.flags[:, 0:1] >> bits) & 1).astype(bool),
            "rate_saturated": self.flags[:, 1].astype(bool),
            "gamma_rate_saturated": self.flags[:, 2].astype(bool),
            "base_frozen_joints": ((self.flags[:, 5:6] >> bits) & 1).astype(bool),
            "base_rate_saturated": self.flags[:, 6].astype(bool),
            "visibility_guarded": self.flags[:, 7].astype(bool),
            "base_command": self.base_cmd.copy(),
            "task_id": self.tasks.task_id.copy(),
            "elapsed_steps": self.steps.copy(),
        }

    def controller_observation(self, row=0):
        """The dict observation an analytic controller's ``predict`` reads, for one row."""
        from continuum_gym.envs.common_kernels import trajectory_batch

        t = np.array([self.steps[row] * self.control_dt])
        p = np.empty((1, 1, 3))
        v = np.empty((1, 1, 3))
        trajectory_batch(self.tasks.centre[row:row + 1], self.tasks.amp[row:row + 1], self.tasks.omega[row:row + 1],
                         self.tasks.phase[row:row + 1], t, p, v)
        return {"q": self.q[row].copy(), "gamma": float(self.gamma[row]), "p_des": p[0, 0], "R_des": self.tasks.R_des[row],
                "v_des": v[0, 0], "dt": self.control_dt / self.substeps}

    # ------------------------------------------------------------------ rendering (pybullet, optional)
    def make_scene(self):
        from continuum_gym.render import OcclusionScene

        return OcclusionScene(robot=self.robot, cone=self.cone)

    def render_row(self, row, scene, camera):
        scene.update(self.q[row], self.gamma[row])
        return scene.render(camera=camera)

    def pixel_occlusion(self, row, scene):
        from continuum_gym.render import pixel_occlusion

        return pixel_occlusion(self.robot, self.q[row], self.gamma[row], cone=self.cone, scene=scene)


_DOC = """The multi-backbone continuum robot of Sarli & Simaan beside the rotating angled-lens endoscope.

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

    The visibility guard (``visibility_guard``, default 0.69 of the half-angle) makes tip visibility a
    hard constraint on the residual: at every substep, the residual's share of the endoscope rotation
    is scaled back (bisection) where it would carry the tip beyond the guard, or beyond where the
    baseline's own rotation leaves it if that is further. The baseline's command is never changed, so a
    zero action is still the baseline exactly. Each intervention sets ``info["visibility_guarded"]``.
    ``visibility_guard=None`` turns it off (visibility is then only a reward term).

    | Num | Action | Unit at 1.0 (default limits) |
    |-----|--------|------|
    | 0, 2, 4 | theta_j rate | 3 rad/s |
    | 1, 3, 5 | delta_j rate | 6 rad/s |
    | 6 | insertion rate | 0.02 m/s |
    | 7 | endoscope rotation rate | 3 rad/s |

    ## Observation Space
    ``Box(-10, 10, (32,), float32)``, each entry clipped to +-10:

    | Num | Observation | Scale |
    |-----|-------------|-------|
    | 0-2 | bend pi/2 - theta_j | / max_bend |
    | 3-8 | sin delta_j, cos delta_j (j = 1..3, interleaved) | - |
    | 9 | insertion | mapped to [-1, 1] over the insertion range |
    | 10-11 | sin gamma, cos gamma | - |
    | 12-14 | tip position error p_des - p (world) | / 0.01 m |
    | 15-17 | tip orientation error log(R_des R^T) | / 0.1 rad |
    | 18-20 | desired tip velocity (feed-forward) | / 0.05 m/s |
    | 21 | tip angle from the view axis | / cone half-angle |
    | 22 | VOI (eq 27, paper-notes §1.3 item 13) | - |
    | 23-30 | baseline command at this state (the next substep's) | / rate limits |
    | 31 | elapsed time | / task duration |

    ## Rewards
    Sum of weighted terms (``reward_weights``; each in ``info["reward_terms"]``):
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

    ## Arguments
    - ``task``: ``"hold"`` (default), ``"random"`` (smooth random tip trajectories, <= 12 mm), ``"mixed"``
      (even task ids hold, odd ids random), ``"circle"`` (the paper's, test split only).
    - ``task_split``: ``"train"`` or ``"test"``, disjoint task instances.
    - ``base_controller``: ``"projected_gradient"`` (default), ``"minimum_norm"`` or ``None``.
    - ``residual_scale`` (0.3), ``residual_space`` (``"nullspace"``), ``reward_weights``.
    - ``visibility_guard``: fraction of the cone half-angle in (0, 1) (default 0.69) or ``None`` (off).
    - ``control_dt`` (0.01 s) and ``substeps`` (10): the paper's 1 ms loop under a 10 ms policy.
    - Limits the paper lacks (assumptions): ``max_bend`` (pi/2, two-sided |pi/2 - theta_j| <= max_bend),
      ``insertion`` ((0, 0.04) m), ``bend_rate`` (3 rad/s), ``plane_rate`` (6 rad/s), ``insertion_rate``
      (0.02 m/s), ``gamma_rate`` (3 rad/s); gamma is wrapped to (-pi, pi].
    - ``lens_model``: ``"literal"`` (default) or ``"physical"`` (paper-notes §1.3 item 7).
    - ``render_mode``: ``None`` or ``"rgb_array"``; ``camera``: ``"external"`` or ``"endoscope"``;
      ``pixel_occlusion``: add the pixel-occlusion fraction to ``info`` (slow).

    ## Version History
    - v0: initial release.
    """


class OcclusionAvoidanceEnv(ContinuumEnv):
    core_class = OcclusionCore
    __doc__ = _DOC


class OcclusionAvoidanceVectorEnv(ContinuumVectorEnv):
    core_class = OcclusionCore
    __doc__ = "Native batched vector version of OcclusionAvoidance-v0 (one compiled call per step).\n\n    " + _DOC
