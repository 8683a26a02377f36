"""The Aurora backend (endocal/backends/aurora.py) through the real scikit-surgerynditracker and
ndicapi against the emulated System Control Unit on a pseudo-terminal (endocal/emulate/aurora.py)."""

from __future__ import annotations

import re
import time

import numpy as np
import pytest

from endocal.backends.aurora import AuroraConfig, AuroraTracker
from endocal.emulate.aurora import AuroraEmulator, AuroraFaults, ndi_crc16, tx_transform
from endocal.errors import HardwareError
from tests._cli import endocal, one_line_exit_2

pytest.importorskip("sksurgerynditracker")


def _frames(tracker: AuroraTracker, tips: int, timeout_s: float = 5.0) -> dict[str, np.ndarray]:
    """The frames a started tracker has read once ``tips`` of them are the tip's (40 Hz: 0.075 s on
    an idle machine; a loaded one may starve the reader thread, which is not what is tested)."""
    parts, deadline = [], time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        time.sleep(0.05)
        parts.append(tracker.drain())
        if sum(int((p["sensor"] == "tip").sum()) for p in parts) >= tips:
            break
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}

TIP = ((12.3456, -4.5, 230.25), (0.9238795, 0.3826834, 0.0, 0.0))  # 45 deg about x
BASE = ((1.0, 2.0, 180.0), (1.0, 0.0, 0.0, 0.0))


def test_crc_matches_the_constants_ndicapi_sends_and_expects():
    # ndicapi hard-codes these: "INIT:E3A5", "OKAYA896", "RESETBE6F", "VER:065EE", "...Version0492"
    assert [f"{ndi_crc16(s):04X}" for s in ("INIT:", "OKAY", "RESET", "VER:0",
                                            "GETINFO:Features.Firmware.Version")] == \
        ["E3A5", "A896", "BE6F", "65EE", "0492"]
    t = tx_transform((12.3456, -4.5, 230.25), (1.0, 0.0, -0.5, 0.0), 0.0012)
    assert len(t) == 51 and t == "+10000+00000-05000+00000+001235-000450+023025+00012"


def _tracker(emu: AuroraEmulator, **kw) -> AuroraTracker:
    return AuroraTracker(AuroraConfig.from_dict({"serial_port": emu.port, "tip_port_handle": 10,
                                                 "base_port_handle": 11, **kw}, "rig.toml"))


@pytest.mark.parametrize("firmware, tol_mm, tol_q", [
    ("AURORA Rev 008", 0.005 + 1e-9, 2e-4),  # TX (ASCII): 0.01 mm and 1e-4 steps
    ("AURORA Rev 009", 1e-4, 1e-6),  # BX (binary float32): 7 significant digits of 230 mm
])
def test_frames_decode_to_the_poses_served(firmware, tol_mm, tol_q):
    with AuroraEmulator(0x0A, 0x0B, firmware=firmware) as emu:
        emu.set_poses({"tip": TIP, "base": BASE})
        tr = _tracker(emu)
        tr.open()
        assert tr.info["port_handles"] == [10, 11]
        tr.start(time.monotonic)
        time.sleep(0.4)
        frames = tr.drain()
        tr.close()
    tip = frames["sensor"] == "tip"
    assert 8 <= tip.sum() <= 20  # 40 Hz for 0.4 s, repeats dropped
    assert frames["valid"].all()
    # positions and quaternion components to the reply format's resolution
    np.testing.assert_allclose(np.column_stack([frames[c][tip] for c in ("x_mm", "y_mm", "z_mm")]),
                               np.tile(TIP[0], (tip.sum(), 1)), atol=tol_mm)
    q = np.column_stack([frames[c][tip] for c in ("qw", "qx", "qy", "qz")])
    np.testing.assert_allclose(np.abs(q), np.tile(np.abs(TIP[1]), (tip.sum(), 1)), atol=tol_q)
    t = frames["t_s"][tip]
    assert np.all(np.diff(t) > 0)  # stamped on arrival, in order


def test_a_sensor_the_tracker_does_not_see_is_refused_at_open():
    with AuroraEmulator(0x0A, 0x0B, faults=AuroraFaults(missing=("base",))) as emu:
        tr = _tracker(emu, detect_timeout_s=0.5)
        with pytest.raises(HardwareError, match=r"base \(port handle 0x0b\) reported no valid pose"):
            tr.open()
        tr.close()


def test_a_port_handle_not_on_the_unit_is_named():
    with AuroraEmulator(0x0A, 0x0C) as emu:
        tr = _tracker(emu)
        with pytest.raises(HardwareError, match=r"no tool on port handle 11 \(0x0b\) for the base sensor.*tools seen: "
                                                r"10 \(0x0a\), 12 \(0x0c\)"):
            tr.open()
        tr.close()


@pytest.mark.parametrize("firmware", ["AURORA Rev 008", "AURORA Rev 009"])  # TX and BX frames
def test_every_session_on_one_unit_finds_the_tools_and_reads_frames(firmware):
    # a real unit serves any number of sessions: each opens with INIT and sets its port handles
    # up again; one that left tracking on (a killed host: no TSTOP) does not block the next
    import ndicapy
    from sksurgerynditracker.nditracker import NDITracker

    with AuroraEmulator(0x0A, 0x0B, firmware=firmware) as emu:
        emu.set_poses({"tip": TIP, "base": BASE})
        for session in range(3):
            tr = _tracker(emu)
            tr.open()
            assert tr.info["port_handles"] == [10, 11], session
            tr.start(time.monotonic)
            frames = _frames(tr, tips=3)
            tr.close()
            assert (frames["sensor"] == "tip").sum() >= 3 and frames["valid"].all(), session
            if session == 1:  # a host that dies while tracking: the port closes without TSTOP
                dead = NDITracker({"tracker type": "aurora", "serial port": emu.port})
                dead.start_tracking()
                ndicapy.ndiClose(dead._device)


@pytest.mark.parametrize("firmware", ["AURORA Rev 008", "AURORA Rev 009"])  # TX and BX frames
def test_port_status_out_of_volume_flags_the_frames_for_its_span_only(firmware):
    # from 0.5 s after TSTART, for 0.5 s: the tip out of the field volume, the base partly out. The
    # unit still sends both poses (10 mm off: endocal/emulate/aurora.py DEGRADED_MM); only the port
    # status, read through ndicapi (ndiGetTXPortStatus / ndiGetBXPortStatus), tells them apart
    faults = AuroraFaults(out_of_volume=("tip",), partly_out_of_volume=("base",), out_of_volume_after_s=0.5,
                          out_of_volume_for_s=0.5)
    with AuroraEmulator(0x0A, 0x0B, firmware=firmware, faults=faults) as emu:
        emu.set_poses({"tip": TIP, "base": BASE})
        tr = _tracker(emu)
        tr.open()  # both sensors seen: the fault starts later
        tr.start(time.monotonic)
        frames = _frames(tr, tips=1000, timeout_s=2.0)  # past the span's end
        tr.close()
    status, sensor = frames["status"], frames["sensor"]
    assert set(status[sensor == "tip"]) == {"ok", "out_of_volume"}
    assert set(status[sensor == "base"]) == {"ok", "partly_out_of_volume"}
    out, partly = status == "out_of_volume", status == "partly_out_of_volume"
    assert (frames["port_status"][out] == 0x71).all() and (frames["port_status"][partly] == 0xB1).all()
    assert (frames["port_status"][status == "ok"] == 0x31).all()
    assert not frames["valid"][out | partly].any() and frames["valid"][status == "ok"].all()
    # the distorted pose, kept (TX carries 0.01 mm steps)
    np.testing.assert_allclose(frames["x_mm"][out], TIP[0][0] + 10.0, atol=0.005 + 1e-9)
    # one span: flagged frames are contiguous in time, valid ones before and after it
    t_tip, out_tip = frames["t_s"][sensor == "tip"], out[sensor == "tip"]
    k = np.flatnonzero(out_tip)
    assert k.size and (np.diff(k) == 1).all() and k[0] > 0 and k[-1] < out_tip.size - 1
    assert np.all(np.diff(t_tip) > 0)


def test_a_unit_that_goes_silent_is_named_as_the_tracker_and_lets_go_within_2_s():
    # the control unit loses power 0.3 s after TSTART: no frame from either sensor, every command
    # unanswered (ndicapi waits 5 s for each reply, so a TX in flight and then TSTOP would hold close 10 s)
    with AuroraEmulator(0x0A, 0x0B, faults=AuroraFaults(silent_after_s=0.3)) as emu:
        emu.set_poses({"tip": TIP, "base": BASE})
        tr = _tracker(emu, max_lost_s=0.5)
        tr.open()
        tr.start(time.monotonic)
        deadline, error = time.monotonic() + 10.0, None
        while error is None and time.monotonic() < deadline:
            time.sleep(0.02)
            try:
                tr.check()
            except HardwareError as exc:
                error = str(exc)
        frames = tr.drain()
        began = time.monotonic()
        tr.close()  # never raises for the device
        closed_in = time.monotonic() - began
    # (how long past max_lost_s the loop here noticed it is the machine's load, not asserted)
    assert error is not None and re.match(
        r"NDI Aurora: the tracker stopped answering: no frame from either sensor for [\d.]+ s \(tracker.max_lost_s = "
        r"0.5; a frame request has waited [\d.]+ s for its reply; serial port /dev/pts/\d+\): ", error), error
    assert error.endswith("check the System Control Unit's power (is it switched on, its lights lit?) and the USB or "
                          "serial cable between it and this computer")
    # what came before the silence was read, both sensors, valid (40 Hz for 0.3 s, from TSTART at open)
    assert set(frames["sensor"]) == {"tip", "base"} and frames["valid"].all() and len(frames["t_s"]) >= 2
    assert closed_in < 2.0 and tr.close_notes == [
        f"NDI Aurora: no answer within 1 s of closing (stopping tracking, then the port {emu.port}): left to the "
        "driver's timeouts in the background"]


@pytest.mark.parametrize("args, fragment", [
    (["aurora", "--silent-after", "-1"], "--silent-after -1: give 0 s (never answers) or more"),
    (["rig", "--config-out", "unused.toml", "--tracker-silent-after", "-0.5"], "--tracker-silent-after -0.5: give 0 s"),
    (["aurora", "--out-of-volume", "elbow"], "--out-of-volume 'elbow': name a sensor, tip or base"),
    (["rig", "--config-out", "unused.toml", "--partly-out-of-volume", "shaft"], "--partly-out-of-volume 'shaft'"),
    (["aurora", "--out-of-volume", "tip", "--out-of-volume-for", "0"], "--out-of-volume-for more than 0 s"),
])
def test_the_out_of_volume_fault_options_name_a_sensor_and_a_span(args, fragment):
    one_line_exit_2(endocal("emulate", *args), fragment)
