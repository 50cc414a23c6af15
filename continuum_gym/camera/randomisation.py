"""Domain randomisation of the rendered images: lens distortion, light and pixel noise, drawn per row.

Everything random is drawn from the ``numpy.random.Generator`` the caller passes, in a fixed order, so a
seeded generator gives the same images on any number of threads. The default ``Randomisation()`` draws
nothing (it leaves the generator untouched) and renders the nominal images.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from continuum_gym.validation import non_negative, number

__all__ = ["Randomisation", "RowDraws", "NOMINAL_AMBIENT", "NOMINAL_DIFFUSE"]

#: The light of the pybullet scenes' endoscope images (``render.scene.Scene._light``): colour x (ambient +
#: diffuse cos(angle to the camera)); a surface facing the camera shows its albedo.
NOMINAL_AMBIENT = 0.45
NOMINAL_DIFFUSE = 1.0 - NOMINAL_AMBIENT  # 0.55


@dataclass(frozen=True)
class RowDraws:
    """What one render call draws per row: k1 (N,), ambient and diffuse gains (N,), noise seeds (N,) uint64."""

    k1: np.ndarray | None
    ambient: np.ndarray
    diffuse: np.ndarray
    seeds: np.ndarray
    noise_std: float


def _pair(value: tuple[float, float], name: str, low: float, high: float, unit: str) -> tuple[float, float]:
    """A (min, max) range with low <= min <= max <= high (min == max: a fixed value)."""
    try:
        lo, hi = value
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a (min, max) pair in [{low:g}, {high:g}] ({unit}); got {value!r}") from None
    lo = number(lo, f"{name}[0]", low=low, high=high, unit=unit)
    hi = number(hi, f"{name}[1]", low=low, high=high, unit=unit)
    if lo > hi:
        raise ValueError(f"{name} must be (min, max) with min <= max; got {value!r}")
    return lo, hi


@dataclass(frozen=True)
class Randomisation:
    """Per-row image randomisation; every range is (min, max), drawn uniformly, a degenerate one is fixed.

    Args:
        k1: radial distortion (``camera.model``); negative is barrel, as endoscopes' lenses. Each row's
            value must keep the distortion invertible over its image (``Cameras`` checks it).
        light: gain on the light's intensity (ambient and diffuse together), 1 nominal.
        ambient_share: ambient part of the light (the nominal is 0.45), the rest diffuse.
        noise_std: standard deviation of the pixel noise (0-255 units, added to each channel; an
            approximately Gaussian counter-based draw per pixel, seeded per row from the generator).
    """

    k1: tuple[float, float] = (0.0, 0.0)
    light: tuple[float, float] = (1.0, 1.0)
    ambient_share: tuple[float, float] = (NOMINAL_AMBIENT, NOMINAL_AMBIENT)
    noise_std: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "k1", _pair(self.k1, "k1", -10.0, 10.0, "normalised"))
        object.__setattr__(self, "light", _pair(self.light, "light", 0.0, 10.0, "gain"))
        object.__setattr__(self, "ambient_share", _pair(self.ambient_share, "ambient_share", 0.0, 1.0, "fraction"))
        object.__setattr__(self, "noise_std", non_negative(self.noise_std, "noise_std", "0-255 units"))

    @property
    def draws_anything(self) -> bool:
        """False for the nominal images (then ``draw`` leaves the generator untouched)."""
        return (self.k1[0] != self.k1[1] or self.light[0] != self.light[1]
                or self.ambient_share[0] != self.ambient_share[1] or self.noise_std > 0)

    def draw(self, rng: np.random.Generator | None, num_rows: int) -> RowDraws:
        """Draw every row's values, in a fixed order (k1, light, ambient share, noise seeds), each only if random."""
        if self.draws_anything and not isinstance(rng, np.random.Generator):
            raise ValueError(f"rng must be a numpy.random.Generator when the randomisation draws; got {rng!r}")

        def uniform(bounds: tuple[float, float]) -> np.ndarray:
            if bounds[0] == bounds[1]:
                return np.full(num_rows, bounds[0])
            assert rng is not None
            return rng.uniform(bounds[0], bounds[1], num_rows)

        k1 = uniform(self.k1)
        light = uniform(self.light)
        share = uniform(self.ambient_share)
        ambient = light * share
        diffuse = light * (1.0 - share)  # nominal: 0.55 = NOMINAL_DIFFUSE
        if self.noise_std > 0:
            assert rng is not None
            seeds = rng.integers(0, np.iinfo(np.uint64).max, num_rows, dtype=np.uint64, endpoint=True)
        else:
            seeds = np.zeros(num_rows, dtype=np.uint64)
        return RowDraws(None if not np.any(k1) else k1, ambient, diffuse, seeds, float(self.noise_std))
