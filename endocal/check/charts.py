"""Control charts of a probe's check figures: individuals/moving-range and EWMA, and the probe's state.

The radiotherapy QA practice (Pawlicki et al., Med Phys 2005): limits from the first checks after
a calibration (here :data:`BASELINE_CHECKS` = 10), an individuals/moving-range (I-MR) chart that
catches a jump and an EWMA that catches a slow shift fixed tolerances miss.

Individuals/moving-range (Montgomery, *Introduction to Statistical Quality Control*, 6th ed.,
sec. 6.4): centre ``mu`` = mean of the baseline, ``MR = |x_i - x_(i-1)|``,
``sigma = MR_bar / d2`` with ``d2 = 1.128``, so the individuals limits ``mu +- 3 sigma`` are the
familiar ``mu +- 2.66 MR_bar``; the moving-range chart's upper limit is ``D4 MR_bar = 3.267 MR_bar``.

EWMA (Montgomery sec. 9.2, eqs. 9.22-9.26): ``z_i = lambda x_i + (1 - lambda) z_(i-1)``,
``z_0 = mu``, ``lambda = 0.2``, with the exact time-varying limits
``mu +- L sigma sqrt(lambda / (2 - lambda) (1 - (1 - lambda)^(2 i)))``.

Two departures from the textbook, both to hold the false-alarm bar (issue 34: 50 checks of an
unchanged probe raise at most one false alarm) with a baseline of only ten checks:

- **The baseline mean is an estimate.** Its error, ``sigma / sqrt(m)``, is as large as the
  EWMA's own spread (``sigma sqrt(lambda / (2 - lambda)) = 0.33 sigma``, against ``0.32 sigma``
  for ``m = 10``), and it does not average out: every later EWMA point carries it. The limits
  here are those of the deviation from the *estimated* centre, exactly:
  ``Var(x_i - mu_hat) = sigma^2 (1 + 1/m)`` for the individuals and
  ``Var(z_i - mu_hat) = sigma^2 [lambda / (2 - lambda) (1 - (1 - lambda)^(2 i)) + (1 - (1 - lambda)^i)^2 / m]``
  for the EWMA started at ``mu_hat`` (the baseline mean's error carried with weight
  ``1 - (1 - lambda)^i``).
- **Sigma is never below the figure's resolution** (:data:`RESOLUTION`): a figure that repeats
  to 0.01 deg on the simulator would otherwise flag a 0.05 deg change no tracker resolves and no
  clinician would act on. Where a figure's noise is at or below its resolution (every figure on
  the simulator), the limits rest on the resolution and the bar holds (tests/test_check_charts.py:
  99 of 100 simulated probes); where it is above, sigma comes from nine moving ranges, is
  underestimated often enough to flag 1.8 of 50 checks of one such figure on average, and ten such
  figures cannot meet the bar with a ten-check baseline.

``L = 3`` rather than 2.7: with sigma known, an EWMA (``lambda = 0.2``, exact limits) of an
unchanged figure first crosses ``L = 3`` after 555 checks on average, ``L = 2.7`` after 232
(Monte Carlo, 20,000 runs, 2026-11-28); the individuals chart's 3 sigma after 370. With ten
figures per check, ``L = 2.7`` alone would spend the bar's one false alarm in 50 checks on the
EWMAs (``10 * 50 / 232 = 2.2``); ``L = 3`` spends 0.9 of it, and a worn probe still moves its
figures by many sigmas (tests/test_check_wear.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

#: Checks after a calibration whose figures set the limits (Pawlicki et al. 2005: 8-12).
BASELINE_CHECKS = 10
#: EWMA weight (issue 34) and width of its limits in sigmas (see the module docstring).
EWMA_LAMBDA = 0.2
EWMA_L = 3.0
#: Individuals limits in sigmas ("a point beyond 3 sigma" is out of control).
I_SIGMAS = 3.0
#: Control-chart constants for moving ranges of two (Montgomery, appendix table VI).
D2 = 1.128
D4 = 3.267
#: Smallest sigma (in the figure's unit) by figure suffix: the resolution of what a check measures.
#: Bend-derived figures (deg of bend): 0.1 deg, the orientation noise of one EM-tracker frame (the
#: simulated Aurora's, configs/sim-default.toml); the bend reached is read at the loop's ends, a
#: few frames, and a tenth of a degree is a tenth of the smallest bend loss worn endoscopes show
#: (Rozeboom et al. 2016). The dead band (deg of knob): the knob's travel between two tracker
#: frames at the check's speed (4 * 45 deg / 14 s = 12.9 deg/s at 40 Hz: 0.32 deg): when the tip
#: starts to move is known to one frame, however many checks agree more closely.
RESOLUTION = {"rmse_deg": 0.1, "loop_width_deg": 0.1, "bend_pos_deg": 0.1, "bend_neg_deg": 0.1,
              "dead_band_deg": 0.32}

STATES = ("baseline", "in control", "drifting", "out of control")


def resolution_of(figure: str) -> float:
    """The sigma floor of a figure column (``ap_loop_width_deg`` -> 0.1), 0 for an unknown one."""
    for suffix, res in RESOLUTION.items():
        if figure.endswith(suffix):
            return res
    return 0.0


@dataclass
class Chart:
    """The I-MR and EWMA charts of one figure over the checks of one calibration.

    Attributes
    ----------
    figure : str
        Column name, e.g. ``ap_dead_band_deg``.
    x : (n,) array
        The figure at each check since the calibration, oldest first.
    mu, sigma, mr_bar : float
        Baseline centre, sigma (``MR_bar / d2``, floored at the resolution) and mean moving range;
        NaN while fewer than :data:`BASELINE_CHECKS` checks exist.
    i_lo, i_hi : (n,) arrays
        Individuals limits (NaN over the baseline).
    mr : (n,) array
        Moving ranges (NaN at the first check); ``mr_ucl`` its upper limit.
    z, z_lo, z_hi : (n,) arrays
        EWMA and its exact limits (NaN over the baseline).
    """

    figure: str
    x: np.ndarray
    mu: float = math.nan
    sigma: float = math.nan
    mr_bar: float = math.nan
    mr_ucl: float = math.nan
    i_lo: np.ndarray = field(default=None)
    i_hi: np.ndarray = field(default=None)
    mr: np.ndarray = field(default=None)
    z: np.ndarray = field(default=None)
    z_lo: np.ndarray = field(default=None)
    z_hi: np.ndarray = field(default=None)

    @property
    def ready(self) -> bool:
        return bool(np.isfinite(self.sigma))

    @property
    def beyond_i(self) -> np.ndarray:
        """Checks whose point lies beyond the individuals limits (False over the baseline)."""
        with np.errstate(invalid="ignore"):
            return (self.x < self.i_lo) | (self.x > self.i_hi)

    @property
    def beyond_ewma(self) -> np.ndarray:
        with np.errstate(invalid="ignore"):
            return (self.z < self.z_lo) | (self.z > self.z_hi)

    @property
    def beyond_mr(self) -> np.ndarray:
        with np.errstate(invalid="ignore"):
            return self.mr > self.mr_ucl

    def states(self) -> list[str]:
        """The state of every check by this figure alone, oldest first (computed once)."""
        cached = self.__dict__.get("_states")
        if cached is None or len(cached) != self.x.size:
            n = self.x.size
            if not self.ready:
                cached = ["baseline"] * n
            else:
                out, drift = self.beyond_i, self.beyond_ewma
                cached = ["baseline" if k < BASELINE_CHECKS else "out of control" if out[k] else
                          "drifting" if drift[k] else "in control" for k in range(n)]
            self.__dict__["_states"] = cached
        return cached

    def state_at(self, k: int) -> str:
        """State of check ``k`` (0-based) by this figure alone."""
        return self.states()[k]


def chart(figure: str, x, *, baseline: int = BASELINE_CHECKS, lam: float = EWMA_LAMBDA, L: float = EWMA_L,
          k_i: float = I_SIGMAS, floor: float | None = None) -> Chart:
    """The charts of one figure (see the module docstring for every formula).

    Parameters
    ----------
    figure : str
        Column name (its suffix sets the sigma floor unless ``floor`` is given).
    x : (n,) array-like
        The figure at each check since the calibration, oldest first (NaN: not measured).
    baseline : int
        Checks that set the limits.
    lam, L, k_i : float
        EWMA weight, EWMA limit width and individuals limit width, in sigmas.
    floor : float, optional
        Smallest sigma; default :func:`resolution_of` ``figure``.

    Returns
    -------
    Chart
    """
    x = np.asarray(x, float)
    n = x.size
    nan = np.full(n, np.nan)
    mr = np.concatenate([[np.nan], np.abs(np.diff(x))]) if n else nan.copy()
    c = Chart(figure, x, i_lo=nan.copy(), i_hi=nan.copy(), mr=mr, z=nan.copy(), z_lo=nan.copy(), z_hi=nan.copy())
    base = x[:baseline]
    if n < baseline or not np.isfinite(base).all():
        return c
    m = baseline
    c.mu = float(base.mean())
    c.mr_bar = float(np.mean(np.abs(np.diff(base))))
    c.mr_ucl = D4 * c.mr_bar
    c.sigma = max(c.mr_bar / D2, resolution_of(figure) if floor is None else floor)
    half_i = k_i * c.sigma * math.sqrt(1 + 1 / m)
    c.i_lo[m:], c.i_hi[m:] = c.mu - half_i, c.mu + half_i
    z = c.mu
    for k in range(m, n):
        i = k - m + 1
        xk = x[k] if np.isfinite(x[k]) else z  # a figure not measured leaves the EWMA where it was
        z = lam * xk + (1 - lam) * z
        var = lam / (2 - lam) * (1 - (1 - lam) ** (2 * i)) + (1 - (1 - lam) ** i) ** 2 / m
        half = L * c.sigma * math.sqrt(var)
        c.z[k], c.z_lo[k], c.z_hi[k] = z, c.mu - half, c.mu + half
    return c


def worst(states) -> str:
    """The most severe of ``states`` (:data:`STATES` order)."""
    return max(states, key=STATES.index, default="baseline")


@dataclass
class ProbeCharts:
    """Every figure's charts for one probe's checks since its last calibration.

    Attributes
    ----------
    probe_id : str
    charts : dict of figure -> Chart
    checked_utc : list of str
        When each check ran, oldest first.
    """

    probe_id: str
    charts: dict
    checked_utc: list

    @property
    def n_checks(self) -> int:
        return len(self.checked_utc)

    def state_at(self, k: int = -1) -> str:
        k = k % self.n_checks if self.n_checks else 0
        return worst(c.state_at(k) for c in self.charts.values())

    @property
    def state(self) -> str:
        """State at the latest check."""
        return self.state_at(-1) if self.n_checks else "baseline"

    def flagged(self, k: int = -1) -> dict[str, str]:
        """Figures not in control at check ``k`` and how (``out of control`` / ``drifting``)."""
        k = k % self.n_checks
        return {f: s for f, c in self.charts.items() if (s := c.state_at(k)) in ("drifting", "out of control")}


def probe_charts(probe_id: str, rows, figures) -> ProbeCharts:
    """Charts of every figure from one calibration's rows.

    Parameters
    ----------
    probe_id : str
    rows : pandas.DataFrame
        The checks since the calibration, oldest first (columns ``checked_utc`` and the figures).
    figures : sequence of str
        Figure columns to chart.
    """
    return ProbeCharts(probe_id, {f: chart(f, rows[f].to_numpy(float)) for f in figures},
                       [str(t) for t in rows["checked_utc"]])
