"""View geometry: the angled-lens cone (force field, VOI) and view frustums (overlap ratio)."""

from continuum_gym.geometry.force_field import (
    ForceField,
    potential_gradient,
    repulsive_force,
)
from continuum_gym.geometry.frustum import FACE_VERTICES, Frustum
from continuum_gym.geometry.lens_cone import (
    LENS_MODELS,
    LensCone,
    centre_distance,
    cone_coordinates,
    lens_origin,
    lens_rotation,
    view_axis,
)
from continuum_gym.geometry.occlusion import occlusion_details, visual_occlusion_index
from continuum_gym.geometry.overlap import overlap_ratio, overlap_ratio_nb
from continuum_gym.geometry.overlap_reference import (
    overlap_ratio_monte_carlo,
    overlap_ratio_reference,
)

__all__ = [
    "LensCone", "LENS_MODELS", "cone_coordinates", "centre_distance", "view_axis", "lens_origin", "lens_rotation",
    "ForceField", "repulsive_force", "potential_gradient", "visual_occlusion_index", "occlusion_details",
    "Frustum", "FACE_VERTICES", "overlap_ratio", "overlap_ratio_reference", "overlap_ratio_monte_carlo",
    "overlap_ratio_nb",
]
