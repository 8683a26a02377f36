"""A run folder as an MCAP file, for Foxglove and PlotJuggler (``endocal export mcap``).

MCAP is the ROS 2 default bag format (since Iron) and Foxglove's native one. Every channel here
is JSON with a JSON Schema, so Foxglove and PlotJuggler open the file without ROS or message
definitions. The channels:

=====================  ==========================  ==============================================
topic                  schema                      one message per
=====================  ==========================  ==============================================
``/motor/<dof>``       ``endocal.MotorSample``     motor tick: ``goal_<u>``, ``pos_<u>``, ``vel_<u>ps``,
                                                   ``current_ma`` of one degree of freedom
``/motor/other``       ``endocal.MotorOther``      motor tick: the stream's other columns (simulator
                                                   extras, ``tick_late_ms``, desired angles)
``/tracker/<sensor>``  ``foxglove.PoseInFrame``    valid tracker frame of the sensor, in the tracker
                                                   frame, metres (Foxglove's unit)
``/tf``                ``foxglove.FrameTransform`` valid tracker frame: ``tracker`` -> ``<sensor>``
                                                   (the 3-D panel draws the tip moving)
``/tracker/raw``       ``endocal.TrackerRow``      tracker row as logged (mm, invalid rows too)
``/truth``             ``endocal.TruthSample``     simulator ground-truth sample (simulator runs)
``/aligned``           ``endocal.AlignedRow``      row of the aligned table
``/model/<axis>``      ``endocal.ModelPrediction`` sample the model predicts (``--model``): command,
                                                   measured, predicted angle and the error
=====================  ==========================  ==============================================

Each message carries ``t_s``, the run's own clock; its MCAP log time is the run's start
(``run.json``'s ``started_utc``) plus ``t_s``, so Foxglove shows wall-clock time and two channels
of one tick share a time stamp. ``run.json`` goes in whole as the metadata record ``run.json``;
the record ``endocal.export`` says what was exported and, for a run that did not complete,
how far it reaches.

A run that did not complete (``status`` ``interrupted``, ``failed`` or still ``running``: the
recording was killed) or with a stream part that cannot be read is exported as far as it is
readable: every part before the first unreadable one, the aligned table rebuilt from the streams
when it is missing. The file is a complete MCAP (summary, index, footer); the result's
``incomplete`` says why it holds less than the run meant to, and the command line turns that into
one line and exit code 2.
"""

from __future__ import annotations

import heapq
import json
import math
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path

from endocal.errors import EndocalError, ModelError, OutputExistsError, OutputPathError, RunFormatError

INSTALL_HINT = "pip install 'endocal-toolkit[mcap]'"

#: How the DoF columns of the motor stream end (run format: ``<dof>_goal_<u>``, ``_pos_<u>``, ``_vel_<u>ps``,
#: ``_current_ma``)
_DOF_FIELDS = ("goal", "pos", "vel", "current")


class MissingExtraError(EndocalError, ImportError):
    """An optional dependency (an extra of endocal-toolkit) is not installed."""


# ---------------------------------------------------------------------------------------------- schemas
def _vec(names: str) -> dict:
    return {"type": "object", "properties": {k: {"type": "number"} for k in names}}


_TIME = {"type": "object", "title": "time", "properties": {"sec": {"type": "integer", "minimum": 0},
                                                            "nsec": {"type": "integer", "minimum": 0}}}

#: Foxglove's schemas (docs.foxglove.dev, message schemas), JSON Schema encoding
POSE_IN_FRAME = {
    "title": "foxglove.PoseInFrame", "description": "A timestamped pose for an object or reference frame in 3D space",
    "type": "object",
    "properties": {
        "timestamp": {**_TIME, "description": "Timestamp of pose"},
        "frame_id": {"type": "string", "description": "Frame of reference for pose position and orientation"},
        "pose": {"type": "object", "properties": {"position": _vec("xyz"), "orientation": _vec("xyzw")}},
    },
}
FRAME_TRANSFORM = {
    "title": "foxglove.FrameTransform", "description": "A transform between two reference frames in 3D space",
    "type": "object",
    "properties": {
        "timestamp": {**_TIME, "description": "Timestamp of transform"},
        "parent_frame_id": {"type": "string", "description": "Name of the parent frame"},
        "child_frame_id": {"type": "string", "description": "Name of the child frame"},
        "translation": _vec("xyz"), "rotation": _vec("xyzw"),
    },
}


def _table_schema(title: str, description: str, columns: dict[str, str]) -> dict:
    """A flat object schema: column -> JSON type (numbers may be null: NaN has no JSON)."""
    props = {}
    for name, kind in columns.items():
        props[name] = {"type": [kind, "null"] if kind == "number" else kind}
    return {"title": title, "description": description, "type": "object", "properties": props}


def _kind(series) -> str:
    import pandas as pd

    if pd.api.types.is_bool_dtype(series):
        return "boolean"
    if pd.api.types.is_integer_dtype(series):
        return "integer"
    if pd.api.types.is_numeric_dtype(series):
        return "number"
    return "string"


# ---------------------------------------------------------------------------------------------- result
@dataclass
class McapExport:
    """What ``export_mcap`` wrote.

    Attributes
    ----------
    path : Path
        The MCAP file.
    run : Path
        The run folder.
    channels : dict of str to int
        Topic -> messages written.
    schemas : dict of str to str
        Topic -> schema name.
    t_range_s : (float, float)
        First and last ``t_s`` of any message (the run's clock).
    start_ns : int
        The log time of ``t_s = 0`` (ns since the Unix epoch; 0 when ``run.json`` has no start).
    incomplete : str
        Why the file holds less than the run meant to (a run that did not complete, an
        unreadable part), ``""`` when it holds the whole run.
    notes : list of str
        What was left out and why (no aligned table, a model's axis missing, ...).
    """

    path: Path
    run: Path
    channels: dict[str, int]
    schemas: dict[str, str]
    t_range_s: tuple[float, float]
    start_ns: int
    incomplete: str = ""
    notes: list[str] = field(default_factory=list)

    @property
    def messages(self) -> int:
        return sum(self.channels.values())

    def to_dict(self) -> dict:
        return {"path": str(self.path), "run": str(self.run), "channels": dict(self.channels),
                "schemas": dict(self.schemas), "t_range_s": list(self.t_range_s), "start_ns": self.start_ns,
                "incomplete": self.incomplete, "notes": list(self.notes), "messages": self.messages}

    def __repr__(self) -> str:
        state = f"; INCOMPLETE: {self.incomplete}" if self.incomplete else ""
        return (f"McapExport({self.path}: {self.messages} messages on {len(self.channels)} channels, "
                f"t_s {self.t_range_s[0]:.3f}..{self.t_range_s[1]:.3f}{state})")


# ---------------------------------------------------------------------------------------------- reading the run
def _read_readable(run: Path, name: str, problems: list[str]):
    """A stream as far as it is readable: every part before the first that cannot be read (None: no part)."""
    import pandas as pd

    from endocal.runs.aligned import read_parquet, read_stream

    folder = run / name
    if not folder.is_dir() or not any(folder.glob("part-*.parquet")):
        return None
    try:
        return read_stream(run, name)
    except RunFormatError as whole_failed:
        frames, torn = [], None
        for part in sorted(folder.glob("part-*.parquet")):
            try:
                frames.append(read_parquet(part))
            except RunFormatError:
                torn = part
                break
        # only a torn part is cut off; a stream that is readable but wrong (a column missing, text for numbers)
        # is refused as the run format refuses it
        if torn is None or not frames or "t_s" not in frames[0].columns:
            raise whole_failed from None
        problems.append(f"{torn} cannot be read: {name} exported up to the part before it")
        return pd.concat(frames, ignore_index=True).sort_values("t_s", kind="stable").reset_index(drop=True)


def _start_ns(meta: dict) -> int:
    text = meta.get("started_utc")
    if not isinstance(text, str):
        return 0
    try:
        when = datetime.fromisoformat(text.replace("Z", "+00:00"))
    except ValueError:
        return 0
    return round(when.timestamp() * 1000) * 1_000_000  # started_utc holds milliseconds


def _stamp(start_ns: int, t_s: float) -> int:
    return start_ns + round(t_s * 1e9)


def _time(ns: int) -> dict:
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def _clean(value):
    """A JSON value: NaN and infinities become null, numpy scalars Python ones."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if hasattr(value, "item"):
        return _clean(value.item())
    return value


def _records(df, columns: list[str], rename: dict[str, str] | None = None, block: int = 8192):
    """``(t_s, json bytes)`` per row of ``df`` with ``columns`` (renamed), converted a block of rows at a time
    (a two-hour run at 1 kHz is 7 million rows: as Python objects all at once, gigabytes)."""
    rename = rename or {}
    keys = [rename.get(c, c) for c in columns]
    t = df["t_s"].to_numpy(float)
    for start in range(0, len(df), block):
        part = df.iloc[start:start + block]
        cols = [part[c].tolist() for c in columns]
        for i in range(len(part)):
            yield float(t[start + i]), json.dumps({k: _clean(col[i]) for k, col in zip(keys, cols)},
                                                  allow_nan=False).encode()


# ---------------------------------------------------------------------------------------------- export
def export_mcap(run, out, *, models=(), force: bool = False) -> McapExport:
    """Write a run folder (and optionally models' predictions on it) as one MCAP file.

    Parameters
    ----------
    run : path
        A run folder (``run.json``, ``motor/``, ``tracker/``, ...).
    out : path
        The ``.mcap`` file to write (atomically: complete or not at all).
    models : sequence of path
        Model files; each adds ``/model/<axis>``: its prediction on the run and the error.
    force : bool
        Replace an existing ``out``.

    Returns
    -------
    McapExport
        ``incomplete`` is non-empty for a run exported only as far as it is readable.

    Raises
    ------
    MissingExtraError
        The ``mcap`` package is not installed.
    RunFormatError
        Not a run folder, or nothing of it readable.
    ModelError
        A model file that cannot be read, or a model of an axis the run lacks.
    OutputExistsError, OutputPathError
    """
    try:
        from mcap.writer import CompressionType, Writer
    except ImportError:
        raise MissingExtraError(f"exporting to MCAP needs the mcap package: {INSTALL_HINT}") from None
    from endocal import __version__
    from endocal.runs.format import ALIGNED, MOTOR, RUN_JSON, TRACKER, TRUTH, read_run_json

    run, out = Path(run), Path(out)
    if not run.is_dir():
        raise RunFormatError(f"{run} is not a run folder (give the folder that holds run.json)")
    if out.exists() and not force:
        raise OutputExistsError(f"{out} already exists: choose another --out or pass --force")
    if out.is_dir():
        raise OutputPathError(f"{out} is a folder: give a file name such as run.mcap")
    meta = read_run_json(run)
    run_json_text = (run / RUN_JSON).read_text(encoding="utf-8")
    problems: list[str] = []
    notes: list[str] = []
    status = meta.get("status", "complete")
    if status != "complete":
        why = {"interrupted": "it was stopped before the end (status 'interrupted')",
               "failed": f"it failed (status 'failed'{': ' + str(meta['error']) if meta.get('error') else ''})",
               "running": "its recording was killed (run.json still says 'running')"}
        problems.append(f"{run} did not complete: {why.get(status, f'status {status!r}')}")

    motor = _read_readable(run, MOTOR, problems)
    tracker = _read_readable(run, TRACKER, problems)
    truth = _read_readable(run, TRUTH, problems)
    if motor is None and tracker is None:
        raise RunFormatError(f"{run}: neither a motor nor a tracker sample was logged: nothing to export")
    aligned = _aligned(run, meta, motor, tracker, ALIGNED, notes)
    start_ns = _start_ns(meta)
    if not start_ns:
        notes.append("run.json has no started_utc: log times count from the Unix epoch (t_s = 0 at 1970-01-01)")

    streams: list = []  # (topic, schema dict, message-encoding generator of (t_s, bytes))
    if motor is not None:
        streams += _motor_streams(motor)
    if tracker is not None:
        streams += _tracker_streams(tracker, start_ns)
    if truth is not None:
        cols = [c for c in truth.columns if c != "t_s"]
        streams.append(("/truth", _table_schema("endocal.TruthSample", "simulator ground truth (noise free)",
                                                {"t_s": "number", **{c: _kind(truth[c]) for c in cols}}),
                        _records(truth, ["t_s", *cols])))
    if aligned is not None:
        cols = list(aligned.table.columns)
        streams.append(("/aligned", _table_schema("endocal.AlignedRow", "a row of the run's aligned table",
                                                  {c: _kind(aligned.table[c]) for c in cols}),
                        _records(aligned.table, cols)))
    for model_path in models:
        stream = _model_stream(Path(model_path), aligned, run)
        if any(stream[0] == topic for topic, _, _ in streams):
            raise ModelError(f"two --model files are models of one axis ({stream[0]}): give one model per axis")
        streams.append(stream)

    tmp = out.with_name(f".{out.name}.partial")
    counts: dict[str, int] = {}
    schemas: dict[str, str] = {}
    t_lo, t_hi = math.inf, -math.inf
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        with open(tmp, "wb") as fh:
            writer = Writer(fh, compression=CompressionType.ZSTD if _has_zstd() else CompressionType.LZ4)
            writer.start(profile="", library=f"endocal {__version__}")
            ids: dict[str, int] = {}
            schema_ids: dict[str, int] = {}
            for topic, schema, _ in streams:
                key = json.dumps(schema, sort_keys=True)
                if key not in schema_ids:
                    schema_ids[key] = writer.register_schema(name=schema["title"], encoding="jsonschema",
                                                             data=json.dumps(schema).encode())
                ids[topic] = writer.register_channel(topic=topic, message_encoding="json", schema_id=schema_ids[key])
                counts[topic] = 0
                schemas[topic] = schema["title"]
            # every stream in time order, merged lazily (a long rig run is millions of messages); ties keep
            # the streams' order, and each stream its own
            merged = heapq.merge(*[_stamped(start_ns, k, topic, gen) for k, (topic, _, gen) in enumerate(streams)])
            for log_ns, _, _, topic, data in merged:
                writer.add_message(channel_id=ids[topic], log_time=log_ns, publish_time=log_ns, data=data,
                                   sequence=counts[topic])
                counts[topic] += 1
                t = (log_ns - start_ns) / 1e9
                t_lo, t_hi = min(t_lo, t), max(t_hi, t)
            writer.add_metadata("run.json", {"run.json": run_json_text})
            writer.add_metadata("endocal.export", {
                "endocal": __version__, "run": str(run), "status": str(status),
                "complete": "false" if problems else "true", "incomplete": "; ".join(problems),
                "start_ns": str(start_ns), "models": json.dumps([str(m) for m in models]), "notes": "; ".join(notes),
                "units": "positions of foxglove.PoseInFrame and FrameTransform in metres; every other field as its "
                         "name says (run format)",
            })
            writer.finish()
        tmp.replace(out)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise OutputPathError(f"cannot write {out}: {exc.strerror or exc}") from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    if not math.isfinite(t_lo):
        t_lo = t_hi = 0.0
    return McapExport(path=out, run=run, channels=counts, schemas=schemas, t_range_s=(t_lo, t_hi), start_ns=start_ns,
                      incomplete="; ".join(problems), notes=notes)


def _stamped(start_ns: int, k: int, topic: str, gen):
    """``(log_ns, k, i, topic, data)`` per message of one stream: the keys :func:`heapq.merge` orders by."""
    for i, (t, data) in enumerate(gen):
        yield _stamp(start_ns, t), k, i, topic, data


def _has_zstd() -> bool:
    try:
        import zstandard  # noqa: F401
    except ImportError:
        return False
    return True


def _aligned(run: Path, meta: dict, motor, tracker, aligned_name: str, notes: list[str]):
    """The run's aligned table (rebuilt from the readable streams when the file is missing), or None."""
    from endocal.runs.aligned import AlignedData, align, check_aligned, drive_units_of, load_aligned

    if (run / aligned_name).is_file():
        try:
            return load_aligned(run)
        except RunFormatError as exc:
            notes.append(f"aligned table left out: {exc}")
            return None
    if motor is None or tracker is None:
        notes.append("aligned table left out: the run has no aligned.parquet and lacks a stream to rebuild it")
        return None
    from endocal.probe import ProbeConfig

    try:
        probe = ProbeConfig.from_dict(meta.get("probe"), where=str(run / "run.json"))
        df = align(motor, tracker, probe).table
        axes = check_aligned(df, str(run))
    except (EndocalError, KeyError, ValueError) as exc:
        notes.append(f"aligned table left out: it could not be rebuilt from the streams ({exc})")
        return None
    notes.append("aligned table rebuilt from the streams (the run has no aligned.parquet)")
    return AlignedData(df, axes, run, "", meta, drive_units_of(df.columns))


def _motor_streams(motor) -> list:
    import re

    pattern = re.compile(rf"^(.+)_({'|'.join(_DOF_FIELDS)})_[a-z]+$")
    dofs: list[str] = []
    for c in motor.columns:
        m = pattern.match(c)
        if m and m.group(1) not in dofs:
            dofs.append(m.group(1))
    used = {"t_s"}
    out = []
    for dof in dofs:
        cols = [c for c in motor.columns if any(c.startswith(f"{dof}_{f}_") for f in _DOF_FIELDS)]
        used.update(cols)
        rename = {c: c[len(dof) + 1:] for c in cols}
        schema = _table_schema("endocal.MotorSample",
                               "one motor tick of a degree of freedom (goal, position, speed, current)",
                               {"t_s": "number", **{rename[c]: _kind(motor[c]) for c in cols}})
        out.append((f"/motor/{dof}", schema, _records(motor, ["t_s", *cols], rename)))
    other = [c for c in motor.columns if c not in used]
    if other:
        schema = _table_schema("endocal.MotorOther", "the motor stream's columns beyond the degrees of freedom",
                               {"t_s": "number", **{c: _kind(motor[c]) for c in other}})
        out.append(("/motor/other", schema, _records(motor, ["t_s", *other])))
    return out


def _tracker_streams(tracker, start_ns: int) -> list:
    import numpy as np

    out = []
    cols = list(tracker.columns)
    out.append(("/tracker/raw", _table_schema("endocal.TrackerRow", "a tracker row as logged (mm, quaternion "
                                              "sensor to tracker, scalar first; invalid rows too)",
                                              {c: _kind(tracker[c]) for c in cols}), _records(tracker, cols)))
    valid = tracker[tracker["valid"].astype(bool)]
    pos = valid[["x_mm", "y_mm", "z_mm", "qw", "qx", "qy", "qz"]].to_numpy(float)
    ok = np.isfinite(pos).all(axis=1)
    valid = valid[ok]
    sensors = sorted(valid["sensor"].astype(str).unique())

    def poses(sub):
        t = sub["t_s"].to_numpy(float)
        p = sub[["x_mm", "y_mm", "z_mm"]].to_numpy(float) / 1000.0  # Foxglove's 3-D panel works in metres
        q = sub[["qx", "qy", "qz", "qw"]].to_numpy(float)
        name = str(sub["sensor"].iloc[0])
        for i in range(t.size):
            stamp = _time(_stamp(start_ns, float(t[i])))
            yield float(t[i]), name, stamp, p[i], q[i]

    for s in sensors:
        sub = valid[valid["sensor"].astype(str) == s]
        gen = ((t, json.dumps({"timestamp": stamp, "frame_id": "tracker",
                               "pose": {"position": dict(zip("xyz", map(float, p))),
                                        "orientation": dict(zip("xyzw", map(float, q)))}}).encode())
               for t, _, stamp, p, q in poses(sub))
        out.append((f"/tracker/{s}", POSE_IN_FRAME, gen))
    gen_tf = ((t, json.dumps({"timestamp": stamp, "parent_frame_id": "tracker", "child_frame_id": name,
                              "translation": dict(zip("xyz", map(float, p))),
                              "rotation": dict(zip("xyzw", map(float, q)))}).encode())
              for t, name, stamp, p, q in poses(valid)) if len(valid) else iter(())
    out.append(("/tf", FRAME_TRANSFORM, gen_tf))
    return out


def _model_stream(path: Path, aligned, run: Path):
    """``/model/<axis>``: the model's prediction on the run, as validate scores it, and its error."""
    from endocal.models import load_model
    from endocal.validation.data import axis_data
    from endocal.validation.predict import predict_scored

    model = load_model(path)
    if aligned is None:
        raise ModelError(f"{run} has no aligned table to predict on: --model {path} needs one")
    axis = model.axis or (aligned.axes[0] if len(aligned.axes) == 1 else None)
    if axis is None:
        raise ModelError(f"{path} names no axis and {run} has {', '.join(aligned.axes)}: refit with --axis")
    if axis not in aligned.axes:
        raise ModelError(f"{path} is a model of axis '{axis}', which {run} lacks (it has {', '.join(aligned.axes)})")
    data = axis_data(aligned, axis)
    pred, _, _ = predict_scored(model, data)
    unit = aligned.drive_unit(axis)
    rows = {"t_s": data.t_s, f"cmd_{unit}": data.cmd_deg, "meas_deg": data.meas_deg, "pred_deg": pred,
            "error_deg": pred - data.meas_deg}
    import pandas as pd

    df = pd.DataFrame(rows)
    schema = _table_schema("endocal.ModelPrediction",
                           f"the model's prediction on the run and its error (pred - meas, deg): {model}",
                           {k: "number" for k in rows})
    return (f"/model/{axis}", schema, _records(df, list(rows)))
