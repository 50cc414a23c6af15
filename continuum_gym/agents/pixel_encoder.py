"""The features extractor of pixel policies (issue 56): one CNN over every image of the observation, plus the state.

SB3's ``MultiInputPolicy`` runs a NatureCNN per image key and flattens every other array: a float depth
image (H, W, 1) would become 4,096 inputs of a linear layer, and ViewTracking's two views would be encoded
apart, so the policy could compare them only after each was reduced to a vector. ``PixelEncoder`` stacks
every image of a row as channels of one tensor (early fusion: the continuum endoscope's and the da Vinci's
views side by side in each pixel, which is what visual servoing compares) and encodes them with one CNN:

- ``rgb`` arrives scaled to [0, 1] (SB3 divides uint8 images by 255 and moves their channels first);
- ``depth`` (m) is divided by its space's far bound, to [0, 1];
- ``segmentation`` ids are divided by the largest id, to [0, 1].

The ``state`` entry (what the real system measures) bypasses the CNN and is concatenated to its features.
``augment`` applies DrQ's random shift (Kostrikov et al. 2020: pad by ``shift`` pixels, crop back at a random
offset per sample) while the policy is in training mode, i.e. on PPO's gradient steps only, never while
acting. ``cnn``: ``"nature"`` (Mnih et al. 2015: 32 8x8/4, 64 4x4/2, 64 3x3/1) or ``"small"`` (16 8x8/4,
32 4x4/2: the first two layers at half the width, 1.2 M multiply-adds per 64x64 4-channel image against 2.5 M).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import torch
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from torch import nn

from continuum_gym.validation import choice, integer

__all__ = ["PixelEncoder", "CNNS"]

CNNS = ("nature", "small")
#: The smallest image side each CNN's strides leave a feature map for (pixels).
MIN_SIDES = {"nature": 36, "small": 20}
_IMAGE_KEYS = ("rgb", "depth", "segmentation")


def _is_image_key(key: str) -> bool:
    return any(key == name or key.endswith("_" + name) for name in _IMAGE_KEYS)


def _shape(space: gym.Space) -> tuple[int, ...]:
    shape = space.shape
    if not isinstance(space, gym.spaces.Box) or shape is None:
        raise ValueError(f"every entry of a pixel observation must be a Box; got {space}")
    return tuple(shape)


def _channels_first(space: gym.Space) -> bool:
    """SB3's ``VecTransposeImage`` moved an rgb image's channels first; depth and ids keep them last."""
    shape = _shape(space)
    return shape[0] < shape[-1]


def _layers(cnn: str, channels: int) -> nn.Sequential:
    if cnn == "nature":
        return nn.Sequential(nn.Conv2d(channels, 32, 8, 4), nn.ReLU(), nn.Conv2d(32, 64, 4, 2), nn.ReLU(),
                             nn.Conv2d(64, 64, 3, 1), nn.ReLU(), nn.Flatten())
    return nn.Sequential(nn.Conv2d(channels, 16, 8, 4), nn.ReLU(), nn.Conv2d(16, 32, 4, 2), nn.ReLU(), nn.Flatten())


class PixelEncoder(BaseFeaturesExtractor):
    """One CNN over all the images of a ``Dict`` observation, the ``state`` entry concatenated after it.

    Args:
        observation_space: the (SB3-transposed) ``Dict`` space of an image ``obs_mode``.
        cnn: ``"nature"`` or ``"small"``.
        features_dim: width of the CNN's output layer (>= 1); the extractor's output adds the state's width.
        augment: random-shift augmentation on gradient steps.
        shift: the random shift's padding (pixels, >= 0).
    """

    def __init__(self, observation_space: gym.spaces.Dict, cnn: str = "small", features_dim: int = 128,
                 augment: bool = False, shift: int = 4) -> None:
        if not isinstance(observation_space, gym.spaces.Dict) or "state" not in observation_space.spaces:
            raise ValueError("observation_space must be the Dict of an image obs_mode (with a 'state' entry)")
        cnn = choice(cnn, CNNS, "cnn")
        features_dim = integer(features_dim, "features_dim", low=1)
        self.image_keys = sorted(k for k in observation_space.spaces if _is_image_key(k))
        if not self.image_keys:
            raise ValueError(f"observation_space has no image entry (keys {sorted(observation_space.spaces)})")
        state_dim = int(np.prod(_shape(observation_space["state"])))
        super().__init__(observation_space, features_dim + state_dim)
        self.augment = bool(augment)
        self.shift = integer(shift, "shift", low=0)
        self._first = {k: _channels_first(observation_space[k]) for k in self.image_keys}
        self._scale = {}
        channels = 0
        for key in self.image_keys:
            shape = _shape(observation_space[key])
            channels += int(shape[0] if self._first[key] else shape[-1])
            high = float(np.max(observation_space[key].high))  # type: ignore[attr-defined]  # a Box (_shape)
            self._scale[key] = 1.0 if key.endswith("rgb") else 1.0 / max(high, 1e-9)  # rgb: SB3 scaled it
        shape = _shape(observation_space[self.image_keys[0]])
        height, width = (shape[1], shape[2]) if self._first[self.image_keys[0]] else (shape[0], shape[1])
        self.cnn = _layers(cnn, channels)
        try:
            with torch.no_grad():
                flat = int(self.cnn(torch.zeros(1, channels, height, width)).shape[1])
        except RuntimeError:
            raise ValueError(f"cnn={cnn!r} needs larger images than {height}x{width} (image_size: at least "
                             f"{MIN_SIDES[cnn]} pixels a side)") from None
        self.head = nn.Sequential(nn.Linear(flat, features_dim), nn.ReLU())

    def images(self, observations: dict[str, torch.Tensor]) -> torch.Tensor:
        """The images of a batch stacked as channels (B, C, H, W), each scaled to [0, 1]."""
        parts = []
        for key in self.image_keys:
            x = observations[key].float()
            if not self._first[key]:
                x = x.permute(0, 3, 1, 2)
            parts.append(x * self._scale[key])
        return torch.cat(parts, dim=1)

    def forward(self, observations: dict[str, Any]) -> torch.Tensor:
        x = self.images(observations)
        if self.augment and self.training and self.shift > 0:
            x = random_shift(x, self.shift)
        features = self.head(self.cnn(x))
        return torch.cat([features, observations["state"].float().flatten(1)], dim=1)


def random_shift(x: torch.Tensor, pad: int) -> torch.Tensor:
    """DrQ's augmentation: replicate-pad by ``pad`` and crop back at a random integer offset per sample."""
    b, _, h, w = x.shape
    padded = nn.functional.pad(x, (pad, pad, pad, pad), mode="replicate")
    dx = torch.randint(0, 2 * pad + 1, (b,), device=x.device)
    dy = torch.randint(0, 2 * pad + 1, (b,), device=x.device)
    rows = (torch.arange(h, device=x.device)[None, :] + dy[:, None])  # (b, h)
    cols = (torch.arange(w, device=x.device)[None, :] + dx[:, None])  # (b, w)
    index = torch.arange(b, device=x.device)[:, None, None]
    return padded.permute(0, 2, 3, 1)[index, rows[:, :, None], cols[:, None, :]].permute(0, 3, 1, 2)
