"""The procedural tissue texture (reddish noise with vessels) and its BMP encoding, in numpy only."""

from __future__ import annotations

import functools

import numpy as np


# ====================================================================== texture
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


def bmp_bytes(image: np.ndarray) -> bytes:
    """24-bit uncompressed BMP of an (h, w, 3) uint8 RGB image (pybullet's stb_image reads it; writing it
    takes a millisecond where PNG encoding takes ~150 ms)."""
    h, w, _ = image.shape
    row = (3 * w + 3) // 4 * 4
    pixels = np.zeros((h, row), dtype=np.uint8)
    pixels[:, :3 * w] = image[::-1, :, ::-1].reshape(h, 3 * w)  # bottom-up rows, BGR
    size = 54 + pixels.size
    header = (b"BM" + size.to_bytes(4, "little") + b"\0\0\0\0" + (54).to_bytes(4, "little")
              + (40).to_bytes(4, "little") + w.to_bytes(4, "little") + h.to_bytes(4, "little")
              + (1).to_bytes(2, "little") + (24).to_bytes(2, "little") + b"\0" * 4
              + pixels.size.to_bytes(4, "little") + (2835).to_bytes(4, "little") * 2 + b"\0" * 8)
    return header + pixels.tobytes()
