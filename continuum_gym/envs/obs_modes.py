"""The observation vocabulary of every env (issue 56): ``obs_mode`` and ``image_size``, and their checks.

Apart from ``envs/pixels.py`` (which renders the images) so that ``envs/config.py`` can check the two keywords
of every ``EnvConfig`` without importing the image layer, which reads the env specs that import the config.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from continuum_gym.validation import choice, describe, integer

#: The observation modes, in ManiSkill's vocabulary.
OBS_MODES = ("state", "rgb", "depth", "segmentation", "rgbd", "rgb+depth+segmentation")
#: The renderer's modalities each image mode observes.
MODE_MODALITIES: dict[str, tuple[str, ...]] = {
    "state": (), "rgb": ("rgb",), "depth": ("depth",), "segmentation": ("segmentation",),
    "rgbd": ("rgb", "depth"), "rgb+depth+segmentation": ("rgb", "depth", "segmentation")}
#: Image side bounds (pixels): below 16 a 30-degree-wide robot is a pixel or two; above 512 a batch of images
#: no longer fits a training rollout in memory.
MIN_IMAGE_SIDE, MAX_IMAGE_SIDE = 16, 512
DEFAULT_IMAGE_SIZE = 64
#: The keywords that choose the observation (fields of every ``EnvConfig``); they define how a policy sees,
#: so a trained policy's env is rebuilt with them (``evaluation.evaluate.policy_env_kwargs``).
OBSERVATION_KEYWORDS = ("obs_mode", "image_size")


def check_obs_mode(value: Any) -> str:
    """``value`` if it is one of ``OBS_MODES``, else a ``ValueError`` naming ``obs_mode`` and the valid modes."""
    return choice(value, OBS_MODES, "obs_mode")


def check_image_size(value: Any) -> int | tuple[int, int]:
    """An int side or an (H, W) pair of ints, each in [16, 512] pixels; a square pair becomes its int."""
    span = f"[{MIN_IMAGE_SIDE}, {MAX_IMAGE_SIDE}]"
    if isinstance(value, (list, tuple, np.ndarray)):
        if len(value) != 2:
            raise ValueError(f"image_size must be an int or an (H, W) pair, each in {span} pixels; got "
                             f"{describe(value)}")
        h, w = (integer(v, "image_size", low=MIN_IMAGE_SIDE, high=MAX_IMAGE_SIDE) for v in value)
        return h if h == w else (h, w)
    try:
        return integer(value, "image_size", low=MIN_IMAGE_SIDE, high=MAX_IMAGE_SIDE)
    except ValueError:
        raise ValueError(f"image_size must be an int or an (H, W) pair, each in {span} pixels; got "
                         f"{describe(value)}") from None


def image_shape(image_size: int | tuple[int, int]) -> tuple[int, int]:
    """(H, W) of a checked ``image_size``."""
    return (image_size, image_size) if isinstance(image_size, int) else (int(image_size[0]), int(image_size[1]))


__all__ = ["OBS_MODES", "MODE_MODALITIES", "MIN_IMAGE_SIDE", "MAX_IMAGE_SIDE", "DEFAULT_IMAGE_SIZE",
           "OBSERVATION_KEYWORDS", "check_obs_mode", "check_image_size", "image_shape"]
