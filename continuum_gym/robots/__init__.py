"""Kinematics of the papers' robots: numpy interfaces over compiled kernels, batched, SI units.

Nothing here imports gymnasium or torch.
"""

from continuum_gym.robots.davinci import ALPHA_CONVENTIONS, DaVinciEndoscope
from continuum_gym.robots.endoscope import (
    ContinuumEndoscope,
    endoscope_segment_jacobian,
    endoscope_segment_pose,
)
from continuum_gym.robots.mbcr import PAPER_PSPS, MultiBackboneRobot
from continuum_gym.robots.rotations import rotation_vector
from continuum_gym.robots.segment import segment_tip_pose

__all__ = [
    "MultiBackboneRobot", "PAPER_PSPS", "ContinuumEndoscope", "DaVinciEndoscope", "ALPHA_CONVENTIONS",
    "endoscope_segment_pose", "endoscope_segment_jacobian", "segment_tip_pose", "rotation_vector",
]
