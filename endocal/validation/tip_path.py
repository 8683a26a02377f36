"""Task-space control on a backend: walk the tip along a path in mm and measure how far it strays.

The thesis's trajectory experiment (summary, "Task Space Control", fig. 5 and table 1): the
desired tip positions go through constant-curvature inverse kinematics to desired bending
angles (:func:`endocal.protocols.paths.path_trajectory`), through the orthogonal compensator
(duodenoscope paper eqs. 3-4) and each knob's inverse hysteresis model to knob commands
(:func:`endocal.validation.playback.task_space_trajectory`); the backend plays them; the EM
tracker measures where the tip went. The error of each point is the distance

    E = || P_r - P_d ||                                                   (thesis, trajectory error)

between reached and desired tip, both in the base_home frame (the base sensor's frame at the
start of the run, see :mod:`endocal.protocols.paths`), at every tracker frame of the walk.
It is summarised by its median (the thesis's table 1), RMSE and maximum, and by the median as
a percentage of the path length (the thesis: about 2.5 %).
"""

from __future__ import annotations

import tempfile
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from endocal.errors import ModelError, RunFormatError
from endocal.excite import run_excitation
from endocal.probe import ProbeConfig
from endocal.protocols.paths import TipPath, path_trajectory
from endocal.runs.aligned import read_stream
from endocal.runs.format import MOTOR, TRACKER, read_run_json
from endocal.validation.metrics import block_length
from endocal.validation.playback import PREROLL_S, task_space_trajectory
from endocal.validation.units import Units


@dataclass(frozen=True)
class TipMetrics:
    """Tip-position error of one walk of a path, mm.

    Attributes
    ----------
    median_mm, rmse_mm, max_mm : float
    path_pct : float
        ``median_mm`` as a percentage of ``length_mm``.
    length_mm : float
        Length of the path walked.
    n : int
        Tracker frames evaluated (points).
    """

    median_mm: float
    rmse_mm: float
    max_mm: float
    path_pct: float
    length_mm: float
    n: int

    def to_dict(self) -> dict:
        return {"median_mm": self.median_mm, "rmse_mm": self.rmse_mm, "max_mm": self.max_mm,
                "path_pct": self.path_pct, "length_mm": self.length_mm, "n": self.n}


def tip_metrics(error_mm: np.ndarray, length_mm: float) -> TipMetrics:
    """Median, RMSE and maximum of per-point tip errors, and the median per path length."""
    e = np.asarray(error_mm, float)
    if e.size == 0:
        raise RunFormatError("no tracker frame fell on the path: nothing to evaluate (was the tip tracked?)")
    med = float(np.median(e))
    return TipMetrics(med, float(np.sqrt(np.mean(e**2))), float(e.max()), 100.0 * med / length_mm, float(length_mm),
                      int(e.size))


@dataclass
class TipPathResult:
    """One walk of a tip path with one set of models.

    Attributes
    ----------
    path : str
    label : str
        Names the models, e.g. ``ap=bspline, ml=bspline``.
    models : dict
        Axis -> model file (or description) used.
    metrics : TipMetrics
    t_s : (n,) array
        Time of each evaluated tracker frame since the walk began, s.
    desired_mm, reached_mm : (n, 3) arrays
        Desired and reached tip in base_home, mm.
    error_mm : (n,) array
        ``|reached - desired|`` per point, mm.
    s_mm : (n,) array
        Distance along the path of each point's desired position, mm.
    run : Path
        The logged run.
    """

    path: str
    label: str
    models: dict
    metrics: TipMetrics
    t_s: np.ndarray
    desired_mm: np.ndarray
    reached_mm: np.ndarray
    error_mm: np.ndarray
    s_mm: np.ndarray
    run: Path | None = None
    events: list = field(default_factory=list)

    def to_dict(self) -> dict:
        return {"path": self.path, "label": self.label, "models": {k: str(v) for k, v in self.models.items()},
                "metrics": self.metrics.to_dict(), "run": str(self.run) if self.run else None,
                "events": list(self.events)}


def tip_in_base_home_mm(tracker, home_until_s: float = np.inf) -> tuple[np.ndarray, np.ndarray]:
    """Tip positions in the base_home frame at each frame where both sensors are valid.

    base_home is the base sensor's pose while the probe is at home: the mean of its valid
    frames before ``home_until_s`` (when translation or rotation first move; all frames when
    they never do), so the base sensor's own noise averages out of the frame instead of
    entering every point. ``tip_in_base_home = base_home2tracker^-1 (tip - base_home)``.

    Returns
    -------
    t_s : (n,) array
    tip_mm : (n, 3) array
    """
    good = tracker[tracker["valid"].astype(bool)]
    tip = good[good["sensor"].astype(str) == "tip"]
    base = good[good["sensor"].astype(str) == "base"]
    if tip.empty or base.empty:
        missing = "tip" if tip.empty else "base"
        raise RunFormatError(f"the tracker logged no valid {missing} sensor frame: the tip path needs both sensors")
    xyz = ["x_mm", "y_mm", "z_mm"]
    home = base[base["t_s"] < home_until_s]
    home = home if not home.empty else base.iloc[:1]
    home2tracker = Rotation.from_quat(home[["qw", "qx", "qy", "qz"]].to_numpy(float), scalar_first=True).mean()
    origin = home[xyz].to_numpy(float).mean(axis=0)
    pairs = tip.merge(base[["t_s"]], on="t_s").sort_values("t_s")  # frames where the base was seen too
    p = home2tracker.inv().apply(pairs[xyz].to_numpy(float) - origin)
    return pairs["t_s"].to_numpy(float), p


def evaluate_tip_run(run: Path, label: str = "", models: dict | None = None) -> TipPathResult:
    """Per-point tip errors of a logged walk of a tip path (a run holding ``tip_desired_*_mm``).

    Only frames of the walk itself count (not the approach from rest or the return), and
    only frames inside the motor clock's span.

    Raises
    ------
    RunFormatError
        The run holds no desired tip positions, or no tracked frame falls on the walk.
    """
    motor = read_stream(run, MOTOR)
    cols = [f"tip_desired_{c}_mm" for c in "xyz"]
    if any(c not in motor.columns for c in cols):
        raise RunFormatError(f"{run}: no tip_desired_x/y/z_mm columns: this run did not walk a tip path")
    meta = read_run_json(Path(run))
    walk = meta.get("protocol", {}).get("walk_s")
    t_m = motor["t_s"].to_numpy(float)
    desired_m = motor[cols].to_numpy(float)
    moves = np.zeros(t_m.size, bool)
    for col in ("translation_goal_mm", "rotation_goal_deg"):
        if col in motor.columns:
            moves |= np.abs(motor[col].to_numpy(float)) > 1e-9
    t_f, reached = tip_in_base_home_mm(read_stream(run, TRACKER), float(t_m[moves][0]) if moves.any() else np.inf)
    lo, hi = walk if walk else (t_m[0], t_m[-1])
    keep = (t_f >= lo) & (t_f <= hi) & (t_f >= t_m[0]) & (t_f <= t_m[-1])
    t = t_f[keep]
    desired = np.column_stack([np.interp(t, t_m, desired_m[:, k]) for k in range(3)])
    reached = reached[keep]
    err = np.linalg.norm(reached - desired, axis=1)
    step = np.linalg.norm(np.diff(desired_m, axis=0), axis=1)
    s_m = np.concatenate([[0.0], np.cumsum(step)])
    inside = (t_m >= lo) & (t_m <= hi)
    s0 = float(s_m[inside][0]) if inside.any() else 0.0
    s = np.interp(t, t_m, s_m) - s0
    length = float(s_m[inside][-1] - s0) if inside.any() else float(s_m[-1])
    name = meta.get("protocol", {}).get("name", Path(run).name)
    return TipPathResult(name, label, dict(models or {}), tip_metrics(err, length), t - lo, desired, reached, err, s,
                         Path(run), list(meta.get("events", [])))


def walk_tip_path(
    path: TipPath,
    models: dict,
    probe: ProbeConfig,
    backend_factory,
    *,
    planes=None,
    seed: int = 0,
    out: Path | None = None,
    label: str = "",
    model_files: dict | None = None,
    guard=None,
    progress=None,
) -> TipPathResult:
    """Walk ``path`` with task-space control and measure the tip error.

    Parameters
    ----------
    path : TipPath
    models : dict
        Bending axis -> fitted hysteresis model (its inverse gives the knob command); an axis
        without a model is commanded its (compensated) desired angle.
    probe : ProbeConfig
    backend_factory : callable
        ``backend_factory() -> Backend``, called once.
    planes : PlanesCalibration, optional
        Orthogonal compensation between inverse kinematics and the hysteresis inverse.
    out : Path, optional
        Run folder to write (when omitted the walk is logged to a temporary folder, removed after).
    guard : ForceGuard, optional
        Contact-force guard for the run.

    Raises
    ------
    UnreachableError
        A path point is out of reach (before anything moves).
    LimitError
        The knob commands leave the probe's limits (before anything moves).
    ModelError
        A model for an axis the probe lacks.
    """
    for axis in models:
        if axis not in probe.bending_axes:
            raise ModelError(f"a model is for axis {axis!r}, but probe '{probe.name}' has {', '.join(probe.bending_axes)}")
    desired = path_trajectory(path, probe)
    traj = task_space_trajectory(desired, probe, models, planes)
    traj.check_limits(probe)  # before anything moves
    seg = next(s for s in desired.segments if s.label == "path")
    walk_s = (seg.start_s + PREROLL_S, seg.stop_s + PREROLL_S)
    info = {"name": path.name, "tip_path": path.to_dict(), "walk_s": list(walk_s), "preroll_s": PREROLL_S,
            "hysteresis_compensation": {a: str((model_files or {}).get(a, type(m).__name__)) for a, m in models.items()},
            "orthogonal_compensation": planes is not None}
    described = model_files or {a: type(m).__name__ for a, m in models.items()}

    def walk(run: Path) -> TipPathResult:
        run_excitation(traj, backend_factory(), probe, run, protocol_info=info, seed=seed, force=True,
                       progress=progress, guard=guard)
        return evaluate_tip_run(run, label=label, models=described)

    if out is not None:
        return walk(Path(out))
    with tempfile.TemporaryDirectory(prefix="endocal-path-") as tmp:  # nothing kept when no run folder is asked for
        return replace(walk(Path(tmp) / "run"), run=None)


def tip_error_units(results: list[TipPathResult]) -> tuple[Units, list[np.ndarray]]:
    """Cut walks of one path into common units along the path, for paired tests.

    Per-point errors are autocorrelated (a lagging tip stays behind for a while), so points
    are grouped into consecutive stretches of the path as long as the errors' decorrelation
    length (the longest over the walks); each walk's errors are first put on the first walk's
    points by distance along the path, so all walks share the units.

    Returns
    -------
    units : Units
    errors : list of (n,) arrays
        Each walk's per-point error on the first walk's points, mm.
    """
    ref = results[0]
    errors = [ref.error_mm] + [np.interp(ref.s_mm, r.s_mm, r.error_mm) for r in results[1:]]
    L = max(block_length(e - e.mean()) for e in errors)
    n = ref.error_mm.size
    n_blocks = max(1, n // L)
    edges = np.linspace(0, n, n_blocks + 1).round().astype(int)
    bounds = [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:]) if b > a]
    reason = (f"{len(bounds)} stretches of the path of about {L} tracker frames each (the errors' decorrelation "
              "length, autocorrelation below 1/e), the same stretches for every walk")
    return Units("block", bounds, reason), errors
