"""How many units the paired test needs: the power of the sign-flip test at the effect seen.

``validate`` compares a candidate with the model as it stands unit by unit (half-cycles of
the validation record, :mod:`endocal.validation.units`): each unit's loss differential
``D_u = sum_t e_base(t)^2 - e_cand(t)^2`` and the one-sided sign-flip randomisation test of
their total (:func:`endocal.validation.paired.unit_test`). When a candidate lowers the
error but not significantly, the question a user asks next is how much more data would
settle it. This module answers it for the test that is used.

Power of the sign-flip test (normal approximation)
    Under the null hypothesis the signs of the ``D_u`` are exchangeable, so the total
    ``T = sum_u D_u`` has randomisation mean 0 and variance ``sum_u D_u^2``; the test
    rejects at one-sided level ``a`` when ``T >= z_a sqrt(sum_u D_u^2)``
    (Fisher's randomisation test; for many units the randomisation distribution is close
    to normal). If the ``N`` units of a longer record are drawn like those seen, with mean
    ``mu`` and standard deviation ``sigma``, then ``T ~ N(N mu, N sigma^2)`` and
    ``sum D_u^2 ~= N (mu^2 + sigma^2)``, so the power is::

        P(reject) = Phi( sqrt(N) mu / sigma - z_a sqrt(1 + mu^2 / sigma^2) )

    and power ``1 - b`` needs::

        sqrt(N) = (z_b sigma + z_a sqrt(sigma^2 + mu^2)) / mu.

    (The ``mu^2`` under the root is what sets this test apart from a t-test: the
    randomisation variance includes the effect itself.) The exact test cannot go below
    ``2^-N`` (every unit in favour), which bounds ``N`` from below as
    :func:`~endocal.validation.paired.min_units_for` says.

Family-wise level
    ``validate`` Holm-corrects over the ``m`` candidates tested; a candidate is significant
    at any rank once its raw p-value is below ``alpha / m`` (Holm's first step is
    Bonferroni's), so ``a = alpha / m`` is what a length must reach.

The estimate holds "at the gain seen": a longer record of the same kind, whose units
differ as these do. It is tested on simulated differentials in ``tests/test_validation_power.py``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import ndtri  # norm.ppf, without scipy.stats' import (0.2 s)

from endocal.validation.paired import min_units_for

#: Power a designed length aims at: the chance that the test reaches its level if the effect
#: is as seen (80 %, the usual design target: a one-in-five chance of another inconclusive record).
POWER = 0.8


def unit_differentials(err_base: np.ndarray, err_cand: np.ndarray, bounds) -> np.ndarray:
    """Per-unit loss differentials ``D_u = sum_{t in u} e_base(t)^2 - e_cand(t)^2`` (deg^2).

    Parameters
    ----------
    err_base, err_cand : (n,) arrays
        Errors ``pred - meas`` (deg) of the model as it stands and of the candidate.
    bounds : sequence of (int, int)
        ``[start, stop)`` of each unit (:attr:`endocal.validation.units.Units.bounds`).
    """
    d = np.asarray(err_base, float) ** 2 - np.asarray(err_cand, float) ** 2
    return np.array([d[a:b].sum() for a, b in bounds], dtype=float)


def units_for_power(mean: float, sd: float, alpha: float, n_candidates: int = 1, power: float = POWER) -> int | None:
    """Units of the kind seen that make the sign-flip test significant with probability ``power``.

    Parameters
    ----------
    mean, sd : float
        Mean and standard deviation of the per-unit loss differential ``D_u`` (deg^2).
    alpha : float
        Family-wise level; the test must reach ``alpha / n_candidates`` (Holm at any rank).
    n_candidates : int
        Candidates tested together.
    power : float
        Probability of reaching the level if the effect is as seen.

    Returns
    -------
    int or None
        The number of units (at least :func:`~endocal.validation.paired.min_units_for`); None when ``mean <= 0``: the
        candidate does not lower the error on average, and no length makes it significant.
    """
    if not (np.isfinite(mean) and np.isfinite(sd)) or mean <= 0:
        return None
    floor = min_units_for(n_candidates, alpha)  # the exact test's 2^-N
    if sd <= 0:
        return floor
    z_a = float(ndtri(1.0 - alpha / max(n_candidates, 1)))
    z_b = float(ndtri(power))
    root = (z_b * sd + z_a * math.hypot(sd, mean)) / mean
    return max(floor, int(math.ceil(root * root)))


@dataclass(frozen=True)
class PowerEstimate:
    """How many units would settle a candidate at the gain seen.

    Attributes
    ----------
    units_needed : int or None
        Units of the kind seen for the paired test to reach its family-wise level with
        probability :data:`POWER`; None when no length will (the candidate does not lower
        the error on average).
    units_seen : int
        Units of the validation record.
    mean_deg2, sd_deg2 : float
        Mean and standard deviation of the per-unit loss differential (deg^2).
    power : float
        The probability aimed at.
    """

    units_needed: int | None
    units_seen: int
    mean_deg2: float
    sd_deg2: float
    power: float = POWER

    def to_dict(self) -> dict:
        return {"units_needed": self.units_needed, "units_seen": self.units_seen, "mean_deg2": self.mean_deg2,
                "sd_deg2": self.sd_deg2, "power": self.power}


def estimate_power(err_base: np.ndarray, err_cand: np.ndarray, bounds, alpha: float, n_candidates: int = 1,
                   power: float = POWER) -> PowerEstimate:
    """:func:`units_for_power` of the differentials of two models' errors over the units ``bounds``.

    Parameters
    ----------
    err_base, err_cand : (n,) arrays
        Validation errors (deg) of the model as it stands and of the candidate.
    bounds : sequence of (int, int)
        The units of the validation record.
    alpha, n_candidates, power
        As :func:`units_for_power`.
    """
    d = unit_differentials(err_base, err_cand, bounds)
    mean = float(d.mean()) if d.size else 0.0
    sd = float(d.std(ddof=1)) if d.size > 1 else 0.0
    return PowerEstimate(units_for_power(mean, sd, alpha, n_candidates, power), int(d.size), mean, sd, power)


def evidence_phrase(estimate: PowerEstimate, kind: str, gain_pct: float, min_gain_pct: float) -> str:
    """What more data would do for a candidate that is not significant, in words.

    ``about 40 half-cycles would make it significant at this gain``; or, when no length
    will, why: it does not lower the error, or its gain is under the bar a suspect must
    clear (then significance alone would not list it: the gain is within the noise).
    """
    if estimate.units_needed is None or gain_pct <= 0:
        return "no length will: it does not lower the error on average"
    if gain_pct < min_gain_pct:
        return f"no length will make it a suspect: its gain is under the {min_gain_pct:g} % bar"
    return (f"about {estimate.units_needed} {kind}s would make it significant at this gain "
            f"({100 * estimate.power:.0f} % power)")
