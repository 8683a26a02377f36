"""Where the report takes its inputs from the rest of endocal, in one place.

The report is downstream of everything: it reads aligned data (:mod:`endocal.runs.aligned`),
models (:mod:`endocal.models`) and scores them with
:func:`endocal.validation.metrics.error_metrics`. The two helpers here turn an aligned table
into the model's :class:`~endocal.models.HysteresisData` and break an error down by regime of
motion. Offline validation (:mod:`endocal.validation.offline`, ``validate_offline``) provides
both when it is installed; these helpers then defer to it so that the report and ``endocal
validate`` never compute a number two ways.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from endocal.models import HysteresisData
from endocal.models.data import OTHER_CMD
from endocal.runs.aligned import AlignedData
from endocal.validation.metrics import error_metrics


def axis_data(aligned: AlignedData, axis: str) -> HysteresisData:
    """The hysteresis data of one bending axis of an aligned table.

    ``cmd_deg``/``meas_deg`` are the axis's columns; ``t_s`` the table's clock; extras are the
    other bending axis's command as ``other_cmd_deg`` (what ``coupling`` reads) and every
    further numeric column (what ``load:COLUMN`` reads).

    Raises
    ------
    RunFormatError
        The table has no such axis.
    """
    cmd = aligned.cmd_deg(axis)
    extras = {c: aligned.table[c].to_numpy(float) for c in aligned.extras}
    others = [a for a in aligned.axes if a != axis]
    if others:
        extras[OTHER_CMD] = aligned.cmd_deg(others[0])
    return HysteresisData(cmd_deg=cmd, meas_deg=aligned.meas_deg(axis), t_s=aligned.t_s, extras=extras)


@dataclass(frozen=True)
class RegimeError:
    """RMSE of one model in one regime of the motion.

    Attributes
    ----------
    family : str
        ``direction`` (near reversals vs steady), ``speed``, ``amplitude``, ``other axis``,
        ``time``.
    regime : str
        Human-readable band, e.g. ``|speed| 4.2-9.0 deg/s``.
    n : int
        Samples in the regime.
    rmse_deg : float
    """

    family: str
    regime: str
    n: int
    rmse_deg: float

    def to_dict(self) -> dict:
        return {"family": self.family, "regime": self.regime, "n": self.n, "rmse_deg": self.rmse_deg}


def _tercile_masks(x: np.ndarray, name: str, unit: str) -> list[tuple[str, np.ndarray]]:
    lo, hi = np.quantile(x, [1 / 3, 2 / 3])
    if not hi > lo:
        return [(f"{name} {float(np.min(x)):.3g}-{float(np.max(x)):.3g} {unit}", np.ones(x.size, bool))]
    return [
        (f"{name} < {lo:.3g} {unit}", x < lo),
        (f"{name} {lo:.3g}-{hi:.3g} {unit}", (x >= lo) & (x < hi)),
        (f"{name} >= {hi:.3g} {unit}", x >= hi),
    ]


def regime_masks(data: HysteresisData, reversals: np.ndarray, near_s: float = 1.0) -> list[tuple[str, str, np.ndarray]]:
    """Sample masks of the regimes the report breaks errors down by.

    Parameters
    ----------
    data : HysteresisData
        One record (``t_s`` required).
    reversals : (m,) int array
        Command reversal indices (see :func:`endocal.report.stats.reversal_indices`).
    near_s : float
        Half-width of the window around a reversal counted as "near reversal", seconds.

    Returns
    -------
    list of (family, regime, mask)
    """
    t = data.t_s if data.t_s is not None else np.arange(data.n_samples, dtype=float)
    cmd = data.cmd_deg
    speed = np.abs(np.gradient(cmd, t)) if cmd.size > 1 else np.zeros(cmd.size)
    out: list[tuple[str, str, np.ndarray]] = []
    near = np.zeros(cmd.size, bool)
    if reversals.size:
        tr = t[np.asarray(reversals, int)]
        j = np.clip(np.searchsorted(tr, t), 1, max(tr.size - 1, 1))
        dist = np.minimum(np.abs(t - tr[j - 1]), np.abs(t - tr[np.minimum(j, tr.size - 1)]))
        near = dist <= near_s
    hold = speed < 0.01 * max(float(np.max(speed)), 1e-12)
    out.append(("direction", f"near reversal (+-{near_s:g} s)", near & ~hold))
    out.append(("direction", "steady motion", ~near & ~hold))
    out.append(("direction", "hold (knob still)", hold))
    out += [("speed", r, m) for r, m in _tercile_masks(speed, "|speed|", "deg/s")]
    out += [("amplitude", r, m) for r, m in _tercile_masks(np.abs(cmd), "|cmd|", "deg")]
    if OTHER_CMD in data.extras and np.ptp(data.extras[OTHER_CMD]) > 0:
        out += [("other axis", r, m) for r, m in _tercile_masks(data.extras[OTHER_CMD], "other cmd", "deg")]
    edges = np.linspace(t[0], t[-1], 5)
    for i in range(4):
        m = (t >= edges[i]) & ((t < edges[i + 1]) if i < 3 else (t <= edges[i + 1]))
        out.append(("time", f"t {edges[i]:.0f}-{edges[i + 1]:.0f} s", m))
    return out


def regime_errors(data: HysteresisData, predicted_deg: np.ndarray, reversals: np.ndarray) -> list[RegimeError]:
    """RMSE per regime of ``predicted_deg`` against the data's measurement (empty regimes omitted).

    Every number comes from :func:`~endocal.validation.metrics.error_metrics` on the regime's samples.
    """
    rows = []
    for family, regime, mask in regime_masks(data, reversals):
        if mask.sum() >= 2:
            m = error_metrics(data.meas_deg[mask], predicted_deg[mask], n_boot=0)
            rows.append(RegimeError(family, regime, int(mask.sum()), m.rmse_deg))
    return rows
