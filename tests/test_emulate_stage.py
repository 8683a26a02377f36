"""The UDP translation/rotation stage: the real client (endocal.backends.hardware.UdpStage)
against the emulated stage (endocal/emulate/stage.py) on loopback, datagram for datagram."""

from __future__ import annotations

import time

import pytest

from endocal.backends.hardware import StageConfig, UdpStage
from endocal.emulate.stage import StageEmulator, StageFaults
from endocal.errors import HardwareError


def _client(port: int, **kw) -> UdpStage:
    return UdpStage(StageConfig(mode="udp", host="127.0.0.1", port=port, **kw))


def test_goals_move_the_stage_and_stop_holds_it():
    events = []
    with StageEmulator(time_constant_s=0.02, on_event=events.append) as emu:
        stage = _client(emu.port)
        assert stage.open() == (0.0, 0.0, 0.0, 0.0)
        for _ in range(40):  # 0.4 s of 100 Hz goals towards 5 mm / 10 deg
            reply = stage.command(5.0, 10.0)
            time.sleep(0.01)
        tr, rot, _, _ = reply
        # a 20 ms lag settles in 0.4 s; 20 mm/s and 60 deg/s reach 5 mm and 10 deg well within it
        assert tr == pytest.approx(5.0, abs=0.05) and rot == pytest.approx(10.0, abs=0.1)
        stage.close()
        time.sleep(0.1)
        assert events == ["stage stopped"] and emu.stopped


def test_dropped_replies_within_the_watchdog_hold_the_last_position():
    with StageEmulator(faults=StageFaults(drop_probability=0.3), seed=1) as emu:
        stage = _client(emu.port, timeout_s=0.02, max_missed_replies=10)
        last = stage.open()
        held, received = 0, [last]
        for k in range(1, 61):
            reply = stage.command(0.05 * k, 0.0)  # a goal that keeps moving away: the stage follows it
            if stage.missed:  # no reply to this goal (dropped, or later than timeout_s)
                assert reply == last  # the position reported is the last one received
                held += 1
            else:
                assert reply[0] >= last[0]  # a reply received: where the stage is now, on its way
                last = reply
                received.append(reply)
            time.sleep(0.005)
        stage.close()
    assert emu.dropped > 0 and held >= 1  # replies were lost, and the client rode them out
    assert len({r[0] for r in received}) > 10  # the replies received moved on: a held one was really the last


def test_a_silent_stage_trips_the_watchdog():
    events = []
    with StageEmulator(faults=StageFaults(silent_after_s=0.2), on_event=events.append) as emu:
        stage = _client(emu.port, timeout_s=0.02, max_missed_replies=3)
        stage.open()
        t0 = time.monotonic()
        with pytest.raises(HardwareError, match=r"stopped answering \(4 replies missing in a row\)"):
            while time.monotonic() - t0 < 5.0:
                stage.command(1.0, 0.0)
                time.sleep(0.01)
        stage.close()
        assert "stage silent (fault)" in events


def test_no_stage_on_the_port_is_refused_at_open():
    with StageEmulator() as emu:
        port = emu.port
    with pytest.raises(HardwareError, match=r"no reply from the translation/rotation stage at 127\.0\.0\.1:\d+"):
        _client(port, timeout_s=0.02).open()
