"""The native vector env and the SB3 adapter as clients use them: autoreset modes, reset options,
rendering, one info layout, and every bad input refused with the parameter's name."""

from __future__ import annotations

import pickle

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import continuum_gym  # noqa: F401  (registers the ids)
from continuum_gym.envs import ContinuumSB3VecEnv
from continuum_gym.envs.info import RewardTerms

OCCLUSION = "ContinuumGym/OcclusionAvoidance-v0"
VIEW = "ContinuumGym/ViewTracking-v0"
ACTION = {OCCLUSION: 8, VIEW: 6}


def vector(env_id, n=3, **kwargs):
    return gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point", **kwargs)


def test_step_before_reset_is_refused():
    venv = vector(VIEW)
    with pytest.raises(gym.error.ResetNeeded):
        venv.step(np.zeros((3, 6), dtype=np.float32))
    env = gym.make(VIEW).unwrapped
    with pytest.raises(gym.error.ResetNeeded):
        env.step(np.zeros(6, dtype=np.float32))


def _run(venv, steps, seed=0):
    obs, _ = venv.reset(seed=seed)
    out = [(obs.copy(), None, None, None, None)]
    for _ in range(steps):
        obs, reward, terminated, truncated, info = venv.step(np.zeros((venv.num_envs, 6), dtype=np.float32))
        out.append((obs.copy(), reward.copy(), terminated.copy(), truncated.copy(), info))
    return out


def test_same_step_autoreset_equals_next_step_shifted_by_one():
    """SAME_STEP resets inside the ending step: its observation there is NEXT_STEP's one step later, and
    final_obs is what NEXT_STEP returned at the ending step."""
    nxt = _run(vector(VIEW, task="random", max_episode_steps=4), 10)
    same_env = vector(VIEW, task="random", max_episode_steps=4, autoreset_mode=AutoresetMode.SAME_STEP)
    assert same_env.unwrapped.autoreset_mode == AutoresetMode.SAME_STEP
    assert same_env.metadata["autoreset_mode"] == AutoresetMode.SAME_STEP
    same = _run(same_env, 8)
    # NEXT_STEP: episode of 4 steps, then one reset step; SAME_STEP: episode of 4 steps, reset in the 4th
    np.testing.assert_array_equal(same[4][0], nxt[5][0])
    assert same[4][3].all() and same[4][4]["_final_obs"].all()
    for row in range(3):
        np.testing.assert_array_equal(same[4][4]["final_obs"][row], nxt[4][0][row])
    np.testing.assert_array_equal(same[4][4]["final_info"]["overlap_ratio"], nxt[4][4]["overlap_ratio"])
    np.testing.assert_array_equal(same[5][1], nxt[6][1])  # the new episode goes on in step with NEXT_STEP
    assert same[3][4].get("final_obs") is None


def test_disabled_autoreset_and_a_reset_mask():
    venv = vector(VIEW, task="random", max_episode_steps=2, autoreset_mode="disabled")
    out = _run(venv, 3)
    _, reward, terminated, truncated, _ = out[3]
    assert truncated.all() and np.all(reward == 0.0)  # ended rows are not stepped, and stay ended
    np.testing.assert_array_equal(out[3][0], out[2][0])
    before = out[3][0]
    obs, info = venv.reset(options={"reset_mask": np.array([True, False, True])})
    np.testing.assert_array_equal(obs[1], before[1])  # row 1 untouched
    assert not np.array_equal(obs[0], before[0])
    assert info["_overlap_ratio"].tolist() == [True, False, True]
    obs, reward, terminated, truncated, _ = venv.step(np.zeros((3, 6), dtype=np.float32))
    assert truncated.tolist() == [False, True, False] and reward[1] == 0.0 and reward[0] != 0.0


def test_reset_options_are_checked():
    venv = vector(OCCLUSION, task="hold")
    for options, message in (({"task_id": 1}, "unknown key"), ({"task_ids": [0, 1, 2.5]}, "task_ids"),
                             ({"task_ids": [0, 1]}, "3 task id"), ({"task_ids": [0, 1, 10**6]}, "task_ids"),
                             ({"reset_mask": [1, 0, 1]}, "reset_mask"), ("hold", "options must be a dict")):
        with pytest.raises(ValueError, match=message):
            venv.reset(options=options)
    with pytest.raises(ValueError, match="seed"):
        venv.reset(seed="abc")
    with pytest.raises(ValueError, match="seed"):
        venv.reset(seed=[1, 2])
    env = gym.make(OCCLUSION)
    with pytest.raises(ValueError, match="task_id"):
        env.reset(options={"task_id": 2.5})
    with pytest.raises(ValueError, match="unknown key"):
        env.reset(options={"task": 1})
    env.reset(options={"task_id": 2.0})  # an integral float is a whole number
    assert env.unwrapped.core.tasks.task_id[0] == 2


@pytest.mark.parametrize("kwargs, message", [
    ({"render_mode": "video"}, "render_mode"), ({"camera": "nope"}, "camera"),
    ({"pixel_occlusion": "yes"}, "pixel_occlusion"), ({"autoreset_mode": "sometimes"}, "autoreset_mode"),
])
def test_front_end_arguments_are_checked(kwargs, message):
    with pytest.raises(ValueError, match=message):
        vector(OCCLUSION, **kwargs)
    if "autoreset_mode" not in kwargs:
        with pytest.raises(ValueError, match=message):
            gym.make(OCCLUSION, **kwargs)
    with pytest.raises(ValueError, match="pixel_occlusion"):
        vector(VIEW, pixel_occlusion=True)


def test_vector_rendering_and_pixel_occlusion_match_the_single_env():
    venv = vector(OCCLUSION, n=2, render_mode="rgb_array", camera="endoscope", pixel_occlusion=True, task="hold")
    env = gym.make(OCCLUSION, render_mode="rgb_array", camera="endoscope", pixel_occlusion=True, task="hold")
    venv.reset(seed=0, options={"task_ids": [3, 4]})
    env.reset(seed=0, options={"task_id": 4})
    _, _, _, _, infos = venv.step(np.zeros((2, 8), dtype=np.float32))
    _, _, _, _, info = env.step(np.zeros(8, dtype=np.float32))
    assert infos["pixel_occlusion"].shape == (2,)
    assert infos["pixel_occlusion"][1] == pytest.approx(info["pixel_occlusion"], abs=1e-12)
    frames = venv.render()
    single = env.render()
    assert len(frames) == 2 and frames[1].shape == single.shape
    # the same state drawn by two scenes: TinyRenderer may round a few pixels differently
    assert np.abs(frames[1].astype(int) - single).max() <= 2 and np.mean(frames[1] != single) < 0.05
    assert np.abs(frames[0].astype(int) - single).max() > 2  # another row, another state
    venv.close()
    env.close()


@pytest.mark.parametrize("env_id", [OCCLUSION, VIEW])
def test_one_info_layout_numpy_only(env_id):
    """Every single-env info value has a dtype (numpy scalar or array), and the keys and row values equal
    the vector env's (minus Gymnasium's masks)."""
    env = gym.make(env_id, task="random")
    venv = vector(env_id, n=2, task="random")
    env.reset(seed=5, options={"task_id": 1})
    venv.reset(seed=5, options={"task_ids": [0, 1]})
    k = ACTION[env_id]
    action = np.linspace(-0.5, 0.5, k).astype(np.float32)
    _, _, _, _, info = env.step(action)
    _, _, _, _, infos = venv.step(np.stack([action, action]))
    for key, value in info.items():
        assert hasattr(value, "dtype"), f"info[{key!r}] is a {type(value).__name__}"
    assert set(info) == {key for key in infos if not key.startswith("_")}
    for key, value in info.items():
        np.testing.assert_array_equal(value, infos[key][1], err_msg=key)
    assert infos["reward_terms"][1].as_dict() == info["reward_terms"].as_dict()


def test_reward_terms_read_like_a_dict_and_pickle_with_their_names():
    terms = RewardTerms(np.array([[1.0, -2.0], [3.0, 0.5]]), ("voi", "tip"))
    assert list(terms) == ["voi", "tip"] and "voi" in terms and "nope" not in terms
    np.testing.assert_array_equal(terms["tip"], [-2.0, 0.5])
    row = terms[1]
    assert isinstance(row, RewardTerms) and row["voi"] == 3.0 and sum(row.values()) == 3.5
    assert dict(row.items()) == {"voi": 3.0, "tip": 0.5} and row.get("nope", 7) == 7
    with pytest.raises(KeyError, match="terms are"):
        row["nope"]
    copy = pickle.loads(pickle.dumps(terms))
    assert copy.names == terms.names and np.array_equal(copy, terms)
    with pytest.raises(ValueError, match="2 entries"):
        RewardTerms(np.zeros(3), ("a", "b"))


def test_sb3_adapter_infos_actions_and_registered_ids():
    from gymnasium.envs.registration import register

    register(id="MyLab/ViewTrackingShort-v0", entry_point="continuum_gym.envs.view_tracking:ViewTrackingEnv",
             vector_entry_point="continuum_gym.envs.view_tracking:ViewTrackingVectorEnv",
             kwargs={"task": "random", "max_episode_steps": 3})
    try:
        venv = ContinuumSB3VecEnv("MyLab/ViewTrackingShort-v0", 2, seed=0)
        assert venv.spec.id == "MyLab/ViewTrackingShort-v0"
        venv.reset()
        with pytest.raises(ValueError, match=r"shape \(2, 6\)"):
            venv.step_async(np.zeros((1, 12)))
        total = np.zeros(2)
        for _ in range(3):
            _, rewards, dones, infos = venv.step(np.zeros((2, 6), dtype=np.float32))
            total += rewards
        assert dones.all()
        single = gym.make("MyLab/ViewTrackingShort-v0")
        _, info = single.reset(seed=0)
        assert set(info) <= set(infos[0]) and infos[0]["reward_terms"].keys() == info["reward_terms"].keys()
        assert infos[0]["episode"]["l"] == 3 and infos[0]["episode"]["r"] == pytest.approx(total[0], rel=1e-6)
        assert infos[0]["TimeLimit.truncated"] and "terminal_observation" in infos[0]
        per_row = venv.env_method("info_row", indices=[1])
        assert len(per_row) == 1 and per_row[0]["task_id"] == venv.core.tasks.task_id[1]
        with pytest.raises(ValueError, match="indices"):
            venv.set_attr("residual_scale", 0.1, indices=[0])
        with pytest.raises(ValueError, match="indices"):
            venv.get_attr("num_envs", indices=[5])
    finally:
        gym.envs.registration.registry.pop("MyLab/ViewTrackingShort-v0", None)
    with pytest.raises(ValueError, match="num_envs"):
        ContinuumSB3VecEnv(VIEW, 0)
    with pytest.raises(ValueError, match="camera"):
        ContinuumSB3VecEnv(VIEW, 1, render_mode="rgb_array", camera="nope")
    images = ContinuumSB3VecEnv(VIEW, 2, render_mode="rgb_array", camera="davinci")
    images.reset()
    frames = images.get_images()
    assert len(frames) == 2 and frames[0].ndim == 3
    images.close()


def test_num_threads_is_checked_and_changes_no_result():
    import numba

    # Each env at the smallest batch its core steps on several threads (the caller's thread and a pool).
    for env_id, n, kwargs in ((OCCLUSION, 64, {"task": "random"}), (VIEW, 128, {})):
        runs = []
        for threads in (1, min(2, numba.config.NUMBA_NUM_THREADS)):
            venv = vector(env_id, n=n, num_threads=threads, **kwargs)
            assert venv.unwrapped.core.num_threads == threads
            venv.reset(seed=3)
            rng = np.random.default_rng(0)
            for _ in range(5):
                obs, *_ = venv.step(rng.uniform(-1, 1, venv.action_space.shape).astype(np.float32))
            runs.append(obs)
        assert venv.unwrapped.core.row_threads == threads
        np.testing.assert_array_equal(runs[0], runs[1])
    # torch is loaded in this test process: the default leaves the cores to the learner.
    assert vector(VIEW, n=64).unwrapped.core.num_threads == 1
    for bad in (0, numba.config.NUMBA_NUM_THREADS + 1, 1.5, "2"):
        with pytest.raises(ValueError, match="num_threads"):
            vector(VIEW, n=4, num_threads=bad)


def test_stepping_a_batch_leaves_the_process_openmp_thread_count_alone():
    """A threaded batch step must not start numba's OpenMP layer, which would set the process's OpenMP
    thread count: a torch imported afterwards would then run 2 threads although OMP_NUM_THREADS=1."""
    import os
    import subprocess
    import sys

    probe = (
        "import gymnasium as gym, numpy as np, continuum_gym\n"
        "venv = gym.make_vec('ContinuumGym/ViewTracking-v0', num_envs=128, vectorization_mode='vector_entry_point')\n"
        "venv.reset(seed=0)\n"
        "for _ in range(3):\n"
        "    venv.step(np.zeros(venv.action_space.shape, dtype=np.float32))\n"
        "import torch\n"
        "print(venv.unwrapped.core.num_threads, torch.get_num_threads())\n"
    )
    environ = dict(os.environ, OMP_NUM_THREADS="1", NUMBA_NUM_THREADS="2")
    done = subprocess.run([sys.executable, "-c", probe], env=environ, capture_output=True, text=True, check=True)
    batch_threads, torch_threads = map(int, done.stdout.split())
    assert batch_threads == 2  # the batch itself was stepped on two threads
    assert torch_threads == 1


def test_one_row_task_copies_equal_index_array_copies():
    """copy_rows' plain-index path for one row (a single env's reset) writes what an index array writes,
    also when the source is a recording whose knots must be padded to the target's capacity."""
    from continuum_gym.envs.task_sources import trajectory_rows
    from continuum_gym.envs.tasks import TaskContext, copy_rows, empty_batch, grown
    from continuum_gym.envs.trajectories import TipTrajectory
    from continuum_gym.robots.mbcr import MultiBackboneRobot

    robot = MultiBackboneRobot()
    context = TaskContext(robot, 0.005)
    rng = np.random.default_rng(3)
    t = np.linspace(0.0, 1.0, 6)
    short = TipTrajectory(t, 0.03 + 0.002 * rng.standard_normal((6, 3)), start_q=robot.psi_a)
    long = TipTrajectory(np.linspace(0.0, 2.0, 9), 0.03 + 0.002 * rng.standard_normal((9, 3)), start_q=robot.psi_a)
    sources = [trajectory_rows([short], [0], context), trajectory_rows([long], [0], context)]
    before = rng.standard_normal((4, robot.dof))  # other rows' contents, which must stay
    targets = []
    for rows in (np.array([2]), [2]):  # a one-row index array (plain indexing) and a list (numpy's fancy indexing)
        target = grown(empty_batch(4, robot.dof, 3), 9)
        target.start_q[:] = before
        for source in sources:
            copy_rows(target, rows, source)
        targets.append(target)
    assert targets[0].n_knots[2] == 9 and np.array_equal(targets[0].start_q[[0, 1, 3]], before[[0, 1, 3]])
    for name in vars(targets[0]):
        np.testing.assert_array_equal(getattr(targets[0], name), getattr(targets[1], name), err_msg=name)
