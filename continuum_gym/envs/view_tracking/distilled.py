"""ViewTracking's ``distilled_optimum`` base: a network distilled from the offline optimum, and a controller
that steers the joints to its configuration.

Why: the learned residuals on the dimension-reduced IK settle on many targets in another configuration than the
best one (experiments/notebook.md, Campaigns 6-11); the best configuration is a function of the target once
its labels are made smooth by continuation (Campaign 11). This base gives the residual that configuration.

The network (``distilled_view.npz``: two tanh layers of 128) maps the da Vinci configuration the target comes
from (``davinci_configuration``, the exact inverse of ``davinci_pose``), scaled as
((L_dV - 0.065 m) / 0.015 m, yaw / (pi/3), pitch / (pi/3), roll / (pi/4)), to the configuration encoded as
(L0 / 0.1 m, theta1, theta2, cos phi, sin phi, theta1 (cos, sin) delta1, theta2 (cos, sin) delta2). It was
fitted (20,000 minibatch Adam steps) to 89,600 continuation labels over insertion 0.050-0.080 m x yaw, pitch in
[-pi/3, pi/3] x roll in [-pi/4, pi/4), all training-split targets: ``experiments/optimum/vt_smooth_labels_4d.py``
made the labels, ``experiments/optimum/vt_label_fit_4d.py --width 128 --steps 20000 --save`` the weights.

The controller: rate = ``GAIN`` x (network configuration - q), the bend directions by their shortest angle,
each joint's rate capped at ``CAP`` action units (``ACTION_SCALE``); then, while the OR is at least
``ASCENT_MIN_OR``, a one-step lookahead on the OR (the network is 0.01-0.05 short of the best configuration on
many targets): the gradient of the OR at the configuration the rate leads to (central differences), in
rate units scaled by ``ASCENT`` x ``ACTION_SCALE``, and the step along it (``ASCENT_FRACTIONS`` of the full
step) that maximises the OR after one control step, where it beats no step. This is the env's
``overlap_polish`` (``envs/view_tracking/polish.py``) moved into the controller, so that the base alone holds
the best configuration near the network's; ``ascent=0`` turns it off. It is registered through the public
registry (``register_controller``), as a researcher's controller is; a config names it
``"continuum_gym.envs.view_tracking.distilled:distilled_optimum"`` so that any process rebuilds it by importing this
module, and ``continuum-gym evaluate`` gives it a row beside the analytic baselines (``packaged_controllers`` of the config).
It knows the paper's robot and da Vinci endoscope only (the network was fitted for them): with other physics the
evaluation leaves its row out.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from continuum_gym.geometry.overlap_clipping import make_overlap_work, overlap_ratio_in
from continuum_gym.robots.compiled import kernel
from continuum_gym.robots.davinci import davinci_configuration
from continuum_gym.robots.endoscope_kernels import endoscope_kinematics, make_endoscope_workspace

if TYPE_CHECKING:
    from continuum_gym.envs.registered import CustomController

NAME = "distilled_optimum"
#: How a config refers to this controller from any process (``continuum_gym.plugins.lookup``).
REFERENCE = f"{__name__}:{NAME}"
WEIGHTS = Path(__file__).with_name("distilled_view.npz")
#: Proportional gain (1/s): 0.4 of the error per 0.01 s control step.
GAIN = 40.0
#: Rate cap per joint, in action units (``ACTION_SCALE``: 0.1 m/s for L0, pi/2 or pi rad/s for the angles).
CAP = 10.0
#: The network's inputs: (da Vinci configuration - INPUT_OFFSET) / INPUT_SCALE, about [-1, 1] over the labels.
INPUT_OFFSET = (0.065, 0.0, 0.0, 0.0)
INPUT_SCALE = (0.015, math.pi / 3, math.pi / 3, math.pi / 4)
#: Largest step of the OR lookahead, in action units (0: no lookahead).
ASCENT = 0.15
#: The lookahead acts only while the OR is at least this (far from the target it would climb the wrong hill).
ASCENT_MIN_OR = 0.75
#: Candidate steps of the lookahead, as fractions of the largest.
ASCENT_FRACTIONS = (0.2, 0.4, 1.0)
#: Central-difference step of the OR's gradient (m for L0, rad).
ASCENT_H = 1e-4
#: params[:HEADER] = gain, signed alpha, Le, width, joint lower (6), joint upper (6), rate caps (6), the
#: lookahead's full step per joint (6, ``ASCENT`` x ``ACTION_SCALE``), its minimum OR, the view frustum's
#: tan(half angle), near and far (m).
HEADER = 32
#: Stand-in for an unlimited joint's bound (the bend directions).
UNLIMITED = 1e9


def network_inputs(q_davinci: np.ndarray) -> np.ndarray:
    """(n, 4) da Vinci configurations [L_dV (m), yaw, pitch, roll] -> (n, 4) network inputs."""
    return (np.asarray(q_davinci, dtype=float) - np.array(INPUT_OFFSET)) / np.array(INPUT_SCALE)


def encode(q: np.ndarray) -> np.ndarray:
    """(n, 6) configurations -> (n, 9) network outputs: L0 / 0.1 m, theta1, theta2, (cos, sin) phi, each
    segment's bend vector theta (cos, sin) delta (a straight segment's direction does not matter)."""
    return np.stack([q[:, 0] / 0.1, q[:, 2], q[:, 4], np.cos(q[:, 1]), np.sin(q[:, 1]),
                     q[:, 2] * np.cos(q[:, 3]), q[:, 2] * np.sin(q[:, 3]),
                     q[:, 4] * np.cos(q[:, 5]), q[:, 4] * np.sin(q[:, 5])], axis=1)


def decode(y: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """(n, 9) network outputs -> (n, 6) configurations within the joint limits (inf: unlimited); the inverse of
    ``encode`` (what ``network_configuration`` computes in the kernel)."""
    q = np.stack([0.1 * y[:, 0], np.arctan2(y[:, 4], y[:, 3]), y[:, 1], np.arctan2(y[:, 6], y[:, 5]),
                  y[:, 2], np.arctan2(y[:, 8], y[:, 7])], axis=1)
    return np.clip(q, np.where(np.isfinite(lower), lower, -np.inf), np.where(np.isfinite(upper), upper, np.inf))


def pack(weights: dict, gain: float = GAIN, cap: float = CAP, ascent: float = ASCENT) -> np.ndarray:
    """The controller's ``params``: the header (see ``HEADER``), then W0, b0, W1, b1, W2, b2 row-major."""
    from continuum_gym.envs.view_tracking.env import ACTION_SCALE
    from continuum_gym.geometry.frustum import Frustum
    from continuum_gym.robots import ContinuumEndoscope, DaVinciEndoscope

    lower, upper = (np.asarray(b, dtype=float) for b in ContinuumEndoscope().joint_limits)
    lower = np.where(np.isfinite(lower), lower, -UNLIMITED)
    upper = np.where(np.isfinite(upper), upper, UNLIMITED)
    dv = DaVinciEndoscope()
    width = weights["b0"].shape[0]
    frustum = Frustum()
    head = np.concatenate([[gain, dv.kernel_args().alpha, dv.Le, width], lower, upper, cap * ACTION_SCALE,
                           ascent * ACTION_SCALE, [ASCENT_MIN_OR, frustum.tan_half, frustum.near, frustum.far]])
    return np.concatenate([head] + [np.asarray(weights[k], dtype=float).reshape(-1)
                                    for k in ("W0", "b0", "W1", "b1", "W2", "b2")])


@kernel
def network_configuration(p_target, R_target, params, out):
    """The network's configuration (6,) for the target (p_target, R_target), clipped to the joint limits."""
    width = int(params[3])
    c = np.empty(4)
    davinci_configuration(p_target, R_target, params[1], params[2], c)
    x = np.empty(4)
    for k in range(4):
        x[k] = (c[k] - INPUT_OFFSET[k]) / INPUT_SCALE[k]
    at = HEADER
    W0 = params[at:at + 4 * width].reshape(width, 4)
    at += 4 * width
    h1 = np.tanh(W0 @ x + params[at:at + width])
    at += width
    W1 = params[at:at + width * width].reshape(width, width)
    at += width * width
    h2 = np.tanh(W1 @ h1 + params[at:at + width])
    at += width
    W2 = params[at:at + 9 * width].reshape(9, width)
    at += 9 * width
    y = W2 @ h2 + params[at:at + 9]
    out[0] = 0.1 * y[0]
    out[1] = math.atan2(y[4], y[3])
    out[2] = y[1]
    out[3] = math.atan2(y[6], y[5])
    out[4] = y[2]
    out[5] = math.atan2(y[8], y[7])
    for k in range(6):
        out[k] = min(max(out[k], params[4 + k]), params[10 + k])


@kernel
def lookahead_overlap(q, rates, step, direction, scale, joint, nudge, dt, lower, upper, robot, p_dv, R_dv, tan_half,
                      near, far, ws, work, q_next, p_cam, R, p_ct, J):
    """OR after one step of dt at rates + step x direction x scale from q (clipped to the joint limits), joint
    ``joint`` (if >= 0) of that configuration moved by ``nudge``."""
    for k in range(6):
        q_next[k] = min(max(q[k] + dt * (rates[k] + step * direction[k] * scale[k]), lower[k]), upper[k])
    if joint >= 0:
        q_next[joint] += nudge
    endoscope_kinematics(q_next, robot, ws, p_cam, R, p_ct, J, False)
    return overlap_ratio_in(p_dv, R_dv, p_cam, R, tan_half, near, far, work)


@kernel
def distilled_rates(q, p_target, R_target, dt, robot, params, out):
    """Joint rates (6,): gain x error towards the network's configuration, capped per joint, then the OR
    lookahead (see the module doc)."""
    goal = np.empty(6)
    network_configuration(p_target, R_target, params, goal)
    gain = params[0]
    for k in range(6):
        error = goal[k] - q[k]
        if k == 3 or k == 5:  # bend directions: unlimited angles, the shortest way
            error = (error + math.pi) % (2.0 * math.pi) - math.pi
        cap = params[16 + k]
        out[k] = min(max(gain * error, -cap), cap)
    if params[22] <= 0.0:
        return
    scale, min_or, tan_half, near, far = params[22:28], params[28], params[29], params[30], params[31]
    lower, upper = params[4:10], params[10:16]
    le = params[2]
    p_dv, R_dv = np.empty(3), np.empty((3, 3))
    for a in range(3):
        for b in range(3):
            R_dv[a, b] = R_target[a, b]
        p_dv[a] = p_target[a] - le * R_target[a, 2]
    ws, work = make_endoscope_workspace(), make_overlap_work()
    q_next, p_cam, p_ct, R, J = np.empty(6), np.empty(3), np.empty(3), np.empty((3, 3)), np.empty((6, 6))
    grad, zero = np.empty(6), np.zeros(6)
    here = lookahead_overlap(q, zero, 0.0, zero, scale, -1, 0.0, 0.0, lower, upper, robot, p_dv, R_dv, tan_half,
                             near, far, ws, work, q_next, p_cam, R, p_ct, J)
    if here < min_or:
        return
    best = lookahead_overlap(q, out, 0.0, zero, scale, -1, 0.0, dt, lower, upper, robot, p_dv, R_dv, tan_half, near,
                             far, ws, work, q_next, p_cam, R, p_ct, J)
    norm = 0.0
    for k in range(6):  # the gradient at the next configuration, in units of the step's scale
        up = lookahead_overlap(q, out, 0.0, zero, scale, k, ASCENT_H, dt, lower, upper, robot, p_dv, R_dv, tan_half,
                               near, far, ws, work, q_next, p_cam, R, p_ct, J)
        down = lookahead_overlap(q, out, 0.0, zero, scale, k, -ASCENT_H, dt, lower, upper, robot, p_dv, R_dv,
                                 tan_half, near, far, ws, work, q_next, p_cam, R, p_ct, J)
        grad[k] = (up - down) / (2.0 * ASCENT_H) * dt * scale[k]
        norm += grad[k] * grad[k]
    if norm <= 0.0:
        return
    norm = math.sqrt(norm)
    for k in range(6):
        grad[k] /= norm
    chosen = 0.0
    for fraction in ASCENT_FRACTIONS:
        value = lookahead_overlap(q, out, fraction, grad, scale, -1, 0.0, dt, lower, upper, robot, p_dv, R_dv,
                                  tan_half, near, far, ws, work, q_next, p_cam, R, p_ct, J)
        if value > best:
            best = value
            chosen = fraction
    for k in range(6):
        out[k] += chosen * grad[k] * scale[k]


def register(weights: Path | None = None, gain: float = GAIN, cap: float = CAP, ascent: float = ASCENT,
             name: str = NAME) -> CustomController:
    """Register the controller (``replace=True``: importing twice is harmless); returns the registration."""
    from continuum_gym.envs.registered import add_controller
    from continuum_gym.envs.view_tracking.config import ViewTrackingConfig

    path = Path(weights) if weights is not None else WEIGHTS
    with np.load(path) as data:
        params = pack(dict(data), gain, cap, ascent)
    return add_controller(name, ViewTrackingConfig.env_id, distilled_rates, np.ascontiguousarray(params, np.float64),
                          f"steers to the configuration distilled from the offline optimum ({path.name}; gain "
                          f"{gain:g} 1/s, cap {cap:g} and OR lookahead {ascent:g} action units)",
                          "continuum_gym.envs.view_tracking.controller", __name__)


def configurations(p_target: np.ndarray, R_target: np.ndarray, weights: Path | None = None) -> np.ndarray:
    """The network's configurations (n, 6) for targets (n, 3), (n, 3, 3) (for analysis and tests)."""
    path = Path(weights) if weights is not None else WEIGHTS
    with np.load(path) as data:
        params = pack(dict(data))
    out = np.empty((len(p_target), 6))
    for i in range(len(p_target)):
        network_configuration(np.ascontiguousarray(p_target[i], dtype=float),
                              np.ascontiguousarray(R_target[i], dtype=float), params, out[i])
    return out


register()

__all__ = ["NAME", "REFERENCE", "WEIGHTS", "GAIN", "CAP", "ASCENT", "ASCENT_MIN_OR", "ASCENT_FRACTIONS",
           "INPUT_OFFSET", "INPUT_SCALE", "network_inputs", "encode", "decode", "pack",
           "network_configuration", "lookahead_overlap", "distilled_rates", "register", "configurations"]
