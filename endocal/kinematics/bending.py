"""Projected bending angles from the tip and base sensor poses (thesis, eq. 1).

The thesis projects the tip position ``P``, expressed in the base frame ``O``, onto the
two standard bending planes and takes the angle of each projection from the probe axis:

    theta_ML = arccos(p_z / ||p_ML||),   theta_AP = arccos(p_z / ||p_AP||)      (thesis, eq. 1)

With endocal's axis convention (see :mod:`endocal.probe`) the first bending axis lives in
the ``y-z`` plane and the second in the ``x-z`` plane, so ``p_first = (p_y, p_z)`` and
``p_second = (p_x, p_z)``. ``arccos`` loses the sign and is ill-conditioned near zero
bend (its derivative diverges at 1), so we evaluate the same angle as
``atan2(p_y, p_z)`` / ``atan2(p_x, p_z)``: identical magnitude, signed towards the
positive half-plane, and well conditioned at every bend up to +-180 deg.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation


def tip_in_base_mm(
    tip_in_tracker_mm: np.ndarray, base_in_tracker_mm: np.ndarray, base2tracker_quat_wxyz: np.ndarray
) -> np.ndarray:
    """Tip sensor position expressed in the base sensor's frame.

    Parameters
    ----------
    tip_in_tracker_mm, base_in_tracker_mm : (n, 3) arrays
        Sensor positions in the tracker frame, mm.
    base2tracker_quat_wxyz : (n, 4) array
        Orientation of the base sensor in the tracker frame, scalar first.

    Returns
    -------
    (n, 3) array
        ``tip_in_base = base2tracker^-1 (tip - base)`` in mm.
    """
    base2tracker = Rotation.from_quat(np.asarray(base2tracker_quat_wxyz, float), scalar_first=True)
    delta = np.asarray(tip_in_tracker_mm, float) - np.asarray(base_in_tracker_mm, float)
    return base2tracker.inv().apply(delta)


def bending_angles_deg(tip_in_base: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Projected bending angles of the first (y-z plane) and second (x-z plane) axis.

    Parameters
    ----------
    tip_in_base : (n, 3) or (3,) array
        Tip position in the base frame, any length unit.

    Returns
    -------
    theta_first_deg, theta_second_deg : arrays of shape (n,) (or scalars)
        Thesis eq. 1, signed: positive towards ``+y`` (first) and ``+x`` (second), degrees.
    """
    p = np.asarray(tip_in_base, float)
    theta_first = np.degrees(np.arctan2(p[..., 1], p[..., 2]))  # thesis eq. 1, AP (y-z) plane
    theta_second = np.degrees(np.arctan2(p[..., 0], p[..., 2]))  # thesis eq. 1, ML (x-z) plane
    return theta_first, theta_second
