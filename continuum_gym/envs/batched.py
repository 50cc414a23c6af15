"""The batched core behind three front ends: ``gymnasium.Env`` (``envs/single.py``),
``gymnasium.vector.VectorEnv`` (``envs/vector.py``) and stable-baselines3's ``VecEnv`` (``envs/sb3.py``).

A core holds the state of N robots as arrays and advances all of them with one compiled call of the env's
row functions (``envs/rows.py``). It is the library's, written once for every environment: an env declares its
rows (``envs/core.py: RowFunctions``) and this class allocates their arrays, resets and steps them on threads,
runs the model-error plant and the plug-ins, and reads ``info`` from the declared columns. ``front_ends`` binds
it to an env's spec (``OcclusionCore``, ``ViewTrackingCore`` are such bindings, not subclasses with code).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, ClassVar, cast

import numpy as np
from gymnasium import spaces

from continuum_gym.envs.common_kernels import task_arrays
from continuum_gym.envs.core import STANDARD_ARRAYS
from continuum_gym.envs.declared import info_fields, step_values
from continuum_gym.envs.info import RewardTerms, fields_table, info_batch, row_reader
from continuum_gym.envs.pixels import make_observer
from continuum_gym.envs.row_claims import KernelCall
from continuum_gym.envs.scenes import OcclusionRowScene, RowScene
from continuum_gym.envs.stepping import row_threads, step_threads
from continuum_gym.validation import integer

if TYPE_CHECKING:
    from continuum_gym.envs.common_kernels import TaskArrays
    from continuum_gym.envs.config import EnvConfig
    from continuum_gym.envs.core import RowFunctions
    from continuum_gym.envs.model_error import MismatchState
    from continuum_gym.envs.pixels import PixelObserver
    from continuum_gym.envs.tasks import TaskBatch

#: Every observation entry is clipped to +-OBS_LIMIT (the observation space's bounds).
OBS_LIMIT = 10.0


class BatchedCore:
    """N robots of one environment as arrays, advanced by one compiled call of its row functions.

    ``front_ends`` binds this class to an env (``spec``, ``rows``); the front ends (``envs/single.py``,
    ``envs/vector.py``, ``envs/sb3.py``), evaluation, rendering and precompilation call what it defines.
    Everything an env is made of comes from its ``RowFunctions`` and its config: the arrays, their columns
    (``metrics``, ``flags``: ``info`` and the evaluation's values come from their declarations), the kernel
    bundles (``RowFunctions.build``), the model-error plant (``envs/model_error.py``), and the plug-ins
    (a registered controller as the base, registered reward terms).
    """

    spec: ClassVar[Any] = None  #: the env's ``EnvSpec`` (set by ``front_ends``)
    rows: ClassVar[Any] = None  #: the env's ``RowFunctions`` (set by ``front_ends``)
    _observe_mask: np.ndarray | None = None  # observe_rows' ``active`` (N,) uint8, zero between calls
    config: EnvConfig  #: the validated configuration the core was built from
    num_envs: int
    dof: int  #: joints per row: the width of joint bit flags (``info["clamped_joints"]``) and of ``q``
    #: one row's observation: the state ``Box`` of ``obs``, or the ``Dict`` of an image ``obs_mode`` (``pixels``)
    single_observation_space: spaces.Space
    single_action_space: spaces.Box
    #: the image observations of ``config.obs_mode`` (``envs/pixels.py``), or None (``"state"``: ``obs`` is observed)
    pixels: PixelObserver | None = None
    task_count: int
    q: np.ndarray  # (N, dof) joints
    steps: np.ndarray  # (N,) int64 control steps since reset
    obs: np.ndarray  # (N, obs_dim) float64
    base_cmd: np.ndarray  # (N, action_dim) the baseline's command at the current state
    metrics: np.ndarray  # (N, n_metrics) float64
    flags: np.ndarray  # (N, n_flags) int64
    terms: np.ndarray  # (N, n_terms) float64 weighted reward terms
    rewards: np.ndarray  # (N,) float64
    limit: np.ndarray  # (N,) int64 episode step limits
    #: (1,) int64: rows the kernels flagged non-finite since the last check (the step's ``out.faults``)
    _faults: np.ndarray
    tasks: TaskBatch
    _tasks: TaskArrays

    def __init__(self, num_envs: int = 1, config: EnvConfig | None = None, num_threads: int | None = None,
                 **kwargs: Any) -> None:
        if self.rows is None:
            raise TypeError("BatchedCore is bound to an environment by envs.front_ends.front_ends(spec, rows, ...); "
                            "make the env's core class (e.g. spec.core_class()), not BatchedCore itself")
        rows: RowFunctions = self.rows
        self.config = config = self._config(config, kwargs)
        self.num_envs = n = self._num_envs(num_envs)
        self.task_split = config.task_split
        self.base_controller = config.base_controller
        self.residual_scale = config.residual_scale
        self.weights = config.reward_weights
        self.control_dt = config.control_dt
        self.substeps = getattr(config, "substeps", 1)
        self.max_episode_steps = config.max_episode_steps
        self.robot = config.robot
        self.dof = self.robot.dof
        built = rows.build(config)
        self.parts = built.parts
        self._bind_parts()
        self.task_context = built.context
        self.task_source = config.task_source
        self.task_count = self.task_source.count(self.task_split, self.task_context)
        self.single_observation_space = spaces.Box(-OBS_LIMIT, OBS_LIMIT, (built.obs_dim,), np.float32)
        self.single_action_space = spaces.Box(-1.0, 1.0, (built.action_dim,), np.float32)
        self.info_fields = info_fields((rows.metrics, rows.flags), rows.info)
        self.metric_columns = {c.declared.info: int(c) for c in rows.metrics if c.declared.info}
        self.builtin_reward_names = rows.reward_terms
        self.terminated_flag = int(rows.flags[rows.terminated])
        self.truncated_flag = int(rows.flags[rows.truncated])
        self.non_finite_flag = len(rows.flags) - 1
        self.parallel_min_rows, self.claim_block = rows.parallel_min_rows, rows.claim_block
        self._setup_mismatch(rows.model_error, getattr(self.robot, "n_segments", 2))
        self._setup_rewards()
        sizes = {"dof": self.dof, "command": built.command, "obs": built.obs_dim, "metrics": len(rows.metrics),
                 "flags": len(rows.flags), "terms": len(self.reward_names)}
        for name, (shape, dtype) in STANDARD_ARRAYS.items():
            setattr(self, name, np.zeros((n, *(sizes[s] for s in shape)), dtype=dtype))
        for name, extra in rows.arrays.items():
            setattr(self, name, np.zeros((n, *extra.shape), dtype=extra.dtype))
        self._faults = np.zeros(1, dtype=np.int64)
        self.num_threads = step_threads(num_threads)
        self.row_threads = row_threads(n, self.num_threads, self.parallel_min_rows)
        self.tasks = self.task_source.batch(self.task_split, np.zeros(n, dtype=np.int64), self.task_context)
        self._state = rows.state(*(getattr(self, name) for name in rows.state._fields))
        self._tasks = task_arrays(self.tasks, self.limit)
        self._out = rows.outputs(*(getattr(self, "_" + name if name == "faults" else name)
                                   for name in rows.outputs._fields))
        self._model, self._params = built.model, built.params
        self.layers = tuple(layer(self) for layer in built.layers)
        self.pixels = make_observer(self)
        if self.pixels is not None:
            self.single_observation_space = self.pixels.space

    if TYPE_CHECKING:  # for mypy only: the env's parts and methods (``_bind_parts``) are attributes of any name
        def __getattr__(self, name: str) -> Any: ...

    def _bind_parts(self) -> None:
        """The env's own objects (its built-in controller, cameras, limits, ...) and methods as ``core.<name>``.

        Instance attributes, not a ``__getattr__``: a class with one pays for the hook on every attribute read
        (about 20 ns each in CPython, a microsecond per single-env step over the step's reads).
        """
        for name, value in self.parts.items():
            if not hasattr(type(self), name):
                self.__dict__.setdefault(name, value)
        for name, method in (self.rows.methods if self.rows is not None else {}).items():
            if not hasattr(type(self), name):
                self.__dict__[name] = functools.partial(method, self)

    def _config(self, config, kwargs):
        """The validated config: ``config`` as given (an ``EnvConfig``, or the dict its ``to_dict()`` wrote, as
        Minari datasets store it), or built from the keyword arguments."""
        if config is None:
            return self.config_class.from_kwargs(**kwargs)
        if isinstance(config, dict):
            config = self.config_class.from_dict(config)
        if not isinstance(config, self.config_class):
            raise ValueError(f"config must be a {self.config_class.__name__}; got {type(config).__name__}")
        return config.replace(**kwargs) if kwargs else config

    @property
    def config_class(self) -> type[EnvConfig]:
        """The ``EnvConfig`` subclass the core is built from (the spec's)."""
        return self.spec.config_class

    @staticmethod
    def _num_envs(num_envs) -> int:
        return integer(num_envs, "num_envs", low=1)

    def info(self) -> dict:
        """Every ``info`` entry for the whole batch: {name: (N, ...) array} (with an image ``obs_mode``, the pixel
        metrics too)."""
        info = info_batch(self.info_fields, self)
        if self.pixels is not None:
            info.update(self.pixels.info())
        return info

    def observations(self, copy: bool = True) -> np.ndarray | dict:
        """Every row's observation, as the front ends return it: ``obs`` as float32 (N, obs_dim), or the images of
        ``obs_mode`` and the measured ``state`` {key: (N, ...)}, rendered from the rows changed since the last read
        (``copy=False``: the image buffers themselves, valid until the next step or reset)."""
        return self.obs.astype(np.float32) if self.pixels is None else self.pixels.observations(copy)

    def observation(self, row: int) -> np.ndarray | dict:
        """One row's observation (fresh arrays): what ``observations()`` holds at ``row``."""
        return self.obs[row].astype(np.float32) if self.pixels is None else self.pixels.observation(row)

    # the written-out reader of info_fields, found on the first info_row
    _info_row_reader: Callable[..., dict] | None = None

    def info_row(self, row: int) -> dict:
        """Every ``info`` entry of one row: numpy scalars and fresh arrays."""
        reader = self._info_row_reader
        if reader is None:
            reader = self._info_row_reader = row_reader(self.info_fields, self)
        info = reader(self, row)
        if self.pixels is not None:
            info.update(self.pixels.info_row(row))
        return info

    def step_values(self) -> dict:
        """Per-step values {name: (N,) array} the evaluation reduces to episode metrics (the declared columns')."""
        return step_values(self, (self.rows.metrics, self.rows.flags))

    def controller_observation(self, row: int = 0) -> dict:
        """The dict observation an analytic or registered controller's ``predict`` reads, for one row."""
        return self.rows.controller_observation(self, row)

    def reset_rows(self, rows: np.ndarray, task_ids: np.ndarray) -> None:
        """Start new episodes in ``rows`` (int64) on the task instances ``task_ids`` and observe them."""
        rows = np.asarray(rows, dtype=np.int64)
        fresh = self.task_source.batch(self.task_split, task_ids, self.task_context)
        self._install_tasks(rows, fresh)
        for name, extra in self.rows.arrays.items():
            getattr(self, name)[rows] = getattr(fresh, extra.start) if extra.start else 0
        self._reset_mismatch(rows, task_ids)
        self.observe_rows(rows)
        for layer in self.layers:
            layer.reset_rows(rows)
        if self.pixels is not None:  # rendered when next observed
            self.pixels.stale(rows)

    def step(self, actions: np.ndarray, active: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Step the rows whose ``active`` (N,) uint8 is 1 (0 leaves a row as it is) by ``actions`` (N, k).

        Returns (rewards, terminated, truncated) arrays and fills ``self.obs``. The value 2
        (``OBSERVE_ONLY``) is reserved for ``observe_rows``: such a row is observed, not stepped.
        """
        if self.pixels is not None:  # the rows stepped are rendered when next observed
            self.pixels.stale(active != 0)
        if self.layers:  # Python layers around the compiled step (``Built.layers``)
            return self._step_layered(actions, active)
        return self._step_rows(actions, active)

    def _step_rows(self, actions: np.ndarray, active: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The compiled step of the rows, the registered reward terms, the check of non-finite values."""
        before = self.joint_values() if self._rates_wanted else None
        self._step_call(self.kernel_args(actions, active), actions, active, self.num_envs, self.row_threads,
                        self.claim_block)
        if before is not None:
            self._add_registered_terms(actions, active, self._applied_rates(before))
        if self._faults[0]:  # a row's value is not finite: raise, or end it as truncated (envs/faults.py)
            from continuum_gym.envs.faults import handle

            handle(self, active == 1, "step")
        # The kernels write the flags as 0 / 1; astype(bool) is `!= 0` at half the cost (0.6 vs 1.3 us per step).
        return (self.rewards, self.flags[:, self.terminated_flag].astype(bool),
                self.flags[:, self.truncated_flag].astype(bool))

    def _step_layered(self, actions: np.ndarray, active: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``step`` through the env's Python layers: each changes the actions the kernel gets, then sees the step."""
        memos = []
        sent = actions
        for layer in self.layers:
            sent, memo = layer.actions(sent, active)
            memos.append(memo)
        out = self._step_rows(sent, active)
        for layer, memo in zip(self.layers, memos):
            layer.after_step(actions, memo)
        return out

    def _setup_rewards(self) -> None:
        """Reward names and slots: the built-in terms, then the registered compiled, then numpy terms."""
        from continuum_gym.envs import registered

        terms = list(registered.REWARD_TERMS[self.spec.env_id].values())
        self._compiled_terms = [t for t in terms if t.compiled]
        self._numpy_terms = [t for t in terms if not t.compiled]
        self.reward_names = (*self.builtin_reward_names, *(t.name for t in self._compiled_terms),
                             *(t.name for t in self._numpy_terms))
        self._make_slots()

    def _make_slots(self) -> None:
        """The compiled slots of the registered controller and reward terms (typed lists, rebuilt on unpickling)."""
        from continuum_gym.envs import registered
        from continuum_gym.envs.custom import controller_slot, reward_slot
        from continuum_gym.envs.rows import step_batch

        controllers = registered.CONTROLLERS[self.spec.env_id]
        if self.base_controller is not None and self.base_controller not in self.spec.baselines \
                and self.base_controller not in controllers:  # imports the plug-in's module, or says where to
            registered.resolve("controller", self.spec.env_id, self.base_controller)
        self._custom = controller_slot(
            self.spec.env_id, controllers.get(self.base_controller))  # type: ignore[arg-type]  # None: no controller
        self._reward_slot = reward_slot(self._compiled_terms, [self.weights[t.name] for t in self._compiled_terms])
        self._rates_wanted = bool(self._compiled_terms or self._numpy_terms)
        self._step_call = KernelCall(step_batch)

    def __getstate__(self) -> dict:
        # numba's typed lists do not pickle; the slots are rebuilt from the registry on unpickling
        state = self.__dict__.copy()
        for name in ("_custom", "_reward_slot", "_step_call", "_info_row_reader", "_model"):
            state.pop(name, None)  # compiled entry points, generated code, read-only arrays: made again
        for name in (self.rows.methods if self.rows is not None else {}):
            state.pop(name, None)  # bound to this core: bound again
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
        self._bind_parts()
        self._model = self.rows.build(self.config).model  # read-only robot arrays again (unpickled ones are not)
        self._make_slots()

    def kernel_args(self, actions: np.ndarray, active: np.ndarray) -> tuple:
        """``envs.rows.step_batch``'s bundles around the per-step ``actions`` (N or 1, k) and ``active`` (N,) uint8."""
        return (self._state, actions, active, self._tasks, self._model, self._params, self._custom, self._out,
                self._plant)

    # ------------------------------------------------------------------ model error (envs/model_error.py)
    #: The ``MismatchState`` of a core whose ``model_error`` is not "none" (the rows then run with its plant).
    _mismatch: MismatchState | None = None
    _plant: Any = None  #: its arrays, the row functions' ``plant`` (None: no model error)

    def _setup_mismatch(self, env: str, n_segments: int) -> None:
        """Per-row model errors and plant state when ``config.model_error`` is not "none"."""
        from continuum_gym.envs.model_error import MismatchState, is_active, with_model_error_info

        if not is_active(getattr(self.config, "model_error", "none")):
            return
        if not env:
            raise ValueError(f"model_error: {self.spec.env_id} has no model-error plant (its RowFunctions name none)")
        self._mismatch = MismatchState(self, env, self.dof, n_segments, self.substeps)
        self._plant = self._mismatch.arrays
        self.info_fields = with_model_error_info(self.info_fields)

    def measured_joints(self, row: int) -> np.ndarray:
        """A copy of a row's joints as its sensors read them (the true ones without a model error)."""
        return self.sensed_joints()[row].copy()

    def sensed_joints(self) -> np.ndarray:
        """Every row's joints as the sensors read them (N, dof): the core's own array, not a copy."""
        return self.q if self._mismatch is None else self._mismatch.arrays.q_meas

    def _reset_mismatch(self, rows: np.ndarray, task_ids: np.ndarray) -> None:
        if self._mismatch is not None:
            self._mismatch.reset(rows, task_ids, self.q[rows])

    def observe_rows(self, rows: Any) -> None:
        """Recompute observation, metrics and the cached baseline command of ``rows`` from their state.

        The step kernel does it for rows marked ``OBSERVE_ONLY`` (it reads no action for them): one
        compiled kernel holds both, so a process loads the observation's code once.
        """
        from continuum_gym.envs.common_kernels import OBSERVE_ONLY

        mask = self._observe_mask
        if mask is None:  # made on the first reset, kept (and pickled)
            mask = self._observe_mask = np.zeros(self.num_envs, dtype=np.uint8)
            self._no_actions = np.zeros((1,) + self.single_action_space.shape)
        mask[rows] = OBSERVE_ONLY
        try:
            self._step_call(self.kernel_args(self._no_actions, mask), self._no_actions, mask, self.num_envs, 1)
            if self._faults[0]:  # the row's first observation is not finite (envs/faults.py)
                from continuum_gym.envs.faults import handle

                handle(self, mask == OBSERVE_ONLY, "reset")
        finally:
            mask[rows] = 0

    def non_finite(self) -> np.ndarray:
        """(N,) bool: rows whose last step (or reset) had a value that is not finite (``info["non_finite"]``)."""
        return self.flags[:, self.non_finite_flag] != 0

    def joint_values(self) -> np.ndarray:
        """A copy of every row's joints (N, k) in the action's index layout (rad; m for insertion): ``q`` and the
        env's joint arrays after it (OcclusionAvoidance's endoscope rotation gamma)."""
        joints = self.rows.joints
        if not joints:
            return self.q.copy()
        return np.concatenate([self.q, *(getattr(self, name)[:, None] for name in joints)], axis=1)

    @property
    def circular_joint_columns(self) -> tuple[int, ...]:
        """Columns of ``joint_values`` that are angles on the circle (their change is wrapped to [-pi, pi))."""
        joints = self.rows.joints
        return tuple(self.dof + k for k, name in enumerate(joints) if self.rows.arrays[name].circular)

    def _applied_rates(self, before: np.ndarray) -> np.ndarray:
        """The rates the robot applied over the last control step: (joints now - ``before``) / control_dt."""
        change = self.joint_values() - before
        for column in self.circular_joint_columns:
            change[:, column] = (change[:, column] + np.pi) % (2.0 * np.pi) - np.pi
        return change / self.control_dt

    def _add_registered_terms(self, actions: np.ndarray, active: np.ndarray, rates: np.ndarray) -> None:
        """The registered terms on the rows that stepped: compiled ones per row, then numpy ones per batch."""
        first = len(self.builtin_reward_names)
        if self._reward_slot is not None:
            from continuum_gym.envs.custom import apply_reward_terms

            apply_reward_terms(self._reward_slot, self.metrics, self.flags, np.ascontiguousarray(actions, np.float64),
                               rates, active, self.terms, self.rewards, first, self.non_finite_flag, self._faults)
        if not self._numpy_terms:
            return
        metrics = {name: self.metrics[:, column] for name, column in self.metric_columns.items()}
        stepped = active != 0
        first += len(self._compiled_terms)
        for k, term in enumerate(self._numpy_terms):
            values = term.fn(metrics, actions, rates) if term.with_rates else term.fn(metrics, actions)
            values = np.asarray(values, dtype=np.float64).reshape(-1)
            if values.shape != (self.num_envs,):
                raise ValueError(f"reward term {term.name!r} must return {self.num_envs} values (one per row); got "
                                 f"shape {values.shape}")
            weighted = self.weights[term.name] * values
            self.terms[stepped, first + k] = weighted[stepped]
            self.rewards[stepped] += weighted[stepped]
            bad = stepped & ~np.isfinite(weighted)
            if bad.any():  # flagged like a compiled term's (envs/faults.py)
                self._faults[0] += int(np.count_nonzero(bad & ~self.non_finite()))
                self.flags[bad, self.non_finite_flag] = 1

    def desired(self, row: int, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Row's desired position (occlusion, m) or da Vinci configuration (view) and its rate at time t (s)."""
        from continuum_gym.envs.common_kernels import trajectory_batch

        dim = self.tasks.centre.shape[1]
        p = np.empty((1, 1, dim))
        v = np.empty((1, 1, dim))
        trajectory_batch(self._tasks, np.array([row], dtype=np.int64), np.array([float(t)]), p, v)
        return p[0, 0], v[0, 0]

    def desired_rotation(self, row: int, t: float) -> np.ndarray:
        """Row's desired tip orientation (3, 3) at time t (s)."""
        from continuum_gym.envs.common_kernels import rotation_at

        out = np.empty((3, 3))
        rotation_at(self._tasks, row, float(t), out)
        return out

    def _install_tasks(self, rows: np.ndarray | int | slice, fresh: TaskBatch) -> None:
        """Copy freshly drawn task instances into ``rows`` and restart their episodes (state from the task)."""
        from continuum_gym.envs.common_kernels import task_arrays
        from continuum_gym.envs.tasks import copy_rows, grown, row_indices

        if fresh.knot_capacity > self.tasks.knot_capacity:  # a longer recording than any before: grow every row
            self.tasks = grown(self.tasks, fresh.knot_capacity)
            self._tasks = task_arrays(self.tasks, self.limit)
        copy_rows(self.tasks, rows, fresh)
        rows, source = row_indices(rows, len(fresh.task_id))
        self.limit[rows] = fresh.duration[source]
        if self.max_episode_steps is not None:
            self.limit[rows] = np.minimum(fresh.duration[source], self.max_episode_steps)
        self.q[rows] = fresh.start_q[source]
        self.steps[rows] = 0
        self.flags[rows] = 0
        self.terms[rows] = 0.0
        self.rewards[rows] = 0.0

    reward_names: tuple = ()

    def reward_terms(self) -> RewardTerms:
        """The weighted reward terms of every row: (N, n_terms), readable by term name."""
        return RewardTerms(self.terms[:, :len(self.reward_names)], self.reward_names)

    def reward_terms_row(self, row: int) -> RewardTerms:
        """The weighted reward terms of one row: (n_terms,), readable by term name (numpy scalars)."""
        return RewardTerms.of_checked(self.terms[row, :len(self.reward_names)], self.reward_names)

    def sample_task_id(self, rng: np.random.Generator) -> int:
        """A task id for a row's next episode from its generator (which also draws a randomised model error)."""
        task_id = int(rng.integers(0, self.task_count))
        if self._mismatch is not None:
            self._mismatch.sample(rng)
        return task_id

    def check_task_ids(self, task_ids: Any, count: int, name: str) -> np.ndarray:
        """``count`` task ids as int64: whole numbers in [0, task_count), else a named error."""
        values = np.asarray(task_ids, dtype=object).reshape(-1) if np.ndim(task_ids) else [task_ids]
        if len(values) != count:
            raise ValueError(f"{name} must hold {count} task id(s); got {len(values)}")
        return np.array([integer(v, name, low=0, high=self.task_count - 1) for v in values], dtype=np.int64)

    def info_fields_doc(self) -> str:
        return fields_table(self.info_fields)

    # ------------------------------------------------------------------ rendering (pybullet, optional)
    def make_scene(self) -> RowScene:
        """The env's pybullet scene (``spec.scene``), built for this core's robot and cameras."""
        return self.spec.scene_class().from_core(self)

    def render_row(self, row: int, scene: RowScene, camera: str, size: int = 128) -> np.ndarray:
        """RGB image (size, size, 3) of one row's state through ``camera``."""
        scene.show_row(self, row)
        return scene.render(camera=camera, width=size, height=size)

    @property
    def supports_pixel_occlusion(self) -> bool:
        """Whether the env's pybullet scene measures the pixel occlusion of its endoscope image."""
        return callable(getattr(self.spec.scene_class(), "pixel_occlusion", None))

    def pixel_occlusion(self, row: int, scene: RowScene, resolution: int = 128) -> float:
        """Fraction of the endoscope image's field of view the robot covers in one row's state."""
        if not callable(getattr(scene, "pixel_occlusion", None)):
            raise ValueError(f"pixel_occlusion applies to OcclusionAvoidance only; this env is {self.spec.env_id}")
        scene.show_row(self, row)
        return cast("OcclusionRowScene", scene).pixel_occlusion(resolution)
