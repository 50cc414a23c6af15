"""The procedural tissue texture (reddish mucosa with vessels) and its mip pyramid, in numpy only.

One generator for both renderers: the pybullet scenes load it as a BMP (``continuum_gym.render.textures``)
and the batched renderer samples it from a mip pyramid, so both draw the same tissue.
"""

from __future__ import annotations

import functools

import numpy as np

from continuum_gym.camera.palette import CAVITY
from continuum_gym.validation import integer, positive

__all__ = ["tissue_texture", "cached_texture", "mip_pyramid", "MipPyramid"]


def _fractal(rng, size, slope, k_min=0.0, k_max=np.inf):
    f = np.fft.fftfreq(size) * size
    k = np.hypot(f[:, None], f[None, :])
    k[0, 0] = 1.0
    gain = k ** (-slope) * ((k >= k_min) & (k <= k_max))
    gain[0, 0] = 0.0
    out = np.real(np.fft.ifft2(np.fft.fft2(rng.standard_normal((size, size))) * gain))
    return (out - out.mean()) / (out.std() + 1e-12)


@functools.lru_cache(maxsize=4)
def cached_texture(size: int, seed: int, features: float) -> np.ndarray:
    """``tissue_texture(size, seed, features)`` computed once per argument set (read-only: do not write)."""
    image = _tissue_texture(size, seed, features)
    image.flags.writeable = False
    return image


def tissue_texture(size: int = 512, seed: int = 0, features: float = 1.0) -> np.ndarray:
    """Tileable (periodic) reddish mucosa texture (size, size, 3) uint8: fractal blotches, grain, dark vessels.

    ``features`` scales the number of blotches and vessels per tile (1: a few vessels per tile).
    """
    return cached_texture(int(size), int(seed), float(features)).copy()


def _tissue_texture(size, seed, features):
    rng = np.random.default_rng(seed)
    f = features
    blotch = _fractal(rng, size, 1.8, k_max=f * size / 8)
    grain = _fractal(rng, size, 0.6, k_min=size / 16)
    vessels = np.zeros((size, size))
    for scale, width, weight in ((3.0, 0.035, 0.9), (8.0, 0.05, 0.6)):
        field = _fractal(rng, size, 1.5, k_min=f * scale * 0.5, k_max=f * scale * 3)
        patch = np.clip(_fractal(rng, size, 2.0, k_max=f * 6) * 0.8 + 0.2, 0.0, 1.0)
        vessels = np.maximum(vessels, weight * patch * np.exp(-(field / width) ** 2))
    base = np.array([0.80, 0.36, 0.32])
    vessel = np.array([0.42, 0.05, 0.10])
    shade = 1.0 + 0.10 * blotch[..., None] + 0.05 * grain[..., None]
    color = base * shade
    color[..., 1:] *= (1.0 - 0.15 * np.clip(blotch, 0, None))[..., None]
    color = color * (1.0 - vessels[..., None]) + vessel * vessels[..., None]
    return np.clip(color * 255.0, 0, 255).astype(np.uint8)


class MipPyramid:
    """A tileable texture and its 2x2 box-filtered halvings, packed for the compiled samplers.

    A 64 x 64 image of a tissue plane 0.1 m away covers about four texels per pixel; sampling the full
    texture there aliases its vessels into noise, so the renderer reads the level whose texels match the
    pixel's footprint (as a GPU's mipmapping does).

    Attributes:
        texels: float32 (2 size^2, 3), colours in [0, 1], level after level, rows first.
        offsets: int64 (levels,), the first texel of each level: 2 size^2 - (2 size^2 >> level).
        packed: uint32 (2 size^2,), the texels as 8-bit r | g << 8 | b << 16 (one read per texel).

    The last texel (in the padding after the smallest level) is the cavity colour (``palette.CAVITY``), which the
    sampler reads for rays that miss the plane.
        sizes: int64 (levels,), the side of each level (texels), a power of 2.
    """

    def __init__(self, texture: np.ndarray, min_size: int = 4) -> None:
        texture = np.asarray(texture)
        size = texture.shape[0]
        if texture.ndim != 3 or texture.shape != (size, size, 3) or size < 1 or size & (size - 1):
            raise ValueError(f"texture must be (size, size, 3) with size a power of 2; got shape {texture.shape}")
        integer(min_size, "min_size", low=1)
        levels = [texture.astype(np.float32) / (255.0 if texture.dtype == np.uint8 else 1.0)]
        while levels[-1].shape[0] > min_size:
            t = levels[-1]
            levels.append(0.25 * (t[0::2, 0::2] + t[1::2, 0::2] + t[0::2, 1::2] + t[1::2, 1::2]))
        self.sizes = np.array([t.shape[0] for t in levels], dtype=np.int64)
        # level l starts at texel 2 size0^2 - (2 size0^2 >> l): each level in a slot twice its size, so that the
        # samplers compute the start with a shift (the packed layout's 4 (size0^2 - size^2) / 3 needs a
        # division, which keeps their loops from vectorising)
        total = 2 * size * size
        self.offsets = total - (total >> np.arange(len(levels), dtype=np.int64))
        self.texels = np.zeros((total, 3), dtype=np.float32)
        for start, t in zip(self.offsets, levels):
            self.texels[start:start + t.shape[0] ** 2] = t.reshape(-1, 3)
        # the last slot (never part of a level) holds the cavity's colour: what a ray that misses the plane shows
        self.texels[-1] = np.asarray(CAVITY) / 255.0
        rgb = np.clip(np.rint(self.texels * 255.0), 0, 255).astype(np.uint32)
        self.packed = np.ascontiguousarray(rgb[:, 0] | (rgb[:, 1] << 8) | (rgb[:, 2] << 16))


@functools.lru_cache(maxsize=4)
def mip_pyramid(size: int = 512, seed: int = 0, features: float = 1.0) -> MipPyramid:
    """The mip pyramid of ``tissue_texture(size, seed, features)``, built once per argument set."""
    integer(size, "size (texels)", low=4, high=4096)
    positive(features, "features", "")
    return MipPyramid(cached_texture(int(size), int(seed), float(features)))
