"""Bending-plane calibration: four half-plane SVD fits and deviation angles (duodenoscope paper,
eqs. 1-2), the orthogonal compensator (eqs. 3-4), the thesis's plane twist delta, and the
versioned ``planes.json``.

Typical use::

    seg = segment_planes_run(aligned, tracker, probe, run="run-1")
    cal = fit_planes(seg)
    first_deg, second_deg = cal.compensate(desired_first_deg, desired_second_deg)
    save_planes(cal, "planes.json")
"""

from endocal.planes.calibration import PlanesCalibration, fit_planes, fit_pooled
from endocal.planes.compensation import OrthogonalCompensator, compensation_matrix, residual_deviation, twisted_plane_bend_rad
from endocal.planes.delta import DeltaFit, fit_delta
from endocal.planes.halfplanes import HALF_PLANES, CalibrationError, HalfPlaneFit, fit_half_plane
from endocal.planes.io import FORMAT, VERSION, load_planes, planes_from_dict, planes_to_dict, save_planes
from endocal.planes.segment import Segmentation, Sweep, segment_planes_run, tip_in_base_from_tracker

__all__ = [
    "CalibrationError",
    "DeltaFit",
    "FORMAT",
    "HALF_PLANES",
    "HalfPlaneFit",
    "OrthogonalCompensator",
    "PlanesCalibration",
    "Segmentation",
    "Sweep",
    "VERSION",
    "compensation_matrix",
    "fit_delta",
    "fit_half_plane",
    "fit_planes",
    "fit_pooled",
    "load_planes",
    "planes_from_dict",
    "planes_to_dict",
    "residual_deviation",
    "save_planes",
    "segment_planes_run",
    "tip_in_base_from_tracker",
    "twisted_plane_bend_rad",
]
