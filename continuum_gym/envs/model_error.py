"""Model mismatch (issue 37): the robot the controller believes in is not the robot that moves.

A ``ModelError`` is the difference between the **nominal** model (the robot, cone or camera that the
analytic controller, the null-space projection and the visibility guard compute with) and the
**true** plant that moves and is scored:

- ``length_scale``: true / nominal length of each bending segment (calibration, and the
  constant-curvature model's error under load);
- mounting / calibration of the endoscope: OcclusionAvoidance ``channel_offset_m`` (error of the
  channel distance d_o) and ``lens_angle_rad`` (error of the lens tilt alpha); ViewTracking
  ``camera_rotation_rad`` (rotation vector of the camera's true mounting at the tip, camera frame);
- ``backlash_rad``: width of the deadband (play) between the actuator-side and the true bending
  angle of each segment (hysteresis of tendon / multi-backbone transmission);
- ``actuator_lag_s``: time constant of a first-order lag of the actuators' rates behind the command;
- ``joint_noise_rad``: standard deviation of the measured angular joints (encoders; prismatic joints
  are measured exactly);
- ``tip_noise_m``: standard deviation of each coordinate of the measured tip (OcclusionAvoidance:
  seen by the endoscope; ViewTracking: a tip-mounted electromagnetic tracker);
- ``delay_steps``: the command is applied this many control steps late.

Presets (``"none"``, ``"mild"``, ``"severe"``) are *ranges*; ``ModelErrorRanges.draw`` picks one
instance. With ``randomize_model_error=False`` the instance of a task is fixed per (split, task id),
so every method faces the same robots; with ``True`` a new instance is drawn per episode from the
env's random stream (domain randomisation). The ranges and their sources: ``docs/model-error.md``.

The per-row state (actuator positions, lagged rates, delay queues, measured joints, noise seeds)
lives in ``MismatchState``; the compiled steps are ``envs/occlusion/mismatch.py`` and
``envs/view_tracking/mismatch.py``. ``model_error="none"`` never reaches them: the env steps by its own
kernel, bit for bit as before.
"""

from __future__ import annotations

import dataclasses
from collections import deque, namedtuple
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from continuum_gym.envs.info import Attribute, RewardTerms
from continuum_gym.validation import boolean, choice, describe, integer, number

PRESETS = ("none", "mild", "severe")
#: Hard validity limits of each field (beyond them the model is no longer a plausible robot).
LIMITS = {
    "length_scale": (0.5, 1.5, ""),
    "channel_offset_m": (-0.002, 0.002, "m"),
    "lens_angle_rad": (-0.2, 0.2, "rad"),
    "camera_rotation_rad": (-0.2, 0.2, "rad"),
    "backlash_rad": (0.0, 0.5, "rad"),
    "actuator_lag_s": (0.0, 1.0, "s"),
    "joint_noise_rad": (0.0, 0.1, "rad"),
    "tip_noise_m": (0.0, 0.01, "m"),
    "delay_steps": (0, 20, "control steps"),
}
#: Fields that exist for one environment only (another env needs them at 0).
OCCLUSION_ONLY = ("channel_offset_m", "lens_angle_rad")
VIEW_ONLY = ("camera_rotation_rad",)


@dataclass(frozen=True)
class ModelError:
    """One instance of the true plant's difference from the nominal model (SI units; see the module doc)."""

    length_scale: float | tuple = 1.0  #: true / nominal segment length: one float, or one per segment
    channel_offset_m: float = 0.0  #: OcclusionAvoidance: true d_o - nominal d_o (m)
    lens_angle_rad: float = 0.0  #: OcclusionAvoidance: true lens tilt alpha - nominal (rad)
    camera_rotation_rad: tuple = (0.0, 0.0, 0.0)  #: ViewTracking: camera mounting rotation vector (rad)
    backlash_rad: float = 0.0  #: deadband width between actuator-side and true bending angle (rad)
    actuator_lag_s: float = 0.0  #: first-order lag time constant of the actuators (s)
    joint_noise_rad: float = 0.0  #: std of the measured angular joints (rad)
    tip_noise_m: float = 0.0  #: std of each coordinate of the measured tip (m)
    delay_steps: int = 0  #: control steps between a command and its application

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        low, high, unit = LIMITS["length_scale"]
        if isinstance(self.length_scale, (list, tuple, np.ndarray)):
            values = tuple(self.length_scale)
            if not 1 <= len(values) <= 4:
                raise ValueError(f"model_error.length_scale must be a number or 1-4 numbers (one per segment) in "
                                 f"[{low:g}, {high:g}]; got {describe(self.length_scale)}")
            set_(self, "length_scale", tuple(number(v, f"model_error.length_scale[{k}]", low=low, high=high)
                                             for k, v in enumerate(values)))
        else:
            set_(self, "length_scale", number(self.length_scale, "model_error.length_scale", low=low, high=high))
        try:
            rotation = tuple(self.camera_rotation_rad)
        except TypeError:
            rotation = ()
        low, high, unit = LIMITS["camera_rotation_rad"]
        if len(rotation) != 3:
            raise ValueError(f"model_error.camera_rotation_rad must be 3 numbers (a rotation vector, each in "
                             f"[{low:g}, {high:g}] rad); got {describe(self.camera_rotation_rad)}")
        set_(self, "camera_rotation_rad", tuple(number(v, f"model_error.camera_rotation_rad[{k}]", low=low, high=high,
                                                       unit=unit) for k, v in enumerate(rotation)))
        for name in ("channel_offset_m", "lens_angle_rad", "backlash_rad", "actuator_lag_s", "joint_noise_rad",
                     "tip_noise_m"):
            low, high, unit = LIMITS[name]
            set_(self, name, number(getattr(self, name), f"model_error.{name}", low=low, high=high, unit=unit))
        low, high, unit = LIMITS["delay_steps"]
        set_(self, "delay_steps", integer(self.delay_steps, "model_error.delay_steps",
                                          low=low, high=high))  # type: ignore[arg-type]  # int bounds, float table

    def scales(self, n_segments: int) -> np.ndarray:
        """The length scale of each of ``n_segments`` segments."""
        if isinstance(self.length_scale, tuple):
            return np.array(self.length_scale, dtype=float)
        return np.full(n_segments, self.length_scale)

    @property
    def is_zero(self) -> bool:
        """No error at all: the true plant is the nominal model."""
        scales = self.length_scale if isinstance(self.length_scale, tuple) else (self.length_scale,)
        return all(v == 1.0 for v in scales) and dataclasses.replace(self, length_scale=1.0) == ModelError()

    def check_for(self, env: str, n_segments: int) -> ModelError:
        """This error, checked against an environment ("occlusion" / "view") and its robot's segments."""
        if isinstance(self.length_scale, tuple) and len(self.length_scale) != n_segments:
            raise ValueError(f"model_error.length_scale must have one entry per segment of the robot "
                             f"({n_segments}); got {len(self.length_scale)}")
        foreign = VIEW_ONLY if env == "occlusion" else OCCLUSION_ONLY
        for name in foreign:
            value = getattr(self, name)
            if any(v != 0.0 for v in (value if isinstance(value, tuple) else (value,))):
                raise ValueError(f"model_error.{name} applies to the other environment; it must be 0 here, got "
                                 f"{value!r}")
        return self

    def to_dict(self) -> dict:
        """Plain YAML/JSON values (tuples as lists)."""
        return {f.name: list(v) if isinstance(v := getattr(self, f.name), tuple) else v for f in fields(self)}

    def values(self, n_segments: int) -> list:
        """The parameters in ``value_names(n_segments)`` order (what ``info["model_error"]`` holds)."""
        return [*self.scales(n_segments), self.channel_offset_m, self.lens_angle_rad, *self.camera_rotation_rad,
                self.backlash_rad, self.actuator_lag_s, self.joint_noise_rad, self.tip_noise_m,
                float(self.delay_steps)]


def value_names(n_segments: int) -> tuple:
    """Names of ``info["model_error"]``'s entries."""
    return (*(f"length_scale_{j + 1}" for j in range(n_segments)), "channel_offset_m", "lens_angle_rad",
            "camera_rotation_x_rad", "camera_rotation_y_rad", "camera_rotation_z_rad", "backlash_rad",
            "actuator_lag_s", "joint_noise_rad", "tip_noise_m", "delay_steps")


@dataclass(frozen=True)
class ModelErrorRanges:
    """A preset: each field drawn uniformly in [low, high]; signed fields get a random sign (magnitude range)."""

    length_scale: tuple = (0.0, 0.0)  #: |true/nominal - 1| per segment
    channel_offset_m: tuple = (0.0, 0.0)  #: |error| (m), random sign
    lens_angle_rad: tuple = (0.0, 0.0)  #: |error| (rad), random sign
    camera_rotation_rad: tuple = (0.0, 0.0)  #: angle of the mounting rotation (rad), uniform random axis
    backlash_rad: tuple = (0.0, 0.0)
    actuator_lag_s: tuple = (0.0, 0.0)
    joint_noise_rad: tuple = (0.0, 0.0)
    tip_noise_m: tuple = (0.0, 0.0)
    delay_steps: tuple = (0, 0)  #: integers, both ends included

    def draw(self, rng: np.random.Generator, env: str, n_segments: int) -> ModelError:
        """One ``ModelError`` for ``env`` ("occlusion" / "view"), with every random number from ``rng``."""
        def uniform(name: str) -> float:
            low, high = getattr(self, name)
            return float(rng.uniform(low, high))

        def signed(name: str) -> float:
            magnitude = uniform(name)
            return magnitude if rng.random() < 0.5 else -magnitude

        scales = tuple(1.0 + signed("length_scale") for _ in range(n_segments))
        offset, tilt = signed("channel_offset_m"), signed("lens_angle_rad")
        axis = rng.standard_normal(3)
        axis /= max(float(np.linalg.norm(axis)), 1e-12)
        rotation = tuple(float(v) for v in axis * uniform("camera_rotation_rad"))
        values: dict[str, Any] = dict(length_scale=scales, backlash_rad=uniform("backlash_rad"),
                                      actuator_lag_s=uniform("actuator_lag_s"),
                                      joint_noise_rad=uniform("joint_noise_rad"), tip_noise_m=uniform("tip_noise_m"),
                                      delay_steps=int(rng.integers(self.delay_steps[0], self.delay_steps[1] + 1)))
        if env == "occlusion":
            values.update(channel_offset_m=offset, lens_angle_rad=tilt)
        else:
            values.update(camera_rotation_rad=rotation)
        return ModelError(**values)


#: The presets' ranges; the reasons and sources of each number are in docs/model-error.md.
PRESET_RANGES = {
    "none": ModelErrorRanges(),
    "mild": ModelErrorRanges(length_scale=(0.0, 0.02), channel_offset_m=(0.0, 1e-4), lens_angle_rad=(0.0, 0.0175),
                             camera_rotation_rad=(0.0, 0.0175), backlash_rad=(0.0, 0.02), actuator_lag_s=(0.0, 0.02),
                             joint_noise_rad=(0.0, 0.001), tip_noise_m=(0.0, 1e-4), delay_steps=(0, 1)),
    "severe": ModelErrorRanges(length_scale=(0.02, 0.05), channel_offset_m=(1e-4, 3e-4),
                               lens_angle_rad=(0.0175, 0.0524), camera_rotation_rad=(0.0175, 0.0524),
                               backlash_rad=(0.02, 0.05), actuator_lag_s=(0.02, 0.06), joint_noise_rad=(0.001, 0.003),
                               tip_noise_m=(1e-4, 3e-4), delay_steps=(1, 3)),
}


def resolve_model_error(value: Any, env: str, n_segments: int) -> str | ModelError:
    """A preset name or a checked ``ModelError`` from a name, an instance or its ``to_dict()``."""
    if isinstance(value, str):
        return choice(value, PRESETS, "model_error")
    if isinstance(value, dict):
        data = {k: v for k, v in value.items() if k != "type"}
        names = {f.name for f in fields(ModelError)}
        unknown = sorted(set(data) - names)
        if unknown:
            raise ValueError(f"model_error: unknown field(s) {unknown}; valid fields: {sorted(names)}")
        value = ModelError(**data)
    if not isinstance(value, ModelError):
        raise ValueError(f"model_error must be one of {list(PRESETS)} or a ModelError; got {describe(value)}")
    return value.check_for(env, n_segments)


def check_randomize(randomize: Any, model_error: Any) -> bool:
    """``randomize_model_error`` as a bool; True needs a preset with ranges ("mild" or "severe")."""
    randomize = boolean(randomize, "randomize_model_error")
    if randomize and model_error not in ("mild", "severe"):
        raise ValueError(f"randomize_model_error=True draws within a preset's ranges: model_error must be 'mild' or "
                         f"'severe'; got {model_error!r}")
    return randomize


def is_active(model_error: Any) -> bool:
    """Whether the env steps through the mismatch kernel (anything but ``"none"``)."""
    return not (isinstance(model_error, str) and model_error == "none")


SPLIT_CODES = {"train": 0, "validation": 1, "test": 2}
#: Seeds of the per-(split, task id) draws: fixed forever, so every method and release faces the same robots.
FIXED_SEED = 37


def fixed_generator(split: str, task_id: int, stream: int) -> np.random.Generator:
    """The generator of one task instance's fixed error (stream 0) or noise seed (stream 1)."""
    return np.random.default_rng([FIXED_SEED, SPLIT_CODES.get(split, 3), int(task_id), stream])


#: Per-row arrays of the mismatch kernels (see ``MismatchState``).
MismatchArrays = namedtuple("MismatchArrays", [
    "scale", "calib", "backlash", "lag", "noise", "tip_noise", "delay", "seed", "q_act", "q_meas", "rate", "queue",
    "head", "flags"])
#: ``flags`` columns of a row: the calibration is exact (skip the seen-tip transform), no tip noise.
MISMATCH_CALIB_EXACT, MISMATCH_TIP_EXACT = range(2)


class ModelErrorValues(RewardTerms):
    """``info["model_error"]``: a float64 array of the instance's parameters that reads like a dict by name."""

    def _column(self, name: str) -> int:
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(f"no model-error parameter {name!r}; the parameters are {self.names}") from None

    def __reduce__(self):
        return ModelErrorValues, (self.view(np.ndarray), self.names)


class NamedRows(Attribute):
    """Info reader of a named per-row array: its row is a fresh named array already."""

    fresh = True


class MismatchState:
    """The per-row model errors and plant state of a core whose ``model_error`` is not ``"none"``."""

    # core: the BatchedCore (its type is not imported: envs.batched imports this module, and cycles are forbidden)
    def __init__(self, core: Any, env: str, dof: int, n_segments: int, substeps: int) -> None:
        config = core.config
        self.env, self.dof, self.n_segments, self.substeps = env, dof, n_segments, substeps
        self.model_error = config.model_error
        self.randomize = config.randomize_model_error
        self.split = config.task_split
        n = core.num_envs
        if isinstance(self.model_error, ModelError):
            max_delay = self.model_error.delay_steps
        else:
            max_delay = PRESET_RANGES[self.model_error].delay_steps[1]
        self.arrays = MismatchArrays(
            scale=np.ones((n, n_segments)), calib=np.zeros((n, 3)), backlash=np.zeros(n), lag=np.zeros(n),
            noise=np.zeros(n), tip_noise=np.zeros(n), delay=np.zeros(n, dtype=np.int64),
            seed=np.zeros(n, dtype=np.int64), q_act=np.zeros((n, dof)), q_meas=np.zeros((n, dof)),
            rate=np.zeros((n, dof + 1)), queue=np.zeros((n, max(1, max_delay * substeps), dof + 1)),
            head=np.zeros(n, dtype=np.int64), flags=np.zeros((n, 2), dtype=np.int64))
        names = value_names(n_segments)
        self.values = ModelErrorValues(np.zeros((n, len(names))), names)
        self.pending: deque = deque()  # per-episode seeds drawn with the front end's row generators
        self.episodes = np.zeros(n, dtype=np.int64)  # episodes per row (fallback stream of explicit task ids)

    def sample(self, rng: np.random.Generator) -> None:
        """Draw the next episode's seed from a row's generator (called with ``sample_task_id``)."""
        if self.randomize:
            self.pending.append(int(rng.integers(0, 2**62)))

    def instance(self, task_id: int, seed: int | None) -> tuple[ModelError, int]:
        """(error, noise seed) of an episode on ``task_id``: drawn from ``seed`` or fixed per (split, task id)."""
        if self.randomize:
            rng = np.random.default_rng(seed)
            error = PRESET_RANGES[self.model_error].draw(rng, self.env, self.n_segments)
            return error, int(rng.integers(0, 2**62))
        if isinstance(self.model_error, ModelError):
            error = self.model_error
        else:
            error = PRESET_RANGES[self.model_error].draw(fixed_generator(self.split, task_id, 0), self.env,
                                                         self.n_segments)
        return error, int(fixed_generator(self.split, task_id, 1).integers(0, 2**62))

    def reset(self, rows: np.ndarray, task_ids: np.ndarray, start_q: np.ndarray) -> None:
        """New episodes in ``rows``: their model errors, actuators at the start pose, at rest, empty queues."""
        seeds = [self.pending.popleft() for _ in rows] if len(self.pending) == len(rows) else [None] * len(rows)
        self.pending.clear()
        a = self.arrays
        for row, task_id, seed in zip(rows, task_ids, seeds):
            if seed is None and self.randomize:  # an explicit task id: a stream of its own per row and episode
                seed = int(fixed_generator(self.split, int(task_id), 2 + int(self.episodes[row])).integers(0, 2**62))
            error, noise_seed = self.instance(int(task_id), seed)
            self.episodes[row] += 1
            a.scale[row] = error.scales(self.n_segments)
            a.calib[row] = ((error.channel_offset_m, error.lens_angle_rad, 0.0) if self.env == "occlusion"
                            else error.camera_rotation_rad)
            a.backlash[row], a.lag[row] = error.backlash_rad, error.actuator_lag_s
            a.noise[row], a.tip_noise[row] = error.joint_noise_rad, error.tip_noise_m
            if error.delay_steps * self.substeps > a.queue.shape[1]:
                raise ValueError(f"model_error.delay_steps={error.delay_steps} exceeds this env's delay queue")
            a.delay[row] = error.delay_steps
            a.seed[row] = noise_seed
            a.flags[row, 0] = 1 if all(v == 0.0 for v in a.calib[row]) else 0
            a.flags[row, 1] = 1 if error.tip_noise_m == 0.0 else 0
            self.values[row, :] = error.values(self.n_segments)
        a.q_act[rows] = start_q
        a.q_meas[rows] = start_q
        a.rate[rows] = 0.0
        a.queue[rows] = 0.0
        a.head[rows] = 0


_INFO_FIELDS: dict = {}


def with_model_error_info(fields: tuple) -> tuple:
    """A core's ``info`` fields and ``model_error`` (one tuple per field list: the info readers cache by it)."""
    from continuum_gym.envs.info import InfoField

    extended = _INFO_FIELDS.get(id(fields))
    if extended is None or extended[0] is not fields:
        extended = _INFO_FIELDS[id(fields)] = (fields, (*fields, InfoField(
            "model_error", NamedRows("_mismatch.values"), None,
            "the row's model error, a named float64 array (``info['model_error']['backlash_rad']``); only with "
            "``model_error`` other than 'none'")))
    return extended[1]


__all__ = ["ModelError", "ModelErrorRanges", "PRESETS", "PRESET_RANGES", "resolve_model_error", "is_active",
           "MismatchState", "value_names"]
