"""Kinematics of the bending section: bending angles from sensor poses (thesis eq. 1) and
constant-curvature maps between bending state and tip pose."""

from endocal.kinematics.bending import bending_angles_deg, tip_in_base_mm
from endocal.kinematics.constant_curvature import tip_pose_in_base

__all__ = ["bending_angles_deg", "tip_in_base_mm", "tip_pose_in_base"]
