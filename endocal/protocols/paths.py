"""Tip paths in millimetres for task-space control: circles, lines, raster scans, point lists.

The thesis's trajectory experiment (summary, "Task Space Control" and its table 1) drives the
probe tip along two circles through its workspace and reports the median distance between
desired and reached tip positions. A :class:`TipPath` is such a path: waypoints in mm,
walked at a constant tip speed, turned by :func:`path_trajectory` into the desired joint
values of every sample (constant-curvature inverse kinematics, thesis section 2.3) that the
orthogonal compensator and the inverse hysteresis models then turn into knob commands.

Frame
-----
``base_home``: the base sensor's frame when the probe is at home (translation 0, rotation 0,
knobs at rest), as the tracker measures it at the start of a run; ``x``/``y`` across the probe,
``z`` along it (distal), mm. It is the tracker frame moved onto the base sensor, fixed in
the room, so the tip position in it is the thesis's ``P - O`` at home. A point given without
``z`` (circles, lines and raster scans by default) lies *on the dome*: the surface the tip
reaches by bending alone, ``z = L sin(a) / a`` at lateral offset ``L (1 - cos a) / a``, so
translation and rotation stay at 0 as in the thesis's circles. A point with a ``z`` off the
dome is reached by translating the probe.

Path files
----------
Shipped paths live in ``protocols/paths/NAME.toml``::

    description = "Thesis circle 1: ..."
    path = "circle"                  # circle | line | raster | points

    [params]
    centre_mm = [0.0, 0.0]
    radius_mm = 21.0

A CSV file with columns ``x_mm, y_mm, z_mm`` (one waypoint per row, header required) is a
``points`` path of its own; ``--set speed_mmps=8`` style overrides apply to every kind.
"""

from __future__ import annotations

import hashlib
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from endocal.errors import ProtocolError
from endocal.kinematics import ProbeKinematics, UnreachableError
from endocal.kinematics.constant_curvature import tip_pose_in_base
from endocal.kinematics.inverse import MAX_UNIQUE_BEND_RAD, bend_from_lateral_offset_rad, lateral_offset_mm
from endocal.probe import ROTATION, TRANSLATION, ProbeConfig
from endocal.protocols.params import DEFAULT_SAMPLE_RATE_HZ, Param, param, positive_param
from endocal.protocols.trajectory import Segment, Trajectory, check_samples

_FILE_KEYS = ("description", "path", "params")
#: Waypoints per full turn of a circle (a 21 mm circle: 0.18 mm chords, 2e-4 mm off the arc).
_POINTS_PER_TURN = 720
#: Longest step between the densified points of a path (on the dome, a chord this long sags < 1e-3 mm).
_MAX_STEP_MM = 0.2
#: Most points a path is walked through (200 m at that step): a coordinate changed by mistake is refused here.
_MAX_DENSE_POINTS = 1_000_000

SPEED = positive_param("speed_mmps", 5.0, "Tip speed along the path, mm/s.")
APPROACH = positive_param("approach_s", 4.0, "From rest to the first point (and from the last back to rest), "
                          "a raised-cosine ramp of the joints, s.")
HOLD = param("hold_s", 1.0, "float", "Hold at the first and the last point, s.", lo=0)
Z = param("z_mm", None, "float_or_none", "Height of the path along the probe (base_home z), mm; "
          "unset: on the dome the tip reaches by bending alone.")
RATE = param("sample_rate_hz", DEFAULT_SAMPLE_RATE_HZ, "float", "Motor clock, samples per second.", lo=0, lo_open=True)
_COMMON = (SPEED, APPROACH, HOLD, RATE)


def _xy(name: str, default, doc: str) -> Param:
    return param(name, default, "floats", doc, length=2)


@dataclass(frozen=True)
class PathShape:
    """A kind of path: its parameters and how they give waypoints ``(m, 3)`` (z NaN: on the dome)."""

    name: str
    doc: str
    params: tuple[Param, ...]
    waypoints: Callable[[dict], tuple[np.ndarray, bool]]

    def param(self, name: str) -> Param:
        return next(q for q in self.params if q.name == name)


def _with_z(xy: np.ndarray, z_mm: float | None) -> np.ndarray:
    z = np.full((xy.shape[0], 1), np.nan if z_mm is None else float(z_mm))
    return np.hstack([xy, z])


def _circle(p: dict) -> tuple[np.ndarray, bool]:
    n = int(round(_POINTS_PER_TURN * p["turns"]))
    phase = np.radians(p["start_deg"]) + 2 * np.pi * p["turns"] * np.arange(n + 1) / n
    xy = np.asarray(p["centre_mm"]) + p["radius_mm"] * np.column_stack([np.cos(phase), np.sin(phase)])
    return _with_z(xy, p["z_mm"]), True


def _line(p: dict) -> tuple[np.ndarray, bool]:
    a, b = np.asarray(p["start_mm"], float), np.asarray(p["end_mm"], float)
    xy = np.vstack([a, b, a]) if p["back"] else np.vstack([a, b])
    return _with_z(xy, p["z_mm"]), False


def _raster(p: dict) -> tuple[np.ndarray, bool]:
    (x0, x1), (y0, y1), rows = p["x_range_mm"], p["y_range_mm"], p["rows"]
    pts = []
    for i, y in enumerate(np.linspace(y0, y1, rows)):
        xs = (x0, x1) if i % 2 == 0 else (x1, x0)  # boustrophedon: every other row backwards
        pts += [(xs[0], y), (xs[1], y)]
    return _with_z(np.asarray(pts, float), p["z_mm"]), False


def _points(p: dict) -> tuple[np.ndarray, bool]:
    return np.asarray(p["points_mm"], float), bool(p["closed"])


SHAPES: dict[str, PathShape] = {
    s.name: s
    for s in (
        PathShape("circle", "Circle across the probe axis, walked once (or `turns` times) at constant speed.",
                  (_xy("centre_mm", [0.0, 0.0], "Centre (x, y) in base_home, mm."),
                   positive_param("radius_mm", 20.0, "Radius, mm."),
                   param("turns", 1.0, "float", "Turns walked.", lo=0, lo_open=True),
                   param("start_deg", 0.0, "float", "Where on the circle the walk starts (from +x towards +y), deg."),
                   Z, *_COMMON), _circle),
        PathShape("line", "Straight line from start to end (and back, by default).",
                  (_xy("start_mm", [-15.0, 0.0], "Start (x, y), mm."), _xy("end_mm", [15.0, 0.0], "End (x, y), mm."),
                   param("back", True, "bool", "Walk back to the start."), Z, *_COMMON), _line),
        PathShape("raster", "Raster scan: rows along x, stepping in y, every other row backwards.",
                  (_xy("x_range_mm", [-15.0, 15.0], "Row extent in x, mm."),
                   _xy("y_range_mm", [-15.0, 15.0], "First and last row in y, mm."),
                   param("rows", 5, "int", "Number of rows.", lo=2), Z, *_COMMON), _raster),
        PathShape("points", "A user's waypoints (a CSV with x_mm, y_mm, z_mm), joined by straight lines.",
                  (param("points_mm", None, "points", "Waypoints (m, 3), mm (from the CSV)."),
                   param("closed", False, "bool", "Return from the last waypoint to the first."), *_COMMON), _points),
    )
}


@dataclass(frozen=True)
class TipPath:
    """A validated tip path.

    Attributes
    ----------
    name : str
        File stem or shipped name.
    shape : str
        Key of :data:`SHAPES`.
    params : dict
        Every parameter of the shape, defaults filled in.
    description : str
    source : Path or None
        The file it came from.
    sha256 : str or None
        Of that file.
    """

    name: str
    shape: str
    params: dict
    description: str = ""
    source: Path | None = None
    sha256: str | None = None
    overrides: dict = field(default_factory=dict)

    def waypoints_mm(self, probe: ProbeConfig) -> np.ndarray:
        """The path densely sampled ``(m, 3)`` in base_home, mm: straight in ``x, y`` between
        waypoints (and in ``z`` where given), on the dome of ``probe`` where ``z`` is not given.

        Raises
        ------
        UnreachableError
            A point is farther off the probe axis than the bending section reaches.
        """
        return self._dense(probe)[0]

    def _dense(self, probe: ProbeConfig) -> tuple[np.ndarray, np.ndarray]:
        """Dense points and which of them lie on the dome (their ``z`` follows the bend)."""
        pts, closed = SHAPES[self.shape].waypoints(self.params)
        pts = np.array(pts, float)
        if closed and np.linalg.norm(np.nan_to_num(pts[-1] - pts[0])) > 1e-9:
            pts = np.vstack([pts, pts[:1]])
        steps = np.linalg.norm(np.nan_to_num(np.diff(pts, axis=0), nan=0.0), axis=1) / _MAX_STEP_MM
        if not (np.isfinite(pts[:, :2]).all() and np.sum(steps) < _MAX_DENSE_POINTS):
            raise ProtocolError(f"path '{self.name}': its waypoints are not finite or span more than "
                                f"{_MAX_DENSE_POINTS * _MAX_STEP_MM / 1e3:g} m; check the path's coordinates (mm)")
        dense = [pts[:1]]
        for a, b in zip(pts[:-1], pts[1:]):
            n = max(int(np.ceil(np.linalg.norm(np.nan_to_num(b - a)) / _MAX_STEP_MM)), 1)
            dense.append(a + (b - a) * (np.arange(1, n + 1) / n)[:, None])
        dense = np.vstack(dense)
        dome = np.isnan(dense[:, 2])
        if dome.any():
            dense[dome, 2] = dome_height_mm(dense[dome, :2], probe, where=f"path '{self.name}'")
        return dense, dome

    def length_mm(self, probe: ProbeConfig) -> float:
        """Length of the walked path, mm."""
        return _polyline_length_mm(self.waypoints_mm(probe))

    def to_dict(self) -> dict:
        params = {k: (np.asarray(v).tolist() if k == "points_mm" else v) for k, v in self.params.items()}
        return {"name": self.name, "path": self.shape, "description": self.description, "params": params,
                "source": str(self.source) if self.source else None, "sha256": self.sha256,
                "overrides": dict(self.overrides)}


def dome_height_mm(xy_mm: np.ndarray, probe: ProbeConfig, where: str = "path") -> np.ndarray:
    """Height ``z`` of the tip on the dome it reaches by bending alone, at lateral positions ``xy_mm``.

    Constant curvature (thesis section 2.3): a bend ``a`` puts the tip ``L (1 - cos a) / a`` off
    the axis at height ``L sin(a) / a``.

    Raises
    ------
    UnreachableError
        A point is farther off the axis than the largest unique bend reaches; names the point
        and the nearest reachable one (same direction, on the rim).
    """
    xy = np.atleast_2d(np.asarray(xy_mm, float))
    L = probe.bending_length_mm
    rho = np.hypot(xy[:, 0], xy[:, 1])
    rho_max = float(lateral_offset_mm(MAX_UNIQUE_BEND_RAD, L))
    far = rho > rho_max
    if far.any():
        i = int(np.flatnonzero(far)[0])
        scale = rho_max / rho[i]
        a = MAX_UNIQUE_BEND_RAD
        nearest = np.array([xy[i, 0] * scale, xy[i, 1] * scale, L * np.sin(a) / a])
        nearest_all = np.column_stack([xy, np.zeros(len(xy))])
        raise UnreachableError(
            f"{where}: the point ({xy[i, 0]:.2f}, {xy[i, 1]:.2f}) mm is {rho[i]:.2f} mm off the probe axis; a "
            f"{L:g} mm bending section reaches {rho_max:.2f} mm: nearest reachable point "
            f"({nearest[0]:.2f}, {nearest[1]:.2f}, {nearest[2]:.2f}) mm; shrink or move the path",
            index=i, nearest_tip_in_tracker_mm=nearest_all, nearest=None)
    alpha = bend_from_lateral_offset_rad(rho, L)
    tip, _ = tip_pose_in_base(alpha, np.zeros_like(alpha), L)
    return tip[:, 2]


# --------------------------------------------------------------------------- joints on the motor clock


def _polyline_length_mm(pts: np.ndarray) -> float:
    """Length (mm) of the polyline through the points ``pts`` (m, 3)."""
    return float(np.sum(np.linalg.norm(np.diff(pts, axis=0), axis=1)))


def _resample_constant_speed(pts: np.ndarray, dome: np.ndarray, speed_mmps: float, fs: float) -> tuple[np.ndarray, np.ndarray]:
    """Positions along the polyline ``pts`` every ``1/fs`` s at ``speed_mmps`` (last point
    included), and whether each lies between two dome points."""
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    total = float(s[-1])
    if total <= 0:
        return pts[:1].copy(), dome[:1].copy()
    n = int(np.ceil(total / speed_mmps * fs - 1e-9)) + 1
    s_t = np.minimum(np.arange(n) * speed_mmps / fs, total)
    walk = np.column_stack([np.interp(s_t, s, pts[:, k]) for k in range(3)])
    return walk, np.interp(s_t, s, dome.astype(float)) > 1 - 1e-9


def path_trajectory(path: TipPath, probe: ProbeConfig) -> Trajectory:
    """Desired joint values on the motor clock that walk the tip along ``path``.

    From rest, the joints ramp (raised cosine, ``approach_s``) to the inverse kinematics of the
    first point and hold there ``hold_s``; the tip then walks the path at ``speed_mmps``; it
    holds at the last point and ramps back to rest. The bending axes' goals are the desired
    eq. 1 angles (deg), to be turned into knob commands by the planes compensator and the
    inverse hysteresis models (:func:`endocal.validation.playback.task_space_trajectory`);
    ``translation`` (mm) and ``rotation`` (deg) are the joints themselves.

    Returns
    -------
    Trajectory
        With ``tip_desired_mm`` (n, 3): the desired tip in base_home, mm (the rest pose, the
        straight probe, during the approach ramps) and segments ``approach``, ``path``,
        ``return``.

    Raises
    ------
    UnreachableError
        A waypoint is outside the workspace (named, with the nearest reachable point), before
        anything is computed for the motors.
    ProtocolError
        The walk would hold more samples than :data:`~endocal.protocols.trajectory.MAX_SAMPLES`
        (a speed typed in m/s, say), before any is made.
    """
    p = path.params
    fs = p["sample_rate_hz"]
    pts, dome = path._dense(probe)
    walk_s = _polyline_length_mm(pts) / p["speed_mmps"]
    check_samples(2 * (p["approach_s"] + p["hold_s"]) + walk_s, fs, f"path '{path.name}'",
                  "its speed_mmps, approach_s, hold_s and sample_rate_hz")
    kin = ProbeKinematics.from_probe(probe)
    try:
        kin.inverse(pts, rotation_deg=0.0)  # every waypoint reachable, named by its index
    except UnreachableError as exc:
        raise UnreachableError(f"path '{path.name}', waypoint {exc.index}: {exc}", index=exc.index,
                               nearest_tip_in_tracker_mm=exc.nearest_tip_in_tracker_mm, nearest=exc.nearest) from None
    walk, on_dome = _resample_constant_speed(pts, dome, p["speed_mmps"], fs)
    if on_dome.any():  # back onto the dome: a chord between dense points sags below it
        walk[on_dome, 2] = dome_height_mm(walk[on_dome, :2], probe)
    j = kin.inverse(walk, rotation_deg=0.0)
    first, second = probe.bending_axes
    walk_goal = {first: j.theta_first_deg, second: j.theta_second_deg, TRANSLATION: j.translation_mm,
                 ROTATION: j.rotation_deg}
    n_ramp = max(int(round(p["approach_s"] * fs)), 1)
    n_hold = int(round(p["hold_s"] * fs))
    up = 0.5 - 0.5 * np.cos(np.pi * np.arange(n_ramp) / n_ramp)  # 0 -> 1, excluding 1
    down = up[::-1]
    rest = _rest_tip_mm(probe)
    goal = {}
    for dof in probe.dofs:
        g = walk_goal[dof]
        goal[dof] = np.concatenate([g[0] * up, np.full(n_hold, g[0]), g, np.full(n_hold, g[-1]), g[-1] * down, [0.0]])
    n_walk = walk.shape[0]
    tip = np.vstack([np.repeat(rest[None], n_ramp, 0), np.repeat(walk[:1], n_hold, 0), walk,
                     np.repeat(walk[-1:], n_hold, 0), np.repeat(rest[None], n_ramp + 1, 0)])
    n = tip.shape[0]
    t = np.arange(n) / fs
    a = (n_ramp + n_hold) / fs
    b = (n_ramp + n_hold + n_walk - 1) / fs
    segments = (Segment("approach", tuple(probe.dofs), 0.0, a), Segment("path", tuple(probe.dofs), a, b),
                Segment("return", tuple(probe.dofs), b, float(t[-1])))
    return Trajectory(t_s=t, goal=goal, sample_rate_hz=fs, protocol=path.name, segments=segments,
                      tip_desired_mm=tip)


def _rest_tip_mm(probe: ProbeConfig) -> np.ndarray:
    return np.array([0.0, 0.0, probe.bending_length_mm])


# --------------------------------------------------------------------------- files


def shipped_paths_dir() -> Path:
    """``protocols/paths`` of the source tree, or of the installed package."""
    from endocal.protocols.protocol import shipped_protocols_dir

    return shipped_protocols_dir() / "paths"


def list_paths() -> list[TipPath]:
    """The shipped tip paths, by name."""
    d = shipped_paths_dir()
    return [read_path_file(f) for f in sorted(d.glob("*.toml"))] if d.is_dir() else []


def _resolve(shape: PathShape, given: dict, where: str) -> dict:
    known = [q.name for q in shape.params]
    unknown = [k for k in given if k not in known]
    if unknown:
        raise ProtocolError(f"{where}: unknown parameter(s) {', '.join(map(repr, unknown))} for path '{shape.name}'; "
                            f"it has {', '.join(known)}")
    params = {q.name: q.default for q in shape.params}
    for k, v in given.items():
        params[k] = _coerce(shape.param(k), v, where)
    return params


def _coerce(q: Param, value: Any, where: str) -> Any:
    if q.kind == "float_or_none":
        if value is None:
            return None
        return Param(q.name, q.default, "float", q.doc).coerce(value, where)
    if q.kind == "bool":
        if not isinstance(value, bool):
            raise ProtocolError(f"{where}: '{q.name}' must be true or false, got {value!r}")
        return value
    if q.kind == "points":
        pts = np.asarray(value, float)
        if pts.ndim != 2 or pts.shape[1] != 3 or pts.shape[0] < 2 or not np.isfinite(pts).all():
            raise ProtocolError(f"{where}: '{q.name}' must be at least 2 finite (x, y, z) points, mm")
        return pts
    return q.coerce(value, where)


def read_path_file(path: str | Path, overrides: dict | None = None) -> TipPath:
    """Load a path TOML file, or a CSV of waypoints (columns ``x_mm, y_mm, z_mm``).

    Raises
    ------
    ProtocolError
        Unreadable file, unknown keys or parameters, a CSV without the x/y/z columns.
    """
    path = Path(path)
    where = str(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise ProtocolError(f"{where}: cannot read the path file ({exc.strerror or exc})") from None
    sha = hashlib.sha256(raw).hexdigest()
    if path.suffix.lower() == ".csv":
        given = {"points_mm": _read_points_csv(raw, where), **(overrides or {})}
        shape = SHAPES["points"]
        return TipPath(path.stem, "points", _resolve(shape, given, where),
                       f"{len(given['points_mm'])} waypoints from {path.name}", path, sha, dict(overrides or {}))
    try:
        data = tomllib.loads(raw.decode("utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ProtocolError(f"{where}: not a valid TOML path file ({exc})") from None
    unknown = [k for k in data if k not in _FILE_KEYS]
    if unknown:
        raise ProtocolError(f"{where}: unknown field(s) {', '.join(map(repr, unknown))}; a path file has "
                            f"{', '.join(_FILE_KEYS)}")
    kind = data.get("path")
    if not isinstance(kind, str) or kind not in SHAPES:
        raise ProtocolError(f"{where}: 'path' must be one of {', '.join(SHAPES)}, got {kind!r}")
    params = data.get("params") or {}
    if not isinstance(params, dict):
        raise ProtocolError(f"{where}: 'params' must be a table ([params]), got {params!r}")
    params = dict(params)
    if "points_file" in params:
        csv = (path.parent / str(params.pop("points_file"))).resolve()
        params["points_mm"] = _read_points_csv(csv.read_bytes(), str(csv))
    given = {**params, **(overrides or {})}
    return TipPath(path.stem, kind, _resolve(SHAPES[kind], given, where), str(data.get("description", "")), path, sha,
                   dict(overrides or {}))


def _read_points_csv(raw: bytes, where: str) -> np.ndarray:
    import pandas as pd

    from endocal.runs.textable import read_csv_table

    try:
        df = read_csv_table(raw)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise ProtocolError(f"{where}: not a CSV table of waypoints ({str(exc).splitlines()[0]})") from None
    cols = ("x_mm", "y_mm", "z_mm")
    headerless = df.attrs.get("headerless", False)
    if headerless and df.shape[1] == 3:  # a bare list of points: x, y, z in mm
        df.columns = list(cols)
    missing = [c for c in cols if c not in df.columns]
    if missing:
        raise ProtocolError(f"{where}: a point list needs columns {', '.join(cols)} (mm, base_home frame); missing "
                            f"{', '.join(missing)} (it has {', '.join(map(str, df.columns)) or 'none'})")
    try:
        pts = df[list(cols)].to_numpy(float)
    except (TypeError, ValueError):
        raise ProtocolError(f"{where}: x_mm, y_mm and z_mm must be numbers") from None
    bad = ~np.isfinite(pts).all(axis=1)
    if bad.any():
        line = int(np.flatnonzero(bad)[0]) + (1 if headerless else 2)
        raise ProtocolError(f"{where}: waypoint on line {line} is not three finite numbers")
    if len(pts) < 2:
        raise ProtocolError(f"{where}: a point list needs at least 2 waypoints, it has {len(pts)}")
    return pts


def load_path(name_or_file: str | Path, overrides: dict | None = None) -> TipPath:
    """A shipped path by name (``circle-1``), a path TOML file, or a waypoint CSV.

    Raises
    ------
    ProtocolError
        Unknown name (listing the shipped ones) or a bad file.
    """
    p = Path(name_or_file)
    if p.suffix.lower() in (".toml", ".csv") or p.exists():
        if not p.is_file():
            raise ProtocolError(f"{p}: no such path file")
        return read_path_file(p, overrides)
    f = shipped_paths_dir() / f"{name_or_file}.toml"
    if not f.is_file():
        names = ", ".join(t.name for t in list_paths())
        raise ProtocolError(f"unknown tip path '{name_or_file}': shipped paths are {names}; or give a .toml or .csv file")
    return read_path_file(f, overrides)


__all__ = ["SHAPES", "PathShape", "TipPath", "dome_height_mm", "list_paths", "load_path", "path_trajectory",
           "read_path_file"]
