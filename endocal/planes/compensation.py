"""Orthogonal compensation of twisted bending planes (duodenoscope paper, eqs. 3-4).

Model (duodenoscope paper, section 2.2, second hypothesis): the bend produced by both knobs is
the vector sum of what each knob alone produces, and a knob alone bends along its half-plane's
actual direction. With signed deviations ``d`` (see :mod:`endocal.planes.halfplanes`) the first
knob at signed angle ``t1`` contributes ``t1 (-sin d_y, cos d_y)`` and the second ``t2 (cos d_x,
sin d_x)`` to the bend direction in the base x-y plane, where ``d_y`` is the deviation of ``y+``
or ``y-`` and ``d_x`` that of ``x+`` or ``x-`` according to the signs of ``t1`` and ``t2``.
In the paper's ``(y, x)`` order the aligned output is

    [g(t_y_aligned)]   [ cos d_y   sin d_x ] [g(t_y)]
    [g(t_x_aligned)] = [-sin d_y   cos d_x ] [g(t_x)]

and the compensated input for a desired aligned output is its inverse

    [g(t_y), g(t_x)]^T = M(d_y, d_x)^-1 [g(t_y_aligned), g(t_x_aligned)]^T   (duodenoscope paper, eq. 3)

The paper writes the matrix with unsigned angles ``alpha_i, alpha_j`` (the signs were lost
with the layout); with signed deviations the one form above covers all four quadrants.
Which pair ``(d_y, d_x)`` applies is the quadrant rule (duodenoscope paper, eq. 4): the desired
direction is compared with the slopes of the four motion planes' traces on the x-y plane, i.e.
it is written as a non-negative combination of the two *actual* half-plane directions that
bracket it. We solve eq. 3 for each of the four pairs and keep the one whose solution has the
signs of that pair, which is exactly that sector test and stays continuous across sectors.

``g`` is how angles add. ``combine="bend_vector"`` (default) takes ``g(t) = t``: the bending
vectors of constant curvature add (endocal's simulator and the CC kinematics), so the inverse
is exact at every amplitude. ``combine="direction_sine"`` takes ``g = sin`` as printed in the
paper (it adds the x-y projections of the distal-end direction); the two agree to first order.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from endocal.errors import LimitError
from endocal.kinematics.constant_curvature import tip_pose_in_base
from endocal.planes.halfplanes import HALF_PLANES, NOMINAL_AZIMUTH_DEG, CalibrationError, HalfPlaneFit, fit_half_plane

COMBINE = ("bend_vector", "direction_sine")
_PAIRS = ((1, 1), (1, -1), (-1, -1), (-1, 1))  # (sign first, sign second): the four quadrants of eq. 4


def _check_deviations(deviation_signed_deg: Mapping[str, float]) -> dict[str, float]:
    missing = [h for h in HALF_PLANES if h not in deviation_signed_deg]
    extra = [h for h in deviation_signed_deg if h not in HALF_PLANES]
    if missing or extra:
        raise CalibrationError(
            f"deviations must be given for exactly {', '.join(HALF_PLANES)}; missing {missing}, unknown {extra}"
        )
    dev = {h: float(deviation_signed_deg[h]) for h in HALF_PLANES}
    bad = [h for h, d in dev.items() if not np.isfinite(d) or abs(d) >= 90.0]
    if bad:
        raise CalibrationError(f"signed deviations must be finite and within +-90 deg; bad: {', '.join(bad)}")
    # The quadrant rule needs the actual half-plane directions to keep their cyclic order
    # x+ < y+ < x- < y- with every gap below 180 deg, so that each pair brackets one sector.
    order = ("x+", "y+", "x-", "y-")
    az = [NOMINAL_AZIMUTH_DEG[h] + dev[h] for h in order]
    gaps = [(az[(i + 1) % 4] - az[i]) % 360.0 for i in range(4)]
    if not all(0.0 < g < 180.0 for g in gaps):
        raise CalibrationError(
            "the four half-plane directions do not alternate around the probe axis with gaps under 180 deg "
            f"(azimuths x+ {az[0]:.1f}, y+ {az[1]:.1f}, x- {az[2]:.1f}, y- {az[3]:.1f} deg): no orthogonal compensation exists"
        )
    return dev


def compensation_matrix(dev_y_deg: float, dev_x_deg: float) -> np.ndarray:
    """Eq. 3 matrix ``M`` (paper's ``(y, x)`` order) mapping input to aligned output.

    Parameters
    ----------
    dev_y_deg, dev_x_deg : float
        Signed deviations of the first-axis and second-axis half-planes in use, degrees.

    Returns
    -------
    (2, 2) array
        ``[[cos d_y, sin d_x], [-sin d_y, cos d_x]]`` (duodenoscope paper, eq. 3).
    """
    dy, dx = np.radians(dev_y_deg), np.radians(dev_x_deg)
    return np.array([[np.cos(dy), np.sin(dx)], [-np.sin(dy), np.cos(dx)]])


class OrthogonalCompensator:
    """Orthogonal compensator of the duodenoscope paper (eqs. 3-4) for four signed deviations.

    Parameters
    ----------
    deviation_signed_deg : mapping
        Signed deviation of each half-plane ``y+ y- x+ x-`` in degrees (counter-clockwise
        about +z positive), as fitted by :func:`endocal.planes.halfplanes.fit_half_plane`.
    combine : {"bend_vector", "direction_sine"}
        How the two knobs' angles add (see module docstring).
    """

    def __init__(self, deviation_signed_deg: Mapping[str, float], combine: str = "bend_vector"):
        if combine not in COMBINE:
            raise CalibrationError(f"unknown combine '{combine}': use one of {', '.join(COMBINE)}")
        self.deviation_signed_deg = _check_deviations(deviation_signed_deg)
        self.combine = combine

    def _g(self, angle_deg: np.ndarray) -> np.ndarray:
        return np.radians(angle_deg) if self.combine == "bend_vector" else np.sin(np.radians(angle_deg))

    def _g_inv(self, value: np.ndarray, what: str) -> np.ndarray:
        if self.combine == "bend_vector":
            return np.degrees(value)
        if np.any(np.abs(value) > 1.0 + 1e-12):
            raise LimitError(f"{what}: sin of the compensated angle would exceed 1 (|sin| = {np.max(np.abs(value)):.4f})")
        return np.degrees(np.arcsin(np.clip(value, -1.0, 1.0)))

    def _dev_pair(self, s1: int, s2: int) -> tuple[float, float]:
        d = self.deviation_signed_deg
        return d["y+" if s1 > 0 else "y-"], d["x+" if s2 > 0 else "x-"]

    def forward(self, first_deg, second_deg) -> tuple[np.ndarray, np.ndarray]:
        """Aligned (standard-frame) angles the twisted planes produce for input angles.

        Parameters
        ----------
        first_deg, second_deg : (n,) arrays or scalars
            Input angles of the first and second axis, degrees.

        Returns
        -------
        first_aligned_deg, second_aligned_deg : (n,) arrays
            ``M(d_y, d_x)`` of eq. 3 applied, the pair picked by the inputs' signs.
        """
        t1, t2 = (np.atleast_1d(np.asarray(v, float)) for v in np.broadcast_arrays(first_deg, second_deg))
        g = np.stack([self._g(t1), self._g(t2)])
        out = np.empty_like(g)
        for s1, s2 in _PAIRS:
            mask = ((t1 >= 0) if s1 > 0 else (t1 < 0)) & ((t2 >= 0) if s2 > 0 else (t2 < 0))
            out[:, mask] = compensation_matrix(*self._dev_pair(s1, s2)) @ g[:, mask]
        return self._g_inv(out[0], "forward"), self._g_inv(out[1], "forward")

    def compensate(self, first_aligned_deg, second_aligned_deg) -> tuple[np.ndarray, np.ndarray]:
        """Input angles that bend the tip to the desired aligned angles (eqs. 3-4).

        Parameters
        ----------
        first_aligned_deg, second_aligned_deg : (n,) arrays or scalars
            Desired angles in the standard planes (first axis: y-z, second: x-z), degrees.

        Returns
        -------
        first_deg, second_deg : (n,) arrays
            Angles to command instead (then through the hysteresis inverse, if any).

        Raises
        ------
        LimitError
            ``combine="direction_sine"`` and a target needs ``|sin| > 1``.
        """
        a1, a2 = (np.atleast_1d(np.asarray(v, float)) for v in np.broadcast_arrays(first_aligned_deg, second_aligned_deg))
        target = np.stack([self._g(a1), self._g(a2)])
        scale = np.maximum(np.abs(target).max(axis=0), 1e-300)
        result = np.full_like(target, np.nan)
        for s1, s2 in _PAIRS:  # duodenoscope eq. 4: the sector whose two half-planes bracket the target
            sol = np.linalg.solve(compensation_matrix(*self._dev_pair(s1, s2)), target)  # eq. 3
            ok = (s1 * sol[0] >= -1e-12 * scale) & (s2 * sol[1] >= -1e-12 * scale) & np.isnan(result[0])
            result[:, ok] = sol[:, ok]
        if np.any(np.isnan(result)):  # cannot happen once _check_deviations passed; kept as a guard on NaN input
            raise CalibrationError("compensation found no quadrant for some target (are the inputs finite?)")
        return self._g_inv(result[0], "compensate"), self._g_inv(result[1], "compensate")


def twisted_plane_bend_rad(first_deg, second_deg, deviation_signed_deg: Mapping[str, float], gain: float = 2.0):
    """Constant-curvature bending vector of knobs acting along twisted half-planes.

    The plant the compensator corrects (duodenoscope paper, section 2.2 hypotheses), used to
    regenerate motion after compensation: ``b = gain * (t1 u(psi_y) + t2 u(psi_x))`` with
    ``psi`` the actual azimuths of the half-planes selected by the signs of ``t1, t2``.

    Parameters
    ----------
    first_deg, second_deg : (n,) arrays
        Per-axis angles, degrees (eq. 1 units: a planar arc's eq. 1 angle is half its bend,
        hence the default ``gain`` of 2).
    deviation_signed_deg : mapping
        Signed deviations of ``y+ y- x+ x-``, degrees.
    gain : float
        Total bend per unit angle.

    Returns
    -------
    bend_x_rad, bend_y_rad : (n,) arrays
    """
    dev = _check_deviations(deviation_signed_deg)
    t1, t2 = (np.radians(np.atleast_1d(np.asarray(v, float))) for v in np.broadcast_arrays(first_deg, second_deg))
    d1 = np.radians(np.where(t1 >= 0, dev["y+"], dev["y-"]))
    d2 = np.radians(np.where(t2 >= 0, dev["x+"], dev["x-"]))
    bx = gain * (-t1 * np.sin(d1) + t2 * np.cos(d2))
    by = gain * (t1 * np.cos(d1) + t2 * np.sin(d2))
    return bx, by


def residual_deviation(
    compensator: OrthogonalCompensator,
    true_deviation_signed_deg: Mapping[str, float],
    amplitude_deg: float = 30.0,
    n_points: int = 40,
) -> dict[str, HalfPlaneFit]:
    """Deviation left after compensation, regenerating each half-plane sweep (paper's figure 8, after).

    For every half-plane, a desired sweep along its *standard* half-plane (0 to
    ``amplitude_deg``) is compensated, played through :func:`twisted_plane_bend_rad` with the
    true deviations, turned into tip directions by constant curvature, and fitted again with
    :func:`endocal.planes.halfplanes.fit_half_plane` (duodenoscope eqs. 1-2).

    Parameters
    ----------
    compensator : OrthogonalCompensator
    true_deviation_signed_deg : mapping
        The deviations of the plant the compensated commands are played on, degrees.
    amplitude_deg : float
        Largest desired angle of the regenerated sweeps (eq. 1 units), degrees.
    n_points : int
        Samples per sweep.

    Returns
    -------
    dict
        Half-plane name -> :class:`HalfPlaneFit` of the compensated motion.
    """
    fits = {}
    ramp = np.linspace(0.0, amplitude_deg, n_points)[1:]
    zero = np.zeros_like(ramp)
    for h in HALF_PLANES:
        sign = 1.0 if h.endswith("+") else -1.0
        desired = (sign * ramp, zero) if h.startswith("y") else (zero, sign * ramp)
        cmd1, cmd2 = compensator.compensate(*desired)
        bx, by = twisted_plane_bend_rad(cmd1, cmd2, true_deviation_signed_deg)
        _, tip2base = tip_pose_in_base(bx, by, 1.0)
        fits[h] = fit_half_plane(tip2base.apply([0.0, 0.0, 1.0]), h, min_excursion_deg=0.0, what="regenerated tip directions")
    return fits
