"""The procedural tissue texture and its BMP encoding, in numpy only.

The generator lives in ``continuum_gym.camera.texture`` (below the environments, where the batched renderer
samples it); it is re-exported here so that both renderers draw the same tissue.
"""

from __future__ import annotations

import numpy as np

from continuum_gym.camera.texture import cached_texture, tissue_texture

__all__ = ["tissue_texture", "cached_texture", "bmp_bytes"]


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
