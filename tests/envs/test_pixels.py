"""Image observations (issue 56, ``envs/pixels.py``): spaces, checkers, content against the renderer and numpy,
the model error's true robot, every front end, determinism, bad input."""

from __future__ import annotations

import math
import re
import warnings

import gymnasium as gym
import numpy as np
import pytest

import continuum_gym  # noqa: F401  (registers the ids)
from continuum_gym.envs.pixels import OBS_MODES

OCC = "ContinuumGym/OcclusionAvoidance-v0"
VIEW = "ContinuumGym/ViewTracking-v0"
IMAGE_MODES = tuple(m for m in OBS_MODES if m != "state")
SIZE = 24  # small images keep the file fast; the layout is the same at 64


def make(env_id: str, obs_mode: str = "rgb+depth+segmentation", **kwargs):
    return gym.make(env_id, obs_mode=obs_mode, image_size=kwargs.pop("image_size", SIZE), **kwargs)


def steps(env, n: int = 3, seed: int = 0):
    obs, info = env.reset(seed=seed)
    for _ in range(n):
        obs, _, terminated, truncated, info = env.step(np.zeros(env.action_space.shape, dtype=np.float32))
        assert not (terminated or truncated)
    return obs, info


# ---------------------------------------------------------------------- spaces and checkers
@pytest.mark.parametrize("env_id", [OCC, VIEW])
@pytest.mark.parametrize("obs_mode", IMAGE_MODES)
def test_checkers_pass_for_every_mode(env_id, obs_mode):
    from gymnasium.utils.env_checker import check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = make(env_id, obs_mode, image_size=36)  # SB3's checker asks images of at least 36x36 (NatureCNN's)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # Gymnasium's checker: any complaint fails
        check_env(env.unwrapped, skip_render_check=True)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        sb3_check_env(env.unwrapped, warn=True)
    # SB3 recommends uint8 images in [0, 255]: the issue fixes depth as float32 metres and the ids as 0..n + 1
    # (PixelEncoder reads both; SB3's own CombinedExtractor flattens them). Nothing else may be said.
    for warning in caught:
        text = str(warning.message)
        key = "depth" if "depth" in text else "segmentation"
        assert key in env.observation_space.spaces and re.search(rf"observation (space )?(goal_)?{key} is an image but (its `dtype`|the "
                                             "upper and lower bounds)", text), text


@pytest.mark.parametrize("env_id, views, state_dim, max_id", [(OCC, ("",), 16, 4), (VIEW, ("", "goal_"), 12, 3)])
def test_spaces_dtypes_and_shapes(env_id, views, state_dim, max_id):
    env = make(env_id, image_size=(16, 32))
    space = env.observation_space
    expected = {"state"} | {p + m for p in views for m in ("rgb", "depth", "segmentation")}
    assert set(space.spaces) == expected
    for prefix in views:
        assert space[prefix + "rgb"].shape == (16, 32, 3) and space[prefix + "rgb"].dtype == np.uint8
        assert space[prefix + "depth"].shape == (16, 32, 1) and space[prefix + "depth"].dtype == np.float32
        assert space[prefix + "segmentation"].dtype == np.uint8 and space[prefix + "segmentation"].high.max() == max_id
    assert space["state"].shape == (state_dim,) and space["state"].dtype == np.float32
    obs, _ = steps(env)
    assert space.contains(obs)
    rgbd = make(env_id, "rgbd")
    assert set(rgbd.observation_space.spaces) == {"state"} | {p + m for p in views for m in ("rgb", "depth")}


def test_state_mode_is_the_flat_box_unchanged():
    default, state = gym.make(OCC), gym.make(OCC, obs_mode="state")
    assert state.observation_space == default.observation_space
    assert isinstance(state.observation_space, gym.spaces.Box) and state.observation_space.shape == (32,)
    a, info_a = steps(default)
    b, info_b = steps(state)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(b, state.unwrapped.core.obs[0].astype(np.float32))
    assert "image_occlusion" not in info_b
    assert state.unwrapped.core.pixels is None  # nothing renders


def test_the_env_spec_names_the_pixel_spec_and_an_env_without_one_refuses_images(monkeypatch):
    from continuum_gym.envs.pixels import PIXEL_SPECS, pixel_spec
    from continuum_gym.envs.spec import get_spec

    for env_id in (OCC, VIEW):
        assert pixel_spec(env_id).env_id == env_id and PIXEL_SPECS[env_id] is pixel_spec(get_spec(env_id).env_id)
        assert get_spec(env_id).pixels.endswith(".pixels:PIXELS")
    monkeypatch.delitem(PIXEL_SPECS, OCC)
    with pytest.raises(ValueError, match="has no image observations"):
        gym.make(OCC, obs_mode="rgb")


@pytest.mark.parametrize("value, message", [
    ("rgbd+", "obs_mode must be one of"), ("RGB", "obs_mode must be one of"), (None, "obs_mode must be one of")])
def test_bad_obs_mode_names_the_parameter(value, message):
    with pytest.raises(ValueError, match=message):
        gym.make(OCC, obs_mode=value)


@pytest.mark.parametrize("value", [8, 513, 64.5, "64", (64,), (64, 64, 3), True])
def test_bad_image_size_names_the_parameter_and_range(value):
    with pytest.raises(ValueError, match=r"image_size must be .*\[16, 512\]"):
        gym.make(OCC, obs_mode="rgb", image_size=value)


# ---------------------------------------------------------------------- content
def test_occlusion_images_equal_the_renderers_output_for_the_same_state():
    import continuum_gym.camera as cam

    env = make(OCC, image_size=(32, 40))
    obs, _ = steps(env, 5)
    core = env.unwrapped.core
    scene = cam.occlusion_scene(core.config.robot, core.config.cone, core.q, core.gamma, width=40, height=32)
    frames = cam.Renderer().render(scene, "endoscope")
    np.testing.assert_array_equal(obs["rgb"], frames.rgb[0])
    np.testing.assert_array_equal(obs["depth"], frames.depth[0])
    np.testing.assert_array_equal(obs["segmentation"], frames.segmentation[0])


def test_view_tracking_images_are_both_views_of_the_renderer():
    import continuum_gym.camera as cam

    env = make(VIEW)
    obs, _ = steps(env, 4)
    core = env.unwrapped.core
    scene = cam.view_tracking_scene(core.config.robot, core.config.davinci, core.frustum, core.q,
                                    core.davinci_configuration(0)[None], width=SIZE)
    renderer = cam.Renderer()
    for view, prefix in (("endoscope", ""), ("davinci", "goal_")):
        frames = renderer.render(scene, view)
        for modality in ("rgb", "depth", "segmentation"):
            np.testing.assert_array_equal(obs[prefix + modality], getattr(frames, modality)[0])
    assert not np.array_equal(obs["rgb"], obs["goal_rgb"])  # the task: make the first look like the second


def test_segmentation_ids_are_the_robots_segments_and_never_the_shaft_in_its_own_view():
    env = make(OCC, image_size=64)
    obs, _ = steps(env, 2)
    ids = set(np.unique(obs["segmentation"]).tolist())
    n = env.unwrapped.core.config.robot.n_segments
    assert ids <= set(range(n + 1)) and 0 in ids and ids & set(range(1, n + 1))  # the robot is in view
    robot = obs["segmentation"][..., 0] > 0
    assert np.all(obs["depth"][..., 0][robot] < 0.065)  # robot pixels are nearer than the tissue
    tissue = obs["segmentation"][..., 0] == 0
    inside = obs["depth"][..., 0] > 0
    assert np.all(np.abs(obs["depth"][..., 0][tissue & inside] - 0.065) < 1e-4)  # the tissue is flat, 65 mm away


def test_occlusion_metric_equals_a_numpy_count_over_the_circular_field_of_view():
    env = make(OCC, image_size=48)
    obs, info = steps(env, 3)
    core = env.unwrapped.core
    cameras = env.unwrapped.core.pixels.renderer.render(
        env.unwrapped.core.pixels.spec.scene(core, np.arange(1), 48, 48), "endoscope", ("segmentation",)).cameras
    inside = cameras.fov_mask(core.config.cone.beta)[0]
    seg = obs["segmentation"][..., 0]
    expected = np.count_nonzero((seg >= 1) & (seg <= core.config.robot.n_segments) & inside) / np.count_nonzero(inside)
    assert info["image_occlusion"] == pytest.approx(expected, abs=1e-12)
    assert 0.0 < info["image_occlusion"] < 0.5


def test_view_centre_error_equals_the_projection_of_the_davinci_target():
    from continuum_gym.robots import DaVinciEndoscope

    env = make(VIEW, image_size=64)
    _, info = steps(env, 6)
    core = env.unwrapped.core
    p_cam, R_cam = core.robot.forward_kinematics(core.q[0])  # the camera frame (x right, y down, z forward)
    target = DaVinciEndoscope().target_point(core.davinci_configuration(0))
    x, y, z = R_cam.T @ (target - p_cam)
    f = 32.0 / math.tan(core.frustum.full_angle / 2.0)  # fy = H / (2 tan(fov / 2)), square pixels
    expected = 100.0 * f * math.hypot(x / z, y / z) / 64.0
    assert info["view_centre_error_pct"] == pytest.approx(expected, rel=1e-9)
    u, v = f * x / z + 32.0, f * y / z + 31.0
    assert bool(info["view_centre_in_image"]) == (-0.5 <= u <= 63.5 and -0.5 <= v <= 63.5)


def test_the_state_entry_holds_the_sensed_joints_not_the_truth_under_model_error():
    from continuum_gym.envs.model_error import ModelError

    env = make(OCC, "rgb", model_error=ModelError(joint_noise_rad=0.01))
    obs, _ = steps(env, 3)
    core = env.unwrapped.core
    dof = core.robot.dof
    np.testing.assert_array_equal(obs["state"][:dof], core.sensed_joints()[0].astype(np.float32))
    assert not np.allclose(obs["state"][:dof], core.q[0], atol=1e-4)  # noise: not the true joints
    assert obs["state"][dof] == np.float32(core.gamma[0])
    np.testing.assert_array_equal(obs["state"][dof + 1:], core.base_cmd[0].astype(np.float32))


def test_the_image_shows_the_true_robot_under_a_length_error():
    import dataclasses

    import continuum_gym.camera as cam
    from continuum_gym.envs.model_error import ModelError

    env = make(OCC, "segmentation", image_size=64, model_error=ModelError(length_scale=1.3))
    obs, _ = env.reset(seed=0)  # a 30 % longer robot loses the tip within a step or two: the first image
    core = env.unwrapped.core
    robot = core.config.robot
    true_robot = dataclasses.replace(robot, lengths=tuple(1.3 * np.asarray(robot.lengths)))
    renderer = cam.Renderer()
    truth = renderer.render(cam.occlusion_scene(true_robot, core.config.cone, core.q, core.gamma, width=64),
                            "endoscope", ("segmentation",)).segmentation[0]
    nominal = renderer.render(cam.occlusion_scene(robot, core.config.cone, core.q, core.gamma, width=64),
                              "endoscope", ("segmentation",)).segmentation[0]
    np.testing.assert_array_equal(obs["segmentation"], truth)
    assert not np.array_equal(truth, nominal)


def test_view_tracking_camera_mounting_error_turns_the_image():
    from continuum_gym.envs.model_error import ModelError

    turned = make(VIEW, "rgb", model_error=ModelError(camera_rotation_rad=(0.0, 0.0, 0.15)))
    exact = make(VIEW, "rgb", model_error=ModelError(camera_rotation_rad=(0.0, 0.0, 0.0)))
    a, _ = turned.reset(seed=3)
    b, _ = exact.reset(seed=3)
    np.testing.assert_array_equal(a["goal_rgb"], b["goal_rgb"])  # the view asked for does not depend on it
    assert not np.array_equal(a["rgb"], b["rgb"])


# ---------------------------------------------------------------------- front ends
def test_seeded_envs_give_identical_images():
    a, b = make(VIEW, "rgbd"), make(VIEW, "rgbd")
    obs_a, _ = a.reset(seed=7)
    obs_b, _ = b.reset(seed=7)
    for key in obs_a:
        np.testing.assert_array_equal(obs_a[key], obs_b[key])
    action = np.full(a.action_space.shape, 0.3, dtype=np.float32)
    for _ in range(3):
        obs_a, *_, info_a = a.step(action)
        obs_b, *_, info_b = b.step(action)
    for key in obs_a:
        np.testing.assert_array_equal(obs_a[key], obs_b[key])
    assert info_a["view_centre_error_pct"] == info_b["view_centre_error_pct"]


def test_vector_env_rows_equal_single_envs_and_partial_resets_render_their_rows():
    vec = gym.make_vec(OCC, num_envs=3, vectorization_mode="vector_entry_point", obs_mode="rgbd", image_size=SIZE)
    obs, info = vec.reset(seed=11)
    assert obs["rgb"].shape == (3, SIZE, SIZE, 3) and info["image_occlusion"].shape == (3,)
    actions = np.zeros((3, 8), dtype=np.float32)
    for _ in range(2):
        obs, *_ = vec.step(actions)
    for row in range(3):
        single = make(OCC, "rgbd")
        expected, _ = steps(single, 2, seed=11 + row)
        for key in expected:
            np.testing.assert_array_equal(obs[key][row], expected[key])
    mask = np.array([False, True, False])
    reset_obs, _ = vec.reset(options={"reset_mask": mask})
    np.testing.assert_array_equal(reset_obs["rgb"][0], obs["rgb"][0])  # rows not reset keep their images
    pixels = vec.unwrapped.core.pixels
    whole = pixels.renderer.render(pixels.spec.scene(vec.unwrapped.core, np.arange(3), SIZE, SIZE), "endoscope",
                                   ("rgb",)).rgb
    np.testing.assert_array_equal(reset_obs["rgb"], whole)


def test_the_core_renders_each_row_a_step_or_reset_changed_once(monkeypatch):
    vec = gym.make_vec(OCC, num_envs=3, vectorization_mode="vector_entry_point", obs_mode="rgb", image_size=SIZE,
                       autoreset_mode="disabled")
    pixels = vec.unwrapped.core.pixels
    rendered = []
    update = pixels.update

    def counted(rows=None):
        rendered.append(None if rows is None else np.asarray(rows).tolist())
        update(rows)

    monkeypatch.setattr(pixels, "update", counted)
    vec.reset(seed=0)
    vec.step(np.zeros((3, 8), dtype=np.float32))
    assert rendered == [None, None]  # every row once per reset and per step: the observation and info share it
    vec.reset(options={"reset_mask": np.array([False, True, False])})
    assert rendered[2:] == [[1]]  # a partial reset renders its rows only


def test_vector_env_same_step_autoreset_keeps_the_final_images():
    vec = gym.make_vec(OCC, num_envs=2, vectorization_mode="vector_entry_point", obs_mode="rgb",
                       image_size=SIZE, max_episode_steps=2, autoreset_mode="same_step")
    vec.reset(seed=0)
    vec.step(np.zeros((2, 8), dtype=np.float32))
    obs, _, _, truncated, info = vec.step(np.zeros((2, 8), dtype=np.float32))
    assert truncated.all() and set(info["final_obs"][0]) == {"rgb", "state"}
    assert not np.array_equal(info["final_obs"][0]["rgb"], obs["rgb"][0])  # the last frame, then the new start
    pixels = vec.unwrapped.core.pixels
    whole = pixels.renderer.render(pixels.spec.scene(vec.unwrapped.core, np.arange(2), SIZE, SIZE), "endoscope",
                                   ("rgb",)).rgb
    np.testing.assert_array_equal(obs["rgb"], whole)  # the new episodes' first images
    # info is the new episodes' (their first images' pixel metric), final_info the last step's, as for every entry
    from continuum_gym.envs.pixels import PixelObserver

    np.testing.assert_array_equal(info["image_occlusion"], PixelObserver(vec.unwrapped.core).info()["image_occlusion"])
    assert not np.array_equal(info["final_info"]["image_occlusion"], info["image_occlusion"])


def test_sb3_adapter_gives_dict_batches_and_terminal_images():
    from continuum_gym.envs.sb3 import ContinuumSB3VecEnv

    venv = ContinuumSB3VecEnv(VIEW, 2, seed=0, obs_mode="rgbd", image_size=SIZE, max_episode_steps=2)
    obs = venv.reset()
    assert obs["goal_depth"].shape == (2, SIZE, SIZE, 1) and obs["state"].dtype == np.float32
    venv.step(np.zeros((2, 6), dtype=np.float32))
    obs, _, dones, infos = venv.step(np.zeros((2, 6), dtype=np.float32))
    assert dones.all()
    terminal = infos[0]["terminal_observation"]
    assert set(terminal) == set(obs) and not np.array_equal(terminal["rgb"], obs["rgb"][0])
    assert "view_centre_error_pct" in infos[1]


def test_sb3_multi_input_policy_and_the_pixel_encoder_learn_a_few_steps():
    from stable_baselines3 import PPO

    from continuum_gym.agents.pixel_encoder import PixelEncoder
    from continuum_gym.agents.residual import zero_init_residual
    from continuum_gym.envs.sb3 import ContinuumSB3VecEnv

    venv = ContinuumSB3VecEnv(VIEW, 2, seed=0, obs_mode="rgbd", image_size=32)
    kwargs = dict(features_extractor_class=PixelEncoder, features_extractor_kwargs=dict(cnn="small", augment=True))
    model = PPO("MultiInputPolicy", venv, n_steps=8, batch_size=8, n_epochs=1, policy_kwargs=kwargs, device="cpu")
    zero_init_residual(model)
    obs = venv.reset()
    action, _ = model.predict(obs, deterministic=True)
    np.testing.assert_array_equal(action, 0.0)  # a zero residual is the base controller
    model.learn(16)
    default = PPO("MultiInputPolicy", ContinuumSB3VecEnv(OCC, 2, seed=0, obs_mode="rgb", image_size=48), n_steps=8,
                  batch_size=8, n_epochs=1, device="cpu")  # SB3's own CombinedExtractor (NatureCNN on rgb)
    default.learn(16)


def test_cnn_policy_takes_one_image_through_gymnasiums_transform_observation():
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env

    def rgb_only():  # CnnPolicy wants one Box image: the rgb entry of obs_mode="rgb" (docs/tutorials/pixels.md)
        env = make(OCC, "rgb", image_size=36)
        return gym.wrappers.TransformObservation(env, lambda obs: obs["rgb"], env.observation_space["rgb"])

    model = PPO("CnnPolicy", make_vec_env(rgb_only, n_envs=1), n_steps=8, batch_size=8, n_epochs=1, device="cpu")
    assert model.observation_space.shape == (3, 36, 36)  # SB3 transposed it (VecTransposeImage)
    model.learn(8)


def test_pixel_encoder_stacks_every_image_and_keeps_the_state():
    import torch

    from continuum_gym.agents.pixel_encoder import PixelEncoder, random_shift

    space = make(VIEW, "rgb+depth+segmentation", image_size=36).observation_space
    encoder = PixelEncoder(space, cnn="nature", features_dim=16)
    batch = {k: torch.as_tensor(np.stack([v.sample(), v.sample()])).float() for k, v in space.spaces.items()}
    assert encoder.images(batch).shape == (2, 10, 36, 36)  # 2 x (3 + 1 + 1) channels
    with pytest.raises(ValueError, match="needs larger images than 24x24"):
        PixelEncoder(make(VIEW, "rgbd", image_size=24).observation_space, cnn="nature")
    out = encoder(batch)
    assert out.shape == (2, 16 + 12)
    torch.testing.assert_close(out[:, 16:], batch["state"])
    x = torch.arange(8 * 1 * 6 * 6, dtype=torch.float32).reshape(8, 1, 6, 6)
    shifted = random_shift(x, 2)
    padded = torch.nn.functional.pad(x, (2, 2, 2, 2), mode="replicate")
    for b in range(8):  # each sample is a crop of its own padded image at some offset
        assert any(torch.equal(shifted[b], padded[b, :, dy:dy + 6, dx:dx + 6]) for dy in range(5) for dx in range(5))
    torch.testing.assert_close(random_shift(x, 0), x)


def test_goal_env_puts_images_beside_the_goals_and_her_can_store_them():
    from gymnasium.utils.env_checker import check_env
    from stable_baselines3 import SAC, HerReplayBuffer

    env = gym.make("ContinuumGym/OcclusionAvoidanceGoal-v0", obs_mode="rgbd", image_size=36,  # NatureCNN's least
                   max_episode_steps=4)
    space = env.observation_space
    assert set(space.spaces) == {"observation", "rgb", "depth", "achieved_goal", "desired_goal"}
    assert space["observation"].shape == (16,)
    check_env(env.unwrapped, skip_render_check=True)
    model = SAC("MultiInputPolicy", env, replay_buffer_class=HerReplayBuffer, learning_starts=8, buffer_size=64,
                batch_size=4, policy_kwargs=dict(net_arch=[8]), device="cpu")
    model.learn(12)
    sample = model.replay_buffer.sample(4)
    assert sample.observations["rgb"].shape == (4, 3, 36, 36)  # SB3 stores images channels-first


def test_rollout_and_evaluation_see_images_and_measure_the_pixel_metric():
    from continuum_gym.evaluation.methods import method_name, policy_env_kwargs
    from continuum_gym.evaluation.rollout import ZeroResidual, make_core, run_episodes
    from continuum_gym.evaluation.tables import aggregate, table_metrics

    state = make_core(OCC, 2, task="hold", task_split="validation")
    images = make_core(OCC, 2, task="hold", task_split="validation", obs_mode="rgbd", image_size=SIZE)
    seen = []

    def policy(observation):
        seen.append(type(observation))
        return np.zeros((2, 8))

    a = run_episodes(state, ZeroResidual(8), np.arange(2), pixel_metrics=True)
    b = run_episodes(images, policy, np.arange(2))
    assert seen and all(t is dict for t in seen)
    np.testing.assert_array_equal(a["mean_voi"], b["mean_voi"])  # a zero residual is the base in either mode
    assert np.all((a["mean_image_occlusion"] > 0) & (a["mean_image_occlusion"] < 0.5))
    assert "mean_image_occlusion" not in run_episodes(state, ZeroResidual(8), np.arange(2))
    results = {"base": {"hold": {"scores": {k: [v] for k, v in a.items()}, "traces": [], "grid": False}}}
    spec = continuum_gym.envs.get_spec(OCC)
    assert [m.name for m in table_metrics(spec, results)][:2] == ["mean_voi", "mean_image_occlusion"]
    assert "mean_image_occlusion" in aggregate(OCC, results)["base"]
    config = {"env_config": {"obs_mode": "rgbd", "image_size": 64, "base_controller": "projected_gradient"}}
    assert policy_env_kwargs(spec, config)["obs_mode"] == "rgbd"
    assert method_name("projected_gradient", "ppo", obs_mode="rgbd") == "residual_projected_gradient_rgbd"
    assert method_name("projected_gradient", "ppo", obs_mode="rgb+depth+segmentation") == \
        "residual_projected_gradient_rgb_depth_segmentation"
    assert method_name("projected_gradient", "ppo", obs_mode="state") == "residual_projected_gradient"
    # what it sees, then what acts after it
    assert method_name("dimension_reduced", "sac", ["overlap_polish"], "rgbd") == \
        "residual_dimension_reduced_sac_rgbd+overlap_polish"


def test_config_round_trip_rebuilds_the_image_env(tmp_path):
    from continuum_gym import make_from_config, save_config

    env = make(VIEW, "depth", image_size=(16, 24))
    path = save_config(env, tmp_path / "env.yml")
    again = make_from_config(path)
    assert again.observation_space == env.observation_space
    assert again.unwrapped.config.image_size == (16, 24) and again.unwrapped.config.obs_mode == "depth"


def test_a_dataset_of_images_records_and_recovers_its_env(tmp_path):
    from continuum_gym.evaluation.datasets import create_dataset, dataset_id

    dataset = create_dataset(OCC, "projected_gradient", split="validation", episodes=1, root=tmp_path,
                             env_kwargs={"obs_mode": "rgb", "image_size": 16, "task": "hold", "max_episode_steps": 3})
    assert dataset.spec.dataset_id == dataset_id(OCC, "projected_gradient", "validation", obs_mode="rgb")
    episode = next(dataset.iterate_episodes())
    assert episode.observations["rgb"].shape == (4, 16, 16, 3) and episode.observations["rgb"].dtype == np.uint8
    env = dataset.recover_environment()
    assert env.observation_space["rgb"].shape == (16, 16, 3)


@pytest.mark.parametrize("env_id", [OCC, VIEW])
def test_the_packaged_pixel_configuration_loads_by_name_and_checks(env_id):
    from continuum_gym.agents.train import resolve_hyperparams

    block = resolve_hyperparams("ppo", env_id, "ppo_pixels.yml")  # a packaged file by its bare name
    assert block["policy"] == "MultiInputPolicy" and block["env_kwargs"]["obs_mode"] == "rgbd"
    assert block["policy_kwargs"]["features_extractor_class"] == "continuum_gym.agents.pixel_encoder:PixelEncoder"
    with pytest.raises(ValueError, match="no file"):
        resolve_hyperparams("ppo", env_id, "no_such_pixels.yml")


def test_the_trainer_keeps_large_blocks_in_its_heap_in_a_child_process():
    import subprocess
    import sys

    code = ("from continuum_gym.agents.allocator import keep_large_blocks; import numpy as np; "
            "assert keep_large_blocks(); a = np.ones(50_000_000 // 8); del a; print('ok')")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0 and result.stdout.strip() == "ok", result.stderr


def test_render_of_an_endoscope_camera_by_the_fast_renderer():
    import continuum_gym.camera as cam

    env = gym.make(VIEW, render_mode="rgb_array", camera="davinci", renderer="fast")
    env.reset(seed=2)
    image = env.render()
    core = env.unwrapped.core
    scene = cam.view_tracking_scene(core.config.robot, core.config.davinci, core.frustum, core.q,
                                    core.davinci_configuration(0)[None], width=128)
    np.testing.assert_array_equal(image, cam.Renderer().render(scene, "davinci", ("rgb",)).rgb[0])
    vec = gym.make_vec(OCC, num_envs=2, vectorization_mode="vector_entry_point", render_mode="rgb_array",
                       camera="endoscope", renderer="fast")
    vec.reset(seed=0)
    images = vec.render()
    assert len(images) == 2 and images[0].shape == (128, 128, 3) and images[0].dtype == np.uint8
    assert not np.array_equal(images[0], images[1])  # two rows, two states
    with pytest.raises(ValueError, match="renderer='fast' draws the endoscope cameras"):
        gym.make(OCC, render_mode="rgb_array", camera="external", renderer="fast")
    with pytest.raises(ValueError, match="renderer must be one of"):
        gym.make(OCC, render_mode="rgb_array", camera="endoscope", renderer="opengl")


def test_rows_of_different_true_robots_are_each_drawn_as_their_own():
    import dataclasses

    import continuum_gym.camera as cam
    from continuum_gym.geometry.lens_cone import LensCone

    vec = gym.make_vec(OCC, num_envs=3, vectorization_mode="vector_entry_point", obs_mode="segmentation",
                       image_size=48, model_error="severe")  # a fixed error per task id: three true robots
    obs, _ = vec.reset(seed=5)
    core = vec.unwrapped.core
    arrays = core._mismatch.arrays
    assert len({tuple(arrays.scale[row]) for row in range(3)}) == 3
    robot, cone = core.config.robot, core.config.cone
    for row in range(3):
        true_robot = dataclasses.replace(robot, lengths=tuple(np.asarray(robot.lengths) * arrays.scale[row]))
        true_cone = LensCone(cone.d_o + arrays.calib[row, 0], cone.alpha + arrays.calib[row, 1], cone.beta,
                             cone.lens_model)
        scene = cam.occlusion_scene(true_robot, true_cone, core.q[row:row + 1], core.gamma[row:row + 1], width=48)
        expected = cam.Renderer().render(scene, "endoscope", ("segmentation",)).segmentation[0]
        np.testing.assert_array_equal(obs["segmentation"][row], expected)


def test_an_image_env_pickles_and_steps_again():
    import pickle

    env = make(OCC, "rgbd")
    obs, _ = steps(env, 1)
    again = pickle.loads(pickle.dumps(env.unwrapped))
    a, *_ = env.unwrapped.step(np.zeros(8, dtype=np.float32))
    b, *_ = again.step(np.zeros(8, dtype=np.float32))
    for key in a:
        np.testing.assert_array_equal(a[key], b[key])


def test_a_table_of_image_and_state_policies_shows_the_pixel_metric_where_it_was_measured():
    """An image policy measures the pixel metric, a state one does not (without --pixel-metrics): one table."""
    from continuum_gym.evaluation.tables import aggregate, markdown

    def task(**scores):
        return {"hold": {"scores": {k: [np.asarray(v, dtype=float)] for k, v in scores.items()}, "traces": [],
                         "grid": False}}

    results = {"state": task(mean_voi=[0.2, 0.3], mean_tip_error_m=[1e-4, 2e-4], tip_in_view_fraction=[1, 1],
                             mean_orientation_error_rad=[0.0, 0.0], visibility_guarded_fraction=[0, 0]),
               "images": task(mean_voi=[0.1, 0.2], mean_tip_error_m=[1e-4, 2e-4], tip_in_view_fraction=[1, 1],
                              mean_orientation_error_rad=[0.0, 0.0], visibility_guarded_fraction=[0, 0],
                              mean_image_occlusion=[0.05, 0.07])}
    table = aggregate(OCC, results)
    assert "mean_image_occlusion" not in table["state"]
    assert table["images"]["mean_image_occlusion"]["mean"] == pytest.approx(0.06)
    text = markdown(OCC, table, results)
    assert "| state | 0.250" in text and "| images | 0.150" in text
