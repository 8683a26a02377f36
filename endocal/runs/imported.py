"""Writing a run folder from streams recorded elsewhere (a ROS bag, a lab's CSV log).

Importers read their source, convert units and times, and hand the motor samples and the
paired tip/base poses to :func:`write_imported_run`, which writes the same motor and tracker
streams, aligned table and ``run.json`` as ``endocal excite`` (:mod:`endocal.runs.format`).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from endocal.probe import ProbeConfig
from endocal.runs.format import (MOTOR, RUN_JSON, create_run_folder, run_meta, sample_rate_hz, utc_now,
                                 write_folder_staged, write_json)
from endocal.runs.logger import StreamLogger, finish_run
from endocal.streams import StreamChunk

POSE_COLUMNS = ("x_mm", "y_mm", "z_mm", "qw", "qx", "qy", "qz")


def tracker_stream(tip: np.ndarray, base: np.ndarray, valid: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """The long-format tracker stream of paired frames.

    Parameters
    ----------
    tip, base : (n, 8) arrays
        ``t_s, x_mm, y_mm, z_mm, qw, qx, qy, qz`` of each frame's tip and base sensor (same times).
    valid : (n, 2) bool array, optional
        Whether the tip and the base reading of each frame is valid (default: all).
    """
    n = tip.shape[0]
    frames = np.concatenate([tip, base])
    out = {"t_s": frames[:, 0], "sensor": np.array(["tip"] * n + ["base"] * n, dtype=object)}
    for j, col in enumerate(POSE_COLUMNS, start=1):
        out[col] = frames[:, j]
    out["valid"] = np.ones(2 * n, bool) if valid is None else np.concatenate([valid[:, 0], valid[:, 1]]).astype(bool)
    order = np.argsort(out["t_s"], kind="stable")
    return {k: v[order] for k, v in out.items()}


def write_imported_run(out: Path, motor: dict[str, np.ndarray], tracker: dict[str, np.ndarray], probe: ProbeConfig, *,
                       source: dict, backend: dict, command: str | None, wall0: float | None = None,
                       drive_units: dict[str, str] | None = None) -> dict:
    """Write ``out`` as a complete run folder and return its ``run.json`` content; staged beside
    ``out`` and renamed into place (:func:`endocal.runs.format.write_folder_staged`), so a
    failure halfway leaves nothing behind.

    Parameters
    ----------
    out : Path
        Checked beforehand with :func:`endocal.runs.format.prepare_output`.
    motor : dict
        Motor stream columns, ``t_s`` first (s from the first sample).
    tracker : dict
        Tracker stream (:func:`tracker_stream`), on the same clock.
    source : dict
        What was imported (``name``, ``source`` path, ``sha256``...), recorded as the run's protocol.
    backend : dict
        How it was recorded and imported (``name`` names the importer).
    drive_units : dict, optional
        Bending axis -> the unit of its drive (``mm`` for a linear stage, whose motor columns are
        ``<axis>_goal_mm`` ...); deg when not given. Recorded in ``run.json``.
    """
    wall0 = time.monotonic() if wall0 is None else wall0
    return write_folder_staged(out, lambda stage: _write_run(stage, motor, tracker, probe, source, backend, command,
                                                              wall0, drive_units))


def _write_run(out: Path, motor: dict, tracker: dict, probe: ProbeConfig, source: dict, backend: dict,
               command: str | None, wall0: float, drive_units: dict[str, str] | None) -> dict:
    rate = sample_rate_hz(motor["t_s"])
    meta = run_meta(protocol=source, probe=probe, backend=backend, seed=None, realtime=True, command=command,
                    sample_rate_hz=rate, planned_duration_s=float(motor["t_s"][-1]), drive_units=drive_units)
    meta["started_utc"] = utc_now()
    create_run_folder(out)
    write_json(out / RUN_JSON, meta)
    logger = StreamLogger(out)
    logger.append(StreamChunk(motor=motor, tracker=tracker))
    logger.flush()
    finish_run(out, meta, logger, "complete", None, time.monotonic() - wall0, probe)
    meta["motor_rows"] = logger.rows_written[MOTOR]
    return meta
