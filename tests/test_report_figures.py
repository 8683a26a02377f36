"""The report's figures and notes say what the record holds (endocal/report/figures.py, build.py).

A linear drive's command (a few mm) drawn on the bending angle's axis (tens of degrees) is a
flat line: it gets its own axis. A record that logged no tracker (an aligned table) has no tip
path to draw, and the report says nothing about it; a tracker stream that is there and cannot be
read still gets its note.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from endocal.report import figures as F

REPO = Path(__file__).resolve().parents[1]


def _command_axes(fig, unit: str):
    """The axes holding the command's line, and the one holding the measured angle."""
    lines = {ln.get_label(): ln for ax in fig.axes for ln in ax.get_lines()}
    return lines[f"knob command ({unit})"].axes, lines["measured"].axes


def test_a_linear_drives_command_is_drawn_on_its_own_axis():
    t_s = np.linspace(0.0, 20.0, 400)
    cmd_mm = 3.0 * np.sin(2 * np.pi * 0.2 * t_s)  # a tendon's travel, mm
    meas_deg = 72.0 + 8.0 * np.sin(2 * np.pi * 0.2 * t_s - 0.3)  # a bend around 72 deg
    fig = F.time_series(t_s, cmd_mm, meas_deg, {"m": meas_deg + 0.1}, {"m": "#1f77b4"}, "r", cmd_unit="mm")
    cmd_ax, meas_ax = _command_axes(fig, "mm")
    assert cmd_ax is not meas_ax
    assert cmd_ax.get_ylabel() == "command (mm)" and meas_ax.get_ylabel() == "angle (deg)"
    # each axis spans its own signal: the command fills its axis (not 6 mm of a 20 deg span)
    lo, hi = cmd_ax.get_ylim()
    assert hi - lo < 2 * 6.0 and lo <= -2.9 and hi >= 2.9, (lo, hi)
    lo, hi = meas_ax.get_ylim()
    assert lo > 60.0 and hi < 85.0, (lo, hi)  # the angle's axis is not stretched down to the command's 0
    # the legend still names the command
    assert "knob command (mm)" in [t.get_text() for t in meas_ax.get_legend().get_texts()]


def test_a_knobs_command_shares_the_angles_axis():
    t_s = np.linspace(0.0, 10.0, 200)
    cmd = 40.0 * np.sin(t_s)
    fig = F.time_series(t_s, cmd, 0.7 * cmd, {}, {}, "r")
    cmd_ax, meas_ax = _command_axes(fig, "deg")
    assert cmd_ax is meas_ax and len(fig.axes) == 2  # the time series and the error below, no twin


@pytest.fixture(scope="module")
def short_run(tmp_path_factory) -> Path:
    from tests._cli import endocal

    run = tmp_path_factory.mktemp("tip") / "run"
    proc = endocal("excite", "triangle", "--set", "cycles=1", "--out", run, "-q", "--seed", 3)
    assert proc.returncode == 0, proc.stderr
    return run


def test_no_tip_path_note_for_a_record_without_a_tracker(short_run, tmp_path):
    """An aligned table logged no tracker: its report draws no tip path and warns of nothing."""
    import pandas as pd

    from endocal.models import make_model
    from endocal.report import build_report
    from endocal.runs.aligned import load_aligned
    from endocal.validation.data import axis_data

    table = tmp_path / "table.parquet"
    pd.read_parquet(short_run / "aligned.parquet").to_parquet(table)
    model = make_model("linear", axis="ap").fit(axis_data(load_aligned(table), "ap"), max_nfev=20)
    report = build_report([model], [table], n_boot=20, regime_boot=20)
    assert not [n for n in report.notes if "tip" in n], report.notes
    assert not [f for f in report.figures if f.section == "task-space"]


def test_a_tracker_stream_that_cannot_be_read_is_still_noted(short_run, tmp_path):
    """Only a tracker stream that is there and unreadable is an error; no stream is no tip path."""
    from endocal.errors import EndocalError
    from endocal.report.build import _tip_path

    run = tmp_path / "run"
    shutil.copytree(short_run, run)
    tip = _tip_path(_entry(run))
    assert tip.ndim == 2 and tip.shape[1] == 3  # a run with its tracker: the tip (mm, in the base frame)
    for part in (run / "tracker").glob("part-*.parquet"):
        part.write_bytes(b"not parquet")
    with pytest.raises(EndocalError):
        _tip_path(_entry(run))
    (tmp_path / "table.csv").write_text("t_s,ap_cmd_deg,ap_meas_deg\n0,0,0\n0.01,1,1\n0.02,2,2\n")
    assert _tip_path(_entry(tmp_path / "table.csv")) is None


def _entry(path: Path):
    """What :func:`endocal.report.build._tip_path` reads of a report's record: its source and label."""
    from types import SimpleNamespace

    from endocal.runs.aligned import load_aligned

    return SimpleNamespace(aligned=load_aligned(path), label=path.name)
