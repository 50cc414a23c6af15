"""The batched renderer's front end: one call renders a view of every row of a ``Scene`` into image buffers.

``Renderer.render(scene, "endoscope")`` returns ``Frames``: ``rgb`` (N, H, W, 3) uint8, ``depth`` (N, H, W, 1)
float32 (m along the optical axis; ``far`` where a ray meets nothing, 0 outside a circular field of view) and
``segmentation`` (N, H, W, 1) uint8 (``camera.scene`` lists the ids), and the cameras they were taken with.
Any subset of the modalities is rendered, into new arrays or into the caller's (``out``), written in place.

Rows are rendered by the compiled ``raster.render_rows`` in blocks, on ``threads`` Python threads
(``camera.threads``). A plane fixed in the camera frame (OcclusionAvoidance's tissue) is rendered once per
intrinsics and copied into every undistorted row.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from continuum_gym.camera.model import Cameras
from continuum_gym.camera.randomisation import NOMINAL_AMBIENT, NOMINAL_DIFFUSE, Randomisation
from continuum_gym.camera.raster import (
    PLANE_CAMERA,
    PLANE_NONE,
    CacheArgs,
    CameraArgs,
    OutputArgs,
    PlaneArgs,
    ShadeArgs,
    TextureArgs,
    TubeArgs,
    render_background,
    render_rows,
)
from continuum_gym.camera.scene import Scene, TexturedPlane
from continuum_gym.camera.texture import MipPyramid
from continuum_gym.camera.threads import default_threads, run_blocks
from continuum_gym.validation import choice, integer

__all__ = ["Renderer", "Frames", "MODALITIES", "allocate_frames"]

#: The modalities, in the order of ``Frames``.
MODALITIES = ("rgb", "depth", "segmentation")
_NO_TEXTURE = MipPyramid(np.zeros((1, 1, 3), dtype=np.uint8), min_size=1)
_NO_CACHE = CacheArgs(np.zeros((1, 1, 3), np.uint8), np.zeros((1, 1, 1), np.float32), np.zeros((1, 1, 3), np.float32),
                      np.zeros((1, 1), np.float32), NOMINAL_AMBIENT, NOMINAL_DIFFUSE, np.zeros(0, dtype=np.uint8))
_EMPTY_PLANE = PlaneArgs(PLANE_NONE, np.zeros(3), np.zeros(3), np.zeros(3), np.zeros(3), np.ones(2), np.ones(2))


@dataclass
class Frames:
    """One view's images of N rows; a modality not rendered is None.

    Attributes:
        rgb: (N, H, W, 3) uint8.
        depth: (N, H, W, 1) float32, m along the optical axis; ``far`` where nothing is hit, 0 outside the
            circular field of view.
        segmentation: (N, H, W, 1) uint8: 0 background and tissue, 1..n robot segments, n + 1 other endoscope.
        cameras: the ``Cameras`` the images were taken with (randomised distortion included).
    """

    rgb: np.ndarray | None
    depth: np.ndarray | None
    segmentation: np.ndarray | None
    cameras: Cameras


def allocate_frames(num_rows: int, width: int, height: int,
                    modalities: tuple[str, ...] = MODALITIES) -> dict[str, np.ndarray]:
    """New buffers {modality: array} for ``Renderer.render(out=...)``: (N, H, W, 3) uint8, (N, H, W, 1) float32,
    (N, H, W, 1) uint8."""
    num_rows = integer(num_rows, "num_rows", low=1)
    shapes = {"rgb": ((num_rows, height, width, 3), np.uint8), "depth": ((num_rows, height, width, 1), np.float32),
              "segmentation": ((num_rows, height, width, 1), np.uint8)}
    return {m: np.empty(*shapes[choice(m, MODALITIES, "modalities")]) for m in modalities}


def _placeholder(dtype: type, channels: int) -> np.ndarray:
    return np.zeros((1, 1, 1, channels), dtype=dtype)


class Renderer:
    """Renders views of batched scenes: the compiled rasteriser on a pool of threads, and its caches.

    Args:
        threads: threads per call, in [1, NUMBA_NUM_THREADS]; None: 1 when torch is loaded, else numba's count.
        block: rows per claim (a thread renders ``block`` rows between claims).
    """

    def __init__(self, threads: int | None = None, block: int = 16) -> None:
        self.threads = default_threads(threads)
        self.block = integer(block, "block", low=1)
        self._backgrounds: dict[tuple, CacheArgs] = {}
        self._textures: dict[int, MipPyramid] = {}

    def render(self, scene: Scene, view: str = "endoscope", modalities: tuple[str, ...] = MODALITIES,
               out: dict[str, np.ndarray] | None = None, randomisation: Randomisation | None = None,
               rng: np.random.Generator | None = None) -> Frames:
        """Render ``view`` of every row of ``scene``.

        Args:
            scene: the ``Scene`` (e.g. from ``occlusion_scene``).
            view: one of ``scene.views``.
            modalities: any of ``MODALITIES``.
            out: buffers to write into ({modality: array} as ``allocate_frames`` makes), else new arrays.
            randomisation: per-row distortion, light and noise (None: the nominal images); drawn from ``rng``.
            rng: the generator the randomisation draws from (not touched when nothing is random).

        Returns:
            ``Frames`` of the view (the arrays of ``out`` when given).
        """
        if not isinstance(scene, Scene):
            raise ValueError(f"scene must be a Scene; got {type(scene).__name__}")
        spec = scene.view(view)
        modalities = tuple(choice(m, MODALITIES, "modalities") for m in modalities)
        n = scene.num_rows
        cameras = spec.cameras
        w, h = cameras.width, cameras.height
        randomisation = Randomisation() if randomisation is None else randomisation
        draws = randomisation.draw(rng, n)
        if draws.k1 is not None:
            cameras = cameras.with_distortion(draws.k1)
        buffers = allocate_frames(n, w, h, modalities) if out is None else dict(out)
        expected = allocate_frames(1, w, h, MODALITIES)
        for m in modalities:
            array = buffers.get(m)
            shape = (n,) + expected[m].shape[1:]
            if not isinstance(array, np.ndarray) or array.shape != shape or array.dtype != expected[m].dtype \
                    or not array.flags.c_contiguous or not array.flags.writeable:
                raise ValueError(f"out[{m!r}] must be a writeable C-contiguous {expected[m].dtype} array of shape "
                                 f"{shape}; got {getattr(array, 'shape', array)!r}")
        outputs = OutputArgs(buffers["rgb"] if "rgb" in modalities else _placeholder(np.uint8, 3),
                             buffers["depth"] if "depth" in modalities else _placeholder(np.float32, 1),
                             buffers["segmentation"] if "segmentation" in modalities else _placeholder(np.uint8, 1),
                             "rgb" in modalities, "depth" in modalities, "segmentation" in modalities)
        plane, texture = self._plane(spec.plane)
        shade = ShadeArgs(draws.ambient, draws.diffuse, draws.seeds, draws.noise_std,
                          float(np.tan(spec.fov_half_angle)) if spec.fov_half_angle is not None else 0.0)
        camera_args = CameraArgs(cameras.intrinsics, cameras.poses, cameras.k1, cameras.near, cameras.far, w, h)
        tubes = scene.tubes
        tube_args = TubeArgs(tubes.a, tubes.b, tubes.u, tubes.radius, tubes.sides, tubes.caps, tubes.ids, tubes.colors,
                             tubes.groups)
        cache = self._cache(spec.plane, plane, texture, cameras, shade.fov_tan)
        run_blocks(render_rows, (camera_args, tube_args, spec.group_mask, plane, texture, shade, cache, outputs), n,
                   self.threads, self.block)
        return Frames(buffers["rgb"] if "rgb" in modalities else None,
                      buffers["depth"] if "depth" in modalities else None,
                      buffers["segmentation"] if "segmentation" in modalities else None, cameras)

    # ------------------------------------------------------------------ caches
    @staticmethod
    def _plane(plane: TexturedPlane | None) -> tuple[PlaneArgs, TextureArgs]:
        if plane is None:
            texture = _NO_TEXTURE
            args = _EMPTY_PLANE
        else:
            texture = plane.texture
            args = PlaneArgs(plane.kind, plane.origin, plane.axis_x, plane.axis_y, plane.normal, plane.half,
                             plane.tiles_per_metre)
        return args, TextureArgs(texture.texels, texture.packed, texture.offsets, texture.sizes)

    def _cache(self, spec: TexturedPlane | None, plane: PlaneArgs, texture: TextureArgs, cameras: Cameras,
               fov_tan: float) -> CacheArgs:
        """The background of a plane fixed in the camera frame, drawn once for the first row's intrinsics and
        copied by every undistorted row that shares them."""
        n = cameras.num_rows
        if spec is None or plane.kind != PLANE_CAMERA:
            return _NO_CACHE._replace(rows=np.zeros(n, dtype=np.uint8))
        K = cameras.intrinsics[0]
        key = (b"".join(a.tobytes() for a in (spec.origin, spec.axis_x, spec.axis_y, spec.normal, spec.half,
                                               spec.tiles_per_metre)), id(spec.texture), K.tobytes(), cameras.width,
               cameras.height, cameras.near, cameras.far, fov_tan)
        cached = self._backgrounds.get(key)
        if cached is None:
            h, w = cameras.height, cameras.width
            rgb, depth = np.empty((h, w, 3), np.uint8), np.empty((h, w, 1), np.float32)
            albedo, cosine = np.empty((h, w, 3), np.float32), np.empty((h, w), np.float32)
            render_background(np.ascontiguousarray(K), cameras.near, cameras.far, w, h, fov_tan, plane, texture,
                              NOMINAL_AMBIENT, NOMINAL_DIFFUSE, rgb, depth, albedo, cosine)
            if len(self._backgrounds) >= 8:
                self._backgrounds.clear()
                self._textures.clear()
            cached = self._backgrounds[key] = CacheArgs(rgb, depth, albedo, cosine, NOMINAL_AMBIENT, NOMINAL_DIFFUSE,
                                                        np.zeros(0, dtype=np.uint8))
            self._textures[id(spec.texture)] = spec.texture  # alive while its id is part of a key
        rows = ((cameras.k1 == 0.0) & np.all(cameras.intrinsics == K, axis=(1, 2))).astype(np.uint8)
        return cached._replace(rows=rows)
