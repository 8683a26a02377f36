"""Kinematics of the bending section and the whole probe.

Bending angles from sensor poses (thesis eq. 1), constant-curvature maps between bending
state and tip pose, and the 4-DoF forward/inverse kinematics (translation, rotation, two
bending angles) in the tracker frame.
"""

from endocal.kinematics.bending import bending_angles_deg, tip_in_base_mm
from endocal.kinematics.constant_curvature import tip_pose_in_base
from endocal.kinematics.inverse import angles_from_bend_deg, bend_from_angles_rad, tip_in_base_from_angles_mm
from endocal.kinematics.probe_fk import ProbeJoints, ProbeKinematics, ProbePose, UnreachableError

__all__ = [
    "ProbeJoints",
    "ProbeKinematics",
    "ProbePose",
    "UnreachableError",
    "angles_from_bend_deg",
    "bend_from_angles_rad",
    "bending_angles_deg",
    "tip_in_base_from_angles_mm",
    "tip_in_base_mm",
    "tip_pose_in_base",
]
