"""Protocol files for several tests in one run (endocal/protocols/catalogue.py `sequence`, protocol.py
`[conditions]`, `[design]`, `Protocol.to_toml`): what `validate --next` writes and `excite` plays."""

from __future__ import annotations

import numpy as np
import pytest

from endocal.errors import ProtocolError
from endocal.probe import PRESETS
from endocal.protocols import load_protocol, read_protocol_file
from endocal.protocols.protocol import list_protocols

TEE = PRESETS["tee"]

SEQUENCE = """
description = "two tests in one run"
signal = "sequence"

[params]
axes = ["ap", "ml"]
rest_s = 1.5

[[params.segments]]
signal = "lissajous"
axes = ["ap", "ml"]
amplitude_deg = 30.0
duration_s = 20.0

[[params.segments]]
signal = "staircase"
axes = ["ap"]
steps = 1
cycles = 2
hold_s = 2.0
step_rate_dps = 30.0

[conditions.sheath_wrap_deg]
instruction = "curve the insertion tube differently"
recorded = [180.0]

[design]
suspects = ["coupling", "creep"]
"""


def _write(tmp_path, text, name="p.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_a_sequence_plays_its_segments_one_after_the_other(tmp_path):
    proto = read_protocol_file(_write(tmp_path, SEQUENCE))
    liss, stairs = proto.params["segments"]
    assert liss["signal"] == "lissajous" and liss["frequencies_hz"] == [0.05, 0.075]  # defaults filled in
    assert "sample_rate_hz" not in liss  # the sequence's clock
    traj = proto.trajectory(TEE)
    traj.check_limits(TEE)
    # the staircase of one step, twice: 0 -> 60 -> 0 -> -60 -> 0, each move 60 deg at a 30 deg/s peak
    # (raised cosine: pi/2 * 60/30 s) with a 2 s hold after it
    move_s = np.pi / 2 * 60.0 / 30.0
    assert proto.duration_s == pytest.approx(20.0 + 1.5 + 8 * (move_s + 2.0), abs=0.011)
    t = traj.t_s
    first = t <= 20.0
    assert np.ptp(traj.goal["ml"][first]) > 50 and np.all(traj.goal["ml"][~first] == 0.0)  # ml moves in the first only
    second = t >= 21.5
    assert traj.goal["ap"][second].max() == pytest.approx(60.0) and traj.goal["ap"][second].min() == pytest.approx(-60.0)
    assert [s.label for s in traj.segments][:1] == ["ap/ml lissajous 30 deg 0.05:0.075 Hz"]


@pytest.mark.parametrize("change, fragment", [
    (("signal = \"staircase\"\naxes = [\"ap\"]", "signal = \"sequence\""), "'signal' must be one of"),
    (("signal = \"staircase\"\naxes = [\"ap\"]", "signal = \"staircase\"\naxes = [\"rotation\"]"),
     "drives 'rotation', which the sequence's 'axes'"),
    (("step_rate_dps = 30.0", "step_rate_dps = 30.0\nsample_rate_hz = 50.0"), "set 'sample_rate_hz' in the sequence"),
    (("steps = 1", "steps = 0"), "segment 2: parameter 'steps' must be an integer >= 1"),
    (("steps = 1", "stepz = 1"), "segment 2: unknown parameter(s) 'stepz'"),
    (('instruction = "curve the insertion tube differently"', 'instruction = ""'), "needs an 'instruction'"),
    (("[conditions.sheath_wrap_deg]", "[conditions.rest_s]"), "not a parameter of the signal"),
    (("recorded = [180.0]", "recorded = 180.0"), "'recorded' must be a list of numbers"),
    (("[design]\nsuspects", "design = 3\n[x]\nsuspects"), "unknown field(s) 'x'"),
])
def test_a_bad_sequence_or_condition_is_refused_naming_where(tmp_path, change, fragment):
    old, new = change
    assert old in SEQUENCE
    with pytest.raises(ProtocolError) as exc:
        read_protocol_file(_write(tmp_path, SEQUENCE.replace(old, new)))
    assert fragment in str(exc.value) and "p.toml" in str(exc.value), str(exc.value)


def test_a_condition_is_asked_for_given_per_run_and_travels_with_the_run(tmp_path):
    proto = read_protocol_file(_write(tmp_path, SEQUENCE))
    with pytest.raises(ProtocolError, match=r"asks for the condition 'sheath_wrap_deg': curve the insertion tube "
                                            r"differently \(earlier records hold 180\); give its value in this run "
                                            r"as --set sheath_wrap_deg=VALUE"):
        proto.check_conditions()
    with pytest.raises(ProtocolError, match="condition 'sheath_wrap_deg' takes a number"):
        proto.with_overrides({"sheath_wrap_deg": "tight"})
    given = proto.with_overrides({"sheath_wrap_deg": 120, "rest_s": 2.0})
    given.check_conditions()
    assert given.condition_values == {"sheath_wrap_deg": 120.0} and given.params["rest_s"] == 2.0
    assert given.trajectory(TEE).conditions == {"sheath_wrap_deg": 120.0}
    again = type(given).from_dict(given.to_dict())  # as run.json records it
    assert again.condition_values == given.condition_values and again.conditions == given.conditions
    assert again.design == {"suspects": ["coupling", "creep"]} and again.params == given.params


def test_to_toml_writes_a_file_that_reads_back_the_same(tmp_path):
    proto = read_protocol_file(_write(tmp_path, SEQUENCE))
    back = read_protocol_file(_write(tmp_path, proto.to_toml("a header\nof two lines"), "q.toml"))
    assert (back.params, back.conditions, back.design, back.description) == (
        proto.params, proto.conditions, proto.design, proto.description)
    assert back.source_path.read_text().startswith("# a header\n# of two lines\n")
    for name, _, _ in list_protocols():  # every shipped protocol too (its [sim] table included)
        shipped = load_protocol(name)
        copy = read_protocol_file(_write(tmp_path, shipped.to_toml(), f"{name}.toml"))
        assert (copy.signal, copy.params, copy.sim) == (shipped.signal, shipped.params, shipped.sim), name


def test_a_staircase_repeats_its_cycles():
    one = load_protocol("staircase", overrides={"steps": 1, "hold_s": 1.0})
    three = one.with_overrides({"cycles": 3})
    assert three.duration_s == pytest.approx(3 * one.duration_s, abs=0.011)
    g = three.trajectory(TEE).goal["ap"]
    reversals = np.flatnonzero(np.diff(np.sign(np.diff(g[np.abs(np.diff(g, prepend=g[0])) > 0]))) != 0)
    assert reversals.size == 6  # +60 and -60, three times
