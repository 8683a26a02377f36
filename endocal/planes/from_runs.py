"""Bending-plane calibration straight from run folders (what `endocal fit planes` calls)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from endocal.errors import RunFormatError
from endocal.planes.calibration import PlanesCalibration, fit_planes
from endocal.planes.segment import Segmentation, segment_planes_run
from endocal.probe import ProbeConfig
from endocal.runs.aligned import load_aligned, read_stream
from endocal.runs.format import RUN_JSON, TRACKER


def segment_runs(runs: list[Path], *, compensated: bool = False) -> tuple[Segmentation, ProbeConfig]:
    """Segment every run folder into half-plane sweeps and add them up.

    Raises
    ------
    RunFormatError
        A path that does not exist, a path that is not a run folder (a bare aligned table has
        no tracker poses, and the plane fit needs the tip direction), a run whose drive is
        linear (mm: the fit needs knob angles), or runs recorded on different probes.
    """
    total: Segmentation | None = None
    probe: ProbeConfig | None = None
    _check_exist(runs)
    for run in map(Path, runs):
        if not run.is_dir():
            raise RunFormatError(
                f"{run}: fit planes needs run folders (the half-plane fit uses the tracker's tip poses), "
                "not an aligned table; record one with `endocal excite planes --out RUN`"
            )
        data = load_aligned(run)
        linear = [a for a in data.axes if data.drive_unit(a) != "deg"]
        if linear:  # the plane fit reads the knobs' angles; a stage's travel turns no knob
            a = linear[0]
            raise RunFormatError(f"{run}: the {a} drive is linear (column {data.cmd_column(a)}, in "
                                 f"{data.drive_unit(a)}): bending planes need knob drives commanded in deg; record "
                                 "the planes protocol on a probe whose knobs turn")
        run_probe = ProbeConfig.from_dict(data.meta["probe"], where=str(run / RUN_JSON))
        if probe is not None and run_probe.bending_axes != probe.bending_axes:
            raise RunFormatError(f"{run}: recorded on probe '{run_probe.name}', the others on '{probe.name}'")
        probe = run_probe
        # A compensated run moves both knobs in every sweep: label its frames by the angles it
        # asked for (logged since the run format had them), else by the larger knob command.
        logged = all(f"{a}_desired_deg" in data.table.columns for a in run_probe.bending_axes)
        seg = segment_planes_run(
            data.table, read_stream(run, TRACKER), run_probe, run=run.name,
            other_max_deg=None if compensated and not logged else 1.0,
            label_from="desired" if compensated and logged else "cmd",
        )
        total = seg if total is None else total + seg
    if total is None:
        raise RunFormatError("fit planes needs at least one run folder")
    return total, probe


def _check_exist(runs, *, after: bool = False) -> None:
    """Every path named exists (a typo is said as such, as every other command says it)."""
    for run in map(Path, runs):
        if not run.exists():
            what = ("(--after) does not exist: give a run folder of the planes protocol played through the "
                    "compensator (`endocal excite planes --planes planes.json --out RUN`)" if after else
                    "does not exist: give a run folder of the planes protocol (`endocal excite planes --out RUN`)")
            raise RunFormatError(f"{run} {what}")


def calibrate_planes(
    runs: list[Path], *, after: list[Path] | None = None, n_bootstrap: int = 200, seed: int = 0
) -> tuple[PlanesCalibration, ProbeConfig]:
    """Fit deviation angles, delta and the orthogonal compensator from ``planes`` runs.

    Parameters
    ----------
    runs : list of Path
        Run folders of the ``planes`` protocol (single-knob sweeps of each half-plane).
    after : list of Path, optional
        Runs recorded with the compensator on; their deviations become the measured residuals.
    n_bootstrap : int
        Bootstrap replicates over sweeps for the 95 % confidence intervals.
    seed : int
        Seed of the bootstrap.
    """
    _check_exist(runs)  # both lists before the first is segmented: a missing --after fails at once
    _check_exist(after or [], after=True)
    seg, probe = segment_runs(runs)
    comp = segment_runs(after, compensated=True)[0] if after else None
    return fit_planes(seg, n_bootstrap=n_bootstrap, seed=seed, compensated=comp), probe


def compensate_trajectory(traj, probe: ProbeConfig, calibration: PlanesCalibration):
    """A copy of ``traj`` whose two knob goals pass through the orthogonal compensator.

    The protocol's goals are read as desired angles in the standard planes; the compensator
    (duodenoscope eqs. 3-4) turns them into the angles to command along the twisted planes.
    Recording the ``planes`` protocol this way and fitting it with ``--after`` measures the
    residual deviation, the paper's fig. 8 before/after.
    """
    from dataclasses import replace

    first, second = probe.bending_axes
    goal = dict(traj.goal)
    goal[first], goal[second] = (np.asarray(g, float) for g in calibration.compensate(traj.goal[first], traj.goal[second]))
    desired = traj.desired or {axis: np.asarray(traj.goal[axis], float) for axis in (first, second)}
    return replace(traj, goal=goal, desired=desired)
