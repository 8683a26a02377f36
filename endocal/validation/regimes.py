"""Where a model fails: the error broken down by regime of the motion.

Every sample is labelled in several independent groupings, and each regime's error gets
the same metrics (with block-bootstrap intervals) as the whole record
(:func:`endocal.validation.metrics.error_metrics`):

``motion``
    ``near reversal`` (the command has moved less than ``reversal_frac`` of its span since
    it last changed direction: the backlash transition, where direction-dependent models
    switch branch), ``steady motion`` (the rest of the moving samples) and ``hold`` (the
    command stands still for at least ``hold_min_s``: creep and drift show here);
``speed``
    moving samples in three bands of knob speed (terciles, deg/s): rate-dependent friction
    and delay grow with speed;
``amplitude``
    ``|cmd - centre|`` in thirds of the half-span: the envelope (dead band, stiffening);
``other axis``
    terciles of the other knob's command, when it moves (coupling);
``time``
    four equal quarters of the record (drift, a changing load).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from endocal.models.data import OTHER_CMD, HysteresisData, hold_mask, is_constant, speed_dps, turning_points
from endocal.validation.metrics import ErrorMetrics, error_metrics


@dataclass(frozen=True)
class Regime:
    """The model error in one regime of the motion.

    Attributes
    ----------
    group : str
        Grouping (``motion``, ``speed``, ``amplitude``, ``other axis``, ``time``).
    name : str
        The regime in words with its bounds, e.g. ``fast (> 42.1 deg/s)``.
    fraction : float
        Share of the samples in this regime.
    metrics : ErrorMetrics
        Error metrics of the regime's samples (deg).
    ratio : float
        The regime's RMSE over the whole record's RMSE (> 1: worse than average).
    """

    group: str
    name: str
    fraction: float
    metrics: ErrorMetrics
    ratio: float

    def to_dict(self) -> dict:
        return {"group": self.group, "name": self.name, "fraction": self.fraction, "ratio": self.ratio,
                **self.metrics.to_dict()}


@dataclass(frozen=True)
class RegimeBreakdown:
    """All regimes of a record, in grouping order; :meth:`worst` ranks them."""

    regimes: tuple[Regime, ...]
    overall_rmse_deg: float

    def worst(self, k: int = 3) -> list[Regime]:
        """The ``k`` regimes with the highest RMSE relative to the whole record."""
        return sorted(self.regimes, key=lambda r: -r.ratio)[:k]

    def to_dict(self) -> list[dict]:
        return [r.to_dict() for r in self.regimes]



def reversal_distance_deg(data: HysteresisData, tol_frac: float = 0.01) -> np.ndarray:
    """Command travel (deg) since the last direction reversal, per sample (inf before the first).

    Reversals as in :func:`turning_points`; samples from the turning point on count from it.
    """
    out = np.full(data.n_samples, np.inf)
    turns = turning_points(data, tol_frac)
    for sl in data.run_slices():
        mine = [int(k) for k in turns if sl.start <= k < sl.stop]
        for a, b in zip(mine, mine[1:] + [sl.stop]):
            out[a:b] = np.abs(data.cmd_deg[a:b] - data.cmd_deg[a])
    return out



def _bands(x: np.ndarray, mask: np.ndarray, fmt: str, unit: str, labels=("low", "mid", "high")):
    """Terciles of ``x`` over ``mask``: list of (name, mask)."""
    if mask.sum() < 3 or is_constant(x[mask]):
        return []
    q1, q2 = np.quantile(x[mask], [1 / 3, 2 / 3])
    return [
        (f"{labels[0]} (< {q1:{fmt}} {unit})", mask & (x < q1)),
        (f"{labels[1]} ({q1:{fmt}}..{q2:{fmt}} {unit})", mask & (x >= q1) & (x <= q2)),
        (f"{labels[2]} (> {q2:{fmt}} {unit})", mask & (x > q2)),
    ]


def regime_masks(data: HysteresisData, *, reversal_frac: float = 0.1, hold_min_s: float = 0.5) -> list[tuple[str, str, np.ndarray]]:
    """``(group, name, mask)`` of every regime of ``data`` (see the module docstring)."""
    n = data.n_samples
    span = float(np.ptp(data.cmd_deg))
    hold = hold_mask(data, hold_min_s)
    moving = ~hold
    near = moving & (reversal_distance_deg(data) < reversal_frac * span)
    cu = data.cmd_unit  # the command's unit: deg, or mm for a linear drive
    out = [("motion", f"near reversal (< {reversal_frac * span:.3g} {cu} after)", near),
           ("motion", "steady motion", moving & ~near),
           ("motion", f"hold (>= {hold_min_s:g} s still)", hold)]
    speed = np.abs(speed_dps(data))
    unit = f"{cu}/s" if data.t_s is not None else f"{cu}/sample"
    out += [("speed", name, m) for name, m in _bands(speed, moving, ".3g", unit, ("slow", "medium", "fast"))]
    centre = 0.5 * (float(data.cmd_deg.max()) + float(data.cmd_deg.min()))
    dist = np.abs(data.cmd_deg - centre)
    half = 0.5 * span
    if half > 0:
        edges = [0.0, half / 3, 2 * half / 3]
        for lo, hi, word in zip(edges, edges[1:] + [np.inf], ("inner", "middle", "outer")):
            bound = f"{lo:.3g}..{hi:.3g}" if np.isfinite(hi) else f">= {lo:.3g}"
            out.append(("amplitude", f"{word} third (|cmd - {centre:.3g}| {bound} {cu})", (dist >= lo) & (dist < hi)))
    if OTHER_CMD in data.extras and not is_constant(data.extras[OTHER_CMD]):
        out += [("other axis", f"other knob {name}", m)
                for name, m in _bands(data.extras[OTHER_CMD], np.ones(n, bool), ".3g", "deg")]
    t = data.t_s if data.t_s is not None else np.arange(n, dtype=float)
    unit_t = "s" if data.t_s is not None else "samples"
    runs = data.run_slices()
    for q in range(4):
        # quarters of each record (several records each restart the clock: one quarter of the
        # concatenation would span records, its times out of order)
        m = np.zeros(n, bool)
        for sl in runs:
            k = sl.stop - sl.start
            m[sl.start + q * k // 4: sl.start + (q + 1) * k // 4] = True
        if not m.any():
            continue
        if len(runs) == 1:
            a, b = np.flatnonzero(m)[[0, -1]]
            out.append(("time", f"quarter {q + 1} ({t[a]:.4g}..{t[b]:.4g} {unit_t})", m))
        else:
            out.append(("time", f"quarter {q + 1} of each of the {len(runs)} records", m))
    return out


def error_by_regime(data: HysteresisData, pred_deg: np.ndarray, *, min_samples: int = 20, n_boot: int = 200,
                    seed: int = 0, reversal_frac: float = 0.1, hold_min_s: float = 0.5) -> RegimeBreakdown:
    """The error ``pred - meas`` of every regime of ``data``.

    Parameters
    ----------
    data : HysteresisData
        Commands, measured angles (deg) and time.
    pred_deg : ndarray (n,)
        The model's predicted angle (deg).
    min_samples : int
        Regimes with fewer samples are left out (their error says nothing).
    n_boot, seed : int
        Bootstrap replicates and seed of the intervals.
    reversal_frac, hold_min_s : float
        Size of the near-reversal zone (fraction of the command span) and shortest hold (s).

    Returns
    -------
    RegimeBreakdown
    """
    meas = data.meas_deg
    pred = np.asarray(pred_deg, dtype=float)
    overall = float(np.sqrt(np.mean((pred - meas) ** 2)))
    regimes = []
    for group, name, mask in regime_masks(data, reversal_frac=reversal_frac, hold_min_s=hold_min_s):
        k = int(mask.sum())
        if k < min_samples:
            continue
        m = error_metrics(meas[mask], pred[mask], n_boot=n_boot, seed=seed)
        regimes.append(Regime(group, name, k / data.n_samples, m, m.rmse_deg / overall if overall > 0 else 1.0))
    return RegimeBreakdown(tuple(regimes), overall)
