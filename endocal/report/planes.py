"""The measured sweeps behind a ``planes.json``, for the report's bending-plane figure.

The duodenoscope paper's figure 8 shows the *measured* tip points of the single-knob sweeps,
seen down the probe axis, before and after orthogonal compensation. ``planes.json`` keeps the
fitted angles and, in ``sweeps_used``, the name of every run folder and sweep it was fitted
on, but not the samples. This module finds those run folders, cuts them into sweeps exactly
as ``endocal fit planes`` did (:func:`endocal.planes.from_runs.segment_runs`) and checks that
they are the sweeps the file records before any point is drawn:

before compensation
    run folders named in ``sweeps_used``, looked up beside the planes file (and in the
    places the caller names); their sweeps must match the recorded ones (run, index,
    half-plane, frame count).
after compensation
    only when the file's residuals are ``measured`` (``fit planes RUN --after AFTER``). The
    file does not name the after-runs, so candidates are run folders recorded through a
    planes file (``run.json`` ``protocol.orthogonal_compensation``); the ones whose refitted
    deviations reproduce the recorded residual deviations (within 1e-6 deg) are used.

Whatever cannot be found or does not match is said in :attr:`PlanesView.notes`; the figure
then draws only the fitted geometry and says so, never points from some other run.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from endocal.errors import EndocalError
from endocal.planes import PlanesCalibration
from endocal.planes.calibration import fit_pooled
from endocal.planes.from_runs import segment_runs
from endocal.planes.halfplanes import HALF_PLANES
from endocal.planes.segment import Segmentation
from endocal.runs.format import RUN_JSON, read_run_json

#: Largest difference between a recorded residual deviation and the one refitted from a
#: candidate after-run for the run to count as the one measured (deg): the refit is the same
#: deterministic computation on the same samples, so only float round-off separates them.
MATCH_TOL_DEG = 1e-6


@dataclass
class SweepPoints:
    """Measured tip points of the sweeps of one phase (before or after compensation).

    Attributes
    ----------
    phase : {"before", "after"}
    runs : list of str
        Run folders the points were read from.
    tip_xy_mm : dict of str to (n, 2) array
        Per half-plane (``y+ y- x+ x-``), the tip position in the base frame projected on the
        base x-y plane (looking down the probe axis), mm; every frame of every sweep.
    sweeps : list of dict
        ``run``, ``index``, ``half_plane``, ``frames`` of each sweep.
    """

    phase: str
    runs: list[str]
    tip_xy_mm: dict[str, np.ndarray]
    sweeps: list[dict]

    @property
    def n_points(self) -> int:
        return int(sum(len(p) for p in self.tip_xy_mm.values()))

    def to_dict(self) -> dict:
        return {"phase": self.phase, "runs": list(self.runs), "n_points": self.n_points,
                "n_points_by_half_plane": {h: int(len(p)) for h, p in self.tip_xy_mm.items()},
                "sweeps": [dict(s) for s in self.sweeps]}


@dataclass
class PlanesView:
    """What the bending-plane figure can show: fitted planes, and the measured points found.

    Attributes
    ----------
    calibration : PlanesCalibration
    before, after : SweepPoints or None
        Measured sweeps before / after compensation (None: not available, see ``notes``).
    notes : list of str
        What could not be drawn from measurements, and why.
    """

    calibration: PlanesCalibration
    before: SweepPoints | None = None
    after: SweepPoints | None = None
    notes: list[str] = field(default_factory=list)

    def to_dict(self) -> dict:
        cal = self.calibration
        return {"residual_source": cal.residual_source,
                "before": None if self.before is None else self.before.to_dict(),
                "after": None if self.after is None else self.after.to_dict(),
                "recorded_frames": int(sum(s.get("frames", 0) for s in cal.sweeps_used)),
                "notes": list(self.notes)}


def _points(seg: Segmentation, phase: str, runs: list[Path]) -> SweepPoints:
    groups = seg.by_half_plane()
    xy = {h: (np.concatenate([s.tip_in_base_mm[:, :2] for s in groups[h]]) if groups[h] else np.zeros((0, 2)))
          for h in HALF_PLANES}
    sweeps = [{"run": s.run, "index": s.index, "half_plane": s.half_plane, "frames": int(len(s.t_s))}
              for s in seg.sweeps]
    return SweepPoints(phase, [str(r) for r in runs], xy, sweeps)


def _run_folders(places: Sequence[Path]) -> list[Path]:
    """Run folders among ``places`` and their sub-folders (one level), in order, once each."""
    out: list[Path] = []
    for p in places:
        if not p.is_dir():
            continue
        for q in [p, *sorted(c for c in p.iterdir() if c.is_dir())]:
            if (q / RUN_JSON).is_file() and q.resolve() not in {o.resolve() for o in out}:
                out.append(q)
    return out


def _compensated_through(run: Path) -> str | None:
    """The planes file a run's knob goals went through (``excite --planes``), or None."""
    try:
        proto = read_run_json(run).get("protocol")
    except EndocalError:
        return None
    return proto.get("orthogonal_compensation") if isinstance(proto, dict) else None


def _key(sweeps: Sequence[dict]) -> list[tuple]:
    return sorted((str(s["run"]), int(s["index"]), str(s["half_plane"]), int(s["frames"])) for s in sweeps)


def _before(cal: PlanesCalibration, folders: list[Path], where: str, notes: list[str]) -> SweepPoints | None:
    names = list(dict.fromkeys(str(s["run"]) for s in cal.sweeps_used))
    if not names:
        notes.append(f"bending planes: {where} records no sweeps, so the measured tip points cannot be drawn; "
                     "the figure shows the fitted planes only")
        return None
    found = {}
    for f in folders:
        if f.name in names and f.name not in found and _compensated_through(f) is None:
            found[f.name] = f
    missing = [n for n in names if n not in found]
    if missing:
        notes.append(f"bending planes: run folder(s) {', '.join(missing)} named in {where} were not found "
                     f"(looked beside the planes file and the records); the figure shows the fitted planes only, "
                     "not the measured sweeps: keep the planes runs beside planes.json")
        return None
    runs = [found[n] for n in names]
    try:
        seg, _ = segment_runs(runs)
    except EndocalError as exc:
        notes.append(f"bending planes: cannot read the sweeps of {', '.join(map(str, runs))} ({exc}); "
                     "the figure shows the fitted planes only")
        return None
    got = _points(seg, "before", runs)
    if _key(got.sweeps) != _key(cal.sweeps_used):
        notes.append(f"bending planes: the sweeps in {', '.join(map(str, runs))} are not the ones {where} was fitted "
                     f"on ({len(got.sweeps)} sweeps, {got.n_points} frames found; {len(cal.sweeps_used)} sweeps, "
                     f"{sum(int(s['frames']) for s in cal.sweeps_used)} frames recorded): the figure shows the fitted "
                     "planes only")
        return None
    return got


def _residuals_of(seg: Segmentation, cal: PlanesCalibration) -> dict[str, float] | None:
    groups = seg.by_half_plane()
    if any(not groups[h] for h in HALF_PLANES):
        return None
    try:
        return {h: fit_pooled(groups[h], h, cal.source, 0.0, cal.model).deviation_signed_deg for h in HALF_PLANES}
    except EndocalError:
        return None


def _after(cal: PlanesCalibration, folders: list[Path], where: str, notes: list[str]) -> SweepPoints | None:
    if cal.residual_source != "measured":
        notes.append(f"bending planes: {where} holds no run recorded with the compensator on, so 'after "
                     f"compensation' shows the {cal.residual_source} prediction of the residual deviation (lines, no "
                     "measured points); to measure it: `endocal excite planes --planes planes.json --out AFTER`, then "
                     "`endocal fit planes RUN --after AFTER`")
        return None
    cands = [f for f in folders if _compensated_through(f) is not None]
    tries = ([cands] if len(cands) > 1 else []) + [[c] for c in cands]
    for runs in tries:
        try:
            seg, _ = segment_runs(runs, compensated=True)
        except EndocalError:
            continue
        res = _residuals_of(seg, cal)
        if res is not None and all(abs(res[h] - cal.residual_deviation_signed_deg[h]) <= MATCH_TOL_DEG
                                   for h in HALF_PLANES):
            return _points(seg, "after", runs)
    tried = ", ".join(str(c) for c in cands) or "none found"
    notes.append(f"bending planes: {where} records measured residuals after compensation but does not name the runs, "
                 f"and no run folder recorded through a planes file reproduces them (candidates: {tried}); 'after "
                 "compensation' shows the recorded residual deviations as lines only")
    return None


def planes_view(calibration: PlanesCalibration, planes_path: str | Path | None = None, *,
                places: Sequence[str | Path] = ()) -> PlanesView:
    """Find the measured sweeps of a bending-plane calibration (see the module docstring).

    Parameters
    ----------
    calibration : PlanesCalibration
    planes_path : path, optional
        The ``planes.json`` it was read from; run folders are looked up beside it first.
    places : sequence of path
        Further run folders, or folders holding run folders, to look in (the report passes
        the folders of its records).

    Returns
    -------
    PlanesView
    """
    where = str(planes_path) if planes_path is not None else "the planes calibration"
    dirs = ([Path(planes_path).parent] if planes_path is not None else []) + [Path(p) for p in places]
    folders = _run_folders(dirs)
    notes: list[str] = []
    before = _before(calibration, folders, where, notes)
    after = _after(calibration, folders, where, notes)
    return PlanesView(calibration, before, after, notes)
