"""Residual analysis as system-identification tools do it (Ljung, *System Identification*, ch. 16.6).

A model that explains the data leaves a residual ``e = meas - pred`` that is (i) white, or
at least no more correlated than the measurement noise, and (ii) uncorrelated with the
input at every lag. Tested here:

- **whiteness**: the residual's autocorrelation ``rho_e(k)``, the Ljung–Box statistic
  ``Q = n (n + 2) sum_k rho_e(k)^2 / (n - k)`` (chi-squared with ``h`` degrees of freedom
  under whiteness) and the correlation time (first lag below ``1/e``);
- **cross-correlation** ``r(tau) = corr(e(t), x(t - tau))`` with the command, its signed
  speed, its speed magnitude, the other knob, time, and each load candidate column times
  the direction of motion. Positive ``tau``: the residual follows the signal's past (lagged
  input: a delay). Both series are autocorrelated, so the null band uses Bartlett's
  variance ``var r(tau) ~ (1/n) sum_k rho_e(k) rho_x(k)`` and a Bonferroni correction over
  the lags searched; white-noise bands (``1.96/sqrt(n)``) would flag almost anything on
  100 Hz data.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np
from scipy.special import chdtrc, ndtri  # chi2.sf and norm.ppf, without scipy.stats' import (0.2 s)

from endocal.messages import Message
from endocal.models.data import OTHER_CMD, HysteresisData
from endocal.models.start import RecordStart
from endocal.validation.data import is_constant, speed_dps
from endocal.validation.regimes import turning_points
from endocal.validation.shift import direction_of_motion


@dataclass(frozen=True)
class Whiteness:
    """Autocorrelation test of the residual.

    Attributes
    ----------
    n : int
        Samples.
    lags : int
        Lags ``1..h`` in the Ljung–Box statistic.
    ljung_box_q, p_value : float
        Statistic and its chi-squared p-value (small: not white).
    white : bool
        ``p_value >= alpha``.
    max_abs_acf : float
        Largest ``|rho_e(k)|`` over the lags.
    frac_outside : float
        Share of lags with ``|rho_e(k)| > 1.96/sqrt(n)``.
    correlation_time_s : float
        First lag where ``rho_e`` drops below ``1/e`` (s; samples when there is no time).
    """

    n: int
    lags: int
    ljung_box_q: float
    p_value: float
    white: bool
    max_abs_acf: float
    frac_outside: float
    correlation_time_s: float


@dataclass(frozen=True)
class CrossCorrelation:
    """Cross-correlation of the residual with one signal.

    Attributes
    ----------
    signal : str
        ``command``, ``speed``, ``abs speed``, ``other command``, ``time``.
    corr_at_zero : float
        ``r(0)``.
    max_abs_corr : float
        Largest ``|r(tau)|`` over the lags searched.
    lag_s : float
        Its lag (s; positive: the residual follows the signal's past).
    bound : float
        Null band of ``|r|`` (Bartlett, Bonferroni over lags, level ``alpha``).
    significant : bool
        ``max_abs_corr > bound``.
    hint : str
        What a significant correlation points to, physically.
    """

    signal: str
    corr_at_zero: float
    max_abs_corr: float
    lag_s: float
    bound: float
    significant: bool
    hint: str


@dataclass(frozen=True)
class ResidualTests:
    """Whiteness and cross-correlation tests of a model's residual."""

    whiteness: Whiteness
    cross: tuple[CrossCorrelation, ...]

    def significant(self) -> list[CrossCorrelation]:
        return [c for c in self.cross if c.significant]

    def to_dict(self) -> dict:
        return {"whiteness": asdict(self.whiteness), "cross_correlation": [asdict(c) for c in self.cross]}


_HINTS = {
    "command": "the error depends on where the knob is: a static shape the model lacks (envelope) or a wrong gain",
    "speed": "the error follows the signed knob speed: a time shift (delay) or speed-dependent friction (rate)",
    "abs speed": "the error grows with how fast the knob moves: speed-dependent friction (rate)",
    "other command": "the other knob moves this axis: coupling",
    "time": "the error changes steadily over the run: drift (or a slowly changing load)",
}


def _xcorr(a: np.ndarray, b: np.ndarray, max_lag: int) -> np.ndarray:
    """``r(tau) = sum_t a_t b_{t - tau} / (n sd_a sd_b)`` for ``tau = -max_lag..max_lag`` (means removed)."""
    n = a.size
    same = a is b  # an autocorrelation: one transform serves both sides (the same numbers)
    a = a - a.mean()
    b = a if same else b - b.mean()
    nfft = 1 << int(np.ceil(np.log2(2 * n)))
    # each spectrum freed once used: the (nfft,) buffers alive at once are the fewest the product needs
    fa = np.fft.rfft(a, nfft)
    fb = np.conj(fa if same else np.fft.rfft(b, nfft))
    prod = fa * fb
    del fa, fb
    c = np.fft.irfft(prod, nfft)
    del prod
    denom = n * a.std() * b.std()
    full = np.concatenate([c[-max_lag:], c[: max_lag + 1]]) if max_lag > 0 else c[:1]
    return full / denom if denom > 0 else np.zeros(2 * max_lag + 1)


def _hint(signal: str) -> str:
    if signal.startswith("load:"):
        col = signal.partition(":")[2]
        return (f"the error follows the direction of motion in proportion to '{col}': friction that scales with it "
                f"({signal})")
    return _HINTS[signal]


def _acf(x: np.ndarray, max_lag: int) -> np.ndarray:
    return _xcorr(x, x, max_lag)[max_lag:]


def residual_tests(data: HysteresisData, resid_deg: np.ndarray, *, max_lag_s: float = 2.0,
                   alpha: float = 0.05, load_columns: Sequence[str] = ()) -> ResidualTests:
    """Whiteness of ``resid_deg`` and its cross-correlation with the input, speed and lagged input.

    Parameters
    ----------
    data : HysteresisData
        The data the residual belongs to (commands, time, other axis).
    resid_deg : ndarray (n,)
        ``meas - pred`` (deg).
    max_lag_s : float
        Lags searched, ``+-max_lag_s`` (s; converted with the median sample interval).
    alpha : float
        Level of every test.
    load_columns : sequence of str
        Extra columns that may carry a load: the residual is also correlated with each one
        (centred) times the direction of motion, the signature of friction scaling with it
        (``load:COLUMN``), as signal ``load:COLUMN``.

    Returns
    -------
    ResidualTests
    """
    e = np.asarray(resid_deg, dtype=float)
    n = e.size
    if data.t_s is not None and n > 1:
        steps = np.diff(data.t_s)
        first = np.zeros(n, bool)
        first[data.run_starts] = True
        dt = float(np.median(steps[~first[1:]])) if (~first[1:]).any() else 1.0
    else:
        dt = 1.0
    max_lag = int(np.clip(round(max_lag_s / dt), 1, max(1, n // 4)))
    rho_e = _acf(e, max_lag) if e.std() > 0 else np.zeros(max_lag + 1)
    k = np.arange(1, max_lag + 1)
    q = float(n * (n + 2) * np.sum(rho_e[1:] ** 2 / (n - k)))
    p = float(chdtrc(max_lag, q))
    below = np.flatnonzero(rho_e < 1 / np.e)
    white = Whiteness(
        n=n, lags=max_lag, ljung_box_q=q, p_value=p, white=p >= alpha,
        max_abs_acf=float(np.max(np.abs(rho_e[1:]))) if max_lag else 0.0,
        frac_outside=float(np.mean(np.abs(rho_e[1:]) > 1.96 / np.sqrt(n))),
        correlation_time_s=float((below[0] if below.size else max_lag) * dt),
    )
    signals = {"command": data.cmd_deg}
    v = speed_dps(data)
    signals["speed"] = v
    signals["abs speed"] = np.abs(v)
    if OTHER_CMD in data.extras:
        signals["other command"] = data.extras[OTHER_CMD]
    signals["time"] = data.t_s if data.t_s is not None else np.arange(n, dtype=float)
    if load_columns:
        d = direction_of_motion(data)
        for col in load_columns:
            if col in data.extras:
                x = np.asarray(data.extras[col], dtype=float)
                signals[f"load:{col}"] = (x - x.mean()) * d
    z = float(ndtri(1 - alpha / (2 * (2 * max_lag + 1))))
    cross = []
    for name, x in signals.items():
        if is_constant(x) or e.std() == 0:
            continue
        r = _xcorr(e, x, max_lag)
        rho_x = _acf(x, max_lag)
        # Bartlett: var r(tau) ~ (1/n) (1 + 2 sum_{k>=1} rho_e(k) rho_x(k)), lags truncated at max_lag
        var = max(1.0 + 2.0 * float(np.sum(rho_e[1:] * rho_x[1:])), 1.0) / n
        bound = z * float(np.sqrt(var))
        i = int(np.argmax(np.abs(r)))
        cross.append(CrossCorrelation(
            signal=name, corr_at_zero=float(r[max_lag]), max_abs_corr=float(abs(r[i])),
            lag_s=float((i - max_lag) * dt), bound=bound, significant=bool(abs(r[i]) > bound), hint=_hint(name)))
    return ResidualTests(white, tuple(cross))


def unexplained_shape(data: HysteresisData, resid: ResidualTests, frac: float = 0.1) -> str:
    """What a residual that is a shape rather than noise says, or ``""``.

    Tracker noise interpolated onto the motor clock stays correlated for a few frames (tens of
    ms); a residual that stays correlated for a tenth of a half-cycle (the time between two
    reversals) or longer is an error that follows the loop: a shape the model lacks, whether or
    not a catalog term captures it. Then "nothing is missing" would contradict the residual.
    """
    w = resid.whiteness
    if w.white or data.t_s is None:
        return ""
    duration = sum(float(np.ptp(data.t_s[sl])) for sl in data.run_slices())
    half = duration / (turning_points(data).size + 1)
    if not half > 0 or w.correlation_time_s < frac * half:
        return ""
    return (f"the residual is not noise: it stays correlated for {w.correlation_time_s:.3g} s, "
            f"{100 * w.correlation_time_s / half:.0f} % of a half-cycle ({half:.3g} s), so the model misses a shape that "
            "follows the loop; look at the loop (endocal report), at another base (--model), or add your own "
            "effect (docs/how-to/add-effect.md)")



#: A record's error before its first reversal this many times its error after it is the start,
#: not the physics (see :func:`cut_start`).
START_ERROR_RATIO = 2.0


def _unexplained_starts(data: HysteresisData, resid_deg: np.ndarray) -> list[tuple[float, float, float, int]]:
    """``(ratio, rmse before, rmse after, run start)`` of each run off :data:`START_ERROR_RATIO`
    times more before its first reversal than after it."""
    tp = turning_points(data)
    found = []
    for sl in data.run_slices():
        first = tp[(tp >= sl.start) & (tp < sl.stop)]
        if not first.size or not float(np.ptp(data.cmd_deg[sl])) > 0:
            continue
        k = int(first[0])
        before, after = resid_deg[sl.start:k], resid_deg[k:sl.stop]
        if before.size < 2 or after.size < 2:
            continue
        rb, ra = float(np.sqrt(np.mean(before**2))), float(np.sqrt(np.mean(after**2)))
        if rb >= START_ERROR_RATIO * ra:
            found.append((rb / max(ra, 1e-12), rb, ra, sl.start))
    return found


def unexplained_start(data: HysteresisData, resid_deg: np.ndarray, what: str = "validation record") -> str:
    """Said when a record's start leaves its error before the first reversal
    :data:`START_ERROR_RATIO` times its error after it (``resid_deg`` from the starts taken), or ``""``:
    then "nothing is missing" would contradict the residual."""
    found = _unexplained_starts(data, resid_deg)
    if not found:
        return ""
    ratio, rb, ra, _ = max(found)
    return (f"the {what}'s start is not explained: its error before the first reversal is {rb:.3g} deg RMS, "
            f"{ratio:.1f}x the {ra:.3g} deg after it (see the note on its start)")


def _start_words(u: np.ndarray, unit: str = "deg") -> str:
    """``"starts mid-swing (command 1.8 deg within 0..3.6, moving down)"`` (``unit``: the command's)."""
    span = float(np.ptp(u))
    moved = u[np.argmax(np.abs(u - u[0]) > 0.01 * span)] - u[0]
    where = "mid-swing" if u.min() < u[0] < u.max() else "at a turning point"
    return (f"starts {where} (command {u[0]:.3g} {unit} within {u.min():.3g}..{u.max():.3g}, moving "
            f"{'up' if moved > 0 else 'down'})")


def cut_start(data: HysteresisData, resid_deg: np.ndarray, what: str = "validation record",
              starts: Sequence[RecordStart] = ()) -> str:
    """How a record's start was taken, when it was not from rest, or what its start did to its error; or ``""``.

    Every model starts each record in an assumed state: its operators as if the knob had come
    straight from 0 (the PI's eq. 5 start), or on the mid-line between its branches (the
    B-spline). A record cut from a longer one has the state its history left; the records in
    ``starts`` were run from a state estimated from their first stretch
    (:mod:`endocal.models.start`), which is said with the RMSE it saved. Of the others, one off
    :data:`START_ERROR_RATIO` times more before its first reversal than after it started in a
    state no start fits (a virgin first sweep, a step from rest, a knob homed to 0 with the tip
    still bent from the last acquisition where the model has never seen the other side): that
    stretch measures the start, not the physics, and a time-dependent candidate (drift, creep)
    can fit it. ``resid_deg`` is the residual of the
    records from rest (only read when ``starts`` is empty).
    """
    runs = data.run_slices()
    if starts:
        st = max(starts, key=lambda s: s.rmse_rest_deg - s.rmse_estimated_deg)
        which = f"the {what}" if data.n_runs == 1 else f"{len(starts)} of {data.n_runs} {what}s (the largest gain)"
        return Message(f"{which} {_start_words(data.cmd_deg[runs[st.run]], data.cmd_unit)}: run from an estimated "
                       f"start, {st.describe(data.cmd_unit)}: a record cut from a longer motion starts where that "
                       "motion left the knob, not in the relaxed state a model assumes; every model here, candidates "
                       "too, runs it from the start that predicts it best", "start-estimated")
    found = _unexplained_starts(data, resid_deg)
    if not found:
        return ""
    _, rb, ra, a = max(found)
    which = f"the {what}" if data.n_runs == 1 else f"{len(found)} of {data.n_runs} {what}s (the worst)"
    u = data.cmd_deg[next(sl for sl in runs if sl.start == a)]
    return Message(f"{which} {_start_words(u, data.cmd_unit)}: its error before the first reversal is {rb:.3g} deg "
                   f"RMS, {rb / ra:.1f}x the {ra:.3g} deg after it. No start tried predicts it (relaxed, from 0, cut "
                   "from a periodic motion, after a sweep the other way): a step, a first sweep from a relaxed sheath, "
                   "or a tip still bent where the model never saw the knob starts a record so; that stretch measures "
                   "the start, not the physics, and a candidate may fit it; cut the records at their first reversal, "
                   "or move the knob through its range before each acquisition", "start-cut")
