"""Plausibility of what a CSV map makes of a log, checked before anything is written.

A unit mistake in a map (:mod:`endocal.runs.csvlog`) gives numbers no rig produces, refused in
one line naming the map key to fix: a unit the column's own name contradicts (a displacement read
as degrees, a column in degrees read as millimetres), knob positions far beyond the probe's limits
(with poses) or a linear drive beyond any tendon's travel, a motor sample rate under 1 Hz or over
10 kHz, tip and base sensors nowhere near a bending length apart, a base quaternion read in the
wrong order, a knob whose bend moves many times as far as it does or that is bent at its zero,
fewer aligned rows than any fit can use. Motor samples the
aligned table leaves out for want of a reading (:func:`reading_gaps`), and measured angles with
such numbers (:func:`measured_angle_warnings`), are not refused but said, for the import to warn.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from endocal.errors import RunFormatError
from endocal.kinematics.bending import bending_angles_deg, tip_in_base_mm
from endocal.models.base import min_fit_samples
from endocal.runs.colnames import named_length, unit_named
from endocal.runs.format import LOG_RATE_RANGE_HZ
from endocal.runs.mapfields import ColumnMap as CsvMap  # the map csvlog reads, as the checks see it

#: Longest gap between readings (tracker frames, angle readings) to interpolate across, s, as
#: :func:`endocal.runs.aligned.align` for tracker frames: the motor samples in a longer gap have no
#: measurement and the aligned table leaves them out.
MAX_GAP_S = 0.2
#: Knob positions and goals may lie beyond the probe's limits by up to one limit span on each
#: side (-270..270 deg for the tee's -90..90 deg) before the import calls them a unit mistake:
#: a real log exceeds a preset's limits a little (overshoot, a zero_ticks a quarter turn off,
#: another probe logged under this preset), while the mistakes this catches scale the values
#: by 11.4 (servo ticks read as deg: 4096 a turn, the mid-turn 2048 read as 2048 deg), 57.3
#: (deg read as rad) or 652 (ticks read as rad), many spans out.
KNOB_MARGIN_SPANS = 1.0
#: A unit mistake moves every sample; a servo answering garbage once moves one. More than 1 %
#: of the motor rows beyond the band is a mistake.
MAX_BEYOND_FRACTION = 0.01
#: The fewest aligned rows worth importing: what a fit of one free parameter needs; no model fits fewer.
MIN_ALIGNED_ROWS = min_fit_samples(1)
#: Tip-to-base sensor distances a log can show, in bending lengths of the probe: the sensors
#: sit at the ends of the bending section, give or take a mounting offset or a base sensor
#: further back on the shaft (a few lengths; the NDI Aurora's field is 0.5 m across), while a
#: length unit read wrongly (m for mm) scales the distance by 1000.
DISTANCE_RANGE_LENGTHS = (0.05, 20.0)
#: Thesis eq. 1 measures the bend from the base sensor's z axis, so a recording that passes
#: through the neutral bend brings the tip near that axis in some frames (a sensor mounted a few
#: degrees askew, or a knob never quite at neutral, keeps it within about 10 deg). Read in the
#: wrong order, the base quaternion is another rotation, which turns the whole recording away
#: from the axis (90 to 180 deg for the sims' and a typical bench's poses). The frames nearest the
#: axis are the :data:`NEAR_AXIS_QUANTILE` quantile of the off-axis angle; the map's order is
#: called a mistake when they stay :data:`OFF_AXIS_WRONG_DEG` off and the other order brings
#: them within :data:`OFF_AXIS_RIGHT_DEG` (a recording that never nears neutral, or a sensor
#: mounted across the probe, is off in both orders and imported as it is).
NEAR_AXIS_QUANTILE = 0.05
OFF_AXIS_WRONG_DEG = 30.0
OFF_AXIS_RIGHT_DEG = 15.0
#: Degrees of bend per knob degree beyond which the knob's unit is called a mistake: a tendon
#: drive turns the knob about as far as the tip bends (the thesis's TEE probe: knob and bend
#: both about +-90 deg; a duodenoscope's knob gear at most a few times), while a knob in
#: radians read as degrees shows 57 times its real gain.
BEND_PER_KNOB_MAX = 10.0
#: Degrees of bend per millimetre of a linear drive beyond which its unit is called a mistake. A
#: tendon r mm off the bending section's neutral axis bends it 180 / (pi r) deg per mm pulled:
#: 11 to 29 deg/mm for the 2 to 5 mm of endoscopes and continuum robots, 115 at r = 0.5 mm (a
#: sub-mm instrument); 360 deg/mm would need r = 0.16 mm. A travel in metres read as mm shows
#: 1000 times its gain.
BEND_PER_MM_MAX = 360.0
#: The farthest a linear drive may pull or push a tendon (mm) before its unit is called a mistake:
#: a tendon r mm off the axis is pulled r times the bend (8 mm for 90 deg at r = 5 mm), a bench's
#: stage a few tens of mm; a travel in metres read as mm is 1000 times its size.
LINEAR_DRIVE_MAX_MM = 500.0
#: The least knob travel (deg, 1st to 99th percentile) and correlation with its bend over which
#: that gain is measured: a knob that stays put (the other one moves in a sine-set, and twisted
#: planes move this bend too) has no gain to measure.
KNOB_SPAN_MIN_DEG = 0.5
KNOB_BEND_MIN_CORR = 0.8
#: The most the tip may be bent at knob 0 (deg, on the straight line through the bend against
#: the knob) before the knob's zero is called a mistake: the knob's zero is where the probe is
#: straight; a loop's width, a dead band and twisted planes move that line by 10 to 15 deg at
#: most, while a zero a quarter turn off bends it by the gain times 90 deg (60 deg on the sims).
ZERO_BEND_MAX_DEG = 30.0


def check_unit_names(cmap: CsvMap, where: str) -> None:
    """Refuse a knob's unit that its column's name contradicts: an angle unit for a column named
    in mm or like a displacement (``Tendon Disp.``: a linear drive), or a length for one named in
    deg, rad or ticks. Read off the names only (before the log is read).

    Raises
    ------
    RunFormatError
        Naming ``[knobs.AXIS] unit``, the column and what its name says.
    """
    for dof, k in cmap.knobs.items():
        w = f"{where} [knobs.{dof}]"
        for col in (k.position, k.goal):
            if col is None:
                continue
            said = unit_named(col)
            if k.run_unit == "deg" and named_length(col):
                raise RunFormatError(
                    f"{w}: unit = \"{k.unit}\" reads column '{col}' as an angle, but {named_length(col)}: a linear "
                    f"drive pulling the tendon takes unit = \"{'m' if said == 'm' else 'mm'}\" (its command stays in "
                    "mm through the run and its models)")
            if k.run_unit == "mm" and said in ("deg", "rad", "ticks"):
                raise RunFormatError(
                    f"{w}: unit = \"{k.unit}\" reads column '{col}' as a length, but its name says {said}: a knob's "
                    f"angle takes unit = \"{said}\"{' (with zero_ticks and ticks_per_rev)' if said == 'ticks' else ''}")


def check_knobs(motor: dict, cmap: CsvMap, where: str, probe_limits: bool = True) -> None:
    """Refuse knob positions or goals far beyond the probe's limits (with ``probe_limits``), or a
    linear drive beyond :data:`LINEAR_DRIVE_MAX_MM`: a unit mistake in the map.

    Raises
    ------
    RunFormatError
        More than :data:`MAX_BEYOND_FRACTION` of the samples beyond the limits widened by
        :data:`KNOB_MARGIN_SPANS` limit spans on each side, naming ``[knobs.AXIS] unit``.
    """
    probe = cmap.probe
    hints = {"deg": 'servo ticks need unit = "ticks" with zero_ticks and ticks_per_rev',
             "rad": 'degrees need unit = "deg", servo ticks unit = "ticks"',
             "ticks": "check zero_ticks and ticks_per_rev",
             "m": 'millimetres need unit = "mm"', "mm": 'metres need unit = "m", micrometres unit = "um"',
             "um": 'millimetres need unit = "mm"'}
    for dof, k in cmap.knobs.items():
        u = cmap.unit(dof)
        if u != probe.unit(dof):  # a bending axis driven by a linear stage: the probe's knob limits are angles
            lo, hi, margin, what = -LINEAR_DRIVE_MAX_MM, LINEAR_DRIVE_MAX_MM, 0.0, "any tendon's travel"
        elif probe_limits:
            lo, hi = probe.limits(dof)
            margin, what = KNOB_MARGIN_SPANS * (hi - lo), f"the limits of probe '{probe.name}'"
        else:
            continue
        for key, col in (("position", k.position), ("goal", k.goal)):
            if col is None:
                continue
            v = motor[f"{dof}_{'pos' if key == 'position' else 'goal'}_{u}"]
            beyond = (v < lo - margin) | (v > hi + margin)
            if beyond.mean() > MAX_BEYOND_FRACTION:
                raise RunFormatError(
                    f"{where}: column '{col}' read as {k.unit} gives {dof} knob {key}s of {v.min():.4g}..{v.max():.4g} "
                    f"{u}, far beyond {what} ({lo:g}..{hi:g} {u}) in "
                    f"{100 * beyond.mean():.0f} % of the motor rows: is [knobs.{dof}] unit right? ({hints[k.unit]})")


def check_rate(motor_t_s: np.ndarray, cmap: CsvMap, time_units: dict[str, float | None], where: str) -> None:
    """Refuse a motor sample rate no lab log has (:data:`~endocal.runs.format.LOG_RATE_RANGE_HZ`): a clock unit mistake,
    named with the unit that would give a usual rate, or a ``sample_rate_hz`` that is not the log's rows per
    second (no unit to guess then: a period, a rate in kHz and a typo all fit).

    ``time_units`` are the clock units a map may give, s per unit (``csvlog.TIME_UNITS``).
    """
    dt = np.diff(motor_t_s)
    if cmap.time_factor is None or not dt.size:  # date-time text carries its unit; one sample: no rate
        return
    step_s = float(np.median(dt))
    rate = 1.0 / step_s
    lo, hi = LOG_RATE_RANGE_HZ
    if lo <= rate <= hi:
        return
    than = f"{'slower' if rate < lo else 'faster'} than any lab log ({lo:g} Hz to {hi:g} Hz)"
    if cmap.time_column is None:
        raise RunFormatError(f"{where}: with [time] sample_rate_hz = {cmap.sample_rate_hz:g} the motor samples are "
                             f"{step_s:.3g} s apart ({rate:.3g} Hz), {than}: set sample_rate_hz to the rows the "
                             "logger wrote per second")
    unit = next(u for u, f in time_units.items() if f == cmap.time_factor)
    step_raw = step_s / cmap.time_factor
    # the unit that puts the rate nearest 100 Hz, a servo loop's usual rate, among plausible ones
    fits = [(abs(np.log(100.0 * step_raw * f)), u) for u, f in time_units.items()
            if f and lo <= 1 / (step_raw * f) <= hi]
    guess = min(fits)[1] if fits else None
    then = f"; in {guess} they would be {1 / (step_raw * time_units[guess]):.4g} Hz" if guess else ""
    raise RunFormatError(f"{where}: with [time] unit = \"{unit}\" the motor samples are {step_s:.3g} s apart "
                         f"({rate:.3g} Hz), {than}{then}: set [time] unit to the unit of column '{cmap.time_column}'")


def check_distance(tip: np.ndarray, base: np.ndarray, good: np.ndarray, cmap: CsvMap, length_units: dict[str, float],
                   where: str) -> None:
    """Refuse a tip-to-base distance the probe cannot have (:data:`DISTANCE_RANGE_LENGTHS`): a
    length unit mistake in ``[tip]`` or ``[base]``.

    ``tip`` and ``base`` are the frames (n, 8: ``t_s``, mm, quaternion scalar first), ``good`` those
    with both sensors valid; ``length_units`` the pose units a map may give, mm per unit
    (``csvlog.LENGTH_UNITS``).
    """
    dist_mm = float(np.median(np.linalg.norm(tip[good, 1:4] - base[good, 1:4], axis=1)))
    length = cmap.probe.bending_length_mm
    lo, hi = DISTANCE_RANGE_LENGTHS
    if lo * length <= dist_mm <= hi * length:
        return
    units = {name: ("m" if pc.factor == length_units["m"] else "mm")
             for name, pc in (("tip", cmap.tip), ("base", cmap.base))}
    raise RunFormatError(f"{where}: read with [tip] unit = \"{units['tip']}\" and [base] unit = \"{units['base']}\" the "
                         f"tip and base sensors are {dist_mm:.3g} mm apart (median), but probe '{cmap.probe.name}' bends "
                         f"over {length:g} mm: is the length unit right (metres need unit = \"m\", millimetres \"mm\")?")


def _off_axis_deg(tip: np.ndarray, base: np.ndarray, q_wxyz: np.ndarray) -> np.ndarray:
    """Angle (deg) of the tip, in the base sensor's frame, from that frame's z axis (the bend of eq. 1)."""
    p = tip_in_base_mm(tip[:, 1:4], base[:, 1:4], q_wxyz)
    return np.degrees(np.arctan2(np.hypot(p[:, 0], p[:, 1]), p[:, 2]))


def check_base_order(tip: np.ndarray, base: np.ndarray, good: np.ndarray, cmap: CsvMap, where: str) -> None:
    """Refuse a base quaternion order that turns the recording away from the base axis when the
    other order does not (:data:`OFF_AXIS_WRONG_DEG`), naming ``[base] order``."""
    q = base[good, 4:]  # scalar first, as the map's order reads the logged columns
    other = "wxyz" if cmap.base.order == "xyzw" else "xyzw"
    q_other = q[:, [1, 2, 3, 0]] if other == "wxyz" else q[:, [3, 0, 1, 2]]
    near = [float(np.quantile(_off_axis_deg(tip[good], base[good], qq), NEAR_AXIS_QUANTILE)) for qq in (q, q_other)]
    if near[0] >= OFF_AXIS_WRONG_DEG and near[1] <= OFF_AXIS_RIGHT_DEG:
        tip_too = " (and [tip] order, if it is logged the same way)" if cmap.tip.order == cmap.base.order else ""
        raise RunFormatError(
            f"{where}: with [base] order = \"{cmap.base.order}\" the tip stays {near[0]:.0f} deg or more off the base "
            f"sensor's z axis in {100 * (1 - NEAR_AXIS_QUANTILE):g} % of the frames (the bend of thesis eq. 1, near 0 "
            f"at neutral), with order = \"{other}\" {100 * NEAR_AXIS_QUANTILE:g} % come within {near[1]:.1f} deg: the "
            f"log's quaternions are {'scalar-first' if other == 'wxyz' else 'scalar-last'}; set [base] order = "
            f"\"{other}\"{tip_too}")


#: The widest a measured bending angle may range (deg, 1st to 99th percentile) before its unit is
#: called a mistake: a bending section or a bench's joint stays within a turn, while degrees read
#: as radians give 57 times the bend.
ANGLE_SPAN_MAX_DEG = 360.0

_KNOB_HINTS = {"deg": 'radians need unit = "rad"',
               "rad": "check the column holds this knob's angle", "ticks": "check ticks_per_rev",
               "mm": 'metres need unit = "m"', "m": "check the column holds this drive's travel",
               "um": "check the column holds this drive's travel"}


def _gain_max(unit: str) -> float:
    """The most degrees of bend per unit of a drive in the run's ``unit`` (deg or mm)."""
    return BEND_PER_MM_MAX if unit == "mm" else BEND_PER_KNOB_MAX


def _knob_line(knob: np.ndarray, bend: np.ndarray) -> tuple[float, float, float, float] | None:
    """The knob's 1st and 99th percentiles and the straight line through the bend against it
    (gain, bend at knob 0); None where the knob barely moves or the bend does not follow it.
    The travel is the run's unit (deg, or mm for a linear drive: :data:`KNOB_SPAN_MIN_DEG` of it)."""
    lo, hi = np.quantile(knob, [0.01, 0.99])
    if hi - lo < KNOB_SPAN_MIN_DEG or abs(np.corrcoef(knob, bend)[0, 1]) < KNOB_BEND_MIN_CORR:
        return None
    gain, at_zero = (float(c) for c in np.polyfit(knob, bend, 1))
    return float(lo), float(hi), gain, at_zero


def _gain_message(line, bend: np.ndarray, dof: str, k, where: str, ask: str = "") -> str:
    lo, hi, gain, _ = line
    b_lo, b_hi = np.quantile(bend, [0.01, 0.99])
    if k.run_unit == "mm":
        moves = f"moves the {dof} drive over {hi - lo:.3g} mm"
        per = f"per mm, where a tendon pulled r mm off the axis gives 57/r (at most {BEND_PER_MM_MAX:g})"
    else:
        moves = f"turns the {dof} knob over {hi - lo:.3g} deg"
        per = f"per knob degree, where a tendon drive gives about 1 (at most {BEND_PER_KNOB_MAX:g})"
    # a tendon pulled by a linear stage, read in degrees, bends 57/r deg per "degree": 11 to 29 at r = 2 to 5 mm
    linear = ' (a tendon pulled by a linear stage: unit = "mm")' if k.unit == "deg" else ""
    return (f"{where}: read as {k.unit}, column '{k.position}' {moves} while the tip bends over {b_hi - b_lo:.3g} deg: "
            f"{abs(gain):.0f} deg of bend {per}: {ask}is [knobs.{dof}] unit right? ({_KNOB_HINTS[k.unit]}){linear}")


def measured_angle_warnings(knob_deg: dict[str, np.ndarray], meas_deg: dict[str, np.ndarray], cmap: CsvMap,
                            where: str) -> list[str]:
    """A map of measured angles (:func:`check_knob_to_bend` for poses): an angle ranging over more
    than :data:`ANGLE_SPAN_MAX_DEG`, or a knob whose angle moves more than :data:`BEND_PER_KNOB_MAX`
    degrees per knob degree (:data:`BEND_PER_MM_MAX` per mm of a linear drive), said in one line
    each naming the map keys. ``knob_deg`` and ``meas_deg`` hold each knob's position (in the run's
    unit: deg, or mm for a linear drive) and each axis' angle on the same samples.

    Warned, not refused: an angles map also carries what is no angle (the real piezo recording's
    drive voltage and displacement, data_samples/piezo), whose numbers may be anything. A bench's knob
    zero is not checked: its encoder may count from anywhere (nor are the probe's knob limits).
    """
    out = []
    for axis, bend in meas_deg.items():
        ang = cmap.angles[axis]
        b_lo, b_hi = np.quantile(bend, [0.01, 0.99])
        if b_hi - b_lo > ANGLE_SPAN_MAX_DEG:
            out.append(f"{where}: read as {ang.unit}, column '{ang.column}' gives a bend ranging over "
                       f"{b_hi - b_lo:.4g} deg ({b_lo:.4g} to {b_hi:.4g}), more than a bending section or joint turns "
                       f"(at most {ANGLE_SPAN_MAX_DEG:g}): if it is an angle, is [angles.{axis}] unit right?")
            continue
        k = cmap.knobs.get(axis)
        line = _knob_line(knob_deg[axis], bend) if k is not None else None
        if line is not None and abs(line[2]) > _gain_max(k.run_unit):
            ask = "if both are angles, " if k.run_unit == "deg" else "if the bend is an angle, "
            out.append(_gain_message(line, bend, axis, k, where, ask) +
                       f", or [angles.{axis}] unit (read as {ang.unit})?")
    return out


def check_knob_to_bend(motor: dict, tip: np.ndarray, base: np.ndarray, good: np.ndarray, cmap: CsvMap,
                       where: str) -> None:
    """Refuse a knob whose bend moves more than :data:`BEND_PER_KNOB_MAX` degrees per knob degree
    (radians read as degrees, a wrong ``ticks_per_rev``), or that is bent more than
    :data:`ZERO_BEND_MAX_DEG` at knob 0 (a wrong ``zero_ticks`` or ``zero``), naming the map key.

    Both read the straight line through the bend against the knob (hysteresis makes it a loop
    around that line), where the knob moves enough and the bend follows it.
    """
    probe = cmap.probe
    bends = dict(zip(probe.bending_axes, bending_angles_deg(tip_in_base_mm(tip[good, 1:4], base[good, 1:4],
                                                                           base[good, 4:]))))
    t_frame = tip[good, 0]
    inside = (t_frame >= motor["t_s"][0]) & (t_frame <= motor["t_s"][-1])
    for dof, k in cmap.knobs.items():
        if dof not in bends or inside.sum() < MIN_ALIGNED_ROWS:
            continue
        knob = np.interp(t_frame[inside], motor["t_s"], motor[f"{dof}_pos_{cmap.unit(dof)}"])
        bend = bends[dof][inside]
        line = _knob_line(knob, bend)
        if line is None:
            continue
        gain, at_zero = line[2:]
        if abs(gain) > _gain_max(k.run_unit):
            raise RunFormatError(_gain_message(line, bend, dof, k, where))
        if abs(at_zero) > ZERO_BEND_MAX_DEG:
            straight = -at_zero / gain
            key = "zero_ticks" if k.unit == "ticks" else "zero"
            raise RunFormatError(
                f"{where}: at {dof} knob 0 as the map reads it the tip is bent {at_zero:.0f} deg (a straight line "
                f"through the bend against the knob); it is straight at knob {straight:.3g} {k.run_unit}, where column "
                f"'{k.position}' reads {k.zero + straight / k.per_unit:.6g}: is [knobs.{dof}] {key} right? (the "
                "reading with the knob at 0, probe straight)")


def check_aligned_rows(n_aligned: int, t_motor: np.ndarray, t_read: np.ndarray, what: str, cmap: CsvMap, where: str) -> None:
    """Refuse an import no fit could use: fewer than :data:`MIN_ALIGNED_ROWS` aligned rows
    (motor samples within :data:`MAX_GAP_S` of a ``what``: tracker frame, angle reading)."""
    if n_aligned >= MIN_ALIGNED_ROWS:
        return
    span = (lambda v: f"{v.min():.3f}..{v.max():.3f} s" if v.size else "nothing")
    clock = f"[time] column '{cmap.time_column}' and unit" if cmap.time_column else "[time] sample_rate_hz"
    article = "an" if what[0] in "aeiou" else "a"
    raise RunFormatError(f"{where}: only {n_aligned} motor sample(s) lie within {MAX_GAP_S:g} s of {article} {what}, "
                         f"fewer than any fit can use ({MIN_ALIGNED_ROWS}); the motor samples span {span(t_motor)}, the "
                         f"{what}s {span(t_read)} after the first row: check {clock}, and that every device's rows "
                         "are on that clock")


@dataclass(frozen=True)
class ReadingGaps:
    """Motor samples the aligned table leaves out for want of a reading (:func:`reading_gaps`).

    Attributes
    ----------
    rows : int
        How many motor samples are left out.
    first_line : int or None
        The first one's line in the log (line 1 is the header); None when none is.
    longest_s : float
        The longest stretch without a reading around a left-out sample, s: between two readings,
        or from the first motor sample to the first reading, or from the last reading to the
        last motor sample (0 when none is left out).
    """

    rows: int
    first_line: int | None
    longest_s: float


def reading_gaps(covered: np.ndarray, t_read: np.ndarray, t_motor: np.ndarray, lines: np.ndarray) -> ReadingGaps:
    """The motor samples left out of the aligned table: in a gap of the readings longer than
    :data:`MAX_GAP_S` (rows whose pose or angle cells are empty or invalid) or outside their span
    by more than that (a shorter edge is the devices starting one after the other, not a gap).

    Parameters
    ----------
    covered : (n_motor,) bool array
        Which motor samples have a reading to interpolate (:func:`endocal.runs.aligned.measured_at`).
    t_read : (n_read,) array
        Times of the usable readings, s, increasing.
    t_motor : (n_motor,) array
        Times of the motor samples, s, increasing.
    lines : (n_motor,) int array
        The motor samples' lines in the log.
    """
    left = ~covered
    if not t_read.size:
        return ReadingGaps(int(left.sum()), int(lines[left][0]), float(t_motor[-1] - t_motor[0])) if left.any() \
            else ReadingGaps(0, None, 0.0)
    # a log whose motor rows begin or end a little before or after its readings (the devices
    # start one after the other) is trimmed there, as every aligned table is: not a gap to warn of
    edges = ((t_motor < t_read[0]) & (t_read[0] - t_motor[0] <= MAX_GAP_S)) | \
        ((t_motor > t_read[-1]) & (t_motor[-1] - t_read[-1] <= MAX_GAP_S))
    left &= ~edges
    if not left.any():
        return ReadingGaps(0, None, 0.0)
    t = t_motor[left]
    k = np.searchsorted(t_read, t, side="right")  # the reading after each left-out sample
    before = np.where(k > 0, t_read[np.maximum(k - 1, 0)], t_motor[0])
    after = np.where(k < t_read.size, t_read[np.minimum(k, t_read.size - 1)], t_motor[-1])
    return ReadingGaps(int(left.sum()), int(lines[left][0]), float((after - before).max()))


__all__ = ["ANGLE_SPAN_MAX_DEG", "BEND_PER_KNOB_MAX", "BEND_PER_MM_MAX", "DISTANCE_RANGE_LENGTHS",
           "LINEAR_DRIVE_MAX_MM", "MAX_GAP_S", "MIN_ALIGNED_ROWS", "ReadingGaps", "check_aligned_rows",
           "check_base_order", "check_distance", "check_knob_to_bend", "check_knobs", "check_rate", "check_unit_names",
           "measured_angle_warnings", "reading_gaps"]
