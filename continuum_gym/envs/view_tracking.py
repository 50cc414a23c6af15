"""``ContinuumGym/ViewTracking-v0``: the continuum endoscope reproducing a moving da Vinci 30-degree view."""

from __future__ import annotations

import math

import numpy as np
from gymnasium import spaces

from continuum_gym.baselines.registry import VIEW_TRACKING_CONTROLLERS, make_controller
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
from continuum_gym.envs.tasks import DAVINCI_LOWER, DAVINCI_UPPER, VIEW_TASKS, view_task_count, view_tasks
from continuum_gym.envs.view_kernel import (
    ACTION_DIM,
    OBS_DIM,
    TARGET_OBS_DIM,
    OBS_LIMIT,
    REWARD_TERMS,
    TARGET_SHIFT_SCALE,
    view_observe_batch,
    view_step_batch,
    view_step_batch_parallel,
)
from continuum_gym.geometry.frustum import Frustum
from continuum_gym.robots import DaVinciEndoscope
from continuum_gym.robots.validation import positive

# overlap_bonus rewards the coverage criterion itself (OR > 0.8); off by default, the paper scores OR.
DEFAULT_WEIGHTS = {"overlap": 1.0, "position": 0.1, "orientation": 0.1, "action": 0.01, "overlap_bonus": 0.0}
#: Joint-rate command at action 1.0 (pure RL) and the unit of the residual: m/s for L0, rad/s.
ACTION_SCALE = np.array([0.1, math.pi / 2, math.pi / 2, math.pi, math.pi / 2, math.pi])
# "joint": the action is added to the baseline's joint rates (6 joints, 6-D task: no null space to project
# into); "target": the action moves the target the baseline tracks (see TARGET_SHIFT_SCALE).
RESIDUAL_SPACES = ("joint", "target")


class ViewTrackingCore(BatchedCore):
    """Batched state and step of the view-tracking environment (see ``ViewTrackingEnv``)."""

    reward_names = REWARD_TERMS

    def __init__(self, num_envs=1, task="random", task_split="train", base_controller="dimension_reduced",
                 residual_scale=0.3, reward_weights=None, control_dt=0.01, substeps=1, rate_limits=None, grid=21,
                 max_episode_steps=None, residual_space="joint", max_bend=None, lens_model=None, observe_target=False):
        self.num_envs = int(num_envs)
        self.task = choose(task, VIEW_TASKS, "task")
        self.task_split = choose(task_split, TASK_SPLITS, "task_split")
        if self.task in ("case1", "case2", "coverage") and self.task_split == "train":
            raise ValueError(f"task={self.task!r} is a fixed evaluation task of the paper: use task_split='test' "
                             "(training draws from 'random', 'static' or 'pan_tilt')")
        if base_controller is not None:
            choose(base_controller, VIEW_TRACKING_CONTROLLERS, "base_controller")
        self.base_controller = base_controller
        self.residual_space = choose(residual_space, RESIDUAL_SPACES, "residual_space")
        if self.residual_space == "target" and base_controller is None:
            raise ValueError("residual_space='target' moves the baseline's target: it needs a base_controller")
        for name, value in (("max_bend", max_bend), ("lens_model", lens_model)):
            if value is not None:
                raise ValueError(f"{name} applies to OcclusionAvoidance only; ViewTracking uses the paper's limits")
        self.residual_scale = positive(residual_scale, "residual_scale", "fraction of the action scale")
        self.weights = validate_weights(reward_weights, DEFAULT_WEIGHTS)
        self.control_dt = positive(control_dt, "control_dt", "s")
        if substeps != 1:
            raise ValueError("substeps must be 1 for ViewTracking: the paper's IK step is the control step")
        self.substeps = 1
        if int(grid) != grid or grid < 2:
            raise ValueError(f"grid must be an integer >= 2 points per axis; got {grid!r}")
        self.grid = int(grid)
        self.controller = make_controller(base_controller or "dimension_reduced")
        self.robot = self.controller.robot
        self.davinci = DaVinciEndoscope()
        self.frustum = Frustum()
        if rate_limits is None:
            self.rate_limits = np.full(ACTION_DIM, np.inf)
        else:
            self.rate_limits = np.asarray(rate_limits, dtype=float)
            if self.rate_limits.shape != (ACTION_DIM,) or np.any(~(self.rate_limits > 0)):
                raise ValueError("rate_limits must be 6 positive joint-rate limits (m/s for L0, rad/s) or None")
        self.max_episode_steps = None if max_episode_steps is None else int(max_episode_steps)
        self.task_count = view_task_count(self.task, self.grid)
        if not isinstance(observe_target, (bool, np.bool_)):
            raise ValueError(f"observe_target must be True or False; got {observe_target!r}")
        self.observe_target = bool(observe_target)
        obs_dim = OBS_DIM + (TARGET_OBS_DIM if self.observe_target else 0)
        self.single_observation_space = spaces.Box(-OBS_LIMIT, OBS_LIMIT, (obs_dim,), np.float32)
        self.single_action_space = spaces.Box(-1.0, 1.0, (ACTION_DIM,), np.float32)
        n = self.num_envs
        self.q = np.zeros((n, 6))
        self.steps = np.zeros(n, dtype=np.int64)
        self.obs = np.zeros((n, obs_dim))
        self.base_cmd = np.zeros((n, ACTION_DIM))
        self.metrics = np.zeros((n, 3))
        self.terms = np.zeros((n, len(REWARD_TERMS)))
        self.rewards = np.zeros(n)
        self.limit = np.zeros(n, dtype=np.int64)
        self.n_chunks = parallel_chunks(n)
        self.flags = np.zeros((n, 4), dtype=np.int64)
        self.tasks = view_tasks(self.task, self.task_split, np.zeros(n, dtype=np.int64), self.control_dt, self.grid)
        self._weights = np.array([self.weights[key] for key in REWARD_TERMS])
        has_base = self.base_controller is not None
        g = self._geometry_args()
        self._step_args = (
            self.tasks.centre, self.tasks.amp, self.tasks.omega, self.tasks.phase, self.tasks.duration,
            self.limit, self.control_dt, self.robot._geom, self.controller.params, has_base,
            self.residual_scale if has_base else 1.0, self.residual_space == "target", TARGET_SHIFT_SCALE, ACTION_SCALE,
            self.rate_limits, *g[:4], *g[5:], self._weights, self.base_cmd, self.obs, self.metrics, self.terms,
            self.rewards, self.flags)

    def _geometry_args(self):
        f = self.frustum
        return (self.davinci.alpha, self.davinci.Le, DAVINCI_LOWER, DAVINCI_UPPER, ACTION_SCALE, f.tan_half, f.near,
                f.far)

    def reset_rows(self, rows, task_ids):
        rows = np.asarray(rows, dtype=np.int64)
        fresh = view_tasks(self.task, self.task_split, task_ids, self.control_dt, self.grid)
        self._install_tasks(rows, fresh)
        self.observe_rows(rows)

    def observe_rows(self, rows):
        """Recompute observation, metrics and the cached baseline command of ``rows`` from their state."""
        view_observe_batch(np.asarray(rows, dtype=np.int64), self.q, self.steps, self.tasks.centre, self.tasks.amp,
                           self.tasks.omega, self.tasks.phase, self.tasks.duration, self.control_dt, self.robot._geom,
                           self.controller.params, self.base_controller is not None, *self._geometry_args(),
                           self.base_cmd, self.obs, self.metrics)

    def step(self, actions, active):
        if self.n_chunks > 1:
            view_step_batch_parallel(self.q, self.steps, actions, active, *self._step_args, self.n_chunks)
        else:
            view_step_batch(self.q, self.steps, actions, active, *self._step_args)
        return self.rewards, self.flags[:, 2] != 0, self.flags[:, 3] != 0

    def info(self):
        bits = np.arange(6)
        return {
            "overlap_ratio": self.metrics[:, 0].copy(),
            "position_error_m": self.metrics[:, 1].copy(),
            "orientation_error_rad": self.metrics[:, 2].copy(),
            "clamped_joints": ((self.flags[:, 0:1] >> bits) & 1).astype(bool),
            "rate_saturated": self.flags[:, 1].astype(bool),
            "base_command": self.base_cmd.copy(),
            "task_id": self.tasks.task_id.copy(),
            "elapsed_steps": self.steps.copy(),
        }

    def info_row(self, row):
        m = self.metrics[row]
        f = self.flags[row]
        return {
            "overlap_ratio": float(m[0]),
            "position_error_m": float(m[1]),
            "orientation_error_rad": float(m[2]),
            "clamped_joints": BIT_TABLE[f[0] & 63, :6].copy(),
            "rate_saturated": bool(f[1]),
            "base_command": self.base_cmd[row].copy(),
            "task_id": int(self.tasks.task_id[row]),
            "elapsed_steps": int(self.steps[row]),
        }

    def davinci_configuration(self, row=0):
        """q_davinci [L_dV, yaw, pitch, roll] of the target at the row's current time (clipped to its ranges)."""
        from continuum_gym.envs.common_kernels import trajectory_batch

        t = np.array([self.steps[row] * self.control_dt])
        x = np.empty((1, 1, 4))
        v = np.empty((1, 1, 4))
        trajectory_batch(self.tasks.centre[row:row + 1], self.tasks.amp[row:row + 1], self.tasks.omega[row:row + 1],
                         self.tasks.phase[row:row + 1], t, x, v)
        return np.clip(x[0, 0], DAVINCI_LOWER, DAVINCI_UPPER)

    def controller_observation(self, row=0):
        p, R = self.davinci.target_pose(self.davinci_configuration(row))
        return {"q": self.q[row].copy(), "p_target": p, "R_target": R, "dt": self.control_dt}

    def make_scene(self):
        from continuum_gym.render import ViewTrackingScene

        return ViewTrackingScene(endoscope=self.robot, davinci=self.davinci, frustum=self.frustum)

    def render_row(self, row, scene, camera):
        scene.update(self.q[row], self.davinci_configuration(row))
        return scene.render(camera=camera)

    def pixel_occlusion(self, row, scene):
        raise ValueError("pixel_occlusion applies to OcclusionAvoidance only")


_DOC = """The 2-segment continuum endoscope of Deng, Xu et al. reproducing a moving da Vinci 30-degree view.

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

    | Num | Observation | Scale |
    |-----|-------------|-------|
    | 0 | L0 | mapped to [-1, 1] over [0, 0.1] m |
    | 1 | phi | / pi |
    | 2 | theta1 | mapped to [-1, 1] over [0, pi/4] |
    | 3-4 | sin delta1, cos delta1 | - |
    | 5 | theta2 | mapped to [-1, 1] over [0, pi/2] |
    | 6-7 | sin delta2, cos delta2 | - |
    | 8-10 | target point error p_dVt - p_ct (world) | / 0.05 m |
    | 11-13 | orientation error log(R_dVt R_ct^T) | rad |
    | 14 | overlap ratio | - |
    | 15-20 | baseline command at this state | / action scale |
    | 21 | elapsed time | / task duration |
    | 22 | da Vinci insertion L_dV (only with ``observe_target``) | (L_dV - 0.05 m) / 0.05 m |
    | 23-24 | da Vinci yaw, pitch (only with ``observe_target``) | / (pi/3) |
    | 25-26 | sin, cos of the da Vinci roll (only with ``observe_target``) | - |

    ## Rewards
    Sum of weighted terms (``reward_weights``; each in ``info["reward_terms"]``): ``overlap`` = +w OR;
    ``position`` = -w eps_p / 0.01 m; ``orientation`` = -w eps_R (rad); ``action`` = -w mean(a^2);
    ``overlap_bonus`` = +w when OR > 0.8 (the coverage map's criterion).
    Defaults: overlap 1.0, position 0.1, orientation 0.1, action 0.01, overlap_bonus 0.

    ## Starting State
    The case-study configuration Psi0 = [8 mm, 0, 0.3857, -1.57, 0.7828, 1.57] of the paper.

    ## Episode End
    ``truncated`` at the task's duration (random 6 s; static, pan_tilt, case studies and coverage 10 s, the
    paper's T_max); ``terminated`` only if the state becomes non-finite.

    ## Arguments
    - ``task``: ``"random"`` (default; smooth random yaw/pitch/roll/insertion trajectories of the da Vinci
      within the paper's ranges), ``"static"`` (random fixed views), ``"pan_tilt"`` (random fixed views with
      the coverage map's insertion and zero roll: its distribution, off its grid), and the paper's fixed
      evaluation tasks
      ``"case1"``, ``"case2"``, ``"coverage"`` (test split only; ``grid`` points per axis, task id = grid index,
      yaw-major).
    - ``task_split``: ``"train"`` or ``"test"``, disjoint task instances.
    - ``base_controller``: ``"dimension_reduced"`` (default), ``"resolved_rate"`` or ``None``.
    - ``observe_target`` (False): append the da Vinci configuration that defines the target (the commanded
      view, which a surgeon's console knows); the pose errors alone define it only through the kinematics.
    - ``residual_scale`` (0.3), ``residual_space`` (``"joint"`` or ``"target"``), ``reward_weights``,
      ``control_dt`` (0.01 s),
      ``substeps`` (1), ``rate_limits`` (None: the paper has none; 6 values in m/s, rad/s to add them).
    - Joint limits of the paper (Table II): L0 in [0, 0.1] m, phi in [-pi, pi] (hard), theta1 in [0, pi/4],
      theta2 in [0, pi/2]; deltas wrapped to [-pi, pi). Clamping is reported in ``info["clamped_joints"]``.
    - ``render_mode``: ``None`` or ``"rgb_array"``; ``camera``: ``"external"``, ``"endoscope"`` or ``"davinci"``.

    ## Version History
    - v0: initial release.
    """


class ViewTrackingEnv(ContinuumEnv):
    core_class = ViewTrackingCore
    __doc__ = _DOC


class ViewTrackingVectorEnv(ContinuumVectorEnv):
    core_class = ViewTrackingCore
    __doc__ = "Native batched vector version of ViewTracking-v0 (one compiled call per step).\n\n    " + _DOC
