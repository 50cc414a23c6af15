"""``ContinuumGym/ViewTracking-v0``'s Python side: what a config builds for its rows, and its front ends.

The row functions are ``view_tracking.kernel``'s; ``ROWS`` declares them with the columns they write (the
library allocates and runs them: ``envs/core.py``). ``build`` makes the kernel bundles from a config (the
endoscope's, the built-in IK's, the da Vinci's, the frustum's, the step parameters); ``ViewTrackingEnv`` and
``ViewTrackingVectorEnv`` are the library's front ends of this env, with its docstring.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from continuum_gym.envs.core import Built, RowFunctions
from continuum_gym.envs.front_ends import env_docstring, front_ends
from continuum_gym.envs.helpers import register_helper
from continuum_gym.envs.tasks import TaskContext
from continuum_gym.envs.view_tracking.config import ViewTrackingConfig
from continuum_gym.envs.view_tracking.kernel import (
    ACTION_DIM,
    REWARD_TERMS,
    TARGET_SHIFT_SCALE,
    ViewOutputs,
    ViewState,
    ViewStepParams,
    make_work,
    observe_row,
    step_row,
)
from continuum_gym.envs.view_tracking.outputs import OBS_DIM, OBSERVATION, TARGET_OBS_DIM, Flag, Metric
from continuum_gym.envs.view_tracking.spec import SPEC

#: Joint-rate command at action 1.0 (pure RL) and the unit of the residual: m/s for L0, rad/s.
ACTION_SCALE = np.array([0.1, math.pi / 2, math.pi / 2, math.pi, math.pi / 2, math.pi])


def build(config: ViewTrackingConfig) -> Built:
    """The kernel bundles of a config: the endoscope's, the built-in IK's (a registered controller's slot
    replaces its command where one is the base), the da Vinci's, the frustum's and the step parameters."""
    from continuum_gym.baselines import make_controller
    from continuum_gym.geometry.frustum import Frustum

    builtin = config.base_controller if config.base_controller in config.baselines else "dimension_reduced"
    controller: Any = make_controller(str(builtin), robot=config.robot)
    robot, davinci, frustum = controller.robot, config.davinci, Frustum()
    rate_limits = np.full(ACTION_DIM, np.inf) if config.rate_limits is None else np.array(config.rate_limits,
                                                                                            dtype=float)
    has_base = config.base_controller is not None
    params = ViewStepParams(
        control_dt=config.control_dt, has_base=has_base, residual_scale=config.residual_scale if has_base else 1.0,
        target_space=config.residual_space == "target", target_scale=TARGET_SHIFT_SCALE, action_scale=ACTION_SCALE,
        rate_limit=rate_limits, weights=np.array([config.reward_weights[key] for key in REWARD_TERMS]))
    return Built(model=(robot.kernel_args(), controller.params, davinci.kernel_args(), frustum.kernel_args()),
                 params=params, action_dim=ACTION_DIM, obs_dim=OBS_DIM + (TARGET_OBS_DIM if config.observe_target else 0),
                 command=ACTION_DIM, context=TaskContext(robot, config.control_dt, grid=config.grid),
                 parts={"controller": controller, "davinci": davinci, "frustum": frustum, "rate_limits": rate_limits,
                        "residual_space": config.residual_space, "grid": config.grid,
                        "observe_target": config.observe_target})


def overlap_polish(config: ViewTrackingConfig) -> Callable[..., np.ndarray]:
    """The helper ``overlap_polish``: a one-step lookahead on the overlap ratio (``polish.py``) for ``config``'s
    rows, of largest step ``POLISH_STEP`` action units. It reads the observation and the nominal model only."""
    from continuum_gym.envs.view_tracking.polish import POLISH_STEP, polish_actions
    from continuum_gym.geometry.frustum import Frustum

    if config.residual_space != "joint":
        raise ValueError("the helper overlap_polish acts on joint-rate actions: it needs residual_space='joint'; got "
                         f"residual_space={config.residual_space!r}")
    lower, upper = config.robot.joint_limits
    frustum = Frustum()
    scale = config.residual_scale if config.base_controller is not None else 1.0
    model = (config.control_dt, scale * ACTION_SCALE, ACTION_SCALE, lower, upper, config.robot.kernel_args(),
             config.davinci.Le, np.array([frustum.tan_half, frustum.near, frustum.far]))

    def polish(obs: np.ndarray, actions: np.ndarray, active: np.ndarray) -> np.ndarray:
        out = np.empty_like(actions)
        polish_actions(obs, actions, active, POLISH_STEP, *model, out)
        return out

    return polish


register_helper(SPEC.env_id, "overlap_polish", overlap_polish)


def controller_observation(core: Any, row: int) -> dict:
    """The dict observation an analytic or registered controller's ``predict`` reads, for one row."""
    p, R = core.davinci.target_pose(davinci_configuration(core, row))
    return {"q": core.measured_joints(row), "p_target": p, "R_target": R, "dt": core.control_dt, "robot": core.robot}


def davinci_configuration(core: Any, row: int = 0) -> np.ndarray:
    """q_davinci [L_dV (m), yaw, pitch, roll] of a row's target at its current time (clipped to its ranges)."""
    x, _ = core.desired(row, core.steps[row] * core.control_dt)
    lower, upper = core.davinci.joint_limits
    return np.clip(x, lower, upper)


ROWS = RowFunctions(
    make_work=make_work, observe_row=observe_row, step_row=step_row, params=ViewStepParams, state=ViewState,
    outputs=ViewOutputs, metrics=Metric, flags=Flag, observation=OBSERVATION, reward_terms=REWARD_TERMS,
    build=build, controller_observation=controller_observation,
    controller="continuum_gym.envs.view_tracking.controller", model_error="view",
    # A row costs ~3 us: at N = 64 waking a second thread costs more than it saves (benchmarks/batch.py times
    # one thread against all cores); from N = 128 it pays. Threads claim 8 rows (~25 us) at a time: one claim per
    # row would add an atomic add on a cache line both cores write, and a call of the row loop, to every ~3 us row.
    methods={"davinci_configuration": davinci_configuration}, parallel_min_rows=128, claim_block=8,
)

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

{image_modes}
    The da Vinci's view, the one to reproduce, comes under the same modalities as ``goal_rgb``, ``goal_depth``, ...

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
{info_intro}
{info}
{info_terms}

    ## Arguments
    Keyword arguments of ``gym.make`` (or one ``config=ViewTrackingConfig(...)``), validated in one place
    (``continuum_gym.envs.config``). The coverage task's id is the grid index (yaw-major). Joint limits of
    the paper (Table II): L0 in [0, 0.1] m, phi in [-pi, pi] (hard), theta1 in [0, pi/4], theta2 in
    [0, pi/2]; deltas wrapped to [-pi, pi); clamping is reported in ``info["clamped_joints"]``.
    Front-end arguments: ``render_mode`` (``None`` or ``"rgb_array"``), ``camera`` (``"external"``,
    ``"endoscope"`` or ``"davinci"``).
{threads}

{arguments}

{version_history}
    """, ROWS, ViewTrackingConfig, OBSERVATION.table())



ViewTrackingCore, ViewTrackingEnv, ViewTrackingVectorEnv = front_ends(SPEC, ROWS, __name__, _DOC)

__all__ = ["ROWS", "build", "controller_observation", "davinci_configuration", "ACTION_SCALE", "ViewTrackingEnv",
           "ViewTrackingVectorEnv", "ViewTrackingCore"]
