"""`endocal export mcap` (issue 34, part 5): a run as MCAP, read back with the mcap package's reader.

Schemas, message counts and time stamps are checked against the run folder itself (its streams
and run.json's counts), not against what the writer meant to write.
"""

from __future__ import annotations

import json
import shutil
import sys

import numpy as np
import pandas as pd
import pytest

from endocal.models import make_model, save_model
from tests._cli import ROOT, endocal, one_line_exit_2
from tests._models_signals import PAPER_TABLE1

RUN = ROOT / "data_samples" / "sim-triangle"


def _read(path):
    from mcap.reader import make_reader

    with open(path, "rb") as fh:
        reader = make_reader(fh)
        summary = reader.get_summary()
        messages = [(ch.topic, sch.name, msg.log_time, json.loads(msg.data))
                    for sch, ch, msg in reader.iter_messages(log_time_order=False)]
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
    return summary, messages, metadata


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    pytest.importorskip("mcap")
    tmp = tmp_path_factory.mktemp("mcap")
    model = make_model("pi", ["envelope"], axis="ap").set_parameters(PAPER_TABLE1, cmd_range_deg=(-90, 90))
    save_model(model, tmp / "ap.json")
    proc = endocal("export", "mcap", RUN, "--out", tmp / "run.mcap", "--model", tmp / "ap.json")
    assert proc.returncode == 0, proc.stderr
    return proc, _read(tmp / "run.mcap"), tmp / "run.mcap"


def test_every_stream_is_there_with_its_schema_and_count(exported):
    proc, (summary, messages, metadata), _ = exported
    meta = json.loads((RUN / "run.json").read_text())
    motor = pd.read_parquet(RUN / "motor")
    tracker = pd.read_parquet(RUN / "tracker")
    valid = tracker[tracker["valid"]]
    topics = {ch.topic: (summary.schemas[ch.schema_id], ch.message_encoding) for ch in summary.channels.values()}
    assert all(enc == "json" and sch.encoding == "jsonschema" for sch, enc in topics.values())
    assert {t: sch.name for t, (sch, _) in topics.items()} == {
        "/motor/ap": "endocal.MotorSample", "/motor/ml": "endocal.MotorSample",
        "/motor/translation": "endocal.MotorSample", "/motor/rotation": "endocal.MotorSample",
        "/motor/other": "endocal.MotorOther", "/tracker/raw": "endocal.TrackerRow",
        "/tracker/tip": "foxglove.PoseInFrame", "/tracker/base": "foxglove.PoseInFrame",
        "/tf": "foxglove.FrameTransform", "/truth": "endocal.TruthSample", "/aligned": "endocal.AlignedRow",
        "/model/ap": "endocal.ModelPrediction"}
    counts = {summary.channels[k].topic: n for k, n in summary.statistics.channel_message_counts.items()}
    c = meta["counts"]
    assert counts["/motor/ap"] == counts["/motor/rotation"] == counts["/motor/other"] == c["motor_rows"] == len(motor)
    assert counts["/tracker/raw"] == c["tracker_rows"]
    assert counts["/tracker/tip"] == (valid["sensor"] == "tip").sum()
    assert counts["/tf"] == c["tracker_rows"] - c["tracker_invalid_dropped"]
    assert counts["/aligned"] == counts["/model/ap"] == c["aligned_rows"]
    assert f"/aligned {c['aligned_rows']}" in proc.stdout
    # run.json whole, as metadata; the export's own record says the file holds the whole run
    assert json.loads(metadata["run.json"]["run.json"]) == meta
    assert metadata["endocal.export"]["complete"] == "true"
    # a DoF's fields carry the run format's units; a pose is in metres (Foxglove's unit)
    first = {t: m for t, _, _, m in reversed(messages)}
    assert set(first["/motor/ap"]) == {"t_s", "goal_deg", "pos_deg", "vel_degps", "current_ma"}
    tip0 = valid[valid["sensor"] == "tip"].iloc[0]
    assert first["/tracker/tip"]["pose"]["position"]["x"] == pytest.approx(tip0["x_mm"] / 1000.0, rel=1e-12)
    assert first["/tracker/tip"]["frame_id"] == "tracker"


def test_time_stamps_are_the_run_s_clock_from_its_start(exported):
    _, (summary, messages, _), _ = exported
    meta = json.loads((RUN / "run.json").read_text())
    start = pd.Timestamp(meta["started_utc"]).value  # ns since the epoch
    motor_t = pd.read_parquet(RUN / "motor")["t_s"].to_numpy()
    for topic, _, log_ns, msg in messages:
        t = msg["t_s"] if "t_s" in msg else None
        if t is None:  # foxglove messages: their own timestamp
            stamp = msg["timestamp"]
            assert stamp["sec"] * 1_000_000_000 + stamp["nsec"] == log_ns, topic
        else:
            assert log_ns == start + round(t * 1e9), topic
    ap = np.array([m["t_s"] for t, _, _, m in messages if t == "/motor/ap"])
    assert np.array_equal(ap, motor_t)
    assert summary.statistics.message_start_time == start + round(motor_t[0] * 1e9)
    assert summary.statistics.message_end_time == start + round(motor_t[-1] * 1e9)
    # written in time order: a reader streams it without sorting
    assert all(a <= b for a, b in zip([m[2] for m in messages], [m[2] for m in messages][1:]))


def test_a_reader_written_from_the_spec_reads_it_and_every_message_fits_its_schema(exported):
    """Not the mcap package: tests/_mcap_spec.py, from the specification; each channel's messages checked
    against its JSON Schema, as Foxglove reads them."""
    jsonschema = pytest.importorskip("jsonschema")
    from tests._mcap_spec import read_spec

    _, (summary, _, metadata), path = exported
    spec = read_spec(path.read_bytes())
    assert spec.library.startswith("endocal ") and spec.chunks >= 1
    by_topic: dict[str, list] = {}
    for cid, _, _, data in spec.messages:
        by_topic.setdefault(spec.channels[cid][1], []).append(data)
    counts = {summary.channels[k].topic: n for k, n in summary.statistics.channel_message_counts.items()}
    assert {t: len(v) for t, v in by_topic.items()} == counts
    assert spec.metadata == metadata
    for cid, (sid, topic, enc) in spec.channels.items():
        name, schema_enc, schema = spec.schemas[sid]
        assert (enc, schema_enc) == ("json", "jsonschema")
        check = jsonschema.Draft7Validator(json.loads(schema))
        for data in by_topic[topic][:: max(1, len(by_topic[topic]) // 40)]:  # 40 of each channel, spread
            check.validate(json.loads(data))


def test_the_model_s_prediction_and_error(exported):
    _, (_, messages, _), _ = exported
    aligned = pd.read_parquet(RUN / "aligned.parquet")
    rows = [m for t, _, _, m in messages if t == "/model/ap"]
    err = np.array([r["error_deg"] for r in rows])
    assert np.allclose(err, [r["pred_deg"] - r["meas_deg"] for r in rows])
    assert np.array_equal([r["meas_deg"] for r in rows], aligned["ap_meas_deg"].to_numpy())
    assert np.array_equal([r["cmd_deg"] for r in rows], aligned["ap_cmd_deg"].to_numpy())
    # the paper's model (another probe) on the simulated TEE: wrong, but a prediction of the bend
    assert 1.0 < np.sqrt(np.mean(err ** 2)) < 60.0


def test_an_interrupted_run_is_exported_as_far_as_readable_and_said_so(tmp_path):
    pytest.importorskip("mcap")
    run = tmp_path / "run"
    shutil.copytree(RUN, run)
    meta = json.loads((run / "run.json").read_text())
    meta["status"] = "interrupted"
    (run / "run.json").write_text(json.dumps(meta))
    (run / "aligned.parquet").unlink()  # a killed run has none: rebuilt from the streams
    motor = pd.read_parquet(run / "motor")
    (run / "motor" / "part-000000.parquet").unlink()
    parts = np.array_split(np.arange(len(motor)), 3)
    for i, idx in enumerate(parts):
        motor.iloc[idx].to_parquet(run / "motor" / f"part-{i:06d}.parquet")
    (run / "motor" / "part-000002.parquet").write_bytes(b"PAR1 cut short")  # the last part, torn
    proc = endocal("export", "mcap", run, "--out", tmp_path / "run.mcap", "--json")
    one_line_exit_2(proc, "did not complete", "interrupted", "part-000002.parquet", "as far as it is readable")
    assert "part-000002.parquet" in json.loads(proc.stdout)["incomplete"]
    summary, messages, metadata = _read(tmp_path / "run.mcap")
    counts = {summary.channels[k].topic: n for k, n in summary.statistics.channel_message_counts.items()}
    readable = len(parts[0]) + len(parts[1])
    assert counts["/motor/ap"] == readable
    assert 0 < counts["/aligned"] <= readable
    assert metadata["endocal.export"]["complete"] == "false"
    assert "part-000002.parquet" in metadata["endocal.export"]["incomplete"]
    assert not list(tmp_path.glob(".*partial"))


def test_bad_input_is_one_line_and_nothing_written(tmp_path, monkeypatch):
    pytest.importorskip("mcap")
    out = tmp_path / "x.mcap"
    one_line_exit_2(endocal("export", "mcap", tmp_path, "--out", out), "run.json")
    model = make_model("pi", ["envelope"], axis="lr").set_parameters(PAPER_TABLE1)
    save_model(model, tmp_path / "lr.json")
    one_line_exit_2(endocal("export", "mcap", RUN, "--out", out, "--model", tmp_path / "lr.json"), "axis 'lr'")
    assert not out.exists() and not list(tmp_path.glob(".*partial"))
    out.write_bytes(b"mine")
    one_line_exit_2(endocal("export", "mcap", RUN, "--out", out), "already exists", "--force")
    assert out.read_bytes() == b"mine"
    monkeypatch.setitem(sys.modules, "mcap", None)  # as if the extra were not installed
    monkeypatch.setitem(sys.modules, "mcap.writer", None)
    one_line_exit_2(endocal("export", "mcap", RUN, "--out", tmp_path / "y.mcap"),
                    "pip install 'endocal-toolkit[mcap]'")
    assert not (tmp_path / "y.mcap").exists()
