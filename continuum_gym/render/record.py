"""``continuum-gym render``: record one episode, external and robot-camera views side by side with VOI/OR.

For ViewTracking the da Vinci camera's image is shown beside the continuum endoscope's, so the two
views can be compared. ``.gif`` always works; ``.mp4`` uses imageio's ffmpeg plugin; ``.png`` is one
still of the last step (after ``--steps`` steps or at the episode's end), with the whole history in the
plot under it. What is recorded (cameras, default task, the value under the frames) comes from the
env's spec. ``--azimuth``, ``--elevation``, ``--distance`` and ``--target`` move the external camera
(default: the scene's); ``--supersample K`` renders every view at K times the size and averages K x K
pixel blocks (smooth wires, same frame size); ``--gap`` puts white columns between the views and
``--no-plot`` leaves out the plot.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np

from continuum_gym.envs.benchmark import benchmark_of
from continuum_gym.envs.spec import ENV_SPECS, get_spec, registered_kwargs
from continuum_gym.validation import as_finite, integer, number

OUTPUTS = (".gif", ".mp4", ".png")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--env", required=True, help=f"environment id: {sorted(ENV_SPECS)}")
    parser.add_argument("--policy", default="baseline",
                        help="'baseline' (zero residual), or a run directory / model .zip / shipped policy name")
    parser.add_argument("--out", required=True,
                        help="output file: .gif or .mp4 (the episode), or .png (a still of the last step)")
    parser.add_argument("--task", default=None, help="task (default: a registered id's own, else circle for occlusion, "
                                                            "case1 for view tracking)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--steps", type=int, default=None, help="steps to run (default: the whole episode)")
    parser.add_argument("--size", type=int, default=192, help="image size in pixels (default 192)")
    parser.add_argument("--every", type=int, default=2, help="record every k-th step (default 2)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--no-plot", action="store_true", help="frames without the VOI/OR plot under them")
    parser.add_argument("--gap", type=int, default=0, metavar="PIXELS",
                        help="white columns between the views (default 0: the views touch)")
    parser.add_argument("--supersample", type=int, default=1, metavar="K",
                        help="render at K times the size and average K x K blocks: anti-aliased (default 1, off)")
    camera = parser.add_argument_group("external camera (default: the environment's framing)")
    camera.add_argument("--azimuth", type=float, default=None, metavar="DEG", help="degrees about z from +x")
    camera.add_argument("--elevation", type=float, default=None, metavar="DEG",
                        help="degrees above the target, in (-90, 90)")
    camera.add_argument("--distance", type=float, default=None, metavar="M", help="metres from the target, in (0, 1.5]")
    camera.add_argument("--target", type=float, nargs=3, default=None, metavar=("X", "Y", "Z"),
                        help="point looked at, metres in the world frame")


def _resolve_policy(name: str, spec):
    from continuum_gym.evaluation.methods import POLICY_DIR, load_policy, policy_env_kwargs

    if name == "baseline":
        return None, {}, ()
    path = Path(name)
    if not path.exists():
        candidates = sorted(POLICY_DIR.rglob(f"{name}/config.yml"))
        if not candidates:
            raise FileNotFoundError(f"--policy {name!r}: no such run directory, model file or shipped policy")
        path = candidates[0].parent
    if path.suffix == ".zip":
        path = path.parent
    model, config = load_policy(path)
    return model, policy_env_kwargs(spec, config), tuple(config.get("helpers") or ())


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


def _external_camera(args) -> dict:
    """The external-camera flags given, validated (each error names its flag)."""
    camera: dict[str, Any] = {}
    if args.azimuth is not None:
        camera["azimuth"] = number(args.azimuth, "--azimuth", unit="deg")
    if args.elevation is not None:
        camera["elevation"] = number(args.elevation, "--elevation", low=-90.0, high=90.0, low_open=True,
                                     high_open=True, unit="deg")
    if args.distance is not None:
        camera["distance"] = number(args.distance, "--distance", low=0.0, high=1.5, low_open=True, unit="m")
    if args.target is not None:
        camera["target"] = tuple(float(x) for x in as_finite(args.target, (3,), "--target X Y Z (m)"))
    return camera


def _view(core, scene, camera: str, size: int, supersample: int) -> np.ndarray:
    """One camera's image of row 0, size x size; rendered at ``supersample`` times the size and block-averaged."""
    if supersample == 1:
        return core.render_row(0, scene, camera, size)
    image = core.render_row(0, scene, camera, size * supersample).astype(np.float32)
    image = image.reshape(size, supersample, size, supersample, 3).mean(axis=(1, 3))
    return np.clip(np.rint(image), 0, 255).astype(np.uint8)


def _write_gif(path: Path, frames, duration_ms: float) -> None:
    """An animated GIF with one palette for all frames (octree over a sample of them, no dithering).

    With one palette a pixel that does not change keeps its index, so Pillow's ``optimize`` stores each
    frame as its difference from the previous one (unchanged pixels transparent): a static external view
    costs nearly nothing and the file is several times smaller than with a palette per frame.
    """
    from PIL import Image

    pixels = frames[0].shape[0] * frames[0].shape[1]
    count = int(np.clip(4_000_000 // pixels, 1, 16))
    sample = np.concatenate([frames[i] for i in np.linspace(0, len(frames) - 1, count).astype(int)], axis=0)
    # 255 colours: Pillow needs a free palette index for the transparent, unchanged pixels
    palette = Image.fromarray(sample).quantize(colors=255, method=Image.Quantize.FASTOCTREE)
    images = [Image.fromarray(frame).quantize(palette=palette, dither=Image.Dither.NONE) for frame in frames]
    images[0].save(path, save_all=True, append_images=images[1:], duration=duration_ms, loop=0, optimize=True)


def run(args: argparse.Namespace) -> int:
    try:
        spec = get_spec(args.env)
        out = Path(args.out)
        if out.suffix not in OUTPUTS:
            raise ValueError(f"--out must end in one of {list(OUTPUTS)}; got {args.out!r}")
        size = integer(args.size, "--size (pixels)", low=16, high=2048)
        every = integer(args.every, "--every", low=1)
        steps = None if args.steps is None else integer(args.steps, "--steps", low=1)
        seed = integer(args.seed, "--seed", low=0, high=2**32 - 1)
        supersample = integer(args.supersample, "--supersample", low=1, high=4)
        gap = integer(args.gap, "--gap (pixels)", low=0, high=256)
        if size * supersample > 4096:
            raise ValueError(f"--size x --supersample must be <= 4096 pixels; got {size} x {supersample}")
        external_camera = _external_camera(args)
        model, env_kwargs, helpers = _resolve_policy(args.policy, spec)
    except (ValueError, FileNotFoundError) as error:
        print(f"continuum-gym render: {error}", file=sys.stderr)
        return 2
    import gymnasium as gym
    import imageio.v2 as imageio
    from tqdm.auto import tqdm

    try:
        task = args.task or registered_kwargs(args.env).get("task") or benchmark_of(spec).record_task  # a registered id's own
        env = gym.make(args.env, task=task, task_split="test", render_mode="rgb_array", **env_kwargs)
        if helpers:  # the run's helpers act after it, as in its evaluation (envs/helpers.py)
            from continuum_gym.envs.helpers import HelperWrapper

            env = HelperWrapper(env, helpers)
    except ValueError as error:  # --task, or a policy's env kwargs, refused by the env
        print(f"continuum-gym render: --task / policy env kwargs: {error}", file=sys.stderr)
        return 2
    env.reset(seed=seed)
    core = env.unwrapped.core  # type: ignore[attr-defined]  # a continuum-gym env (envs.single): its core
    scene = env.unwrapped.scene()  # type: ignore[attr-defined]
    if external_camera:
        scene.set_external_camera(**external_camera)
    still = out.suffix == ".png"
    history, frames = [], []
    total = steps or int(core.limit[0])
    bar = tqdm(total=total, desc="render", unit="step", disable=args.no_progress)
    step = 0
    while True:
        obs = core.obs[0].astype(np.float32)
        action = (np.zeros(env.action_space.shape, np.float32)  # type: ignore[type-var]  # a Box: shape is set
                  if model is None else model.predict(obs, deterministic=True)[0])
        _, _, terminated, truncated, info = env.step(action)
        history.append(info[benchmark_of(spec).record_value])
        step += 1
        bar.update()
        done = terminated or truncated or bool(steps and step >= steps)
        if (done if still else step % every == 0):
            images = [_view(core, scene, camera, size, supersample) for camera in spec.cameras]
            if gap:
                spacer = np.full((size, gap, 3), 255, dtype=np.uint8)
                images = [part for image in images for part in (spacer, image)][1:]
            frame = np.concatenate(images, axis=1)
            if not args.no_plot:
                frame = np.concatenate([frame, _strip(history, frame.shape[1], max(size // 4, 24))], axis=0)
            frames.append(frame)
        if done:
            break
    bar.close()
    out.parent.mkdir(parents=True, exist_ok=True)
    fps = max(1, int(round(1.0 / (core.control_dt * every))))
    if still:
        imageio.imwrite(out, frames[-1])
    elif out.suffix == ".gif":
        _write_gif(out, frames, 1000 / fps)
    else:
        imageio.mimsave(out, frames, fps=fps)  # type: ignore[arg-type]  # list[ArrayLike] is invariant; read only
    env.close()
    what = f"the state after step {step}" if still else f"{len(frames)} frames"
    print(f"wrote {out}: {what}, mean {benchmark_of(spec).record_value} {np.mean(history):.3f}")
    return 0
