"""The data a hysteresis model is fitted on and predicts from: :class:`HysteresisData`.

One axis, one or more runs concatenated along the sample axis. Besides the knob
command (deg) and the measured bending angle (deg) it carries the time stamps
(s) and any extra named columns (the other axis's command or angle, logged
covariates such as ``sheath_wrap_deg``) that effect terms may need.

A bending axis driven by a linear stage pulling its tendon is commanded in mm: ``cmd_deg``
then holds millimetres and ``drive_unit`` says so (the hysteresis maths is the same in either
unit). A model fitted on such data records the unit and refuses data of another
(:meth:`~endocal.models.base.HysteresisModel.check_drive_unit`).
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from endocal.errors import ModelError
from endocal.models._kernels import count_reversals

#: Extra column holding the other bending axis's knob command (deg), used by ``coupling``.
OTHER_CMD = "other_cmd_deg"
#: The least travel back from an extreme that counts as a direction reversal (deg), whatever the
#: command's span: below it a command is not moving but rounding (an inverse model holding a knob
#: still computes its goal to about 1e-12 deg, which counted as thousands of reversals).
REVERSAL_TOL_MIN_DEG = 1e-6


def reversals(u: np.ndarray, tol_frac: float = 0.01) -> int:
    """Direction reversals of the command ``u`` (deg), ignoring wiggles below ``tol_frac`` of its
    span or :data:`REVERSAL_TOL_MIN_DEG`."""
    u = np.ascontiguousarray(u, dtype=float)
    span = float(u.max() - u.min()) if u.size else 0.0
    return int(count_reversals(u, max(tol_frac * span, REVERSAL_TOL_MIN_DEG))) if span > 0.0 else 0


def common_drive_unit(units, what: str = "runs") -> str | None:
    """The one drive unit of ``units`` (None ones say nothing), or None when none is stated.

    Raises
    ------
    ModelError
        Two different units: records of a knob (deg) and of a linear drive (mm) cannot be one fit.
    """
    stated = list(dict.fromkeys(u for u in units if u is not None))
    if len(stated) > 1:
        raise ModelError(f"the {what} command their drive in different units ({' and '.join(stated)}): a knob's "
                         "angle and a linear drive's travel are not one model's input; give records of one drive")
    return stated[0] if stated else None


def _as_1d(name: str, values, n: int | None = None) -> np.ndarray:
    try:
        arr = np.asarray(values, dtype=float)
    except (TypeError, ValueError):
        raise ModelError(f"{name} must be numeric") from None
    if arr.ndim != 1:
        raise ModelError(f"{name} must be one-dimensional (time along axis 0), got shape {arr.shape}")
    if n is not None and arr.shape[0] != n:
        raise ModelError(f"{name} has {arr.shape[0]} samples but cmd_deg has {n}")
    bad = ~np.isfinite(arr)
    if bad.any():
        k = int(np.flatnonzero(bad)[0])
        raise ModelError(f"{name} contains NaN or inf ({int(bad.sum())} samples, first at index {k}); "
                         "drop or interpolate those samples before fitting")
    return arr


@dataclass(frozen=True)
class HysteresisData:
    """Command and measurement sequences of one axis, possibly several runs.

    Parameters
    ----------
    cmd_deg : ndarray, shape (n,)
        Knob command (deg; mm for a linear drive, as ``drive_unit`` says).
    meas_deg : ndarray, shape (n,), optional
        Measured bending angle (deg). Needed to fit, not to predict.
    t_s : ndarray, shape (n,), optional
        Time stamps (s), strictly increasing within each run. Needed by time-based
        effects (delay, rate, drift, creep).
    extras : dict of str to ndarray, optional
        Further named columns of shape (n,), e.g. ``other_cmd_deg`` or a logged covariate.
    run_starts : ndarray of int, optional
        Index of the first sample of each run (starts with 0). Operator states
        restart at every run start. Default: one run.
    lead_in : ndarray of int, optional
        Per run, how many of its first samples are a lead-in: a path the knob is taken to have
        come along before the record, run to set the model's state and not part of the record
        (:mod:`endocal.models.start`). Time-based terms count the record's time from the first
        sample after it. Default: none.
    drive_unit : str, optional
        The unit of ``cmd_deg``: ``"deg"`` (a knob) or ``"mm"`` (a linear stage pulling the
        tendon, whose command ``cmd_deg`` then holds in mm). None (arrays given directly) states
        none: any model takes it, in its own unit.

    Raises
    ------
    ModelError
        NaN/inf, mismatched lengths, time not strictly increasing inside a run,
        malformed run starts.
    """

    cmd_deg: np.ndarray
    meas_deg: np.ndarray | None = None
    t_s: np.ndarray | None = None
    extras: Mapping[str, np.ndarray] = field(default_factory=dict)
    run_starts: np.ndarray | None = None
    lead_in: np.ndarray | None = None
    drive_unit: str | None = None

    @property
    def cmd_unit(self) -> str:
        """The unit of the command, for messages: ``drive_unit``, or deg when none is stated."""
        return self.drive_unit or "deg"

    def __post_init__(self) -> None:
        if self.drive_unit is not None and not (isinstance(self.drive_unit, str) and self.drive_unit.isidentifier()):
            raise ModelError(f"drive_unit must name a unit (deg, mm), got {self.drive_unit!r}")
        cmd = _as_1d("cmd_deg", self.cmd_deg)
        n = cmd.shape[0]
        if n == 0:
            raise ModelError("cmd_deg is empty")
        object.__setattr__(self, "cmd_deg", cmd)
        if self.meas_deg is not None:
            object.__setattr__(self, "meas_deg", _as_1d("meas_deg", self.meas_deg, n))
        if self.run_starts is None:
            starts = np.zeros(1, dtype=np.int64)
        else:
            starts = np.asarray(self.run_starts, dtype=np.int64).ravel()
            if starts.size == 0 or starts[0] != 0 or np.any(np.diff(starts) <= 0) or starts[-1] >= n:
                raise ModelError(f"run_starts must start at 0, increase strictly and stay below {n}; got {starts.tolist()}")
        object.__setattr__(self, "run_starts", starts)
        lead = (np.zeros(starts.size, dtype=np.int64) if self.lead_in is None
                else np.asarray(self.lead_in, dtype=np.int64).ravel())
        if lead.shape != starts.shape or np.any(lead < 0) or np.any(lead >= np.diff(np.append(starts, n))):
            raise ModelError(f"lead_in must give one count per run, each below its run's length; got {lead.tolist()}")
        object.__setattr__(self, "lead_in", lead)
        if self.t_s is not None:
            t = _as_1d("t_s", self.t_s, n)
            dt = np.diff(t)
            first_of_run = np.zeros(n, dtype=bool)
            first_of_run[starts] = True
            bad = (dt <= 0) & ~first_of_run[1:]
            if bad.any():
                k = int(np.flatnonzero(bad)[0]) + 1
                raise ModelError(f"t_s is not strictly increasing at sample {k} ({t[k - 1]!r} -> {t[k]!r} s); "
                                 "sort the samples or split the data into runs")
            object.__setattr__(self, "t_s", t)
        ex = {}
        for name, col in dict(self.extras).items():
            if not isinstance(name, str) or not name:
                raise ModelError(f"extra column names must be non-empty strings, got {name!r}")
            ex[name] = _as_1d(name, col, n)
        object.__setattr__(self, "extras", ex)

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_runs(cls, runs: Sequence[HysteresisData]) -> HysteresisData:
        """Concatenate runs (each may itself hold several runs); columns must agree."""
        runs = list(runs)
        if not runs:
            raise ModelError("no runs given")
        has_meas = {r.meas_deg is not None for r in runs}
        has_t = {r.t_s is not None for r in runs}
        keys = {tuple(sorted(r.extras)) for r in runs}
        if len(has_meas) > 1 or len(has_t) > 1 or len(keys) > 1:
            raise ModelError("runs disagree on their columns (meas_deg, t_s or extras); give every run the same columns")
        offsets = np.cumsum([0] + [r.n_samples for r in runs[:-1]])
        return cls(
            cmd_deg=np.concatenate([r.cmd_deg for r in runs]),
            meas_deg=np.concatenate([r.meas_deg for r in runs]) if runs[0].meas_deg is not None else None,
            t_s=np.concatenate([r.t_s for r in runs]) if runs[0].t_s is not None else None,
            extras={k: np.concatenate([r.extras[k] for r in runs]) for k in runs[0].extras},
            run_starts=np.concatenate([r.run_starts + o for r, o in zip(runs, offsets)]),
            lead_in=np.concatenate([r.lead_in for r in runs]),
            drive_unit=common_drive_unit(r.drive_unit for r in runs),
        )

    # ------------------------------------------------------------------ views
    @property
    def n_samples(self) -> int:
        return int(self.cmd_deg.shape[0])

    @property
    def n_runs(self) -> int:
        return int(self.run_starts.shape[0])

    def run_slices(self) -> list[slice]:
        """One slice per run into the concatenated sample axis."""
        ends = list(self.run_starts[1:]) + [self.n_samples]
        return [slice(int(a), int(b)) for a, b in zip(self.run_starts, ends)]

    def record_starts(self) -> np.ndarray:
        """Index of each run's first sample after its lead-in (its first recorded sample)."""
        return self.run_starts + self.lead_in

    def split(self, values: np.ndarray) -> list[np.ndarray]:
        """Cut a concatenated (n,) array into per-run arrays."""
        return [values[s] for s in self.run_slices()]

    def decimate(self, step: int) -> HysteresisData:
        """Every ``step``-th sample of each run (each run keeps its first sample)."""
        return self.take([np.arange(sl.start, sl.stop, step) for sl in self.run_slices()])

    def take(self, parts: list[np.ndarray]) -> HysteresisData:
        """The samples at ``parts`` (one index array per run, in order; empty ones dropped), each part a run
        (without lead-in)."""
        parts = [np.asarray(p, dtype=int) for p in parts if len(p)]
        idx = np.concatenate(parts)
        starts = np.concatenate([[0], np.cumsum([p.size for p in parts])[:-1]]).astype(self.run_starts.dtype)
        return HysteresisData(
            cmd_deg=self.cmd_deg[idx],
            meas_deg=None if self.meas_deg is None else self.meas_deg[idx],
            t_s=None if self.t_s is None else self.t_s[idx],
            extras={k: v[idx] for k, v in self.extras.items()},
            run_starts=starts,
            drive_unit=self.drive_unit,
        )

    def with_cmd(self, cmd_deg: np.ndarray) -> HysteresisData:
        """Same time base, extras and runs, another command (and no measurement)."""
        return HysteresisData(cmd_deg=cmd_deg, t_s=self.t_s, extras=self.extras, run_starts=self.run_starts,
                              lead_in=self.lead_in, drive_unit=self.drive_unit)

    def column(self, name: str) -> np.ndarray:
        """An extra column by name.

        Raises
        ------
        ModelError
            The column is absent (the message lists those present).
        """
        try:
            return self.extras[name]
        except KeyError:
            have = ", ".join(sorted(self.extras)) or "none"
            raise ModelError(f"the data has no column '{name}' (extra columns read: {have}; columns of text or with "
                             "empty cells are not read)") from None

    def require_time(self, who: str) -> np.ndarray:
        """``t_s``, or a ModelError naming the effect ``who`` that needs it."""
        if self.t_s is None:
            raise ModelError(f"{who} needs time stamps: give t_s (s) with the data")
        return self.t_s

    def elapsed_s(self, who: str) -> np.ndarray:
        """Time since each run's record began (s, n): negative on a lead-in (:mod:`endocal.models.start`), which runs
        before the record's time 0. A ModelError naming ``who`` without time stamps."""
        t = self.require_time(who)
        out = np.empty_like(t)
        for sl, first in zip(self.run_slices(), self.record_starts()):
            out[sl] = t[sl] - t[first]
        return out

    def n_reversals(self, tol_frac: float = 0.01) -> int:
        """Direction reversals of the command per run (:func:`reversals`), summed."""
        return sum(reversals(self.cmd_deg[s], tol_frac) for s in self.run_slices())

    def fingerprint(self) -> list[dict]:
        """Per-run SHA-256 of the command, measurement and time bytes (recorded in model files)."""
        out = []
        for s in self.run_slices():
            h = hashlib.sha256()
            for arr in (self.cmd_deg, self.meas_deg, self.t_s):
                if arr is not None:
                    h.update(np.ascontiguousarray(arr[s], dtype="<f8").tobytes())
            out.append({"sha256": h.hexdigest(), "n_samples": s.stop - s.start})
        return out


def as_data(data=None, meas_deg=None, *, t_s=None, extras=None) -> tuple[HysteresisData, bool]:
    """Turn what a user passes to ``fit``/``predict``/``inverse`` into :class:`HysteresisData`.

    Accepts a :class:`HysteresisData`, a list of them, a 1-D array of commands (with
    optional ``meas_deg``, ``t_s``, ``extras``), or lists of such arrays (one per run).

    Returns
    -------
    data : HysteresisData
    was_list : bool
        Whether the input was a list of runs (then results are returned per run).
    """
    if isinstance(data, HysteresisData):
        if meas_deg is not None or t_s is not None or extras is not None:
            raise ModelError("give either a HysteresisData or arrays (cmd_deg, meas_deg, t_s, extras), not both")
        return data, False
    if isinstance(data, (list, tuple)) and data and isinstance(data[0], HysteresisData):
        if meas_deg is not None or t_s is not None or extras is not None:
            raise ModelError("give either HysteresisData runs or arrays, not both")
        return HysteresisData.from_runs(data), True
    if isinstance(data, (list, tuple)) and data and np.ndim(data[0]) == 1:
        n = len(data)

        def per_run(x, name):
            if x is None:
                return [None] * n
            if not isinstance(x, (list, tuple)) or len(x) != n:
                raise ModelError(f"{name} must be a list of {n} arrays, one per run, like the commands")
            return list(x)

        ms, ts = per_run(meas_deg, "meas_deg"), per_run(t_s, "t_s")
        exs = per_run(extras, "extras") if extras is not None else [{}] * n
        runs = [HysteresisData(cmd_deg=c, meas_deg=m, t_s=t, extras=e or {}) for c, m, t, e in zip(data, ms, ts, exs)]
        return HysteresisData.from_runs(runs), True
    if data is None:
        raise ModelError("no data given")
    return HysteresisData(cmd_deg=data, meas_deg=meas_deg, t_s=t_s, extras=extras or {}), False


# ---- what a record holds (reversals, holds, speeds, constant columns): asked by the effects'
# requirements (models.effects.requirements) and by validation alike
def is_constant(values: np.ndarray) -> bool:
    """True when a column carries no variation a fit could use (spread below 1e-9 of its scale)."""
    v = np.asarray(values, dtype=float)
    scale = max(float(np.max(np.abs(v))), 1.0) if v.size else 1.0
    return v.size == 0 or float(np.ptp(v)) <= 1e-9 * scale


def speed_dps(data: HysteresisData) -> np.ndarray:
    """Command speed (deg/s, signed) per sample, per run; per sample when there is no time."""
    out = np.zeros(data.n_samples)
    for sl in data.run_slices():
        u = data.cmd_deg[sl]
        if u.size < 2:
            continue
        x = data.t_s[sl] if data.t_s is not None else np.arange(u.size, dtype=float)
        out[sl] = np.gradient(u, x)
    return out


def turning_points(data: HysteresisData, tol_frac: float = 0.01) -> np.ndarray:
    """Indices (into the concatenated samples) of the command's direction reversals.

    A reversal is a turning point of the command that it then leaves by more than
    ``tol_frac`` of its run's span (wiggles below that, or below
    :data:`~endocal.models.data.REVERSAL_TOL_MIN_DEG`, are ignored).
    """
    out = []
    for sl in data.run_slices():
        u = data.cmd_deg[sl]
        if not np.ptp(u) > 0:
            continue
        tol = max(tol_frac * float(np.ptp(u)), REVERSAL_TOL_MIN_DEG)
        ext_i, direction = 0, 0
        for k in range(1, u.size):
            if direction == 0:
                if abs(u[k] - u[0]) > tol:
                    direction, ext_i = (1 if u[k] > u[0] else -1), k
            elif (u[k] - u[ext_i]) * direction > 0:
                ext_i = k  # further in the current direction
            elif abs(u[k] - u[ext_i]) > tol:
                out.append(sl.start + ext_i)
                direction, ext_i = -direction, k
    return np.asarray(out, dtype=np.int64)


def half_cycles(data: HysteresisData, tol_frac: float = 0.01) -> np.ndarray:
    """(k, 2) indices of the reversals that start and end each half-cycle of the command, within one run
    (reversals as :func:`turning_points` finds them with ``tol_frac``)."""
    turns = turning_points(data, tol_frac)
    same = np.searchsorted(data.run_starts, turns[1:], side="right") == np.searchsorted(
        data.run_starts, turns[:-1], side="right")
    return np.column_stack([turns[:-1], turns[1:]])[same]


def hold_mask(data: HysteresisData, hold_min_s: float = 0.5) -> np.ndarray:
    """Samples where the command stands still for at least ``hold_min_s`` (or 5 samples without time)."""
    v = np.abs(speed_dps(data))
    still = v <= 1e-6 * max(float(v.max()), 1e-12)
    out = np.zeros(data.n_samples, dtype=bool)
    for sl in data.run_slices():
        s = still[sl]
        t = data.t_s[sl] if data.t_s is not None else None
        k = 0
        while k < s.size:
            if not s[k]:
                k += 1
                continue
            j = k
            while j < s.size and s[j]:
                j += 1
            long_enough = (t[j - 1] - t[k] >= hold_min_s) if t is not None else (j - k >= 5)
            if long_enough:
                out[sl.start + k: sl.start + j] = True
            k = j
    return out
