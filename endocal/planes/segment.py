"""Cut a ``planes`` run into single-knob sweeps of the four half-planes.

A ``planes`` protocol moves one knob at a time out from rest and back while the other stays
near zero. From the run's aligned table (for the knob commands) and its raw tracker stream
(for the tip pose in the base sensor's frame) this module returns one :class:`Sweep` per
excursion, labelled ``y+``, ``y-``, ``x+`` or ``x-`` (first knob positive/negative, second
knob positive/negative), together with counts of every frame it had to drop.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial.transform import Rotation

from endocal.errors import RunFormatError
from endocal.planes.halfplanes import HALF_PLANES, knob_half_plane
from endocal.probe import ProbeConfig

if TYPE_CHECKING:  # pandas is imported where a tracker stream is read: loading planes (validate) never needs it
    import pandas as pd

_POSE_COLUMNS = ("t_s", "sensor", "x_mm", "y_mm", "z_mm", "qw", "qx", "qy", "qz")


@dataclass(frozen=True)
class Sweep:
    """One excursion of one knob, in the base sensor's frame.

    Attributes
    ----------
    half_plane : str
        ``y+``, ``y-``, ``x+`` or ``x-``.
    run : str
        Label of the run it came from.
    index : int
        Order of the sweep within its run (0-based, over all half-planes).
    t_s : (n,) array
        Tracker frame times, s.
    tip_in_base_mm : (n, 3) array
        Tip sensor position in the base frame, mm.
    tip_dir_in_base : (n, 3) array
        Tip sensor ``z`` axis (distal-end direction) in the base frame, unit.
    cmd_deg : (n, 2) array
        First and second knob commands at the frame times, degrees.
    """

    half_plane: str
    run: str
    index: int
    t_s: np.ndarray
    tip_in_base_mm: np.ndarray
    tip_dir_in_base: np.ndarray
    cmd_deg: np.ndarray

    def describe(self) -> dict:
        """What the result objects and JSON record about this sweep."""
        return {
            "run": self.run,
            "index": self.index,
            "half_plane": self.half_plane,
            "frames": int(len(self.t_s)),
            "t_start_s": float(self.t_s[0]),
            "t_end_s": float(self.t_s[-1]),
        }


@dataclass
class Segmentation:
    """Sweeps found in one or more runs, and the frames dropped on the way.

    ``dropped`` counts, per reason: ``tip_invalid`` / ``base_invalid`` (flagged invalid or with
    non-finite values), ``unpaired`` (a tip frame without a base frame close enough in time, or
    the reverse), ``outside_commands`` (tracked outside the commanded span), ``both_knobs``
    (both knobs away from rest, so no single half-plane), ``short_sweep`` (frames in excursions
    shorter than ``min_frames``). ``frames_at_rest`` counts frames with both knobs at rest,
    which carry no plane and are not used.
    """

    sweeps: list[Sweep]
    dropped: dict[str, int] = field(default_factory=dict)
    frames_at_rest: int = 0

    def __add__(self, other: Segmentation) -> Segmentation:
        dropped = dict(self.dropped)
        for k, v in other.dropped.items():
            dropped[k] = dropped.get(k, 0) + v
        return Segmentation(self.sweeps + other.sweeps, dropped, self.frames_at_rest + other.frames_at_rest)

    def by_half_plane(self) -> dict[str, list[Sweep]]:
        """Sweeps grouped by half-plane, in ``y+ y- x+ x-`` order (lists may be empty)."""
        return {h: [s for s in self.sweeps if s.half_plane == h] for h in HALF_PLANES}


def _sensor_frames(tracker: pd.DataFrame, sensor: str) -> tuple[pd.DataFrame, int]:
    rows = tracker[tracker["sensor"] == sensor]
    values = rows[["x_mm", "y_mm", "z_mm", "qw", "qx", "qy", "qz"]].to_numpy(float)
    ok = np.isfinite(values).all(axis=1) & (np.linalg.norm(values[:, 3:], axis=1) > 0.5)
    if "valid" in rows:
        ok &= rows["valid"].fillna(False).to_numpy(bool)
    return rows[ok].sort_values("t_s", kind="stable"), int((~ok).sum())


def tip_in_base_from_tracker(tracker: pd.DataFrame, max_pair_gap_s: float = 0.01, where: str = "run"):
    """Tip positions and directions in the base sensor's frame from a raw tracker stream.

    Parameters
    ----------
    tracker : DataFrame
        Long format: ``t_s``, ``sensor`` (``tip``/``base``), ``x_mm y_mm z_mm``, ``qw qx qy qz``
        (sensor -> tracker, scalar first), optional ``valid``.
    max_pair_gap_s : float
        Largest time between a tip frame and the base frame it is paired with, s.
    where : str
        Name of the run, for messages.

    Returns
    -------
    t_s : (n,) array
    tip_in_base_mm : (n, 3) array
        ``base2tracker^-1 (tip - base)``.
    tip_dir_in_base : (n, 3) array
        ``base2tracker^-1 tip2tracker z``.
    dropped : dict
        ``tip_invalid``, ``base_invalid``, ``unpaired`` frame counts.

    Raises
    ------
    RunFormatError
        A column is missing, or there is no (valid) base or tip sensor frame.
    """
    missing = [c for c in _POSE_COLUMNS if c not in tracker.columns]
    if missing:
        raise RunFormatError(f"{where}: tracker stream lacks column(s) {', '.join(missing)}")
    import pandas as pd

    seen = sorted(str(s) for s in pd.unique(tracker["sensor"]))
    for sensor in ("tip", "base"):
        if sensor not in seen:
            raise RunFormatError(
                f"{where}: the tracker stream has no '{sensor}' sensor frames (sensors seen: {', '.join(seen) or 'none'}); "
                "the planes fit needs both the tip and the base sensor to express the tip in the base frame"
            )
    tip, tip_bad = _sensor_frames(tracker, "tip")
    base, base_bad = _sensor_frames(tracker, "base")
    for sensor, frames, bad in (("tip", tip, tip_bad), ("base", base, base_bad)):
        if len(frames) == 0:
            raise RunFormatError(f"{where}: all {bad} '{sensor}' sensor frames are flagged invalid; nothing to fit")
    base = base.rename(columns={c: f"base_{c}" for c in base.columns if c != "t_s"})
    base["t_base_s"] = base["t_s"]
    paired = pd.merge_asof(tip, base, on="t_s", direction="nearest", tolerance=max_pair_gap_s)
    has_base = paired["t_base_s"].notna().to_numpy()
    n_paired = int(has_base.sum())
    paired = paired[has_base]
    unpaired = (len(tip) - n_paired) + max(0, len(base) - n_paired)
    base2tracker = Rotation.from_quat(paired[["base_qw", "base_qx", "base_qy", "base_qz"]].to_numpy(float), scalar_first=True) \
        if n_paired else None
    if base2tracker is None:
        raise RunFormatError(f"{where}: no tip frame has a base frame within {max_pair_gap_s:g} s; cannot pair the sensors")
    tip2tracker = Rotation.from_quat(paired[["qw", "qx", "qy", "qz"]].to_numpy(float), scalar_first=True)
    delta = paired[["x_mm", "y_mm", "z_mm"]].to_numpy(float) - paired[["base_x_mm", "base_y_mm", "base_z_mm"]].to_numpy(float)
    inv = base2tracker.inv()
    tip_in_base = inv.apply(delta)
    tip_dir = (inv * tip2tracker).apply([0.0, 0.0, 1.0])
    dropped = {"tip_invalid": tip_bad, "base_invalid": base_bad, "unpaired": unpaired}
    return paired["t_s"].to_numpy(float), tip_in_base, tip_dir, dropped


def _runs_of(labels: np.ndarray) -> list[tuple[int, int]]:
    """``(start, stop)`` of each maximal block of equal, non-empty labels."""
    blocks = []
    start = 0
    for i in range(1, len(labels) + 1):
        if i == len(labels) or labels[i] != labels[start]:
            if labels[start] != "":
                blocks.append((start, i))
            start = i
    return blocks


def segment_planes_run(
    aligned: pd.DataFrame,
    tracker: pd.DataFrame,
    probe: ProbeConfig,
    *,
    run: str = "run",
    rest_deg: float = 2.0,
    other_max_deg: float | None = 1.0,
    label_from: str = "cmd",
    min_frames: int = 10,
    max_pair_gap_s: float = 0.01,
) -> Segmentation:
    """Split a ``planes`` run into single-knob half-plane sweeps.

    A frame belongs to half-plane ``y+``/``y-`` when the first knob's command is beyond
    ``+-rest_deg`` and the second's within ``other_max_deg`` (and the other way round for
    ``x+``/``x-``); consecutive frames with one label form a sweep.

    Parameters
    ----------
    aligned : DataFrame
        The run's aligned table (``t_s``, ``<axis>_cmd_deg`` for both bending axes).
    tracker : DataFrame
        The run's raw tracker stream (long format).
    probe : ProbeConfig
        Names the two bending axes (first: y-z plane, second: x-z plane).
    run : str
        Label of the run, kept in each sweep and used in messages.
    rest_deg : float
        Knob commands within ``+-rest_deg`` count as rest, degrees.
    other_max_deg : float or None
        Largest command of the other knob during a single-knob sweep, degrees. ``None``
        labels each frame by the knob with the larger command instead, which is what a run
        played through an orthogonal compensator needs when it did not log what it asked
        for (the other knob then moves a little).
    label_from : {"cmd", "desired"}
        Label frames by the knob commands (``<axis>_cmd_deg``) or by the desired angles a
        compensated run logs (``<axis>_desired_deg``: single-axis sweeps even though both
        knobs move). Only the labels change; the sweeps keep the knob commands.
    min_frames : int
        Excursions with fewer frames are dropped (counted as ``short_sweep``).
    max_pair_gap_s : float
        Largest time between paired tip and base frames, s.

    Returns
    -------
    Segmentation

    Raises
    ------
    RunFormatError
        Missing command columns, tracker columns or sensors.
    """
    axes = probe.bending_axes
    if label_from not in ("cmd", "desired"):
        raise ValueError(f"label_from must be 'cmd' or 'desired', got {label_from!r}")
    cmd_cols = [f"{a}_cmd_deg" for a in axes]
    label_cols = [f"{a}_{label_from}_deg" for a in axes]
    missing = [c for c in ("t_s", *cmd_cols, *label_cols) if c not in aligned.columns]
    if missing:
        raise RunFormatError(f"{run}: aligned table lacks column(s) {', '.join(dict.fromkeys(missing))} (probe '{probe.name}')")
    t_s, tip_in_base, tip_dir, dropped = tip_in_base_from_tracker(tracker, max_pair_gap_s=max_pair_gap_s, where=run)
    t_cmd = aligned["t_s"].to_numpy(float)
    inside = (t_s >= t_cmd[0]) & (t_s <= t_cmd[-1])
    dropped["outside_commands"] = int((~inside).sum())
    t_s, tip_in_base, tip_dir = t_s[inside], tip_in_base[inside], tip_dir[inside]
    cmd = np.stack([np.interp(t_s, t_cmd, aligned[c].to_numpy(float)) for c in cmd_cols], axis=1)
    asked = cmd if label_from == "cmd" else np.stack(
        [np.interp(t_s, t_cmd, aligned[c].to_numpy(float)) for c in label_cols], axis=1)
    active = np.abs(asked) > rest_deg
    if other_max_deg is None:
        knob = np.argmax(np.abs(asked), axis=1)
        single = active.any(axis=1)
        mixed = np.zeros(len(t_s), bool)
    else:
        quiet = np.abs(asked) <= other_max_deg
        first_only = active[:, 0] & quiet[:, 1]
        second_only = active[:, 1] & quiet[:, 0]
        knob = np.where(second_only, 1, 0)
        single = first_only | second_only
        mixed = active.any(axis=1) & ~single
    labels = np.array([""] * len(t_s), dtype=object)
    for i in np.flatnonzero(single):
        labels[i] = knob_half_plane(int(knob[i]), asked[i, knob[i]])
    dropped["both_knobs"] = int(mixed.sum())
    dropped["short_sweep"] = 0
    sweeps = []
    for start, stop in _runs_of(labels):
        if stop - start < min_frames:
            dropped["short_sweep"] += stop - start
            continue
        sl = slice(start, stop)
        sweeps.append(Sweep(str(labels[start]), run, len(sweeps), t_s[sl], tip_in_base[sl], tip_dir[sl], cmd[sl]))
    return Segmentation(sweeps=sweeps, dropped=dropped, frames_at_rest=int((~active.any(axis=1)).sum()))
