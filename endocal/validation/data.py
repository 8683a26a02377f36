"""From aligned tables to the :class:`~endocal.models.HysteresisData` of one bending axis.

Validation reads runs the way fitting does (:func:`endocal.runs.aligned.load_aligned`) and
hands each model the columns its effect terms may ask for:

``other_cmd_deg``, ``other_meas_deg``
    the other bending axis's knob command and measured angle (``coupling``), when the
    data has a second axis (also under their own names, ``ml_cmd_deg``, ``ml_meas_deg``;
    ``ml_cmd_mm`` for a linear drive);
every other numeric column
    kept under its own name (``sheath_wrap_deg``, knob currents, ...) for ``load:COLUMN``
    (columns of text, a fixture's name say, and columns with empty or infinite cells are
    left out).

Several tables become several runs of one :class:`HysteresisData` (operator states restart
at each); only the extra columns every table has are kept. The axis' drive unit (deg for a
knob, mm for a linear stage: :attr:`~endocal.runs.aligned.AlignedData.drive_units`) becomes the
data's ``drive_unit``; tables that disagree on it are refused.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np
from scipy.ndimage import median_filter

from endocal.errors import ModelError
from endocal.messages import Message
from endocal.models.data import OTHER_CMD, HysteresisData, common_drive_unit, is_constant, speed_dps
from endocal.runs.aligned import AlignedData, is_number_array

#: Extra column holding the other bending axis's measured angle (deg).
OTHER_MEAS = "other_meas_deg"
#: A command that spans less than this never excites its axis (deg): nothing to validate or report.
MIN_SPAN_DEG = 1.0
#: The same for a linear drive (mm): a tendon r = 2 to 5 mm off the axis bends the section 57/r deg
#: per mm pulled, so 0.1 mm is 1 to 3 deg of bend, about what a knob's 1 deg gives.
MIN_SPAN_MM = 0.1


def min_cmd_span(data: HysteresisData) -> float:
    """The least span of ``data``'s command that excites its axis, in its drive unit."""
    return MIN_SPAN_MM if data.cmd_unit == "mm" else MIN_SPAN_DEG


def _as_list(aligned) -> list[AlignedData]:
    if isinstance(aligned, AlignedData):
        return [aligned]
    out = list(aligned)
    if not out:
        raise ModelError("no data given: name at least one run folder or aligned table")
    return out


#: Spikes (:func:`spikes`): a sample further from the median of its 3 neighbours on each side than
#: 8 robust standard deviations of those distances and a tenth of the signal's span (1st to 99th
#: percentile). A tip has inertia and a servo a speed limit: neither jumps away for a few samples
#: and back, while an EM tracker's glitch (a wild reading, a flipped frame) or a corrupt logger
#: cell does. The median keeps a step and a turning point (at the apex of a triangle it sits two
#: samples' travel below, past a tenth of the span only at under 20 samples a half-cycle).
SPIKE_HALF_WINDOW = 3
SPIKE_SIGMAS = 8.0
SPIKE_SPAN_FRAC = 0.1


def spikes(values: np.ndarray) -> np.ndarray:
    """Samples of one record that jump away from their neighbours and back (a Hampel filter,
    thresholds above), shape (n,) bool."""
    v = np.asarray(values, float)
    size = 2 * SPIKE_HALF_WINDOW + 1
    if v.size < size:
        return np.zeros(v.size, bool)
    dev = np.abs(v - median_filter(v, size=size, mode="nearest"))
    lo, hi = np.quantile(v, [0.01, 0.99])
    return dev > max(SPIKE_SIGMAS * 1.4826 * float(np.median(dev)), SPIKE_SPAN_FRAC * float(hi - lo))


#: A held reading (:func:`held`): a measured angle that repeats exactly for at least
#: HELD_MIN_SAMPLES samples while the command moves by more than HELD_MIN_MOVE_FRAC of its span,
#: in a record whose readings otherwise repeat in under HELD_MAX_REPEAT_FRAC of consecutive
#: pairs. An EM tracker's noise never gives one number twice, so a run of one value is the
#: tracker or its bridge repeating its last frame (a sensor out of the field, a stalled driver);
#: a quantised encoder, or a table that holds a slower tracker's frame until the next, repeats
#: throughout and is left alone, as is a tip resting while the knob rests.
HELD_MIN_SAMPLES = 10
HELD_MIN_MOVE_FRAC = 0.01
HELD_MAX_REPEAT_FRAC = 0.01


def held(meas: np.ndarray, cmd: np.ndarray) -> np.ndarray:
    """Samples of one record whose measured angle repeats the one before while the command moves
    (a frozen reading; thresholds above), shape (n,) bool: every repeat, not the reading held."""
    v, u = np.asarray(meas, float), np.asarray(cmd, float)
    out = np.zeros(v.size, bool)
    same = np.diff(v) == 0
    if not same.any():
        return out
    edges = np.flatnonzero(np.diff(np.concatenate([[0], same.astype(np.int8), [0]])))
    runs = [(a, b) for a, b in zip(edges[::2], edges[1::2]) if b - a + 1 >= HELD_MIN_SAMPLES]  # pairs a..b-1
    elsewhere = same.sum() - sum(b - a for a, b in runs)
    if elsewhere > HELD_MAX_REPEAT_FRAC * same.size:
        return out  # readings repeat anyway: quantised, or held between a slower sensor's frames
    span = float(np.ptp(u))
    for a, b in runs:
        if np.ptp(u[a:b + 1]) > HELD_MIN_MOVE_FRAC * span:
            out[a + 1:b + 1] = True
    return out


def glitch_note(dropped: list[tuple[str, int, int, int, float]], axis: str) -> str:
    """One line for the glitches :func:`axis_data` left out (its ``dropped`` list), or ``""``."""
    if not dropped:
        return ""
    n_cmd, n_meas, n_held = (sum(d[i] for d in dropped) for i in (1, 2, 3))
    jumps = " and ".join(x for x in (f"{n_meas} measured {axis} angle(s)" if n_meas else "",
                                     f"{n_cmd} {axis} command(s)" if n_cmd else "") if x)
    parts = [f"{jumps} that jump away from their neighbours and back by over a tenth of the signal's span"
             if jumps else "",
             f"{n_held} measured {axis} angle(s) repeating one reading exactly while the knob moved (a frozen "
             "tracker)" if n_held else ""]
    src, t0 = dropped[0][0], dropped[0][-1]
    return Message(f"left out {'; and '.join(x for x in parts if x)} (a tracker or logger glitch; the first in {src} "
                   f"at t = {t0:.3f} s): the fit and the scores use the samples around them", "glitches")


def axis_data(aligned: AlignedData | Sequence[AlignedData], axis: str, planes=None,
              dropped: list | None = None) -> HysteresisData:
    """The command, measurement, time and extra columns of ``axis``, one run per table.

    ``fit hysteresis``, ``validate`` and ``report`` all read data through this function, so a
    model file's training-data hashes match the records they evaluate and a model is scored
    on the same angles it was fitted on.

    Parameters
    ----------
    aligned : AlignedData or sequence of AlignedData
        Loaded run folders or aligned tables (:func:`~endocal.runs.aligned.load_aligned`).
    axis : str
        Bending axis (``ap``, ``ml``, ``ud``, ``lr`` or a table's own axis name).
    planes : PlanesCalibration, optional
        Bending planes (``endocal fit planes``): the measured standard-plane angles are mapped
        into the twisted half-planes the knobs actually drive. The orthogonal compensator of
        duodenoscope eqs. 3-4 maps an output in the standard planes to the input along the
        twisted planes that produces it, so a hysteresis model sees one knob against its own
        plane.

    Returns
    -------
    HysteresisData
        ``cmd_deg``, ``meas_deg``, ``t_s`` and ``extras`` (see the module docstring);
        ``run_starts`` at the first sample of every table.

    Raises
    ------
    ModelError
        A table lacks ``axis`` (the message names the table and the axes it has), tables
        command ``axis`` in different units, or ``planes`` is given for a table without both
        bending axes.

    Samples where the command or the measured angle spikes (:func:`spikes`), or the measured
    angle is a reading held while the knob moved (:func:`held`), are left out; with ``dropped`` a
    list, one ``(source, n_command, n_measured, n_held, first_t_s)`` per table with any is
    appended to it (:func:`glitch_note` words them).
    """
    tables = _as_list(aligned)
    for a in tables:
        if axis not in a.axes:
            raise ModelError(f"{a.source}: no axis '{axis}' in the data (it has {', '.join(a.axes)}); "
                             "name one of those axes, or give data of this one")
    units = {a.drive_unit(axis) for a in tables}
    if len(units) > 1:
        odd = next(a for a in tables if a.drive_unit(axis) != tables[0].drive_unit(axis))
        raise ModelError(f"{tables[0].source} commands the {axis} drive in {tables[0].drive_unit(axis)}, {odd.source} "
                         f"in {odd.drive_unit(axis)}: records of a knob and of a linear drive are not one model's "
                         "data; give records of one drive")
    unit = common_drive_unit(units)
    if planes is not None:
        tables = [_through_planes(a, axis, planes) for a in tables]
    common = set.intersection(*(set(a.extras) for a in tables))
    others = [[b for b in a.axes if b != axis] for a in tables]
    # The other axis is used only when every table has the same single one (coupling needs a
    # consistent meaning of "the other knob").
    other = others[0][0] if all(len(o) == 1 and o[0] == others[0][0] for o in others) and others[0] else None
    numeric = [c for c in sorted(common) if all(is_number_array(a.columns[c], bool_ok=False) for a in tables)]
    numeric = [c for c in numeric if all(np.isfinite(a.column(c)).all() for a in tables)]
    runs = []
    for a in tables:
        extras = {c: a.column(c) for c in numeric}
        if other is not None:
            extras[OTHER_CMD] = a.cmd(other)
            extras[OTHER_MEAS] = a.meas_deg(other)
            # also under their own names, for effects that name them (``coupling:ml_meas_deg``)
            extras[a.cmd_column(other)] = extras[OTHER_CMD]
            extras[f"{other}_meas_deg"] = extras[OTHER_MEAS]
        cmd, meas, t = a.cmd(axis), a.meas_deg(axis), np.asarray(a.t_s, float)
        bad_cmd, bad_meas = spikes(cmd), spikes(meas)
        frozen = held(meas, cmd) & ~bad_cmd & ~bad_meas
        keep = ~(bad_cmd | bad_meas | frozen)
        if not keep.all() and keep.any():
            if dropped is not None:
                dropped.append((str(a.source), int(bad_cmd.sum()), int((bad_meas & ~bad_cmd).sum()),
                                int(frozen.sum()), float(t[np.argmax(~keep)])))
            cmd, meas, t = cmd[keep], meas[keep], t[keep]
            extras = {k: v[keep] for k, v in extras.items()}
        runs.append(HysteresisData(cmd_deg=cmd, meas_deg=meas, t_s=t, extras=extras, drive_unit=unit))
    return runs[0] if len(runs) == 1 else HysteresisData.from_runs(runs)


def _through_planes(data: AlignedData, axis: str, planes) -> AlignedData:
    if len(data.axes) != 2:
        raise ModelError(f"{data.source}: the model was fitted through bending planes, which need both bending "
                         f"axes in the data (it has {', '.join(data.axes)}): give a record of both axes, or validate "
                         "a model fitted without --planes")
    first, second = data.axes
    comp = planes.compensate(data.meas_deg(first), data.meas_deg(second))
    return replace(data, columns={**data.columns,
                                  f"{axis}_meas_deg": np.asarray(comp[0] if axis == first else comp[1], float)})



def load_candidates(data: HysteresisData, bending_axes: Sequence[str] = ()) -> tuple[list[str], list[str]]:
    """Extra columns that may carry a load (``load:COLUMN``), and the constant ones skipped.

    Excluded by design: the other axis (``other_*``: that is ``coupling``), the bending
    knobs' own readings (``<axis>_pos_deg``, ``_vel_degps``, ``_current_ma``: they respond
    to the bend itself, so a term on them would explain the angle with the angle) and
    columns that are mostly noise (:func:`is_smooth`). Name such a column explicitly to
    test it anyway.

    Parameters
    ----------
    data : HysteresisData
    bending_axes : sequence of str
        Bending axis names whose drive columns are excluded.

    Returns
    -------
    candidates, constant : list of str
    """
    prefixes = tuple(f"{a}_" for a in bending_axes)
    candidates, constant = [], []
    for name, col in data.extras.items():
        if name in (OTHER_CMD, OTHER_MEAS) or (prefixes and name.startswith(prefixes)):
            continue
        if is_constant(col):
            constant.append(name)
        elif is_smooth(col, data):
            candidates.append(name)
    return candidates, constant


def is_smooth(values: np.ndarray, data: HysteresisData, min_lag1: float = 0.5) -> bool:
    """True when a column varies slowly enough to be a physical load (lag-1 autocorrelation >= ``min_lag1``).

    A column that is mostly sample-to-sample noise (a current reading of a motor at rest) is
    not a load on the tendons; a play whose width follows it acts as an extra backlash of
    random width and would pass for a load on data with any lag. A column constant within
    each record but not across them (the sheath curvature each acquisition was made at) is
    the smoothest load of all: a condition per record.
    """
    num = den = 0.0
    for sl in data.run_slices():
        x = np.asarray(values[sl], dtype=float)
        x = x - x.mean()
        num += float(x[1:] @ x[:-1])
        den += float(x @ x)
    if den == 0.0:
        return not is_constant(values)
    return num / den >= min_lag1


def check_columns(data: HysteresisData, columns: Sequence[str], vary: bool = True, what: str = "the data") -> None:
    """Refuse ``load:COLUMN`` on a column that is absent, or constant where ``vary`` (data to fit on).

    Raises
    ------
    ModelError
        Naming the column and the extra columns present.
    """
    have = ", ".join(sorted(data.extras)) or "none"
    for c in columns:
        if c not in data.extras:
            raise ModelError(f"load:{c}: {what} has no column '{c}' (extra columns read: {have}; columns of text or "
                             "with empty cells are not read)")
        if vary and is_constant(data.extras[c]):
            raise ModelError(f"load:{c}: column '{c}' is constant in {what}, so a load on it cannot be "
                             "identified; log a covariate that varies, or drop the term")


def prefix(data: HysteresisData, n: int) -> HysteresisData:
    """The first ``n`` samples of ``data`` (runs cut where the prefix ends)."""
    n = int(n)
    starts = data.run_starts[data.run_starts < n]
    return HysteresisData(
        cmd_deg=data.cmd_deg[:n],
        meas_deg=None if data.meas_deg is None else data.meas_deg[:n],
        t_s=None if data.t_s is None else data.t_s[:n],
        extras={k: v[:n] for k, v in data.extras.items()},
        run_starts=starts,
        drive_unit=data.drive_unit,
    )


