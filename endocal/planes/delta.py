"""Twist ``delta`` of the bending planes (thesis, section 2.3 and figure 6 B).

The thesis corrects a misalignment between the bending planes and the tendon attachment with
one deviation angle ``delta``, found by an optimisation under three assumptions, which we
encode as follows (the summary states them in prose only):

* the AP and ML planes stay *perpendicular*: one rotation ``delta`` about the probe axis turns
  both standard planes, ``p' = Rz(-delta) p`` (counter-clockwise about +z positive, the sign
  convention of the half-plane deviations);
* the tendons act *independently*: in the rotated frame a sweep of one knob does not move the
  other axis's eq. 1 angle, so we minimise the cross-talk: the within-sweep variance of
  ``theta_second'`` over first-knob sweeps plus that of ``theta_first'`` over second-knob sweeps
  (eq. 1 angles, thesis eq. 1, of the rotated tip positions). Variance about each sweep's mean
  rather than the mean square, so that a bend the other knob keeps from backlash (constant
  during the sweep) is not mistaken for cross-talk;
* the *ML range is symmetric*: the mean peak of ``theta_second'`` over ``x+`` sweeps and the
  mean trough over ``x-`` sweeps cancel. With a single unknown a hard constraint would fix
  ``delta`` by itself, so it enters as a penalty ``symmetry_weight * (peak + trough)^2``.
  Its slope in ``delta`` is small (turning the frame changes the peaks only through
  ``cos``), while sweeps of unequal amplitude make it degrees large, so at weight 1 it would
  decide ``delta`` alone and sweep-to-sweep amplitude jitter would move ``delta`` by degrees;
  the default 0.1 keeps it a tie-breaker to the cross-talk terms.

With all four half-planes twisted by the same angle, that angle zeroes every term, so the
fit recovers it exactly; with unequal twists ``delta`` is the compromise the thesis uses.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize_scalar

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
        Within-sweep standard deviation of the other axis's eq. 1 angle during first-knob /
        second-knob sweeps, after rotating by ``delta``, degrees.
    ml_asymmetry_deg : float
        Mean ``x+`` peak plus mean ``x-`` trough of the second-axis angle after rotation, degrees.
    """

    delta_deg: float
    cost_deg2: float
    crosstalk_first_rms_deg: float
    crosstalk_second_rms_deg: float
    ml_asymmetry_deg: float


def fit_delta(
    sweeps: Sequence[Sweep],
    *,
    symmetry_weight: float = 0.1,
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
    starts_first = np.cumsum([0] + [len(p) for p in first])[:-1]
    starts_second = np.cumsum([0] + [len(p) for p in second])[:-1]
    n_first, n_second = np.diff(np.r_[starts_first, len(p_first)]), np.diff(np.r_[starts_second, len(p_second)])
    p_plus = np.concatenate(groups["x+"]) if groups["x+"] else np.zeros((0, 3))
    p_minus = np.concatenate(groups["x-"]) if groups["x-"] else np.zeros((0, 3))
    starts_plus = np.cumsum([0] + [len(p) for p in groups["x+"]])[:-1]
    starts_minus = np.cumsum([0] + [len(p) for p in groups["x-"]])[:-1]

    def second_angle(p: np.ndarray, c: float, s: float) -> np.ndarray:
        return np.degrees(np.arctan2(c * p[:, 0] + s * p[:, 1], p[:, 2]))  # thesis eq. 1 (x-z) of Rz(-delta) p

    def within_sweep_variance(angle: np.ndarray, starts: np.ndarray, counts: np.ndarray) -> float:
        mean = np.repeat(np.add.reduceat(angle, starts) / counts, counts)
        return float(np.mean((angle - mean) ** 2))

    def terms(delta: float) -> tuple[float, float, float]:
        c, s = np.cos(np.radians(delta)), np.sin(np.radians(delta))
        cross_first = second_angle(p_first, c, s)
        cross_second = np.degrees(np.arctan2(-s * p_second[:, 0] + c * p_second[:, 1], p_second[:, 2]))  # eq. 1 (y-z)
        asym = 0.0
        if symmetry_weight > 0:
            peak = np.mean(np.maximum.reduceat(second_angle(p_plus, c, s), starts_plus))
            trough = np.mean(np.minimum.reduceat(second_angle(p_minus, c, s), starts_minus))
            asym = float(peak + trough)
        return (within_sweep_variance(cross_first, starts_first, n_first),
                within_sweep_variance(cross_second, starts_second, n_second), asym)

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
