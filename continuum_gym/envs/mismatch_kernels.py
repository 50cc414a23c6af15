"""Compiled pieces of the model-mismatch plant both environments share (issue 37; ``envs/model_error.py``).

- ``gaussian``: a standard normal number of (seed, counter, index): splitmix64 and Box-Muller. Noise is
  a function of the row's seed and the measurement's index, so it is the same whatever the threads,
  the batch size or the order rows are stepped in (same seed, same result).
- ``measure``: the measured joints, actuator positions plus encoder noise on the angular joints.
- ``delay_command``: a per-row ring buffer that returns the command of ``delay_steps`` control steps ago.
- ``lag_rates``: the actuators' rates after a first-order lag behind the command (exact discretisation).
- ``play``: the backlash (deadband) between an actuator-side and the true bending angle.

With a zero error each piece returns its input exactly (no arithmetic on it), which is what makes an
all-zero ``ModelError`` reproduce ``model_error="none"`` bit for bit.
"""

from __future__ import annotations

import math

import numpy as np

from continuum_gym.robots.compiled import kernel

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_INDEX = np.uint64(0xD1B54A32D192ED03)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S30 = np.uint64(30)
_S27 = np.uint64(27)
_S31 = np.uint64(31)
_S11 = np.uint64(11)
_ONE = np.uint64(1)
_TO_UNIT = 1.0 / 9007199254740992.0  # 2^-53


@kernel(inline="always")
def _mix(x):
    x = (x ^ (x >> _S30)) * _M1
    x = (x ^ (x >> _S27)) * _M2
    return x ^ (x >> _S31)


@kernel(inline="always")
def gaussian(seed, counter, index):
    """A standard normal number determined by (seed, counter, index) (all non-negative integers)."""
    x = np.uint64(seed) + np.uint64(counter) * _GOLDEN + np.uint64(index) * _INDEX
    a = _mix(x)
    b = _mix(a + _GOLDEN)
    u1 = float((a >> _S11) + _ONE) * _TO_UNIT  # (0, 1]
    u2 = float(b >> _S11) * _TO_UNIT  # [0, 1)
    return math.sqrt(-2.0 * math.log(u1)) * math.cos(2.0 * math.pi * u2)


@kernel(inline="always")
def measure(me, i, counter, prismatic):
    """me.q_meas[i] = me.q_act[i] + noise on every joint but ``prismatic`` (measurement ``counter`` of the row)."""
    qa = me.q_act[i]
    qm = me.q_meas[i]
    sigma = me.noise[i]
    for k in range(qa.shape[0]):
        if sigma == 0.0 or k == prismatic:
            qm[k] = qa[k]
        else:
            qm[k] = qa[k] + sigma * gaussian(me.seed[i], counter, k)


@kernel(inline="always")
def tip_noise(me, i, counter, a):
    """Noise of coordinate ``a`` of the measured tip (m) at measurement ``counter``."""
    return me.tip_noise[i] * gaussian(me.seed[i], counter, 64 + a)


@kernel(inline="always")
def delay_command(me, i, u, substeps):
    """Swap ``u`` (the command now) with the one queued ``delay_steps * substeps`` substeps ago."""
    size = me.delay[i] * substeps
    if size == 0:
        return
    h = me.head[i]
    queue = me.queue[i, h]
    for k in range(u.shape[0]):
        old = queue[k]
        queue[k] = u[k]
        u[k] = old
    me.head[i] = (h + 1) % size


@kernel(inline="always")
def lag_rates(me, i, u, dt):
    """me.rate[i] follows ``u`` with time constant ``actuator_lag_s`` over one substep dt (exact for constant u)."""
    rate = me.rate[i]
    tau = me.lag[i]
    if tau == 0.0:
        for k in range(u.shape[0]):
            rate[k] = u[k]
    else:
        gain = 1.0 - math.exp(-dt / tau)
        for k in range(u.shape[0]):
            rate[k] += (u[k] - rate[k]) * gain


@kernel(inline="always")
def play(true, actuator, width):
    """The true angle after the actuator moved, with a deadband of ``width`` (rad) between them."""
    if width == 0.0:
        return actuator
    half = 0.5 * width
    if actuator - true > half:
        return actuator - half
    if true - actuator > half:
        return actuator + half
    return true


__all__ = ["gaussian", "measure", "tip_noise", "delay_command", "lag_rates", "play"]
