"""``continuum-gym render``: record one episode, external and robot-camera views side by side with VOI/OR.

For ViewTracking the da Vinci camera's image is shown beside the continuum endoscope's, so the two
views can be compared. ``.gif`` always works; ``.mp4`` uses imageio's ffmpeg plugin.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

OCCLUSION = "ContinuumGym/OcclusionAvoidance-v0"
VIEW = "ContinuumGym/ViewTracking-v0"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--env", required=True, help=f"{OCCLUSION} or {VIEW}")
    parser.add_argument("--policy", default="baseline",
                        help="'baseline' (zero residual), or a run directory / model .zip / shipped policy name")
    parser.add_argument("--out", required=True, help="output file, .gif or .mp4")
    parser.add_argument("--task", default=None, help="task (default: circle for occlusion, case1 for view tracking)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--steps", type=int, default=None, help="frames to record (default: the whole episode)")
    parser.add_argument("--size", type=int, default=192, help="image size in pixels (default 192)")
    parser.add_argument("--every", type=int, default=2, help="record every k-th step (default 2)")


def _resolve_policy(name):
    from continuum_gym.evaluation.evaluate import POLICY_DIR, load_policy

    if name == "baseline":
        return None, {}
    path = Path(name)
    if not path.exists():
        candidates = sorted(POLICY_DIR.rglob(f"{name}/config.yml"))
        if not candidates:
            raise FileNotFoundError(f"--policy {name!r}: no such run directory, model file or shipped policy")
        path = candidates[0].parent
    if path.suffix == ".zip":
        path = path.parent
    model, config = load_policy(path)
    env_kwargs = {k: v for k, v in config.get("env_kwargs", {}).items() if k in ("base_controller", "residual_scale")}
    return model, env_kwargs


def _strip(values, width, height, label, vmax=1.0):
    """A small line plot of ``values`` as an RGB array (no matplotlib per frame)."""
    image = np.full((height, width, 3), 255, dtype=np.uint8)
    if len(values) > 1:
        xs = np.linspace(0, width - 1, len(values)).astype(int)
        ys = (height - 1 - np.clip(np.asarray(values) / vmax, 0, 1) * (height - 1)).astype(int)
        for x0, y0, x1, y1 in zip(xs[:-1], ys[:-1], xs[1:], ys[1:]):
            n = max(abs(x1 - x0), abs(y1 - y0), 1)
            image[np.linspace(y0, y1, n + 1).astype(int), np.linspace(x0, x1, n + 1).astype(int)] = (200, 30, 30)
    image[0, :] = image[-1, :] = 120
    return image


def run(args) -> int:
    import gymnasium as gym
    import imageio.v2 as imageio

    import continuum_gym  # noqa: F401

    if args.env not in (OCCLUSION, VIEW):
        print(f"continuum-gym render: unknown env {args.env!r}; valid: {[OCCLUSION, VIEW]}", file=sys.stderr)
        return 2
    out = Path(args.out)
    if out.suffix not in (".gif", ".mp4"):
        print("continuum-gym render: --out must end in .gif or .mp4", file=sys.stderr)
        return 2
    try:
        model, env_kwargs = _resolve_policy(args.policy)
    except FileNotFoundError as error:
        print(f"continuum-gym render: {error}", file=sys.stderr)
        return 2
    occlusion = args.env == OCCLUSION
    task = args.task or ("circle" if occlusion else "case1")
    env = gym.make(args.env, task=task, task_split="test", render_mode="rgb_array", **env_kwargs)
    env.reset(seed=args.seed)
    core = env.unwrapped.core
    scene = env.unwrapped._get_scene()
    cameras = ("external", "endoscope") if occlusion else ("external", "endoscope", "davinci")
    size = args.size
    metric_name = "voi" if occlusion else "overlap_ratio"
    history, frames = [], []
    step = 0
    while True:
        obs = core.obs[0].astype(np.float32)
        action = np.zeros(env.action_space.shape, np.float32) if model is None else model.predict(obs, deterministic=True)[0]
        _, _, terminated, truncated, info = env.step(action)
        history.append(info[metric_name])
        step += 1
        if step % args.every == 0:
            images = [_render(scene, core, camera, size, occlusion) for camera in cameras]
            strip = _strip(history, size * len(cameras), max(size // 4, 24), metric_name)
            frames.append(np.concatenate([np.concatenate(images, axis=1), strip], axis=0))
        if terminated or truncated or (args.steps and step >= args.steps):
            break
    out.parent.mkdir(parents=True, exist_ok=True)
    fps = max(1, int(round(1.0 / (core.control_dt * args.every))))
    if out.suffix == ".gif":
        imageio.mimsave(out, frames, duration=1000 / fps, loop=0)
    else:
        imageio.mimsave(out, frames, fps=fps)
    env.close()
    print(f"wrote {out}: {len(frames)} frames, mean {metric_name} {np.mean(history):.3f}")
    return 0


def _render(scene, core, camera, size, occlusion):
    if occlusion:
        scene.update(core.q[0], core.gamma[0])
    else:
        scene.update(core.q[0], core.davinci_configuration(0))
    return scene.render(camera=camera, width=size, height=size)
