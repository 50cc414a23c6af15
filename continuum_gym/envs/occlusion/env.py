"""``ContinuumGym/OcclusionAvoidance-v0``'s Python side: what a config builds for its rows, and its front ends.

The row functions are ``occlusion.kernel``'s; ``ROWS`` declares them with the columns and arrays they write
(the library allocates and runs them: ``envs/core.py``). ``build`` makes the kernel bundles from a config (the
robot's, the built-in controller's, the step parameters); ``OcclusionAvoidanceEnv`` and
``OcclusionAvoidanceVectorEnv`` are the library's front ends of this env, with its docstring.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from continuum_gym.envs.core import Built, Extra, RowFunctions
from continuum_gym.envs.front_ends import env_docstring, front_ends
from continuum_gym.envs.info import InfoField, attribute
from continuum_gym.envs.occlusion.config import OcclusionConfig
from continuum_gym.envs.occlusion.kernel import (
    REWARD_TERMS,
    OcclusionOutputs,
    OcclusionState,
    OcclusionStepParams,
    make_work,
    observation_dim,
    observe_row,
    step_row,
)
from continuum_gym.envs.occlusion.outputs import OBSERVATION, BaseInfo, Flag, Metric
from continuum_gym.envs.occlusion.spec import SPEC
from continuum_gym.envs.occlusion.tasks import VISIBILITY_FRACTION
from continuum_gym.envs.tasks import TaskContext


def build(config: OcclusionConfig) -> Built:
    """The kernel bundles of a config: the robot's, the built-in controller's (its rate limits, cone and kernels;
    a registered controller's slot replaces its command where one is the base) and the step parameters."""
    from continuum_gym.baselines import make_controller

    robot, cone, limits = config.robot, config.cone, config.limits
    # arc_plan is the projected gradient underneath its plans (``plan_base.py``)
    builtin = config.base_controller if config.base_controller in ("minimum_norm", "projected_gradient") \
        else "projected_gradient"
    controller: Any = make_controller(str(builtin), robot=robot, cone=cone, limits=limits)
    lower, upper, rate_limit = limits.bounds(robot.n_segments)
    rate_scale_vec = np.append(rate_limit, limits.gamma_rate)
    has_base = config.base_controller is not None
    guard = config.visibility_guard
    params = OcclusionStepParams(
        control_dt=config.control_dt, substeps=config.substeps, has_base=has_base,
        nullspace=config.residual_space == "nullspace", residual_scale=config.residual_scale if has_base else 1.0,
        rate_scale_vec=rate_scale_vec, rate_limit=rate_limit, gamma_rate_limit=limits.gamma_rate, lower=lower,
        upper=upper, max_bend=limits.max_bend, weights=np.array([config.reward_weights[key] for key in REWARD_TERMS]),
        visibility_fraction=VISIBILITY_FRACTION, visibility_guard=-1.0 if guard is None else float(guard))
    layers: tuple = ()
    # no plans under a model error: they run along the guard's edge, which the true tip crosses (plan_base.py)
    if config.base_controller == "arc_plan" and not _model_error(config):
        from continuum_gym.envs.occlusion.plan_base import ArcPlanBase

        layers = (ArcPlanBase,)
    return Built(model=(robot.kernel_args(), controller.params), params=params, action_dim=robot.dof + 1,
                 obs_dim=observation_dim(robot.n_segments), command=robot.dof + 1,
                 context=TaskContext(robot, config.control_dt, cone, limits),
                 parts={"controller": controller, "rate_scale_vec": rate_scale_vec, "limits": limits, "cone": cone,
                        "visibility_guard": guard, "residual_space": config.residual_space},
                 layers=layers)


def _model_error(config: OcclusionConfig) -> bool:
    from continuum_gym.envs.model_error import is_active

    return is_active(config.model_error)


def controller_observation(core: Any, row: int) -> dict:
    """The dict observation an analytic or registered controller's ``predict`` reads, for one row."""
    t = core.steps[row] * core.control_dt
    p, v = core.desired(row, t)
    return {"q": core.measured_joints(row), "gamma": float(core.gamma[row]), "p_des": p,
            "R_des": core.desired_rotation(row, t), "v_des": v, "dt": core.control_dt / core.substeps,
            "robot": core.robot, "cone": core.cone}


ROWS = RowFunctions(
    make_work=make_work, observe_row=observe_row, step_row=step_row, params=OcclusionStepParams,
    state=OcclusionState, outputs=OcclusionOutputs, metrics=Metric, flags=Flag, observation=OBSERVATION,
    reward_terms=REWARD_TERMS, build=build, controller_observation=controller_observation,
    controller="continuum_gym.envs.occlusion.controller", model_error="occlusion",
    arrays={"gamma": Extra(start="start_gamma", joint=True, circular=True),
            "base_info": Extra(shape=(len(BaseInfo),), dtype=np.int64)},
    info=(InfoField("gamma", attribute("gamma"), float, "endoscope rotation (rad)"),),
)

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

{image_modes}

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
{info_intro}
{info}
{info_terms}

    ## Arguments
    Keyword arguments of ``gym.make`` (or one ``config=OcclusionConfig(...)``), validated in one place
    (``continuum_gym.envs.config``); physics limits the paper lacks are assumptions (paper-notes §5).
    Front-end arguments: ``render_mode`` (``None`` or ``"rgb_array"``), ``camera`` (``"external"`` or
    ``"endoscope"``), ``pixel_occlusion`` (add the pixel-occlusion fraction to ``info``; slow).
{threads}

{arguments}

{version_history}
    """, ROWS, OcclusionConfig, OBSERVATION.table(3))



OcclusionCore, OcclusionAvoidanceEnv, OcclusionAvoidanceVectorEnv = front_ends(SPEC, ROWS, __name__, _DOC,
                                                                          core_name="OcclusionCore")

__all__ = ["ROWS", "build", "controller_observation", "OcclusionAvoidanceEnv", "OcclusionAvoidanceVectorEnv",
           "OcclusionCore"]
