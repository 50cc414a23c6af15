"""A plug-in's NaN or inf is never a score (issue 54, item 1), fuzzed at run time in every front end.

Each case runs the same env twice in lockstep: once with a finite plug-in (A) and once with a twin (B)
that writes a NaN or an inf only at some states, here chosen from A's own trajectory (a controller when
the desired tip velocity or the da Vinci target crosses a threshold; a reward term when a metric
does). Until the first state at which B's plug-in fires, B must equal A bit for bit; at that step B must
raise a ``NonFiniteError`` that names the plug-in and the row (``on_non_finite="raise"``), or end the
episode as truncated with ``info["non_finite"]``, NaN metrics, reward 0 and a finite observation
(``"truncate"``); and ``evaluate`` refuses to average such an episode. The robots are drawn with 1-4
segments of random lengths.
"""

from __future__ import annotations

import contextlib
import math

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import HealthCheck, assume, event, given, settings
from hypothesis import strategies as st
from numba import njit

import continuum_gym  # noqa: F401  (registers the ids)
from continuum_gym.envs import ContinuumSB3VecEnv
from continuum_gym.envs.faults import NonFiniteError
from continuum_gym.registry import register_controller, register_reward_term, unregister
from continuum_gym.robots import MultiBackboneRobot

OCCLUSION = "ContinuumGym/OcclusionAvoidance-v0"
VIEW = "ContinuumGym/ViewTracking-v0"


# ---------------------------------------------------------------------- the plug-ins
@njit(cache=True)
def occlusion_trigger(q, gamma, p_des, R_des, v_des, dt, robot, cone, params, out):
    """Zero rates (finite), or NaN / inf in entry params[2] while |v_des[params[0]]| > params[1] (params[3] > 0:
    inf). params[0] < 0: never (the finite twin). At the registration's trial state v_des is 0: it registers."""
    for k in range(out.shape[0]):
        out[k] = 0.0
    axis = int(params[0])
    if axis >= 0 and abs(v_des[axis]) > params[1]:
        out[int(params[2]) % out.shape[0]] = math.inf if params[3] > 0 else math.nan


@njit(cache=True)
def view_trigger(q, p_target, R_target, dt, robot, params, out):
    """Zero rates (finite), or NaN / inf while p_target[params[0]] > params[1] (as ``occlusion_trigger``)."""
    for k in range(6):
        out[k] = 0.0
    axis = int(params[0])
    if axis >= 0 and p_target[axis] > params[1]:
        out[int(params[2]) % 6] = math.inf if params[3] > 0 else math.nan


@njit(cache=True)
def metric_trigger(metrics, flags, action, rates, params):
    """0.0, or NaN / inf while metrics[params[0]] > params[1]."""
    if metrics[int(params[0])] > params[1]:
        return math.inf if params[2] > 0 else math.nan
    return 0.0


def numpy_trigger(column: str, threshold: float, value: float):
    def term(metrics, actions):
        return np.where(metrics[column] > threshold, value, 0.0)

    return term


@pytest.fixture
def registered():
    names = []
    yield names
    for name, env in names:
        unregister(name, env)


@contextlib.contextmanager
def plugins():
    """Names registered inside, removed on leaving (one hypothesis example must not leak into the next)."""
    names: list = []
    try:
        yield names
    finally:
        for name, env in names:
            unregister(name, env)


# ---------------------------------------------------------------------- the lockstep runs
def _make(front_end: str, env_id: str, rows: int, seed: int, **kwargs):
    if front_end == "single":
        return gym.make(env_id, **kwargs).unwrapped
    if front_end == "vector":
        return gym.make_vec(env_id, num_envs=rows, vectorization_mode="vector_entry_point",
                            autoreset_mode="Disabled", **kwargs)
    return ContinuumSB3VecEnv(env_id, rows, seed=seed, **kwargs)


def _reset(env, front_end: str, seed: int):
    if front_end == "sb3":
        return env.reset(), None
    return env.reset(seed=seed)


def _step(env, front_end: str, actions):
    """(obs, rewards, terminated, truncated, infos as a list of per-row dicts) of any front end."""
    if front_end == "single":
        obs, reward, terminated, truncated, info = env.step(actions[0])
        return obs[None], np.array([reward]), np.array([terminated]), np.array([truncated]), [info]
    if front_end == "vector":
        obs, rewards, terminated, truncated, info = env.step(actions)
        rows = [{key: value[i] for key, value in info.items() if not key.startswith("_")} for i in range(len(obs))]
        return obs, rewards, terminated, truncated, rows
    obs, rewards, dones, infos = env.step(actions)
    truncated = np.array([bool(info.get("TimeLimit.truncated", False)) for info in infos])
    return obs, rewards, dones & ~truncated, truncated, infos


def _core(env):
    return env.unwrapped.core if hasattr(env, "unwrapped") else env.core


def _fired(core, env_id: str, row: int, kind: str, params) -> bool:
    """Whether B's plug-in fires at A's state of ``row`` in the step just taken (or at the reset)."""
    if kind == "controller" and env_id == OCCLUSION:  # substeps 1..S-1 of the step and the observe after it
        t_end = core.steps[row] * core.control_dt
        sub = core.control_dt / core.substeps
        times = [t_end] if core.steps[row] == 0 else [t_end - core.control_dt + s * sub
                                                      for s in range(1, core.substeps + 1)]
        return any(abs(core.desired(row, t)[1][int(params[0])]) > params[1] for t in times)
    if kind == "controller":  # one IK call per control step, at the observed state
        return bool(core.controller_observation(row)["p_target"][int(params[0])] > params[1])
    return bool(core.metrics[row, int(params[0])] > params[1])


def _register(names: list, env_id: str, kind: str, params, value: float) -> dict:
    """Register B's plug-in; the keyword arguments that select it."""
    if kind == "controller":
        register_controller("fuzz_trigger", occlusion_trigger if env_id == OCCLUSION else view_trigger, env=env_id,
                            params=params)
        names.append(("fuzz_trigger", env_id))
        return {"base_controller": "fuzz_trigger"}
    if kind == "compiled term":
        register_reward_term("fuzz_term", metric_trigger, env=env_id, params=[params[0], params[1], value > 0])
    else:
        column = {OCCLUSION: ("voi", "tip_error_m"), VIEW: ("overlap_ratio", "position_error_m")}[env_id]
        register_reward_term("fuzz_term", numpy_trigger(column[int(params[0])], params[1], value), env=env_id,
                             compiled=False)
    names.append(("fuzz_term", env_id))
    return {}


def _threshold(env_id: str, kind: str, axis: int, quantile: float, seed: int, kwargs: dict) -> float:
    """A quantile of what A's first row goes through in 60 steps of zero actions."""
    probe = gym.make(env_id, **kwargs).unwrapped
    probe.reset(seed=seed)
    core = probe.core
    zero = np.zeros(probe.action_space.shape, dtype=np.float32)
    samples = []
    for _ in range(60):
        if kind == "controller" and env_id == OCCLUSION:
            samples.append(abs(core.desired(0, core.steps[0] * core.control_dt)[1][axis]))
        elif kind == "controller":
            samples.append(core.controller_observation(0)["p_target"][axis])
        _, _, terminated, truncated, _ = probe.step(zero)
        if kind != "controller":
            samples.append(core.metrics[0, axis])
        if terminated or truncated:
            break
    return float(np.quantile(samples, quantile))


METRIC = {OCCLUSION: "voi", VIEW: "overlap_ratio"}


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture,
                                                                 HealthCheck.filter_too_much])
@given(env_id=st.sampled_from([OCCLUSION, VIEW]), kind=st.sampled_from(["controller", "compiled term", "numpy term"]),
       front_end=st.sampled_from(["single", "vector", "sb3"]), mode=st.sampled_from(["raise", "truncate"]),
       segments=st.integers(1, 4), lengths=st.lists(st.floats(0.015, 0.03), min_size=4, max_size=4),
       value=st.sampled_from([math.nan, math.inf, -math.inf]), quantile=st.floats(0.2, 0.95),
       axis=st.integers(0, 2), seed=st.integers(0, 2**16))
def test_a_plugin_that_goes_non_finite_sometimes_is_never_scored(env_id, kind, front_end, mode, segments, lengths,
                                                                 value, quantile, axis, seed):
    rows = 1 if front_end == "single" else 3
    physics = {"robot": MultiBackboneRobot(lengths=tuple(lengths[:segments]))} if env_id == OCCLUSION else {}
    common = {**physics, "task": "random", "task_split": "validation", "max_episode_steps": 60, "on_non_finite": mode}
    axis = axis if kind == "controller" else axis % 2
    with plugins() as names:
        a_kwargs = common
        if kind == "controller":  # A: the same controller, never firing
            register_controller("fuzz_twin", occlusion_trigger if env_id == OCCLUSION else view_trigger, env=env_id,
                                params=[-1.0, 0.0, 0.0, 0.0])
            names.append(("fuzz_twin", env_id))
            a_kwargs = {**common, "base_controller": "fuzz_twin"}
        env_a = _make(front_end, env_id, rows, seed, **a_kwargs)  # made before a term is registered: without it
        threshold = _threshold(env_id, kind, axis, quantile, seed, a_kwargs)
        params = [float(axis), threshold, float(seed % 10), 1.0 if value > 0 else 0.0]
        try:
            b_kwargs = {**common, **_register(names, env_id, kind, params, value)}
        except ValueError as error:  # the controller fires at the paper's home state: refused at registration
            assert "finite" in str(error)
            assume(False)
        env_b = _make(front_end, env_id, rows, seed, **b_kwargs)
        _run_lockstep(env_a, env_b, env_id, kind, front_end, mode, rows, params, seed)


def _run_lockstep(env_a, env_b, env_id, kind, front_end, mode, rows, params, seed):
    core_a, core_b = _core(env_a), _core(env_b)
    if kind != "controller":  # B adds the term as its last one
        assert core_b.reward_names[:-1] == core_a.reward_names and core_b.reward_names[-1] == "fuzz_term"
    obs_a, _ = _reset(env_a, front_end, seed)
    flagged = [kind == "controller" and _fired(core_a, env_id, r, kind, params) for r in range(rows)]
    if mode == "raise" and any(flagged):
        with pytest.raises(NonFiniteError, match="fuzz_trigger") as caught:
            _reset(env_b, front_end, seed)
        assert f"row {flagged.index(True)} at step 0" in str(caught.value)
        event("raised at reset")
        return
    obs_b, _ = _reset(env_b, front_end, seed)
    for row in range(rows):  # a row flagged at reset has a finite observation and ends at its first step
        assert np.array_equal(obs_a[row], obs_b[row]) if not flagged[row] else \
            (np.all(np.isfinite(obs_b[row])) and core_b.non_finite()[row])
    live = np.ones(rows, dtype=bool)  # rows whose episode goes on in both runs
    rng = np.random.default_rng(seed)
    for step in range(1, 61):
        actions = rng.uniform(-0.3, 0.3, (rows,) + core_a.single_action_space.shape).astype(np.float32)
        obs_a, rew_a, term_a, trunc_a, info_a = _step(env_a, front_end, actions)
        fires = [bool(live[r] and (flagged[r] or _fired(core_a, env_id, r, kind, params))) for r in range(rows)]
        if mode == "raise" and any(fires):
            with pytest.raises(NonFiniteError, match="fuzz_t") as caught:
                _step(env_b, front_end, actions)
            assert f"row {fires.index(True)} at step {step}" in str(caught.value)
            event("raised at a step")
            return
        obs_b, rew_b, term_b, trunc_b, info_b = _step(env_b, front_end, actions)
        for row in np.flatnonzero(live):
            if fires[row]:  # ends as truncated: flagged, no metric value, reward 0, a finite observation
                event("truncated at a step")
                assert info_b[row]["non_finite"] and trunc_b[row] and not term_b[row]
                assert rew_b[row] == 0.0 and np.isnan(info_b[row][METRIC[env_id]])
                assert np.all(np.isfinite(obs_b[row] if front_end != "sb3" else info_b[row]["terminal_observation"]))
            else:  # bit for bit the finite twin's step
                assert np.array_equal(obs_a[row], obs_b[row]) and rew_a[row] == rew_b[row]
                assert (term_a[row], trunc_a[row]) == (term_b[row], trunc_b[row]) and not info_b[row]["non_finite"]
                assert info_a[row][METRIC[env_id]] == info_b[row][METRIC[env_id]]
        if any(fires) or term_a.any() or trunc_a.any():
            event(f"{kind} in the {front_end} env ended")
        ended = term_a | trunc_a | np.array(fires)
        if front_end != "vector" and ended.any():
            return  # the single env needs a reset, the SB3 adapter resets the row into another episode
        live &= ~ended  # the vector env (autoreset disabled) leaves ended rows as they are


# ---------------------------------------------------------------------- the issue's reproduction
@njit(cache=True)
def nan_for_four_segments(q, gamma, p_des, R_des, v_des, dt, robot, cone, params, out):
    for k in range(out.shape[0]):
        out[k] = 0.0
    if q.shape[0] == 9:  # 4 segments: 2 n + 1 joints
        out[0] = math.nan


FOUR = MultiBackboneRobot(lengths=(0.018,) * 4)


def test_the_issues_controller_passes_registration_and_is_refused_at_run_time(registered):
    register_controller("nan4", nan_for_four_segments)  # the paper's robot at home: finite, so it registers
    registered.append(("nan4", OCCLUSION))
    env = gym.make(OCCLUSION, robot=FOUR, base_controller="nan4")
    with pytest.raises(NonFiniteError, match=r"registered controller '[\w.]+:nan4'.*row 0|row 0.*nan4"):
        env.reset(seed=0)
    venv = gym.make_vec(OCCLUSION, num_envs=4, vectorization_mode="vector_entry_point", robot=FOUR,
                        base_controller="nan4", on_non_finite="truncate")
    obs, info = venv.reset(seed=0)
    assert info["non_finite"].all() and np.isnan(info["voi"]).all() and np.isfinite(obs).all()
    obs, rewards, terminated, truncated, info = venv.step(np.zeros((4, 10), dtype=np.float32))
    assert truncated.all() and not terminated.any() and (rewards == 0).all() and np.isnan(info["voi"]).all()


def test_evaluate_refuses_to_average_an_episode_that_carries_the_flag(registered):
    from continuum_gym.evaluation import evaluate_policy

    register_controller("nan4", nan_for_four_segments)
    registered.append(("nan4", OCCLUSION))
    zero = lambda obs: np.zeros((obs.shape[0], 10))  # noqa: E731
    for mode in ("raise", "truncate"):
        with pytest.raises(NonFiniteError, match="nan4" if mode == "raise" else "non_finite"):
            evaluate_policy(zero, OCCLUSION, env_kwargs={"robot": FOUR, "base_controller": "nan4",
                                                         "on_non_finite": mode},
                            episodes=2, split="validation", progress=False)


def test_a_built_in_env_without_plugins_never_raises_the_flag():
    venv = gym.make_vec(VIEW, num_envs=64, vectorization_mode="vector_entry_point", task="mixed")
    venv.reset(seed=3)
    rng = np.random.default_rng(3)
    for _ in range(200):
        _, _, _, _, info = venv.step(rng.uniform(-1, 1, (64, 6)).astype(np.float32))
        assert not info["non_finite"].any()
