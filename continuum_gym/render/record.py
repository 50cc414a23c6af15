"""``continuum-gym render``: record one episode, external and robot-camera views side by side with VOI/OR.

For ViewTracking the da Vinci camera's image is shown beside the continuum endoscope's, so the two
views can be compared. ``.gif`` always works; ``.mp4`` uses imageio's ffmpeg plugin. What is recorded
(cameras, default task, the value under the frames) comes from the env's spec.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from continuum_gym.envs.spec import ENV_SPECS, get_spec
from continuum_gym.validation import integer


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--env", required=True, help=f"environment id: {sorted(ENV_SPECS)}")
    parser.add_argument("--policy", default="baseline",
                        help="'baseline' (zero residual), or a run directory / model .zip / shipped policy name")
    parser.add_argument("--out", required=True, help="output file, .gif or .mp4")
    parser.add_argument("--task", default=None, help="task (default: circle for occlusion, case1 for view tracking)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--steps", type=int, default=None, help="frames to record (default: the whole episode)")
    parser.add_argument("--size", type=int, default=192, help="image size in pixels (default 192)")
    parser.add_argument("--every", type=int, default=2, help="record every k-th step (default 2)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def _resolve_policy(name: str, spec):
    from continuum_gym.evaluation.evaluate import (
        POLICY_DIR,
        load_policy,
        policy_env_kwargs,
    )

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
    return model, policy_env_kwargs(spec, config)


def _strip(values, width: int, height: int, vmax: float = 1.0) -> np.ndarray:
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
    try:
        spec = get_spec(args.env)
        out = Path(args.out)
        if out.suffix not in (".gif", ".mp4"):
            raise ValueError(f"--out must end in .gif or .mp4; got {args.out!r}")
        size = integer(args.size, "--size (pixels)", low=16, high=2048)
        every = integer(args.every, "--every", low=1)
        steps = None if args.steps is None else integer(args.steps, "--steps", low=1)
        seed = integer(args.seed, "--seed", low=0, high=2**32 - 1)
        model, env_kwargs = _resolve_policy(args.policy, spec)
    except (ValueError, FileNotFoundError) as error:
        print(f"continuum-gym render: {error}", file=sys.stderr)
        return 2
    import gymnasium as gym
    import imageio.v2 as imageio
    from tqdm.auto import tqdm

    try:
        env = gym.make(args.env, task=args.task or spec.record_task, task_split="test", render_mode="rgb_array",
                       **env_kwargs)
    except ValueError as error:  # --task, or a policy's env kwargs, refused by the env
        print(f"continuum-gym render: --task / policy env kwargs: {error}", file=sys.stderr)
        return 2
    env.reset(seed=seed)
    core = env.unwrapped.core
    scene = env.unwrapped.scene()
    history, frames = [], []
    total = steps or int(core.limit[0])
    bar = tqdm(total=total, desc="render", unit="step", disable=args.no_progress)
    step = 0
    while True:
        obs = core.obs[0].astype(np.float32)
        action = np.zeros(env.action_space.shape, np.float32) if model is None else \
            model.predict(obs, deterministic=True)[0]
        _, _, terminated, truncated, info = env.step(action)
        history.append(info[spec.record_value])
        step += 1
        bar.update()
        if step % every == 0:
            images = [core.render_row(0, scene, camera, size) for camera in spec.cameras]
            strip = _strip(history, size * len(spec.cameras), max(size // 4, 24))
            frames.append(np.concatenate([np.concatenate(images, axis=1), strip], axis=0))
        if terminated or truncated or (steps and step >= steps):
            break
    bar.close()
    out.parent.mkdir(parents=True, exist_ok=True)
    fps = max(1, int(round(1.0 / (core.control_dt * every))))
    if out.suffix == ".gif":
        imageio.mimsave(out, frames, duration=1000 / fps, loop=0)
    else:
        imageio.mimsave(out, frames, fps=fps)
    env.close()
    print(f"wrote {out}: {len(frames)} frames, mean {spec.record_value} {np.mean(history):.3f}")
    return 0
