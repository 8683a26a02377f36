"""Inverse of the projected bending angles: eq. 1 angles -> bending vector -> tip position.

The thesis's equation 1 (see :mod:`endocal.kinematics.bending`) measures the angle of the
tip position ``P`` (in the base frame) projected on the two standard planes:

    theta_first  = atan2(p_y, p_z)      (y-z plane, first bending axis)       (thesis, eq. 1)
    theta_second = atan2(p_x, p_z)      (x-z plane, second bending axis)

Each angle fixes a plane through the base ``x`` (resp. ``y``) axis; the tip lies on their
intersection, so the two angles give the *chord* direction ``c`` from base to tip:

    c ~ s * (cos t1 sin t2,  sin t1 cos t2,  cos t1 cos t2),   s = sign(cos t1)

(``s`` picks the half-line on which ``atan2`` returns the given angles; ``cos t1`` and
``cos t2`` must have the same sign, since both carry the sign of ``p_z``). Under constant
curvature (thesis section 2.3) the chord of an arc bent by ``alpha`` towards azimuth
``phi`` leaves the base at ``alpha / 2`` from ``z`` in the direction ``phi``, so

    alpha = 2 * angle(c, z),   phi = atan2(c_y, c_x),   b = alpha * (cos phi, sin phi)

and the tip follows from :func:`endocal.kinematics.constant_curvature.tip_pose_in_base`.
Everything here works in radians inside and takes/returns degrees at the edges, as named.
"""

from __future__ import annotations

import numpy as np

from endocal.errors import LimitError
from endocal.kinematics.constant_curvature import tip_pose_in_base

#: Bend (rad) at which the lateral tip offset ``L (1 - cos a) / a`` of a constant-curvature arc
#: peaks (root of ``a sin a = 1 - cos a``). Beyond it two bends give the same lateral offset, so
#: position-only inverse kinematics is unique only for ``alpha`` below this value (133.56 deg).
MAX_UNIQUE_BEND_RAD = 2.3311223704144226


def chord_direction_in_base(theta_first_deg: np.ndarray, theta_second_deg: np.ndarray) -> np.ndarray:
    """Unit chord direction (base -> tip) whose projected bending angles are the given ones.

    Parameters
    ----------
    theta_first_deg, theta_second_deg : (n,) arrays or scalars
        Signed eq. 1 angles of the first (y-z plane) and second (x-z plane) axis, degrees,
        each in ``(-180, 180]``.

    Returns
    -------
    (n, 3) array
        Unit vectors in the base frame (thesis eq. 1 inverted, see module docstring).

    Raises
    ------
    LimitError
        The pair is not the projection of any direction: the angles sit on opposite
        sides of 90 deg (``cos`` of different signs) or one of them is exactly +-90 deg.
    """
    t1 = np.radians(np.atleast_1d(np.asarray(theta_first_deg, float)))
    t2 = np.radians(np.atleast_1d(np.asarray(theta_second_deg, float)))
    t1, t2 = np.broadcast_arrays(t1, t2)
    c1, s1, c2, s2 = np.cos(t1), np.sin(t1), np.cos(t2), np.sin(t2)
    bad = ~(c1 * c2 > 0.0)
    if np.any(bad):
        i = int(np.flatnonzero(bad)[0])
        raise LimitError(
            f"bending angles ({np.degrees(t1[i]):.3f}, {np.degrees(t2[i]):.3f}) deg are not the eq. 1 projections "
            "of any tip position: both must lie on the same side of +-90 deg (same sign of the tip's z)"
        )
    sign = np.sign(c1)
    c = sign[:, None] * np.stack([c1 * s2, s1 * c2, c1 * c2], axis=1)
    return c / np.linalg.norm(c, axis=1, keepdims=True)


def bend_from_angles_rad(theta_first_deg: np.ndarray, theta_second_deg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Constant-curvature bending vector from the two eq. 1 angles.

    Parameters
    ----------
    theta_first_deg, theta_second_deg : (n,) arrays or scalars
        Signed eq. 1 angles (thesis eq. 1), degrees.

    Returns
    -------
    bend_x_rad, bend_y_rad : (n,) arrays
        ``b = alpha (cos phi, sin phi)`` in radians, with ``alpha`` twice the chord's angle
        from ``z`` (constant curvature: the chord bisects the tip tangent turn).
    """
    c = chord_direction_in_base(theta_first_deg, theta_second_deg)
    rho = np.hypot(c[:, 0], c[:, 1])
    half_alpha = np.arctan2(rho, c[:, 2])
    # alpha / rho -> 2 / c_z as rho -> 0: use the ratio only where it is well defined.
    safe = rho > 1e-12
    scale = np.where(safe, 2.0 * half_alpha / np.where(safe, rho, 1.0), 2.0 / np.where(safe, 1.0, c[:, 2]))
    return scale * c[:, 0], scale * c[:, 1]


def angles_from_bend_deg(bend_x_rad: np.ndarray, bend_y_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 1 angles of the constant-curvature arc with bending vector ``b`` (forward map).

    Parameters
    ----------
    bend_x_rad, bend_y_rad : (n,) arrays or scalars
        Bending vector, radians.

    Returns
    -------
    theta_first_deg, theta_second_deg : (n,) arrays
        Thesis eq. 1 (signed) applied to the chord, which leaves the base at ``alpha / 2``.
    """
    bx = np.atleast_1d(np.asarray(bend_x_rad, float))
    by = np.atleast_1d(np.asarray(bend_y_rad, float))
    alpha = np.hypot(bx, by)
    # chord direction = (sin(a/2) cos phi, sin(a/2) sin phi, cos(a/2)); sin(a/2)/a kept exact near 0.
    small = alpha < 1e-6
    half_sinc = np.where(small, 0.5 - alpha**2 / 48.0, np.sin(alpha / 2.0) / np.where(small, 1.0, alpha))
    cx, cy, cz = half_sinc * bx, half_sinc * by, np.cos(alpha / 2.0)
    return np.degrees(np.arctan2(cy, cz)), np.degrees(np.arctan2(cx, cz))  # thesis eq. 1


def tip_in_base_from_angles_mm(
    theta_first_deg: np.ndarray,
    theta_second_deg: np.ndarray,
    length_mm: float,
    max_bend_deg: float | None = None,
) -> np.ndarray:
    """Tip position in the base frame reached by a constant-curvature arc with the given eq. 1 angles.

    Parameters
    ----------
    theta_first_deg, theta_second_deg : (n,) arrays or scalars
        Signed eq. 1 angles (thesis eq. 1), degrees.
    length_mm : float
        Arc length of the bending section, mm.
    max_bend_deg : float, optional
        Largest total bend ``alpha`` the section can reach, degrees. ``None`` allows any
        bend below 360 deg.

    Returns
    -------
    (n, 3) array
        Tip position in the base frame, mm.

    Raises
    ------
    LimitError
        The angles are inconsistent (see :func:`chord_direction_in_base`) or ask for a bend
        beyond ``max_bend_deg``; the message gives the nearest reachable angles.
    """
    if not length_mm > 0:
        raise LimitError(f"length_mm must be positive, got {length_mm}")
    bx, by = bend_from_angles_rad(theta_first_deg, theta_second_deg)
    if max_bend_deg is not None:
        alpha = np.hypot(bx, by)
        over = alpha > np.radians(max_bend_deg) * (1.0 + 1e-12)
        if np.any(over):
            i = int(np.flatnonzero(over)[0])
            t1, t2 = np.broadcast_arrays(np.atleast_1d(theta_first_deg), np.atleast_1d(theta_second_deg))
            k = np.radians(max_bend_deg) / alpha[i]
            n1, n2 = angles_from_bend_deg(bx[i] * k, by[i] * k)
            raise LimitError(
                f"bending angles ({t1[i]:.3f}, {t2[i]:.3f}) deg need a bend of "
                f"{np.degrees(alpha[i]):.2f} deg, beyond max_bend_deg={max_bend_deg:g}; nearest reachable angles in the "
                f"same direction: ({n1[0]:.3f}, {n2[0]:.3f}) deg"
            )
    tip, _ = tip_pose_in_base(bx, by, length_mm)
    return tip


def lateral_offset_mm(bend_rad: np.ndarray, length_mm: float) -> np.ndarray:
    """Distance of a constant-curvature tip from the base ``z`` axis, ``L (1 - cos a) / a``, mm.

    Written as ``2 L sin^2(a/2) / a`` so it stays exact for small bends.
    """
    a = np.abs(np.asarray(bend_rad, float))
    safe = np.where(a > 0.0, a, 1.0)
    return np.where(a > 0.0, 2.0 * length_mm * np.sin(safe / 2.0) ** 2 / safe, 0.0)


def bend_from_lateral_offset_rad(offset_mm: np.ndarray, length_mm: float) -> np.ndarray:
    """Total bend ``alpha`` whose constant-curvature tip sits ``offset_mm`` off the base axis.

    Parameters
    ----------
    offset_mm : (n,) array
        Lateral distance of the tip from the base ``z`` axis, mm, in
        ``[0, lateral_offset_mm(MAX_UNIQUE_BEND_RAD, length_mm)]``.
    length_mm : float
        Arc length, mm.

    Returns
    -------
    (n,) array
        ``alpha`` in ``[0, MAX_UNIQUE_BEND_RAD]`` radians (the branch where the offset grows
        with the bend), solved by bisection to machine precision.

    Raises
    ------
    LimitError
        An offset is beyond the largest the arc can reach.
    """
    rho = np.atleast_1d(np.asarray(offset_mm, float))
    rho_max = float(lateral_offset_mm(MAX_UNIQUE_BEND_RAD, length_mm))
    if np.any(rho > rho_max * (1.0 + 1e-12)) or np.any(rho < 0):
        worst = float(rho[np.argmax(np.abs(rho))])
        raise LimitError(
            f"a tip {worst:.3f} mm off the base axis is out of reach of a {length_mm:g} mm bending section "
            f"(at most {rho_max:.3f} mm)"
        )
    lo = np.zeros_like(rho)
    hi = np.full_like(rho, MAX_UNIQUE_BEND_RAD)
    for _ in range(64):  # bisection: 2.33 * 2**-64 is far below double precision of alpha
        mid = 0.5 * (lo + hi)
        below = lateral_offset_mm(mid, length_mm) < rho
        lo = np.where(below, mid, lo)
        hi = np.where(below, hi, mid)
    return 0.5 * (lo + hi)
