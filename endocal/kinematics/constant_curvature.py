"""Constant-curvature forward map of the bending section.

The bending state is the *bending vector* ``b = alpha * (cos phi, sin phi)`` in the base
``x-y`` plane, in radians: ``alpha`` is the total angle the tip tangent turns through and
``phi`` the direction of bending. Under constant curvature (thesis section 2.3; Webster &
Jones 2010) an arc of length ``L`` gives

    tip = (L / alpha) * ((1 - cos alpha) cos phi, (1 - cos alpha) sin phi, sin alpha)

and the tip frame is the base frame rotated by ``alpha`` about ``(-sin phi, cos phi, 0)``,
i.e. by the rotation vector ``(-b_y, b_x, 0)``.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation


def tip_pose_in_base(bend_x_rad: np.ndarray, bend_y_rad: np.ndarray, length_mm: float) -> tuple[np.ndarray, Rotation]:
    """Tip position and orientation in the base frame for a constant-curvature arc.

    Parameters
    ----------
    bend_x_rad, bend_y_rad : (n,) arrays
        Components of the bending vector in radians (bending towards +x and +y).
    length_mm : float
        Arc length of the bending section, mm.

    Returns
    -------
    tip_in_base_mm : (n, 3) array
    tip2base : scipy Rotation of length n
    """
    bx = np.atleast_1d(np.asarray(bend_x_rad, float))
    by = np.atleast_1d(np.asarray(bend_y_rad, float))
    alpha = np.hypot(bx, by)
    small = alpha < 1e-4
    safe = np.where(small, 1.0, alpha)
    # (1 - cos a)/a^2 and sin(a)/a, with their series where a -> 0 to stay exact near straight.
    one_minus_cos_over_a2 = np.where(small, 0.5 - alpha**2 / 24.0, (1.0 - np.cos(safe)) / safe**2)
    sin_over_a = np.where(small, 1.0 - alpha**2 / 6.0, np.sin(safe) / safe)
    tip = np.empty((bx.size, 3))
    tip[:, 0] = length_mm * one_minus_cos_over_a2 * bx
    tip[:, 1] = length_mm * one_minus_cos_over_a2 * by
    tip[:, 2] = length_mm * sin_over_a
    rotvec = np.stack([-by, bx, np.zeros_like(bx)], axis=1)
    return tip, Rotation.from_rotvec(rotvec)
