"""Twist ``delta`` of the bending planes (thesis, section 2.3 and figure 6 B).

The thesis corrects a misalignment between the bending planes and the tendon attachment with
one deviation angle ``delta``, found by an optimisation under three assumptions, which we
encode as follows (the summary states them in prose only):

* the AP and ML planes stay *perpendicular*: one rotation ``delta`` about the probe axis turns
  both standard planes, ``p' = Rz(-delta) p`` (counter-clockwise about +z positive, the sign
  convention of the half-plane deviations);
* the tendons act *independently*: in the rotated frame a sweep of one knob leaves the other
  axis's eq. 1 angle at zero, so we minimise the mean squared cross-talk
  ``mean(theta_second'^2)`` over first-knob sweeps plus ``mean(theta_first'^2)`` over
  second-knob sweeps (eq. 1 angles, thesis eq. 1, of the rotated tip positions);
* the *ML range is symmetric*: the mean peak of ``theta_second'`` over ``x+`` sweeps and the
  mean trough over ``x-`` sweeps cancel. With a single unknown a hard constraint would fix
  ``delta`` by itself, so it enters as a penalty ``symmetry_weight * (peak + trough)^2``.

With all four half-planes twisted by the same angle, that angle zeroes every term, so the
fit recovers it exactly; with unequal twists ``delta`` is the compromise the thesis uses.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize_scalar

from endocal.kinematics.bending import bending_angles_deg
from endocal.planes.halfplanes import CalibrationError
from endocal.planes.segment import Sweep


@dataclass(frozen=True)
class DeltaFit:
    """Result of the thesis's delta optimisation.

    Attributes
    ----------
    delta_deg : float
        Twist of both bending planes about the probe axis, degrees (counter-clockwise about +z).
    cost_deg2 : float
        Objective at the optimum, deg^2.
    crosstalk_first_rms_deg, crosstalk_second_rms_deg : float
        RMS of the other axis's eq. 1 angle during first-knob / second-knob sweeps, after
        rotating by ``delta``, degrees.
    ml_asymmetry_deg : float
        Mean ``x+`` peak plus mean ``x-`` trough of the second-axis angle after rotation, degrees.
    """

    delta_deg: float
    cost_deg2: float
    crosstalk_first_rms_deg: float
    crosstalk_second_rms_deg: float
    ml_asymmetry_deg: float


def _rotated_angles(tip_in_base_mm: np.ndarray, delta_deg: float) -> tuple[np.ndarray, np.ndarray]:
    c, s = np.cos(np.radians(delta_deg)), np.sin(np.radians(delta_deg))
    p = tip_in_base_mm
    rotated = np.stack([c * p[:, 0] + s * p[:, 1], -s * p[:, 0] + c * p[:, 1], p[:, 2]], axis=1)  # Rz(-delta) p
    return bending_angles_deg(rotated)  # thesis eq. 1 in the twisted frame


def fit_delta(
    sweeps: Sequence[Sweep],
    *,
    symmetry_weight: float = 1.0,
    bounds_deg: tuple[float, float] = (-45.0, 45.0),
    around_deg: float | None = None,
) -> DeltaFit:
    """Fit the bending-plane twist ``delta`` (thesis, section 2.3).

    Parameters
    ----------
    sweeps : sequence of Sweep
        Single-knob sweeps; at least one of each knob and one of each sign of the second knob
        (``x+`` and ``x-``) when ``symmetry_weight > 0``.
    symmetry_weight : float
        Weight of the squared ML-range asymmetry against the mean squared cross-talk (both deg^2).
    bounds_deg : (float, float)
        Search interval for ``delta``, degrees.
    around_deg : float, optional
        Skip the coarse scan and search only within 5 deg of this value (for bootstrap
        replicates, started from the full-data estimate), degrees.

    Returns
    -------
    DeltaFit

    Raises
    ------
    CalibrationError
        A knob has no sweep (or ``x+``/``x-`` is missing while the symmetry term is on).
    """
    groups = {h: [s.tip_in_base_mm for s in sweeps if s.half_plane == h] for h in ("y+", "y-", "x+", "x-")}
    first = [p for h in ("y+", "y-") for p in groups[h]]
    second = [p for h in ("x+", "x-") for p in groups[h]]
    if not first or not second:
        raise CalibrationError("the delta fit needs sweeps of both knobs (found "
                               f"{len(first)} first-knob and {len(second)} second-knob sweeps)")
    if symmetry_weight > 0 and not (groups["x+"] and groups["x-"]):
        raise CalibrationError("the delta fit's symmetric-ML-range term needs sweeps of both x+ and x-")
    p_first, p_second = np.concatenate(first), np.concatenate(second)

    def terms(delta: float) -> tuple[float, float, float]:
        _, cross_first = _rotated_angles(p_first, delta)
        cross_second, _ = _rotated_angles(p_second, delta)
        asym = 0.0
        if symmetry_weight > 0:
            peak = np.mean([_rotated_angles(p, delta)[1].max() for p in groups["x+"]])
            trough = np.mean([_rotated_angles(p, delta)[1].min() for p in groups["x-"]])
            asym = float(peak + trough)
        return float(np.mean(cross_first**2)), float(np.mean(cross_second**2)), asym

    def cost(delta: float) -> float:
        a, b, asym = terms(delta)
        return a + b + symmetry_weight * asym**2

    lo, hi = bounds_deg
    if around_deg is None:
        grid = np.arange(lo, hi + 1e-9, 1.0)  # coarse scan first: the cost is not convex over +-45 deg
        best, half_width = grid[int(np.argmin([cost(d) for d in grid]))], 1.0
    else:
        best, half_width = float(around_deg), 5.0
    res = minimize_scalar(cost, bounds=(max(lo, best - half_width), min(hi, best + half_width)), method="bounded",
                          options={"xatol": 1e-7})
    delta = float(res.x)
    a, b, asym = terms(delta)
    return DeltaFit(delta_deg=delta, cost_deg2=float(res.fun), crosstalk_first_rms_deg=float(np.sqrt(a)),
                    crosstalk_second_rms_deg=float(np.sqrt(b)), ml_asymmetry_deg=asym)
