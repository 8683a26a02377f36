"""Contact-force prediction from the knob torque (duodenoscope paper, sec. 2.4, eqs. 12-15).

The knob torque of a tendon-driven bending section is the contact moment at the tip, scaled
by a transmission coefficient ``G``, plus an internal resistance that depends on the knob
angle and on the direction of motion (duodenoscope paper, eq. 12)::

    M_knob = G * M_contact + M_r(theta, direction)

``M_r`` is calibrated per direction of motion with no load (eq. 13); with known loads ``F``
at the tip, ``Delta M_knob = M_knob - M_r(theta) = G * F * L`` gives ``G`` (eq. 14), where
the lever arm ``L`` varies with the bend (paper fig. 10b). Here ``L`` comes from constant
curvature: a force perpendicular to the tip has the lever ``l sin(beta)/beta`` about the
section base (:func:`endocal.kinematics.tip_pose_in_base`), and the bend ``beta`` is read
from the tracker during calibration. A load also straightens the section at a given knob
angle (the tendons stretch), so the model carries the no-load bend ``beta_0(theta)`` and a
compliance ``c`` (bend lost per N*mm of contact moment): ``beta = beta_0(theta) - c M_contact``.
The prediction inverts eq. 14 (the paper's eq. 15)::

    F = Delta M_knob / (G * L(beta_0(theta) - c * Delta M_knob / G))

``theta`` is the knob angle (deg); torques are in N*mm (motor current times the torque constant).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from endocal.errors import ModelError, RunFormatError
from endocal.kinematics import bend_from_angles_rad, tip_pose_in_base

#: Width of the knob-angle bins of the internal-resistance and bend tables (deg).
BIN_DEG = 2.0
#: Fewest samples a bin needs to count (a 100 Hz sweep at 24 deg/s leaves ~8 per 2 deg bin per pass).
MIN_PER_BIN = 5
#: A sample belongs to a direction of motion when the knob moves faster than this (deg/s).
MOVING_DPS = 2.0


def lever_arm_mm(bend_rad: np.ndarray, length_mm: float) -> np.ndarray:
    """Lever arm (mm) about the section base of a force perpendicular to the tip.

    Constant curvature: the tip's axial distance from the base, ``l sin(beta)/beta``
    (``z`` of :func:`endocal.kinematics.tip_pose_in_base`).
    """
    b = np.abs(np.atleast_1d(np.asarray(bend_rad, float)))
    return tip_pose_in_base(b, np.zeros_like(b), length_mm)[0][:, 2]


@dataclass
class ForceTrial:
    """One calibration run reduced to what the force model needs (motor-clock rows).

    Attributes
    ----------
    source : str
        Run folder.
    load_n : float
        Known tip load (N); 0 for an unloaded trial.
    knob_deg, knob_dps, torque_nmm, bend_rad, t_s : ndarray
        Knob angle, speed, knob torque (current x torque constant), measured bend magnitude
        of the section (from the tracker's eq.-1 angles under constant curvature), time.
    true_force_n : ndarray or None
        The simulator's true tip force, when the run has it (tests only; never fitted).
    """

    source: str
    load_n: float
    t_s: np.ndarray
    knob_deg: np.ndarray
    knob_dps: np.ndarray
    torque_nmm: np.ndarray
    bend_rad: np.ndarray
    true_force_n: np.ndarray | None = None


@dataclass
class HeldOut:
    """Force predicted on a loaded trial by a model fitted without it."""

    source: str
    load_n: float
    pred_mean_n: float
    rms_error_n: float
    n_samples: int

    @property
    def error_n(self) -> float:
        """Mean prediction minus the known load (N)."""
        return self.pred_mean_n - self.load_n

    @property
    def error_pct(self) -> float:
        return 100.0 * self.error_n / self.load_n

    def to_dict(self) -> dict:
        return {"source": self.source, "load_n": self.load_n, "pred_mean_n": self.pred_mean_n,
                "error_n": self.error_n, "error_pct": self.error_pct, "rms_error_n": self.rms_error_n,
                "n_samples": self.n_samples}


@dataclass
class ForceModel:
    """Contact-force model of one knob (duodenoscope paper, eqs. 12-15).

    Build it with :func:`fit_force` (or :func:`endocal.force.io.load_force_model`).

    Attributes
    ----------
    probe, axis : str
        Probe name and bending axis the model was calibrated on.
    side : int
        +1 when the loads opposed bending towards the positive half-plane (the knob turning
        positive bends into the load), -1 otherwise.
    torque_constant_nm_per_a : float
        Motor torque per current (N*m/A): ``torque_nmm = current_ma * torque_constant``.
    bending_length_mm : float
        Arc length of the bending section (mm), for the lever arm.
    theta0_deg, bin_deg : float
        First knob angle and spacing of the tables (deg).
    m_r_loading_nmm, m_r_unloading_nmm : ndarray
        Internal resistance M_r(theta) (N*mm) moving into / out of the load (eq. 13).
    bend0_rad : ndarray
        No-load bend magnitude beta_0(theta) (rad) moving into the load.
    g_ : float
        Transmission coefficient G (knob torque per contact moment) at the knob angle
        ``g_theta_ref_deg`` (deg, towards the load), ``g_se_`` its standard error.
    g_slope_per_deg_ : float
        Change of G per knob degree towards the load, ``g_slope_se_`` its standard error: the
        bending section stiffens at large bends, so less of the knob torque reaches the tip.
    compliance_rad_per_nmm_ : float
        Bend lost per contact moment (rad per N*mm), ``compliance_se_`` its standard error.
    heldout_ : list of HeldOut
        Leave-one-loaded-trial-out predictions.
    loads_n : list of float
        The known loads of the calibration trials (N).
    theta_min_deg : float
        Start of the active bending phase used in the fit (knob deg towards the load).
    source : str or None
        The file the model was loaded from.
    """

    probe: str
    axis: str
    side: int
    torque_constant_nm_per_a: float
    bending_length_mm: float
    theta0_deg: float
    bin_deg: float
    m_r_loading_nmm: np.ndarray
    m_r_unloading_nmm: np.ndarray
    bend0_rad: np.ndarray
    g_: float
    g_se_: float
    g_slope_per_deg_: float
    g_slope_se_: float
    g_theta_ref_deg: float
    compliance_rad_per_nmm_: float
    compliance_se_: float
    heldout_: list = field(default_factory=list)
    loads_n: list = field(default_factory=list)
    theta_min_deg: float = 0.0
    source: str | None = None

    @property
    def theta_range_deg(self) -> tuple[float, float]:
        """Knob angles the tables cover (deg); beyond them the edge values hold."""
        return self.theta0_deg, self.theta0_deg + self.bin_deg * (self.bend0_rad.size - 1)

    def evaluator(self) -> _Evaluator:
        """A scalar, allocation-free predictor for per-tick use (:class:`ForceGuard`)."""
        return _Evaluator(self)

    def predict(self, knob_deg, knob_dps, current_ma) -> np.ndarray:
        """Predicted tip force (N) per sample (eq. 15), moving into the load unless the knob backs off.

        Parameters
        ----------
        knob_deg, knob_dps, current_ma : array_like
            Knob angle (deg), speed (deg/s) and motor current (mA), same shape.
        """
        theta = np.asarray(knob_deg, float)
        torque = np.asarray(current_ma, float) * self.torque_constant_nm_per_a
        loading = np.asarray(knob_dps, float) * self.side >= -MOVING_DPS
        return self.force_from_torque(theta, torque, loading)

    def force_from_torque(self, theta_deg: np.ndarray, torque_nmm: np.ndarray, loading: np.ndarray) -> np.ndarray:
        """Eq. 15 on arrays: force (N) from knob angle (deg), knob torque (N*mm) and direction (bool)."""
        theta = np.asarray(theta_deg, float)
        grid = self.theta0_deg + self.bin_deg * np.arange(self.bend0_rad.size)
        m_r = np.where(loading, np.interp(theta, grid, self.m_r_loading_nmm), np.interp(theta, grid, self.m_r_unloading_nmm))
        dm = (np.asarray(torque_nmm, float) - m_r) * self.side  # duodenoscope paper, eq. 13: increment over M_r
        g = self.g_ + self.g_slope_per_deg_ * (theta * self.side - self.g_theta_ref_deg)
        bend = np.interp(theta, grid, self.bend0_rad) - self.compliance_rad_per_nmm_ * dm / g
        return dm / (g * lever_arm_mm(np.clip(bend, 0.0, None), self.bending_length_mm))  # eq. 15

    def __str__(self) -> str:
        lo, hi = self.theta_range_deg
        return (f"{self.axis}: F_n = dM_knob / (G * L(beta)) [G={self.g_:.3f}+-{self.g_se_:.3f} at "
                f"{self.g_theta_ref_deg * self.side:+.0f} deg, dG/dtheta={self.g_slope_per_deg_:+.4f}+-{self.g_slope_se_:.4f} /deg, "
                f"compliance={self.compliance_rad_per_nmm_ * 1e3:.3f}+-{self.compliance_se_ * 1e3:.3f} mrad/(N*mm)]; "
                f"M_r(theta) per direction on {lo:+.0f}..{hi:+.0f} deg (duodenoscope paper, eqs. 12-15)")


class _Evaluator:
    """Eq. 15 for one sample on Python floats (no numpy calls: a guard tick must stay cheap)."""

    __slots__ = ("_t0", "_inv_bin", "_n", "_up", "_down", "_bend", "_g", "_gs", "_gref", "_c", "_side", "_kt", "_l")

    def __init__(self, m: ForceModel) -> None:
        self._t0, self._inv_bin, self._n = m.theta0_deg, 1.0 / m.bin_deg, m.bend0_rad.size
        self._up = [float(v) for v in m.m_r_loading_nmm]
        self._down = [float(v) for v in m.m_r_unloading_nmm]
        self._bend = [float(v) for v in m.bend0_rad]
        self._g, self._c, self._side = m.g_, m.compliance_rad_per_nmm_, m.side
        self._gs, self._gref = m.g_slope_per_deg_, m.g_theta_ref_deg
        self._kt, self._l = m.torque_constant_nm_per_a, m.bending_length_mm

    def _lookup(self, table: list, theta: float) -> float:
        x = (theta - self._t0) * self._inv_bin
        if x <= 0.0:
            return table[0]
        i = int(x)
        if i >= self._n - 1:
            return table[-1]
        f = x - i
        return table[i] + f * (table[i + 1] - table[i])

    def torque_increment_nmm(self, theta_deg: float, current_ma: float, loading: bool) -> float:
        """``(M_knob - M_r(theta)) * side`` (N*mm), eq. 13."""
        m_r = self._lookup(self._up if loading else self._down, theta_deg)
        return (current_ma * self._kt - m_r) * self._side

    def force_n(self, theta_deg: float, dm_nmm: float) -> float:
        """Eq. 15: tip force (N) from the torque increment at knob angle ``theta_deg``."""
        g = self._g + self._gs * (theta_deg * self._side - self._gref)
        bend = self._lookup(self._bend, theta_deg) - self._c * dm_nmm / g
        if bend < 1e-4:
            lever = self._l * (1.0 - bend * bend / 6.0)
        else:
            lever = self._l * math.sin(bend) / bend
        return dm_nmm / (g * lever)


# --------------------------------------------------------------------------- fitting


def read_trial(run_dir: str | Path, axis: str | None = None, torque_constant_nm_per_a: float | None = None):
    """Read one calibration run: its known load, knob signals, torque and measured bend.

    Parameters
    ----------
    run_dir : path
        Run folder written by ``endocal excite`` (``run.json`` records the tip load given by
        ``--tip-load-n``; a run without one is an unloaded trial).
    axis : str, optional
        Bending axis; default the one the run's tip load names, else the protocol's first axis.
    torque_constant_nm_per_a : float, optional
        Motor torque constant; default the simulator's, recorded in ``run.json``.

    Returns
    -------
    trial : ForceTrial
    info : dict
        ``probe`` (name), ``bending_length_mm``, ``axis``, ``side``, ``torque_constant_nm_per_a``.

    Raises
    ------
    RunFormatError
        Not a run folder, or the axis is missing.
    ModelError
        No torque constant known.
    """
    from endocal.runs.aligned import load_aligned

    data = load_aligned(run_dir)
    meta = data.meta
    if not meta:
        raise RunFormatError(f"{run_dir}: fit force needs run folders (run.json records the tip load), not bare tables")
    proto = meta.get("protocol") or {}
    load = proto.get("tip_load") or {}
    load_n = float(load.get("force_n", 0.0))
    side = -1 if load.get("opposes") == "-" else 1
    probe = meta.get("probe") or {}
    axes = list(probe.get("bending_axes") or data.axes)
    if axis is None:
        axis = load.get("axis")
    if axis is None:
        params_axes = (proto.get("params") or {}).get("axes") or []
        first = params_axes[0] if params_axes else axes[0]
        axis = {"axis1": axes[0], "axis2": axes[1]}.get(first, first) if len(axes) == 2 else first
    if axis not in data.axes:
        raise RunFormatError(f"{run_dir}: no axis '{axis}' in the run (it has {', '.join(data.axes)})")
    kt = torque_constant_nm_per_a
    if kt is None:
        kt = (((meta.get("backend") or {}).get("config") or {}).get("motor") or {}).get("torque_constant_nm_per_a")
    if kt is None:
        raise ModelError(f"{run_dir}: run.json records no motor torque constant (a hardware run): "
                         "give --torque-constant N_M_PER_A (the motor's torque per current)")
    if data.drive_unit(axis) != "deg":
        raise RunFormatError(f"{run_dir}: the {axis} drive is a linear stage (commanded in {data.drive_unit(axis)}): "
                             "fit force models a knob's torque against its angle, not a stage's force against its "
                             "travel")
    tab = data.table
    for col in (f"{axis}_pos_deg", f"{axis}_vel_degps", f"{axis}_current_ma"):
        if col not in tab.columns:
            raise RunFormatError(f"{run_dir}: column '{col}' is missing; fit force needs the knob's position, speed and current")
    if not tab[f"{axis}_current_ma"].to_numpy(float).any():
        # a motor's current is never exactly 0 throughout a run that moves: a log without one
        # (endocal import csv fills an unmapped current with 0)
        raise RunFormatError(f"{run_dir}: column '{axis}_current_ma' is 0 throughout: fit force needs the knob motor's "
                             f"current (when importing a CSV log, map it: [knobs.{axis}] current = COLUMN)")
    first, second = axes[0], axes[1]
    bx, by = bend_from_angles_rad(data.meas_deg(first), data.meas_deg(second))
    true_f = tab["contact_force_n"].to_numpy(float) if "contact_force_n" in tab.columns else None
    trial = ForceTrial(
        source=str(run_dir), load_n=load_n, t_s=data.t_s,
        knob_deg=tab[f"{axis}_pos_deg"].to_numpy(float), knob_dps=tab[f"{axis}_vel_degps"].to_numpy(float),
        torque_nmm=tab[f"{axis}_current_ma"].to_numpy(float) * float(kt), bend_rad=np.hypot(bx, by),
        true_force_n=true_f,
    )
    info = {"probe": probe.get("name"), "bending_length_mm": float(probe.get("bending_length_mm", np.nan)),
            "axis": axis, "side": side, "torque_constant_nm_per_a": float(kt)}
    return trial, info


def _binned(theta: np.ndarray, value: np.ndarray, edges0: float, n: int, bin_deg: float) -> np.ndarray:
    """Mean of ``value`` per knob-angle bin centred on the grid; NaN where a bin has too few samples."""
    idx = np.round((theta - edges0) / bin_deg).astype(int)
    ok = (idx >= 0) & (idx < n)
    s = np.bincount(idx[ok], weights=value[ok], minlength=n)
    c = np.bincount(idx[ok], minlength=n)
    out = np.full(n, np.nan)
    good = c >= MIN_PER_BIN
    out[good] = s[good] / c[good]
    return out


def _fill(table: np.ndarray, grid: np.ndarray) -> np.ndarray:
    ok = np.isfinite(table)
    if ok.sum() < 2:
        return table
    return np.interp(grid, grid[ok], table[ok])


def _tables(unloaded: list[ForceTrial], side: int):
    """Grid, M_r per direction (eq. 13) and the no-load bend, from the unloaded trials."""
    theta = np.concatenate([t.knob_deg for t in unloaded])
    vel = np.concatenate([t.knob_dps for t in unloaded]) * side
    torque = np.concatenate([t.torque_nmm for t in unloaded])
    bend = np.concatenate([t.bend_rad for t in unloaded])
    into, out = vel > MOVING_DPS, vel < -MOVING_DPS
    lo = math.floor(theta[into].min() / BIN_DEG) * BIN_DEG
    hi = math.ceil(theta[into].max() / BIN_DEG) * BIN_DEG
    n = int(round((hi - lo) / BIN_DEG)) + 1
    grid = lo + BIN_DEG * np.arange(n)
    up = _binned(theta[into], torque[into], lo, n, BIN_DEG)
    down = _binned(theta[out], torque[out], lo, n, BIN_DEG)
    b0 = _binned(theta[into], bend[into], lo, n, BIN_DEG)
    if np.isfinite(up).sum() < 2 or np.isfinite(b0).sum() < 2:
        raise ModelError("the unloaded trials have too few samples moving into the load to calibrate M_r(theta)")
    up, b0 = _fill(up, grid), _fill(b0, grid)
    down = _fill(down, grid) if np.isfinite(down).sum() >= 2 else up.copy()
    return grid, up, down, b0


def _active(trial: ForceTrial, side: int, theta_min: float) -> np.ndarray:
    """Samples of the active bending phase (paper fig. 10a, grey): moving into the load, tendon taut."""
    return (trial.knob_dps * side > MOVING_DPS) & (trial.knob_deg * side >= theta_min)


def _sweeps(mask: np.ndarray) -> list[slice]:
    """Contiguous runs of ``mask`` (one per reciprocating pass)."""
    d = np.diff(np.concatenate(([0], mask.astype(int), [0])))
    starts, stops = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
    return [slice(a, b) for a, b in zip(starts, stops) if b - a >= 2 * MIN_PER_BIN]


def _fit_g(loaded: list[ForceTrial], grid, up, b0, side, length_mm, theta_min, theta_ref):
    """G(theta) (eq. 14) and the compliance from loaded trials, with standard errors over passes.

    ``Delta M = (G + G' (theta - theta_ref)) * F * L(beta)``: least squares through the origin,
    per reciprocating pass; the estimate is the pass average weighted by each pass' information.
    Returns ``(g, g_se, g_slope, g_slope_se, c, c_se)``.
    """
    est, wts = [], []
    for tr in loaded:
        act = _active(tr, side, theta_min)
        for sl in _sweeps(act):
            theta = tr.knob_deg[sl]
            dm = (tr.torque_nmm[sl] - np.interp(theta, grid, up)) * side  # eq. 13
            m_c = tr.load_n * lever_arm_mm(tr.bend_rad[sl], length_mm)   # contact moment F * L(beta)
            a = np.column_stack([m_c, (theta * side - theta_ref) * m_c])
            (g, gs), *_ = np.linalg.lstsq(a, dm, rcond=None)               # eq. 14, G linear in theta
            lost = np.interp(theta, grid, b0) - tr.bend_rad[sl]
            c = float(np.sum(lost * m_c) / np.sum(m_c * m_c))
            est.append((g, gs, c))
            wts.append(float(np.sum(m_c * m_c)))
    if len(est) < 2:
        raise ModelError("the loaded trials hold fewer than 2 passes into the load: record more cycles or loads")
    est, w = np.array(est), np.array(wts) / np.sum(wts)
    mean = w @ est
    n_eff = 1.0 / np.sum(w * w)
    se = np.sqrt((w @ (est - mean) ** 2) / max(n_eff - 1.0, 1.0))
    return float(mean[0]), float(se[0]), float(mean[1]), float(se[1]), float(mean[2]), float(se[2])


def fit_force(runs: list, *, axis: str | None = None, torque_constant_nm_per_a: float | None = None,
              theta_min_deg: float | None = None) -> ForceModel:
    """Fit the contact-force model of one knob from unloaded and loaded calibration runs.

    Parameters
    ----------
    runs : list of path
        Run folders of the ``force-calibration`` protocol: at least one with no tip load and
        at least two with known loads (``excite --tip-load-n F``).
    axis : str, optional
        Bending axis (default: the one the runs' loads name).
    torque_constant_nm_per_a : float, optional
        Motor torque constant (default: recorded by the simulator in ``run.json``).
    theta_min_deg : float, optional
        Smallest knob angle (deg, towards the load) of the active bending phase; default the
        angle where the no-load bend first exceeds 10 deg (the tendon is taut past the slack).

    Returns
    -------
    ForceModel
        With ``heldout_``: each loaded trial predicted by a model fitted on the others.

    Raises
    ------
    ModelError
        Too few unloaded or loaded runs, runs of different probes, axes, sides or torque constants.
    """
    if not runs:
        raise ModelError("fit force needs run folders: unloaded and loaded force-calibration runs")
    trials, infos = [], []
    for r in runs:
        tr, info = read_trial(r, axis, torque_constant_nm_per_a)
        trials.append(tr)
        infos.append(info)
    for key in ("probe", "axis", "side", "torque_constant_nm_per_a", "bending_length_mm"):
        values = {i[key] for i in infos}
        if len(values) > 1:
            raise ModelError(f"the runs differ in {key} ({', '.join(map(str, sorted(values, key=str)))}): "
                             "calibrate one probe, axis and load side at a time")
    info = infos[0]
    side = info["side"] if any(t.load_n > 0 for t in trials) else 1
    side = next((i["side"] for i, t in zip(infos, trials) if t.load_n > 0), side)
    unloaded = [t for t in trials if t.load_n == 0.0]
    loaded = [t for t in trials if t.load_n > 0.0]
    if not unloaded:
        raise ModelError("no unloaded run: M_r(theta) (duodenoscope paper eq. 13) needs a force-calibration run without --tip-load-n")
    if len(loaded) < 2:
        raise ModelError(f"{len(loaded)} loaded run(s): G needs at least two runs with known loads "
                         "(excite force-calibration --tip-load-n F), so one can be held out")
    grid, up, down, b0 = _tables(unloaded, side)
    if theta_min_deg is None:
        taut = np.flatnonzero((b0 > math.radians(10.0)) & (grid * side > 0))
        theta_min_deg = float(np.min(grid[taut] * side)) if taut.size else 0.0
    length = info["bending_length_mm"]
    theta_ref = float(np.round(0.5 * (theta_min_deg + np.max(grid * side)), 1))
    g, g_se, gs, gs_se, c, c_se = _fit_g(loaded, grid, up, b0, side, length, theta_min_deg, theta_ref)

    def build(g_, g_se_, gs_, gs_se_, c_, c_se_, heldout):
        return ForceModel(probe=info["probe"], axis=info["axis"], side=side,
                          torque_constant_nm_per_a=info["torque_constant_nm_per_a"], bending_length_mm=length,
                          theta0_deg=float(grid[0]), bin_deg=BIN_DEG, m_r_loading_nmm=up, m_r_unloading_nmm=down,
                          bend0_rad=b0, g_=g_, g_se_=g_se_, g_slope_per_deg_=gs_, g_slope_se_=gs_se_,
                          g_theta_ref_deg=theta_ref, compliance_rad_per_nmm_=c_, compliance_se_=c_se_,
                          heldout_=heldout, loads_n=sorted({t.load_n for t in trials}), theta_min_deg=theta_min_deg)

    heldout = []
    for k, tr in enumerate(loaded):
        others = [t for j, t in enumerate(loaded) if j != k]
        try:
            gk, _, gsk, _, ck, _ = _fit_g(others, grid, up, b0, side, length, theta_min_deg, theta_ref)
        except ModelError:
            continue
        mk = build(gk, 0.0, gsk, 0.0, ck, 0.0, [])
        act = _active(tr, side, theta_min_deg)
        pred = mk.force_from_torque(tr.knob_deg[act], tr.torque_nmm[act], np.ones(act.sum(), bool))
        heldout.append(HeldOut(tr.source, tr.load_n, float(pred.mean()),
                               float(np.sqrt(np.mean((pred - tr.load_n) ** 2))), int(act.sum())))
    return build(g, g_se, gs, gs_se, c, c_se, heldout)
