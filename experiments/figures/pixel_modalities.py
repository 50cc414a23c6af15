"""The environment pages' figure of every image modality (issue 56): pybullet's endoscope image beside the batched
renderer's rgb, depth and segmentation of the same state.

    python experiments/figures/pixel_modalities.py [--size 128] [--out docs/img]

Writes ``pixels-occlusion-avoidance.png`` and ``pixels-view-tracking.png``: one state of each environment
(seed 0, 20 steps of the baseline), the pybullet image (``render_mode="rgb_array"``, the endoscope camera,
TinyRenderer) first, then the observation of ``obs_mode="rgb+depth+segmentation"``; ViewTracking adds the
da Vinci's view (``goal_*``) on a second row.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import gymnasium as gym
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import continuum_gym  # noqa: E402,F401

PAGES = {"ContinuumGym/OcclusionAvoidance-v0": ("pixels-occlusion-avoidance.png", (("endoscope", ""),)),
         "ContinuumGym/ViewTracking-v0": ("pixels-view-tracking.png", (("endoscope", ""), ("davinci", "goal_")))}


def figure(env_id: str, size: int, out: Path) -> Path:
    name, views = PAGES[env_id]
    env = gym.make(env_id, obs_mode="rgb+depth+segmentation", image_size=size, render_mode="rgb_array",
                   camera="endoscope")
    obs, _ = env.reset(seed=0)
    for _ in range(20):
        obs, *_ = env.step(np.zeros(env.action_space.shape, dtype=np.float32))
    inner = env.unwrapped
    fig, axes = plt.subplots(len(views), 4, figsize=(10, 2.7 * len(views)), squeeze=False)
    for row, (camera, prefix) in enumerate(views):
        inner.camera = camera
        pictures = [(inner.render(), f"pybullet ({camera})", None),
                    (obs[prefix + "rgb"], f"{prefix}rgb", None),
                    (obs[prefix + "depth"][..., 0], f"{prefix}depth (m)", "viridis"),
                    (obs[prefix + "segmentation"][..., 0], f"{prefix}segmentation (ids)", "tab10")]
        for ax, (image, title, cmap) in zip(axes[row], pictures):
            shown = ax.imshow(image, cmap=cmap, interpolation="nearest",
                              **({"vmin": 0, "vmax": 9} if cmap == "tab10" else {}))
            if cmap == "viridis":
                fig.colorbar(shown, ax=ax, fraction=0.046)
            ax.set_title(title, fontsize=9)
            ax.axis("off")
    fig.tight_layout()
    path = out / name
    fig.savefig(path, dpi=110)
    plt.close(fig)
    env.close()
    return path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=128)
    parser.add_argument("--out", default="docs/img")
    args = parser.parse_args()
    for env_id in PAGES:
        print(f"wrote {figure(env_id, args.size, Path(args.out))}")


if __name__ == "__main__":
    main()
