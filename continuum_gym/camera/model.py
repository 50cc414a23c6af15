"""The public pinhole camera model: batched intrinsics and poses, ``project``, one radial distortion term.

Conventions (those of ``continuum_gym.render.camera`` and of OpenCV):

- **camera frame**: z the optical axis (looking direction), x image right, y image *down*. A row's pose is
  world-from-camera, ``T = [[R, p], [0, 1]]``: R's columns are the camera axes in {w}, p the optical centre (m).
- **pixel coordinates** (u, v): u the column, v the row, in pixels; the sample of pixel (row i, column j)
  is at (u, v) = (j, i), so an image spans u in [-0.5, W - 0.5].
- **intrinsics** ``K = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` (pixels): a camera-frame point X lands at
  ``u = fx x_d + cx``, ``v = fy y_d + cy`` with ``(x_d, y_d) = distort(X_x / X_z, X_y / X_z)``.
- **radial distortion** (one coefficient): ``distort(x, y) = (x, y) (1 + k1 (x^2 + y^2))``; k1 < 0 is barrel
  (the image edges see wider angles), k1 > 0 pincushion. A row's k1 must keep the map invertible over the
  image (``k1_lower_bound``).
- **depth** is the camera-frame z of a point (m along the optical axis), not its distance.

``intrinsics(width, height, fov_y)`` gives fx = fy = H / (2 tan(fov_y / 2)) and, by default, the principal
point of pybullet's TinyRenderer, (cx, cy) = (W / 2, H / 2 - 1): TinyRenderer samples column j at
x_ndc = 2 j / W - 1 and row i at y_ndc = 2 (H - 1 - i) / H - 1 (``continuum_gym.render.camera``), half a
pixel off the image centre, and the two renderers' images line up pixel for pixel only with the same
samples. ``centred=True`` puts it at the image centre ((W - 1) / 2, (H - 1) / 2).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import ArrayLike

from continuum_gym.validation import as_finite, integer, number

__all__ = [
    "Cameras", "intrinsics", "pose_matrix", "look_at_frame", "pixel_rays", "pixel_angles", "fov_mask",
    "distort", "undistort", "k1_lower_bound",
]


# ---------------------------------------------------------------------- helpers of the pybullet scenes' cameras
def look_at_frame(eye: ArrayLike, target: ArrayLike,
                  up: ArrayLike = (0.0, 0.0, 1.0)) -> tuple[np.ndarray, np.ndarray]:
    """Camera frame (p, R) at ``eye`` looking at ``target`` with image-up as close to ``up`` as possible."""
    eye = np.asarray(eye, dtype=np.float64).reshape(3)
    z = np.asarray(target, dtype=np.float64).reshape(3) - eye
    n = np.linalg.norm(z)
    if n < 1e-12:
        raise ValueError("eye and target coincide")
    z /= n
    up = np.asarray(up, dtype=np.float64).reshape(3)
    x = np.cross(z, up)  # image right = forward x up
    if np.linalg.norm(x) < 1e-9:
        x = np.cross(z, [1.0, 0.0, 0.0] if abs(z[0]) < 0.9 else [0.0, 1.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(z, x)  # image down
    return eye, np.column_stack([x, y, z])


def pixel_rays(width: int, height: int, fov_y: float) -> np.ndarray:
    """Unnormalised ray directions (H, W, 3) in the camera frame of every pixel sample (x right, y down, z = 1).

    The samples of pybullet's TinyRenderer, i.e. those of ``intrinsics(width, height, fov_y)``.
    """
    t = math.tan(0.5 * fov_y)
    x_ndc = 2.0 * np.arange(width) / width - 1.0
    y_ndc = 2.0 * (height - 1 - np.arange(height)) / height - 1.0
    rays = np.empty((height, width, 3))
    rays[..., 0] = (x_ndc * t * width / height)[None, :]
    rays[..., 1] = (-y_ndc * t)[:, None]
    rays[..., 2] = 1.0
    return rays


def pixel_angles(width: int, height: int, fov_y: float) -> np.ndarray:
    """Angle (rad, (H, W)) between each pixel's ray and the optical axis."""
    rays = pixel_rays(width, height, fov_y)
    return np.arctan(np.hypot(rays[..., 0], rays[..., 1]))


_FOV_MASKS: dict = {}


def fov_mask(width: int, height: int, fov_y: float, half_angle: float) -> np.ndarray:
    """Boolean (H, W): pixels whose ray is within ``half_angle`` (rad) of the optical axis (cached, read-only)."""
    key = (int(width), int(height), float(fov_y), float(half_angle))
    mask = _FOV_MASKS.get(key)
    if mask is None:
        mask = pixel_angles(width, height, fov_y) <= half_angle
        mask.flags.writeable = False
        if len(_FOV_MASKS) > 64:
            _FOV_MASKS.clear()
        _FOV_MASKS[key] = mask
    return mask


# ---------------------------------------------------------------------- the batched model
def intrinsics(width: int, height: int, fov_y: float, centred: bool = False) -> np.ndarray:
    """Intrinsics K (3, 3) in pixels of a ``width`` x ``height`` image with vertical field of view ``fov_y`` (rad).

    Square pixels, fx = fy = H / (2 tan(fov_y / 2)); principal point (W / 2, H / 2 - 1), pybullet's samples
    (module docstring), or ((W - 1) / 2, (H - 1) / 2) with ``centred``.
    """
    width = integer(width, "width (pixels)", low=1, high=4096)
    height = integer(height, "height (pixels)", low=1, high=4096)
    fov_y = number(fov_y, "fov_y", low=0.0, high=math.pi, low_open=True, high_open=True, unit="rad")
    f = height / (2.0 * math.tan(0.5 * fov_y))
    cx, cy = ((width - 1) / 2.0, (height - 1) / 2.0) if centred else (width / 2.0, height / 2.0 - 1.0)
    return np.array([[f, 0.0, cx], [0.0, f, cy], [0.0, 0.0, 1.0]])


def pose_matrix(p: ArrayLike, R: ArrayLike) -> np.ndarray:
    """World-from-camera poses (..., 4, 4) from positions p (..., 3) in m and rotations R (..., 3, 3)."""
    p = np.asarray(p, dtype=np.float64)
    R = np.asarray(R, dtype=np.float64)
    if p.shape[-1:] != (3,) or R.shape[-2:] != (3, 3) or p.shape[:-1] != R.shape[:-2]:
        raise ValueError(f"p must be (..., 3) and R (..., 3, 3) with one leading shape; got {p.shape} and {R.shape}")
    T = np.zeros(p.shape[:-1] + (4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = p
    T[..., 3, 3] = 1.0
    return T


def distort(x: ArrayLike, y: ArrayLike, k1: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Distorted normalised coordinates (x, y) (1 + k1 (x^2 + y^2)) of undistorted ones (broadcasting)."""
    x, y, k1 = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64), np.asarray(k1, dtype=np.float64)
    g = 1.0 + k1 * (x * x + y * y)
    return x * g, y * g


def undistort(x_d: ArrayLike, y_d: ArrayLike, k1: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Undistorted normalised coordinates of distorted ones: the inverse of ``distort`` (Newton on the radius).

    Exact to rounding where the radial map is invertible (k1 >= ``k1_lower_bound`` of the radius).
    """
    x_d, y_d, k1 = (np.asarray(v, dtype=np.float64) for v in (x_d, y_d, k1))
    r_d = np.hypot(x_d, y_d)
    r = r_d.copy()
    for _ in range(8):  # r + k1 r^3 = r_d, from r = r_d: quadratic convergence in the invertible range
        r = r - (r + k1 * r**3 - r_d) / (1.0 + 3.0 * k1 * r * r)
    scale = np.divide(r, r_d, out=np.ones_like(r), where=r_d > 0)
    return x_d * scale, y_d * scale


def k1_lower_bound(max_radius: float) -> float:
    """Smallest (most barrel) k1 whose distortion stays invertible out to the distorted radius ``max_radius``.

    r -> r (1 + k1 r^2) grows only up to r = 1 / sqrt(-3 k1), where it reaches (2 / 3) / sqrt(-3 k1); the
    image corners must lie below that: k1 > -4 / (27 max_radius^2).
    """
    return -4.0 / (27.0 * max_radius**2)


@dataclass(frozen=True)
class Cameras:
    """N cameras, one per row of a batch: intrinsics, world-from-camera poses, radial distortion, image size.

    Args:
        intrinsics: (N, 3, 3) in pixels, ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` with fx, fy > 0.
        poses: (N, 4, 4) world-from-camera (rotation orthonormal, right-handed), positions in m.
        width, height: image size (pixels), in [1, 4096].
        near, far: clip distances along the optical axis (m), 0 < near < far: nothing nearer or farther is drawn.
        k1: (N,) radial distortion per row (0: none); each above the row's ``k1_lower_bound``.
    """

    intrinsics: np.ndarray
    poses: np.ndarray
    width: int
    height: int
    near: float = 1e-3
    far: float = 0.3
    k1: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def __post_init__(self) -> None:
        K = np.ascontiguousarray(as_finite(self.intrinsics, (3, 3), "intrinsics"))
        if K.ndim != 3:
            raise ValueError(f"intrinsics must be (N, 3, 3) (pixels); got shape {K.shape}")
        n = K.shape[0]
        T = np.ascontiguousarray(as_finite(self.poses, (4, 4), "poses"))
        if T.shape != (n, 4, 4):
            raise ValueError(f"poses must be ({n}, 4, 4) like intrinsics; got shape {T.shape}")
        if np.any(K[:, 0, 0] <= 0) or np.any(K[:, 1, 1] <= 0) or np.any(K[:, [0, 1, 2, 2], [1, 0, 0, 1]] != 0) \
                or np.any(K[:, 2, 2] != 1):
            raise ValueError("intrinsics must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0 (pixels)")
        R = T[:, :3, :3]
        if np.any(np.abs(R @ np.swapaxes(R, 1, 2) - np.eye(3)) > 1e-6) or np.any(np.linalg.det(R) < 0) \
                or np.any(T[:, 3] != [0.0, 0.0, 0.0, 1.0]):
            raise ValueError("poses must be rigid transforms [[R, p], [0, 0, 0, 1]] with R a rotation (det +1)")
        width = integer(self.width, "width (pixels)", low=1, high=4096)
        height = integer(self.height, "height (pixels)", low=1, high=4096)
        near = number(self.near, "near", low=0.0, low_open=True, unit="m")
        far = number(self.far, "far", low=near, low_open=True, unit="m (> near)")
        k1 = np.asarray(self.k1, dtype=np.float64)
        k1 = np.zeros(n) if k1.size == 0 else np.ascontiguousarray(np.broadcast_to(as_finite(k1, (), "k1"), (n,)))
        bound = self._k1_bounds(K, width, height)
        bad = np.flatnonzero(k1 <= bound)
        if bad.size:
            i = int(bad[0])
            raise ValueError(f"k1 must be > {bound[i]:.4g} for row {i} (the largest barrel distortion that stays "
                             f"invertible over its image); got {k1[i]!r}")
        for name, value in (("intrinsics", K), ("poses", T), ("width", width), ("height", height), ("near", near),
                            ("far", far), ("k1", k1)):
            object.__setattr__(self, name, value)
        for array in (K, T, k1):
            array.flags.writeable = False

    @staticmethod
    def _k1_bounds(K: np.ndarray, width: int, height: int) -> np.ndarray:
        """Per row, ``k1_lower_bound`` of the farthest pixel sample's distorted radius."""
        fx, fy, cx, cy = K[:, 0, 0], K[:, 1, 1], K[:, 0, 2], K[:, 1, 2]
        dx = np.maximum(np.abs(0.0 - cx), np.abs(width - 1.0 - cx)) / fx
        dy = np.maximum(np.abs(0.0 - cy), np.abs(height - 1.0 - cy)) / fy
        return -4.0 / (27.0 * np.maximum(np.hypot(dx, dy), 1e-9) ** 2)  # k1_lower_bound, per row

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_frames(cls, p: ArrayLike, R: ArrayLike, width: int, height: int, fov_y: float, near: float = 1e-3,
                    far: float = 0.3, centred: bool = False, k1: ArrayLike = 0.0) -> Cameras:
        """Cameras at positions p (N, 3) in m with rotations R (N, 3, 3) (columns x right, y down, z optical axis),
        all with ``intrinsics(width, height, fov_y, centred)``."""
        T = pose_matrix(p, R)
        if T.ndim != 3:
            raise ValueError(f"p must be (N, 3) and R (N, 3, 3); got {np.shape(p)} and {np.shape(R)}")
        K = np.broadcast_to(intrinsics(width, height, fov_y, centred), (T.shape[0], 3, 3))
        return cls(K, T, width, height, near, far, np.broadcast_to(np.asarray(k1, dtype=np.float64), (T.shape[0],)))

    def with_distortion(self, k1: ArrayLike) -> Cameras:
        """The same cameras with radial distortion ``k1`` (scalar or (N,))."""
        return replace(self, k1=np.broadcast_to(np.asarray(k1, dtype=np.float64), (self.num_rows,)))

    def rows(self, index: np.ndarray | slice) -> Cameras:
        """The cameras of some rows (an integer or boolean index array, or a slice)."""
        return replace(self, intrinsics=self.intrinsics[index], poses=self.poses[index], k1=self.k1[index])

    # ------------------------------------------------------------------ properties
    @property
    def num_rows(self) -> int:
        """N, the number of cameras."""
        return int(self.intrinsics.shape[0])

    @property
    def positions(self) -> np.ndarray:
        """Optical centres (N, 3) in {w} (m)."""
        return self.poses[:, :3, 3]

    @property
    def rotations(self) -> np.ndarray:
        """^wR_camera (N, 3, 3): columns x right, y down, z optical axis."""
        return self.poses[:, :3, :3]

    # ------------------------------------------------------------------ projection
    def to_camera(self, points: ArrayLike) -> np.ndarray:
        """World points (N, ..., 3) (or (..., 3), the same for every row) in each row's camera frame (N, ..., 3)."""
        X = self._points(points)
        R, p = self.rotations, self.positions
        lead = X.shape[1:-1]
        flat = (X.reshape(self.num_rows, -1, 3) - p[:, None, :]) @ R  # R^T (x - p), row vectors
        return flat.reshape((self.num_rows,) + lead + (3,))

    def project(self, points: ArrayLike) -> np.ndarray:
        """Pixel coordinates (N, ..., 2), (u, v) = (column, row), of world points (N, ..., 3) (or (..., 3)).

        A point at or behind the camera plane (camera z <= 0) has no image: NaN. Points outside the image
        get coordinates outside [-0.5, W - 0.5] x [-0.5, H - 0.5]; nothing is clipped.
        """
        Xc = self.to_camera(points)
        z = Xc[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            x = np.where(z > 0, Xc[..., 0] / z, np.nan)
            y = np.where(z > 0, Xc[..., 1] / z, np.nan)
        extra = (1,) * (Xc.ndim - 2)
        x, y = distort(x, y, self.k1.reshape((-1,) + extra))
        K = self.intrinsics.reshape((-1,) + extra + (3, 3))
        return np.stack([K[..., 0, 0] * x + K[..., 0, 2], K[..., 1, 1] * y + K[..., 1, 2]], axis=-1)

    def depth(self, points: ArrayLike) -> np.ndarray:
        """Depth (N, ...) of world points: camera-frame z in m (along the optical axis; < 0 behind the camera)."""
        return self.to_camera(points)[..., 2]

    def pixel_rays(self) -> np.ndarray:
        """Undistorted ray of every pixel sample (N, H, W, 3) in the camera frame, scaled to z = 1 (float64).

        The renderer draws along exactly these rays: a hit at depth z lies at z times the ray.
        """
        K = self.intrinsics
        u = np.arange(self.width, dtype=np.float64)
        v = np.arange(self.height, dtype=np.float64)
        x_d = (u[None, None, :] - K[:, 0, 2, None, None]) / K[:, 0, 0, None, None]
        y_d = (v[None, :, None] - K[:, 1, 2, None, None]) / K[:, 1, 1, None, None]
        x_d, y_d = np.broadcast_arrays(x_d, y_d)
        x, y = undistort(x_d, y_d, self.k1[:, None, None])
        return np.stack([x, y, np.ones_like(x)], axis=-1)

    def fov_mask(self, half_angle: float) -> np.ndarray:
        """Boolean (N, H, W): pixel samples whose ray lies within ``half_angle`` (rad) of the optical axis."""
        half_angle = number(half_angle, "half_angle", low=0.0, high=math.pi / 2, high_open=True, unit="rad")
        rays = self.pixel_rays()
        return rays[..., 0] ** 2 + rays[..., 1] ** 2 <= math.tan(half_angle) ** 2

    def _points(self, points: ArrayLike) -> np.ndarray:
        X = np.asarray(points, dtype=np.float64)
        if X.shape[-1:] != (3,):
            raise ValueError(f"points must have shape (N, ..., 3) or (..., 3) (m); got {X.shape}")
        if X.ndim == 1 or X.shape[0] != self.num_rows:
            X = np.broadcast_to(X, (self.num_rows,) + X.shape)
        return X
