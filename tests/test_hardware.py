"""The hardware backend (endocal/backends/hardware.py, dynamixel.py, aurora.py) without hardware.

Its safety promises are tested on the wire: the backend drives the emulated XM430 bus
(endocal/emulate/servos.py) through the real dynamixel-sdk on a pseudo-terminal, and the
emulator's log of every write that reached a servo proves what was sent and what never was
(here in-process, ``emulated_backend``; as a user runs it, ``endocal excite`` in a child
process, in tests/test_hardware_wire.py). The tracker is a fake here (the Aurora's own tests,
through ndicapi against its emulator, are tests/test_emulate_aurora.py).

``FakeBus``, a Python double of the SDK's port and packet handlers, is kept only where no
emulator can reach:

- register decoding (``test_read_state_decodes_signed_registers_through_sync_read``): the test
  sets present current, velocity and position to chosen signed values; the emulated servo
  computes them from its own physics and cannot be made to report chosen ones;
- an interrupt inside a bus transaction
  (``test_torque_off_after_keyboard_interrupt_inside_a_bus_transaction``): ``KeyboardInterrupt``
  raised at a chosen point inside the SDK's transaction, leaving its port marked busy; a real
  Ctrl-C lands wherever the process happens to be, so only a double can place it there;
- exactly one reply lost at a chosen sync read
  (``test_one_lost_reply_is_retried_within_the_tick_and_counted``); the emulator loses replies
  at random (its own test counts recoveries statistically, tests/test_emulate_dynamixel.py);
- the chunk's columns against the goals to half a tick
  (``test_chunk_columns_match_the_run_format``): an ideal servo that reaches each goal at once;
  the emulated one lags like a real servo.
"""

from __future__ import annotations

import json
import math
import os
import signal
import socket
import subprocess
import sys
import textwrap
import threading
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

from endocal.backends import aurora as aur
from endocal.backends import dynamixel as dxl
from endocal.backends.base import Backend, motor_columns
from endocal.backends.hardware import HardwareBackend, HardwareConfig, check_goals
from endocal.emulate.servos import BusFaults, ServoBus
from endocal.errors import ConfigError, HardwareError, LimitError, ProtocolError, StopSignal
from endocal.probe import PRESETS
from tests._wire import goal_syncs

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "configs" / "hardware-example.toml"
TEE = PRESETS["tee"]

COMM_SUCCESS, COMM_PORT_BUSY, COMM_RX_TIMEOUT = 0, -1000, -3001
ERR_DATA_LIMIT, ERR_ACCESS = 5, 7
HALF_TICK_DEG = 0.5 * 360.0 / 4096  # rounding of a knob goal to the nearest tick


# --- a Python double of an XM430-W350 bus (only where no emulator reaches: see the docstring) ---
class FakeServo:
    def __init__(self, model=1020, present_ticks=2048, firmware=45):
        self.mem = bytearray(700)
        self.put(0, 2, model)
        self.put(6, 1, firmware)
        self.put(11, 1, 3)
        self.put(48, 4, 4095)
        self.put(52, 4, 0)
        self.put(116, 4, present_ticks)
        self.put(132, 4, present_ticks)

    def put(self, addr, n, value):
        value &= (1 << (8 * n)) - 1
        self.mem[addr:addr + n] = value.to_bytes(n, "little")

    def get(self, addr, n):
        return int.from_bytes(self.mem[addr:addr + n], "little")

    @property
    def torque(self):
        return self.mem[64]


class FakeBus:
    """Plays both the dynamixel_sdk PortHandler and the Protocol 2.0 PacketHandler."""

    def __init__(self, servos: dict[int, FakeServo], port_name="/dev/ttyFAKE"):
        self.servos = servos
        self.port_name = port_name
        self.is_using = False
        self.is_open = False
        self.baudrate = None
        self.log: list[tuple] = []
        self.goal_writes = 0
        self.interrupt_sync_read_at: int | None = None  # raise KeyboardInterrupt mid-transaction
        self.fail_sync_read_at: int | None = None  # answer with a timeout from this read on
        self.lose_sync_read_at: int | None = None  # lose this one reply only
        self.sync_reads = 0
        self.pending: list[int] = []

    # PortHandler
    def openPort(self):
        self.is_open = True
        return True

    def setBaudRate(self, baud):
        self.baudrate = baud
        return True

    def closePort(self):
        self.is_open = False

    def clearPort(self):
        self.pending = []

    def getPortName(self):
        return self.port_name

    # PacketHandler
    def getProtocolVersion(self):
        return 2.0

    def getTxRxResult(self, result):
        return {COMM_RX_TIMEOUT: "[TxRxResult] There is no status packet!",
                COMM_PORT_BUSY: "[TxRxResult] Port is in use!"}.get(result, f"result {result}")

    def getRxPacketError(self, error):
        return f"[RxPacketError] error {error}"

    def _busy(self):
        return self.is_using

    def ping(self, port, dxl_id):
        if self._busy():
            return 0, COMM_PORT_BUSY, 0
        if dxl_id not in self.servos:
            return 0, COMM_RX_TIMEOUT, 0
        return self.servos[dxl_id].get(0, 2), COMM_SUCCESS, 0

    def _read(self, dxl_id, addr, n):
        if self._busy():
            return 0, COMM_PORT_BUSY, 0
        if dxl_id not in self.servos:
            return 0, COMM_RX_TIMEOUT, 0
        return self.servos[dxl_id].get(addr, n), COMM_SUCCESS, 0

    def read1ByteTxRx(self, port, dxl_id, addr):
        return self._read(dxl_id, addr, 1)

    def read2ByteTxRx(self, port, dxl_id, addr):
        return self._read(dxl_id, addr, 2)

    def read4ByteTxRx(self, port, dxl_id, addr):
        return self._read(dxl_id, addr, 4)

    def _write(self, dxl_id, addr, n, value):
        if self._busy():
            return COMM_PORT_BUSY, 0
        if dxl_id not in self.servos:
            return COMM_RX_TIMEOUT, 0
        servo = self.servos[dxl_id]
        if addr < 64 and servo.torque:  # EEPROM area is locked while torque is on
            return COMM_SUCCESS, ERR_ACCESS
        if addr == 116:
            error = self._goal(servo, value)
            if error:
                return COMM_SUCCESS, error
        servo.put(addr, n, value)
        self.log.append(("write", dxl_id, addr, dxl.to_signed(value, n)))
        return COMM_SUCCESS, 0

    def _goal(self, servo, raw):
        ticks = dxl.to_signed(raw, 4)
        if servo.get(11, 1) == 3 and not servo.get(52, 4) <= ticks <= servo.get(48, 4):
            return ERR_DATA_LIMIT
        if servo.torque:  # an ideal, instantaneous position loop
            old = dxl.to_signed(servo.get(132, 4), 4)
            servo.put(132, 4, ticks)
            servo.put(128, 4, 1 if ticks > old else (-1 if ticks < old else 0))
        return 0

    def write1ByteTxRx(self, port, dxl_id, addr, value):
        return self._write(dxl_id, addr, 1, value)

    def write4ByteTxRx(self, port, dxl_id, addr, value):
        return self._write(dxl_id, addr, 4, value)

    def syncWriteTxOnly(self, port, start, length, param, param_length):
        if self._busy():
            return COMM_PORT_BUSY
        assert start == 116 and length == 4 and param_length == len(param)
        self.goal_writes += 1
        for k in range(0, len(param), 1 + length):
            dxl_id = param[k]
            raw = int.from_bytes(bytes(param[k + 1:k + 1 + length]), "little")
            servo = self.servos[dxl_id]
            assert self._goal(servo, raw) == 0, "a goal outside the Position Limit registers reached the bus"
            servo.put(116, 4, raw)
            self.log.append(("sync_goal", dxl_id, 116, dxl.to_signed(raw, 4)))
        return COMM_SUCCESS

    def syncReadTx(self, port, start, length, param, param_length, fast):
        if self._busy():
            return COMM_PORT_BUSY
        self.sync_reads += 1
        if self.interrupt_sync_read_at == self.sync_reads:
            self.is_using = True  # what the SDK leaves behind when interrupted inside txRxPacket
            raise KeyboardInterrupt
        if self.fail_sync_read_at is not None and self.sync_reads >= self.fail_sync_read_at:
            return COMM_RX_TIMEOUT  # from then on
        if self.lose_sync_read_at == self.sync_reads:
            return COMM_RX_TIMEOUT  # once: a reply lost on the bus
        self._sync = (start, length)
        return COMM_SUCCESS

    def readRx(self, port, dxl_id, length):
        start, n = self._sync
        return list(self.servos[dxl_id].mem[start:start + n]), COMM_SUCCESS, 0

    def fastSyncReadRx(self, port, dxl_id, length):
        # one status packet for all servos: per servo [error, id, data..., crc_l, crc_h]
        start, n = self._sync
        raw = []
        for servo_id, servo in self.servos.items():
            raw += [0, servo_id, *servo.mem[start:start + n], 0, 0]
        assert len(raw) == length
        return raw, COMM_SUCCESS, 0

    # test helpers
    def torques(self):
        return {i: s.torque for i, s in self.servos.items()}

    def writes_of(self, kind):
        return [entry for entry in self.log if entry[0] == kind]


# --- a fake NDI tracker -------------------------------------------------------------------
def rot_x(angle_rad):
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def transform(r, p):
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = r, p
    return m


class FakeTracker:
    def __init__(self, settings, handles=(0x0A, 0x0B), nan_base_every=0):
        self.settings = settings
        self.handles = list(handles)
        self.frame_number = 0
        self.nan_base_every = nan_base_every
        self.started = self.stopped = self.closed = 0

    def get_tool_descriptions(self):
        return self.handles, [str(k) for k in range(len(self.handles))]

    def start_tracking(self):
        self.started += 1

    def stop_tracking(self):
        self.stopped += 1

    def close(self):
        self.closed += 1

    def get_frame(self):
        self.frame_number += 1
        tip = transform(rot_x(0.3), [1.0, 2.0, 60.0])
        base = transform(np.eye(3), [0.0, 0.0, 0.0])
        if self.nan_base_every and self.frame_number % self.nan_base_every == 0:
            base = np.full((4, 4), np.nan)
        mats = {0x0A: tip, 0x0B: base}
        tracking = [mats.get(h, np.full((4, 4), np.nan)) for h in self.handles]
        n = len(self.handles)
        return self.handles, [0.0] * n, [self.frame_number] * n, tracking, [0.1] * n


class PortStatusFakeTracker(FakeTracker):
    """Frames with a sixth element, port handle -> port status, as ``PortStatusTracker`` returns them:
    the tip out of the field volume (bit 6) from frame ``out_from`` on, its pose still reported."""

    def __init__(self, settings, out_from=3, bits=0x40):
        super().__init__(settings)
        self.out_from, self.bits = out_from, bits

    def get_frame(self):
        frame = super().get_frame()
        out = self.frame_number >= self.out_from
        return (*frame, {0x0A: 0x31 | (self.bits if out else 0), 0x0B: 0x31})


# --- fixtures -----------------------------------------------------------------------------
def rig_toml(tmp_path, stage="", safety="", extra_motor="", rate_hz=200.0, port="/dev/ttyFAKE"):
    text = f"""
name = "test-rig"
[dynamixel]
port = "{port}"
baudrate = 1000000
latency_timer_ms = 500.0
[dynamixel.motors.ap]
id = 1
zero_ticks = 2048
direction = 1
limits_deg = [-60.0, 80.0]
max_speed_dps = 100.0
{extra_motor}
[dynamixel.motors.ml]
id = 2
zero_ticks = 2048
direction = -1
limits_deg = [-70.0, 70.0]
[tracker]
tip_port_handle = 0x0A
base_port_handle = 0x0B
rate_hz = {rate_hz}
detect_timeout_s = 0.5
{stage}
{safety}
"""
    path = tmp_path / "rig.toml"
    path.write_text(text)
    return path


def make_backend(tmp_path, *, servos=None, tracker_kwargs=None, **toml_kwargs):
    config = HardwareConfig.from_toml(rig_toml(tmp_path, **toml_kwargs))
    bus = FakeBus(servos if servos is not None else {1: FakeServo(), 2: FakeServo()})
    trackers = []

    def factory(settings):
        trackers.append(FakeTracker(settings, **(tracker_kwargs or {})))
        return trackers[-1]

    backend = HardwareBackend(config, TEE, port_handler=bus, packet_handler=bus, tracker_factory=factory)
    return backend, bus, trackers


@contextmanager
def emulated_backend(tmp_path, *, ids=(1, 2), bus_kwargs=None, tracker_kwargs=None, tracker=FakeTracker,
                     **toml_kwargs):
    """``(backend, bus, trackers)``: a backend on the emulated servo bus (real dynamixel-sdk, a
    pseudo-terminal at 1 Mbd) and a fake tracker; closed, and the bus stopped, on the way out.
    ``bus.writes()`` is every write the servos received."""
    with ServoBus(list(ids), baudrate=1_000_000, **(bus_kwargs or {})) as bus:
        config = HardwareConfig.from_toml(rig_toml(tmp_path, port=bus.port, **toml_kwargs))
        trackers = []

        def factory(settings):
            trackers.append(tracker(settings, **(tracker_kwargs or {})))
            return trackers[-1]

        backend = HardwareBackend(config, TEE, tracker_factory=factory)
        try:
            yield backend, bus, trackers
        finally:
            backend.close()


def torque_switched_on(bus) -> bool:
    return any(w.value == 1 and w.error == 0 for w in bus.writes(64))


def only_torque_off(bus) -> bool:
    """Nothing reached the servos but Torque Enable = 0 (closing switches it off whatever happened)."""
    return all(w.address == 64 and w.value == 0 for w in bus.writes())


def sine_chunk(t0=0.0, n=20, rate_hz=100.0, amp_deg=5.0, f_hz=1.0):
    t = t0 + np.arange(1, n + 1) / rate_hz
    g = {"ap": amp_deg * np.sin(2 * np.pi * f_hz * t), "ml": -0.5 * amp_deg * np.sin(2 * np.pi * f_hz * t),
         "translation": np.zeros(n), "rotation": np.zeros(n)}
    return t, g


# --- unit conversions ---------------------------------------------------------------------
def test_ticks_deg_conversions_against_hand_values():
    # 4096 ticks per turn: a quarter turn is 1024 ticks = 90 deg.
    assert dxl.ticks_to_knob_deg(3072, 2048, 1) == pytest.approx(90.0, abs=1e-12)
    assert dxl.ticks_to_knob_deg(3072, 2048, -1) == pytest.approx(-90.0, abs=1e-12)
    assert dxl.ticks_to_knob_deg(2048 + 2048, 2048, 1, gear_ratio=2.0) == pytest.approx(90.0, abs=1e-12)
    assert int(dxl.knob_deg_to_ticks(45.0, 2048, -1)) == 2048 - 512
    assert int(dxl.knob_deg_to_ticks(1.0, 0, 1)) == 11  # 1 deg = 11.378 ticks, rounds to 11
    # round trip error is at most half a tick
    deg = np.linspace(-90, 90, 1001)
    back = dxl.ticks_to_knob_deg(dxl.knob_deg_to_ticks(deg, 2000, -1), 2000, -1)
    assert np.max(np.abs(back - deg)) <= HALF_TICK_DEG + 1e-12


def test_velocity_and_current_units():
    # 0.229 rev/min = 0.229 * 360 / 60 = 1.374 deg/s per unit; 2.69 mA per unit.
    assert dxl.velocity_units_to_knob_dps(100) == pytest.approx(137.4, abs=1e-9)
    assert dxl.velocity_units_to_knob_dps(100, direction=-1, gear_ratio=2.0) == pytest.approx(-68.7, abs=1e-9)
    assert dxl.current_units_to_ma(-372) == pytest.approx(-1000.68, abs=1e-9)
    assert dxl.current_units_to_ma(10, direction=-1) == pytest.approx(-26.9, abs=1e-12)
    assert dxl.to_signed(0xFFFF, 2) == -1
    assert dxl.to_signed(2**32 - 100, 4) == -100
    assert dxl.to_signed(4095, 4) == 4095


@pytest.mark.parametrize("fast", [False, True])
def test_read_state_decodes_signed_registers_through_sync_read(tmp_path, fast):
    path = rig_toml(tmp_path)
    path.write_text(path.read_text().replace("baudrate = 1000000", f"baudrate = 1000000\nfast_sync_read = {str(fast).lower()}"))
    config = HardwareConfig.from_toml(path).dynamixel
    assert config.fast_sync_read is fast
    servos = {1: FakeServo(), 2: FakeServo()}
    bus = FakeBus(servos)
    knobs = dxl.KnobServos(config, port_handler=bus, packet_handler=bus)
    knobs.open()
    servos[1].put(132, 4, 2048 + 1024)  # +90 deg
    servos[1].put(128, 4, -10)  # -13.74 deg/s
    servos[1].put(126, 2, 100)  # 269 mA
    servos[2].put(132, 4, 2048 - 512)  # motor -45 deg, direction -1 -> knob +45 deg
    servos[2].put(128, 4, 7)
    servos[2].put(126, 2, -50)
    state = knobs.read_state()
    assert state.pos_deg == {"ap": pytest.approx(90.0), "ml": pytest.approx(45.0)}
    assert state.vel_dps == {"ap": pytest.approx(-13.74), "ml": pytest.approx(-7 * 1.374)}
    assert state.current_ma == {"ap": pytest.approx(269.0), "ml": pytest.approx(134.5)}
    knobs.close()


def test_limit_registers_hold_the_tighter_limits_in_ticks(tmp_path):
    with emulated_backend(tmp_path) as (backend, bus, _):
        with backend:
            pass
    # ap: limits (-60, 80) deg, +1: 2048 - 60*4096/360 = 1365.33 -> 1365; 2048 + 80*11.378 = 2958.2 -> 2958
    assert bus.servos[1].get(52) == 1365 and bus.servos[1].get(48) == 2958  # in the servo's EEPROM
    # ml: limits (-70, 70), direction -1: 2048 -+ 796.4 -> 1252 .. 2844
    assert bus.servos[2].get(52) == 1252 and bus.servos[2].get(48) == 2844
    assert all(w.error == 0 for w in bus.writes())  # every write was accepted: EEPROM written with torque off
    assert backend.limits["ap"] == (-60.0, 80.0)
    assert backend.max_speed["ap"] == 100.0 and backend.max_speed["ml"] == TEE.max_knob_speed_dps


def test_extended_position_mode_sets_the_mode_and_leaves_limit_registers_alone(tmp_path):
    with emulated_backend(tmp_path) as (backend, bus, _):
        path = Path(backend.config.source)
        path.write_text(path.read_text().replace("baudrate = 1000000", 'baudrate = 1000000\noperating_mode = "extended_position"'))
        backend = HardwareBackend(HardwareConfig.from_toml(path), TEE, tracker_factory=lambda s: FakeTracker(s))
        with backend:
            backend.execute(*sine_chunk())
    assert all(s.get(11) == 4 for s in bus.servos.values())  # Operating Mode 4 = extended position
    assert not bus.writes(48) and not bus.writes(52)  # the servo ignores them in this mode
    assert "position_limit_ticks" not in backend.describe()["dynamixel"]["servos"]["ap"]


# --- safety: limits refused before any write ----------------------------------------------
def test_limit_violation_refused_before_any_goal_is_written(tmp_path):
    with emulated_backend(tmp_path) as (backend, bus, _), backend:
        t, g = sine_chunk()
        g["ap"][-1] = -60.5  # last tick beyond the rig limit -60 deg (the probe allows -90)
        with pytest.raises(LimitError, match=r"'ap' at t = 0\.200 s is -60\.500 deg, beyond its limit -60\.000"):
            backend.execute(t, g)
        assert goal_syncs(bus) == []
        # a jump faster than 100 deg/s on ap is refused too, with the speed and limit named
        g = {k: np.zeros(t.size) for k in TEE.dofs}
        g["ap"][5:] = 2.0  # 2 deg in 10 ms = 200 deg/s
        with pytest.raises(LimitError, match=r"'ap' at t = 0\.060 s moves at 200\.0 deg/s.*limit 100 deg/s"):
            backend.execute(t, g)
        assert goal_syncs(bus) == []
        # NaN and the absent stage are refused the same way
        g = {k: np.zeros(t.size) for k in TEE.dofs}
        g["ml"][3] = np.nan
        with pytest.raises(ProtocolError, match="'ml'.*not a number"):
            backend.execute(t, g)
        g = {k: np.zeros(t.size) for k in TEE.dofs}
        g["translation"][-1] = 0.5
        with pytest.raises(ProtocolError, match="moves 'translation'.*no translation/rotation stage"):
            backend.execute(t, g)
        assert goal_syncs(bus) == []
        # a good chunk, then a second chunk whose step into it is too fast: refused whole
        t1, g1 = sine_chunk(amp_deg=5.0)
        backend.execute(t1, g1)
        written = len(goal_syncs(bus))
        assert written == 2 * t1.size  # one goal per servo and tick
        t2, g2 = sine_chunk(t0=t1[-1])
        g2["ap"][:] = g1["ap"][-1] + 3.0  # +3 deg within one 10 ms tick: 300 deg/s
        with pytest.raises(LimitError, match="'ap'.*faster than the limit"):
            backend.execute(t2, g2)
        assert len(goal_syncs(bus)) == written


def test_check_goals_argues_speed_from_time_steps():
    t = np.array([0.0, 0.5, 1.0])
    limits, units = {"ap": (-90.0, 90.0)}, {"ap": "deg"}
    check_goals(t, {"ap": np.array([0.0, 50.0, 90.0])}, limits, {"ap": 100.0}, units)  # 100 and 80 deg/s
    with pytest.raises(LimitError, match="moves at 110.0 deg/s"):
        check_goals(t, {"ap": np.array([0.0, 50.0, 105.0])}, {"ap": (-90, 200)}, {"ap": 100.0}, units)
    with pytest.raises(ProtocolError, match="increase strictly"):
        check_goals(np.array([0.0, 0.0]), {"ap": np.zeros(2)}, limits, {"ap": 100.0}, units)
    with pytest.raises(LimitError, match="at t = 0.000 s moves at 40.0 deg/s"):
        check_goals(np.array([0.0]), {"ap": np.array([4.0])}, limits, {"ap": 10.0}, units, previous=(-0.1, {"ap": 0.0}))


def test_start_far_from_present_position_is_refused_unless_homed(tmp_path):
    far = {"bus_kwargs": {"present_ticks": {1: 2048 + 114}}}  # ap rests at +10.0 deg
    with emulated_backend(tmp_path, **far) as (backend, bus, _), backend:
        t, g = sine_chunk()
        with pytest.raises(LimitError, match=r"'ap' is at 10\.02 deg but the first goal.*start tolerance 2 deg"):
            backend.execute(t, g)
        assert goal_syncs(bus) == []
        # torque on held each knob where it was: the only goals written are the present positions
        assert {(w.id, w.value) for w in bus.writes(116)} == {(1, 2048 + 114), (2, 2048)}
    with emulated_backend(tmp_path, **far, safety="[safety]\nhome_on_open = true\nhome_speed_dps = 400.0\n") as (
            backend, bus, _):
        with pytest.raises(LimitError, match="faster than the limit"):  # homing itself respects the 100 deg/s limit
            backend.open()
        assert bus.torque() == {1: False, 2: False} and goal_syncs(bus) == []
    with emulated_backend(tmp_path, **far, safety="[safety]\nhome_on_open = true\nhome_speed_dps = 100.0\n") as (
            backend, bus, _):
        with backend:
            backend.servos.read_state()  # a round trip: the servos have seen every sync write before it
            ramp = [w.value for w in goal_syncs(bus) if w.id == 1]
            assert ramp[-1] == 2048 and bus.servos[1].get(116) == 2048  # the goal is 0 deg
            steps_deg = np.abs(np.diff([2048 + 114, *ramp])) * 360 / 4096
            assert steps_deg.max() <= 100.0 / 50.0 + 2 * HALF_TICK_DEG  # 100 deg/s at 50 Hz, plus rounding
            chunk = backend.execute(*sine_chunk())
    assert len(chunk.motor["t_s"]) == 20


# --- safety: torque off on every exit path ------------------------------------------------
def test_torque_off_after_normal_close_and_close_is_idempotent(tmp_path):
    with emulated_backend(tmp_path) as (backend, bus, trackers):
        backend.open()
        assert bus.torque() == {1: True, 2: True}
        backend.execute(*sine_chunk())
        backend.close()
        assert bus.torque() == {1: False, 2: False}
        assert trackers[0].stopped == 1 and trackers[0].closed == 1
        n_writes = len(bus.writes())
        backend.close()
        assert len(bus.writes()) == n_writes and trackers[0].closed == 1


def test_torque_off_after_exception_in_execute(tmp_path):
    overload = {"bus_kwargs": {"faults": BusFaults(hardware_error={2: "overload"}, hardware_error_after_s=0.3)}}
    with emulated_backend(tmp_path, **overload) as (backend, bus, _):
        with pytest.raises(HardwareError, match=r"ID 2 \(knob 'ml'\).*hardware alert.*overload"):
            with backend:
                backend.execute(*sine_chunk(n=300))  # 3 s: the servo overloads 0.3 s after the first packet
        assert bus.torque() == {1: False, 2: False}
        last = {w.id: w for w in bus.writes(64)}  # the last Torque Enable write to each servo: off
        assert last[1].value == 0 and last[1].error == 0


def test_one_lost_reply_is_retried_within_the_tick_and_counted(tmp_path):
    backend, bus, _ = make_backend(tmp_path)
    bus.lose_sync_read_at = 5
    with backend:
        chunk = backend.execute(*sine_chunk())
        info = backend.describe()
    assert len(chunk.motor["t_s"]) == len(sine_chunk()[0])
    assert info["dynamixel"]["recovered_reads"] == 1


def test_torque_off_after_keyboard_interrupt_inside_a_bus_transaction(tmp_path):
    backend, bus, _ = make_backend(tmp_path)
    bus.interrupt_sync_read_at = 7
    with pytest.raises(KeyboardInterrupt):
        with backend:
            backend.execute(*sine_chunk())
    # the interrupted transaction left the port busy; close cleared it and still switched torque off
    assert bus.torques() == {1: 0, 2: 0} and not bus.is_open


def test_sigterm_turns_torque_off_and_restores_the_handler(tmp_path):
    before = signal.getsignal(signal.SIGTERM)
    with emulated_backend(tmp_path) as (backend, bus, _):
        backend.open()
        assert signal.getsignal(signal.SIGTERM) == backend._on_signal
        with pytest.raises(StopSignal) as info:
            os.kill(os.getpid(), signal.SIGTERM)
            backend.execute(*sine_chunk())  # the handler runs at the latest here
        assert info.value.code == 128 + signal.SIGTERM and info.value.signame == "SIGTERM"
        assert bus.torque() == {1: False, 2: False}
        assert signal.getsignal(signal.SIGTERM) == before


def test_atexit_turns_torque_off_when_the_caller_never_closes(tmp_path):
    # a Python caller that opens the rig and exits without close(): the child process runs the
    # real SDK against the emulated bus here, and says when it is about to exit
    script = textwrap.dedent(f"""
        import sys
        sys.path.insert(0, {str(ROOT)!r})
        import tests.test_hardware as th
        from endocal.backends.hardware import HardwareBackend, HardwareConfig
        backend = HardwareBackend(HardwareConfig.from_toml(sys.argv[1]), th.TEE, tracker_factory=th.FakeTracker)
        backend.open()
        backend.execute(*th.sine_chunk(n=5))
        print("open", flush=True)
        sys.stdin.readline()
        sys.exit(0)
    """)
    with ServoBus([1, 2], baudrate=1_000_000) as bus:
        config = rig_toml(tmp_path, port=bus.port)
        proc = subprocess.Popen([sys.executable, "-c", script, str(config)], stdin=subprocess.PIPE,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            assert proc.stdout.readline().strip() == "open", proc.stderr.read()
            during = bus.torque()
            _, errors = proc.communicate("exit\n", timeout=120)
        finally:
            proc.kill()
        assert proc.returncode == 0, errors
        assert during == {1: True, 2: True} and bus.torque() == {1: False, 2: False}


# --- opening checks -----------------------------------------------------------------------
def test_open_refuses_a_missing_servo_with_port_and_id(tmp_path):
    with emulated_backend(tmp_path, ids=(1,)) as (backend, bus, trackers):
        with pytest.raises(HardwareError, match=rf"ID 2 \(knob 'ml'\) on {bus.port} at 1000000 baud did not answer"):
            backend.open()
        assert only_torque_off(bus) and trackers == []  # nothing else written, the tracker never opened


def test_open_refuses_the_wrong_model(tmp_path):
    with emulated_backend(tmp_path, bus_kwargs={"model_number": 1060}) as (backend, bus, _):
        with pytest.raises(HardwareError, match=r"model number 1060 \(XL430-W250\), expected 1020 \(XM430-W350\)"):
            backend.open()
        assert only_torque_off(bus)


def test_open_refuses_a_missing_tracker_tool_before_torque_on(tmp_path):
    with emulated_backend(tmp_path, tracker_kwargs={"handles": (0x0A, 0x0C)}) as (backend, bus, trackers):
        with pytest.raises(HardwareError, match=r"no tool on port handle 11 \(0x0b\) for the base sensor.*12 \(0x0c\)"):
            backend.open()
        assert bus.torque() == {1: False, 2: False} and not torque_switched_on(bus) and goal_syncs(bus) == []
        assert trackers[0].closed == 1


def test_open_refuses_a_knob_resting_outside_its_limits(tmp_path):
    outside = {"bus_kwargs": {"present_ticks": {1: 2048 - 700}}}  # ap at -61.5 deg < -60
    with emulated_backend(tmp_path, **outside) as (backend, bus, _):
        with pytest.raises(HardwareError, match=r"knob 'ap' rests at -61\.5 deg, outside its limits -60\.\.80"):
            backend.open()
        assert not torque_switched_on(bus) and not bus.writes(116)


def test_missing_aurora_package_is_a_hardware_error_with_the_install_command(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "sksurgerynditracker", None)
    monkeypatch.setitem(sys.modules, "sksurgerynditracker.nditracker", None)
    with pytest.raises(HardwareError, match=r"pip install 'endocal-toolkit\[aurora\]'"):
        aur.default_tracker_factory({"tracker type": "aurora"})
    with ServoBus([1, 2], baudrate=1_000_000) as bus:
        backend = HardwareBackend(HardwareConfig.from_toml(rig_toml(tmp_path, port=bus.port)), TEE)
        with pytest.raises(HardwareError, match="scikit-surgerynditracker, which is not installed"):
            backend.open()
        assert bus.torque() == {1: False, 2: False} and not torque_switched_on(bus)


# --- tracker ------------------------------------------------------------------------------
def quat_from_axis_angle(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    return np.concatenate(([math.cos(angle / 2)], math.sin(angle / 2) * axis))


def test_matrix_to_quaternion_hand_values_and_every_branch():
    s = math.sqrt(0.5)
    rz90 = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1]], float)
    cases = [
        (np.eye(3), [1, 0, 0, 0]),
        (rz90, [s, 0, 0, s]),
        (np.diag([1.0, -1.0, -1.0]), [0, 1, 0, 0]),  # 180 deg about x: Shepperd's x branch
        (np.diag([-1.0, 1.0, -1.0]), [0, 0, 1, 0]),
        (np.diag([-1.0, -1.0, 1.0]), [0, 0, 0, 1]),
    ]
    mats = np.stack([transform(r, [1.0, -2.0, 3.5]) for r, _ in cases])
    pos, q = aur.matrix_to_pose(mats)
    np.testing.assert_allclose(q, [c for _, c in cases], atol=1e-15)
    np.testing.assert_allclose(pos, np.tile([1.0, -2.0, 3.5], (len(cases), 1)), atol=0)


def test_matrix_to_quaternion_random_rotations_round_trip():
    rng = np.random.default_rng(7)
    for _ in range(200):
        axis, angle = rng.normal(size=3), rng.uniform(-math.pi, math.pi)
        q_true = quat_from_axis_angle(axis, angle)
        q_true = q_true if q_true[0] >= 0 else -q_true
        w, x, y, z = q_true
        r = np.array([  # rotation matrix of a unit quaternion
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ])
        _, q = aur.matrix_to_pose(transform(r, [0, 0, 0]))
        # float64 round-off through 3x3 products and one sqrt: a few ulp
        np.testing.assert_allclose(q[0], q_true, atol=1e-12)
        assert q[0][0] >= 0
    pos, q = aur.matrix_to_pose(np.full((4, 4), np.nan))
    assert np.isnan(pos).all() and np.isnan(q).all()


def test_tracker_frames_rows_with_missing_and_nan_tools():
    frame = FakeTracker({}, nan_base_every=1).get_frame()
    rows, numbers = aur._frame_rows(frame, {"tip": 0x0A, "base": 0x0B}, 1.25)
    assert [r[1] for r in rows] == ["tip", "base"]
    tip, base = rows
    assert len(tip) == len(aur.HARDWARE_TRACKER_COLUMNS)
    assert tip[0] == 1.25 and tip[9] is True and tip[2:5] == (1.0, 2.0, 60.0)
    assert tip[10:] == ("ok", aur.PORT_STATUS_UNKNOWN)  # a tracker object that reports no port status
    np.testing.assert_allclose(tip[5:9], [math.cos(0.15), math.sin(0.15), 0, 0], atol=1e-15)
    assert base[9] is False and base[10] == "missing" and all(math.isnan(v) for v in base[2:9])
    rows, numbers = aur._frame_rows(frame, {"tip": 0x0A, "base": 0x0C}, 0.0)  # base not plugged in
    assert rows[1][9] is False and rows[1][10] == "missing" and numbers[1] is None


@pytest.mark.parametrize("bits, status", [
    (0x31, "ok"),  # occupied, initialised, enabled
    (0x71, "out_of_volume"),  # bit 6
    (0xB1, "partly_out_of_volume"),  # bit 7
    (0xF1, "out_of_volume"),  # both: the worse one
])
def test_the_port_status_flags_a_frame_whatever_its_pose(bits, status):
    # out of volume the Aurora still sends a (degraded) transform: the port status alone tells
    frame = PortStatusFakeTracker({}, out_from=1, bits=bits & 0xC0).get_frame()
    tip, base = aur._frame_rows(frame, {"tip": 0x0A, "base": 0x0B}, 0.5)[0]
    assert tip[10:] == (status, bits) and tip[9] is (status == "ok")
    assert tip[2:5] == (1.0, 2.0, 60.0)  # the reported pose is kept in the stream, flagged
    assert base[9:] == (True, "ok", 0x31)
    assert aur.sensor_status(0x01, False) == "missing" and aur.sensor_status(aur.PORT_STATUS_UNKNOWN, True) == "ok"


def test_port_status_as_ndicapi_returns_it_from_a_bx_reply():
    # ndicapi 3.7 builds a BX port status from signed chars: 0xB1 comes back sign-extended
    assert aur._port_status_bits(2**64 - 79) == 0xB1 and aur._port_status_bits(-79) == 0xB1
    assert aur._port_status_bits(0x71) == 0x71 and aur._port_status_bits(0x131) == 0x131


def test_a_sensor_out_of_volume_for_max_lost_s_stops_the_run_and_says_why(tmp_path):
    with emulated_backend(tmp_path, tracker=PortStatusFakeTracker) as (backend, bus, _):
        path = Path(backend.config.source)
        path.write_text(path.read_text().replace("detect_timeout_s = 0.5", "detect_timeout_s = 0.5\nmax_lost_s = 0.2"))
        backend = HardwareBackend(HardwareConfig.from_toml(path), TEE,
                                  tracker_factory=lambda s: PortStatusFakeTracker(s, out_from=40))
        with pytest.raises(HardwareError, match=r"tip sensor \(port handle 0x0a\) has reported no valid pose for "
                                                r"[\d.]+ s \(out of the field generator's volume; tracker.max_lost_s = 0.2\)"):
            with backend:
                backend.execute(*sine_chunk(n=300))
        assert bus.torque() == {1: False, 2: False}


class DeadPortTracker(FakeTracker):
    """From frame ``dead_from`` on every frame request fails at once as ndicapi fails it (a port whose
    unit is gone), and stopping waits until ``release`` is set (a unit that never answers TSTOP)."""

    def __init__(self, settings, dead_from=5):
        super().__init__(settings)
        self.dead_from = dead_from
        self.release = threading.Event()

    def get_frame(self):
        if self.frame_number >= self.dead_from:
            raise OSError("Error 0x0103: Device->host communication timeout")
        return super().get_frame()

    def stop_tracking(self):
        self.release.wait(30.0)
        super().stop_tracking()


def test_a_tracker_that_stops_answering_is_named_and_let_go_of_without_raising(tmp_path, caplog):
    # the reader asks again after each failed request; after max_lost_s with no frame at all the run stops
    # naming the tracker and the driver's last error; the close waits CLOSE_TIMEOUT_S for TSTOP, no longer
    import logging
    import time

    with emulated_backend(tmp_path, tracker=DeadPortTracker) as (backend, bus, trackers):
        path = Path(backend.config.source)
        path.write_text(path.read_text().replace("detect_timeout_s = 0.5", "detect_timeout_s = 0.5\nmax_lost_s = 0.2"))
        made = []
        backend = HardwareBackend(HardwareConfig.from_toml(path), TEE,
                                  tracker_factory=lambda settings: made.append(DeadPortTracker(settings)) or made[-1])
        backend.open()
        with pytest.raises(HardwareError, match=r"^NDI Aurora: the tracker stopped answering: no frame from either "
                                                r"sensor for [\d.]+ s \(tracker.max_lost_s = 0.2; the driver: Error "
                                                r"0x0103: Device->host communication timeout; serial port auto\): check "
                                                r"the System Control Unit's power"):
            backend.execute(*sine_chunk(n=300))
        with caplog.at_level(logging.WARNING, logger="endocal.backends.aurora"):
            began = time.monotonic()
            backend.close()  # the tracker's TSTOP never returns: not raised, not waited for
            closed_in = time.monotonic() - began
        assert bus.torque() == {1: False, 2: False}
        assert closed_in < 2.0
        assert backend.close_notes == ["NDI Aurora: no answer within 1 s of closing (stopping tracking, then the port "
                                       "auto): left to the driver's timeouts in the background"]
        assert [r.getMessage().split(" (after")[0] for r in caplog.records] == backend.close_notes
        dead = made[0]
        assert dead.closed == 0  # still waiting for the unit, in the background
        dead.release.set()
        deadline = time.monotonic() + 5.0
        while dead.closed == 0 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert dead.stopped == 1 and dead.closed == 1  # once the unit answers, the port is closed


# --- the chunk ----------------------------------------------------------------------------
def test_chunk_columns_match_the_run_format(tmp_path):
    backend, bus, _ = make_backend(tmp_path, tracker_kwargs={"nan_base_every": 3})
    assert isinstance(backend, Backend) and backend.name == "hardware" and backend.realtime
    with backend:
        t, g = sine_chunk(n=30)
        chunk = backend.execute(t, g)
        t2, g2 = sine_chunk(t0=t[-1], n=30)
        chunk2 = backend.execute(t2, g2)
        info = backend.describe()
    m = chunk.motor
    assert list(m) == motor_columns(TEE) + ["tick_late_ms"]
    assert (m["tick_late_ms"] >= 0).all()
    timing = info["timing"]
    assert timing["set_rate_hz"] == pytest.approx(1.0 / np.median(np.diff(t)))
    assert timing["achieved_rate_hz"] == pytest.approx(timing["set_rate_hz"], rel=0.2)
    assert timing["overrun_pct"] == pytest.approx(100.0 * timing["overruns"] / info["timing"]["ticks_played"])
    tracker = info["tracker"]  # every frame stamped mid round trip: half of it bounds the stamp's error
    assert tracker["frames_read"] > 0 and 0 <= tracker["stamp_uncertainty_ms"] <= tracker["round_trip_ms_max"] / 2
    assert all(len(v) == t.size for v in m.values())
    # never early: each tick is read after its scheduled time on the run clock
    assert (m["t_s"] >= t).all() and (np.diff(m["t_s"]) > 0).all() and chunk2.motor["t_s"][0] > m["t_s"][-1]
    np.testing.assert_array_equal(m["ap_goal_deg"], g["ap"])
    # the simulated servo follows at once, so position = goal to within the tick rounding
    assert np.max(np.abs(m["ap_pos_deg"] - g["ap"])) <= HALF_TICK_DEG + 1e-12
    assert np.max(np.abs(m["ml_pos_deg"] - g["ml"])) <= HALF_TICK_DEG + 1e-12
    for dof in ("translation", "rotation"):
        u = TEE.unit(dof)
        for kind in (f"goal_{u}", f"pos_{u}", f"vel_{u}ps", "current_ma"):
            assert np.all(m[f"{dof}_{kind}"] == 0.0)
    assert all(np.isfinite(v).all() for v in m.values())
    tr = chunk.tracker
    assert list(tr) == list(aur.HARDWARE_TRACKER_COLUMNS)  # the run format's, then status and port_status
    n_rows = len(tr["t_s"]) + len(chunk2.tracker["t_s"])
    assert n_rows >= 2 and n_rows % 2 == 0  # one tip and one base row per frame
    assert set(tr["sensor"]) <= {"tip", "base"}
    bad = ~tr["valid"]
    assert np.isnan(tr["x_mm"][bad]).all() and np.isfinite(tr["x_mm"][~bad]).all()
    assert set(tr["status"][bad]) == {"missing"} and set(tr["status"][~bad]) == {"ok"}
    assert info["dynamixel"]["servos"]["ap"]["model_number"] == 1020
    assert info["dynamixel"]["servos"]["ml"]["firmware_version"] == 45
    assert info["tracker"]["tools_seen"]["port_handles"] == [10, 11]
    assert info["packages"]["dynamixel-sdk"] != "unknown"
    assert info["timing"]["ticks_played"] == 60
    json.dumps(info)  # run.json must be able to hold it


# --- the UDP translation/rotation stage (127.0.0.1 only) -----------------------------------
class FakeStage(threading.Thread):
    """A LabVIEW stand-in: follows each goal at once and reports a current proportional to speed."""

    def __init__(self, silent_after=None):
        super().__init__(daemon=True)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(0.05)
        self.port = self.sock.getsockname()[1]
        self.pos = (0.0, 0.0)
        self.requests = 0
        self.silent_after = silent_after
        self.stopped = threading.Event()
        self.got_stop = False

    def run(self):
        while not self.stopped.is_set():
            try:
                data, addr = self.sock.recvfrom(512)
            except (TimeoutError, socket.timeout):
                continue
            parts = data.decode().split()
            if parts[0] == "STOP":
                self.got_stop = True
                continue
            self.requests += 1
            if self.silent_after is not None and self.requests > self.silent_after:
                continue
            if parts[0] == "GOAL":
                self.pos = (float(parts[2]), float(parts[3]))
            self.sock.sendto(f"POS {parts[1]} {self.pos[0]} {self.pos[1]} 12.5 -3.0".encode(), addr)

    def stop(self):
        self.stopped.set()
        self.join(1.0)
        self.sock.close()


def test_udp_stage_moves_translation_and_rotation(tmp_path):
    stage = FakeStage()
    stage.start()
    try:
        section = f'[stage]\nmode = "udp"\nhost = "127.0.0.1"\nport = {stage.port}\ntimeout_s = 0.5\n'
        with emulated_backend(tmp_path, stage=section) as (backend, _, _), backend:
            t, g = sine_chunk(n=20)
            g["translation"] = 0.5 * np.sin(2 * np.pi * t)  # at most 3.1 mm/s < 10 mm/s
            g["rotation"] = -2.0 * np.sin(2 * np.pi * t)
            chunk = backend.execute(t, g)
            info = backend.describe()
        m = chunk.motor
        np.testing.assert_allclose(m["translation_pos_mm"], g["translation"], atol=1e-6)  # 6 decimals on the wire
        np.testing.assert_allclose(m["rotation_pos_deg"], g["rotation"], atol=1e-6)
        assert np.all(m["translation_current_ma"] == 12.5) and np.all(m["rotation_current_ma"] == -3.0)
        v = m["translation_vel_mmps"][1:]
        expected = np.diff(m["translation_pos_mm"]) / np.diff(m["t_s"])
        np.testing.assert_allclose(v, expected, rtol=1e-12)
        assert info["stage"]["address"] == f"127.0.0.1:{stage.port}"
        # too fast for the stage's 10 mm/s: refused
        with emulated_backend(tmp_path, stage=section) as (backend2, _, _), backend2:
            g["translation"] = np.linspace(0, 1.0, t.size)  # 1 mm in 0.19 s = 5.3 mm/s: fine
            backend2.execute(t, g)
            t3 = t + t[-1]
            g3 = {k: np.full(t.size, v[-1]) for k, v in g.items()}
            g3["translation"] = 1.0 + np.linspace(0.2, 2.0, t.size)  # 0.2 mm in 10 ms: 20 mm/s
            with pytest.raises(LimitError, match="'translation'.*20.0 mm/s.*limit 10 mm/s"):
                backend2.execute(t3, g3)
        assert stage.got_stop
    finally:
        stage.stop()


def test_udp_stage_that_never_answers_is_a_hardware_error(tmp_path):
    silent = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    silent.bind(("127.0.0.1", 0))
    try:
        port = silent.getsockname()[1]
        section = f'[stage]\nmode = "udp"\nhost = "127.0.0.1"\nport = {port}\ntimeout_s = 0.02\n'
        with emulated_backend(tmp_path, stage=section) as (backend, bus, _):
            with pytest.raises(HardwareError, match=f"no reply from the translation/rotation stage at 127.0.0.1:{port}"):
                backend.open()
            assert bus.torque() == {1: False, 2: False} and not torque_switched_on(bus)
    finally:
        silent.close()


def test_udp_stage_that_stops_answering_stops_the_run(tmp_path):
    stage = FakeStage(silent_after=4)  # answers READ and 3 goals, then nothing
    stage.start()
    try:
        section = (f'[stage]\nmode = "udp"\nhost = "127.0.0.1"\nport = {stage.port}\n'
                   "timeout_s = 0.01\nmax_missed_replies = 2\n")
        with emulated_backend(tmp_path, stage=section) as (backend, bus, _):
            with pytest.raises(HardwareError, match="stopped answering \\(3 replies missing in a row\\)"):
                with backend:
                    backend.execute(*sine_chunk())
            assert bus.torque() == {1: False, 2: False}
    finally:
        stage.stop()


# --- configuration ------------------------------------------------------------------------
def test_example_config_parses_and_matches_the_tee_probe():
    config = HardwareConfig.from_toml(EXAMPLE)
    assert config.dynamixel.motors["ap"].id == 1 and config.dynamixel.motors["ml"].direction == -1
    assert config.tracker.tip_port_handle == 0x0A and config.tracker.serial_port == "auto"
    assert config.stage.mode == "absent"
    backend = HardwareBackend(config, TEE)
    assert backend.limits["ap"] == (-90.0, 90.0) and backend.max_speed["ap"] == 120.0


def test_unknown_keys_are_config_errors_naming_key_and_file(tmp_path):
    path = rig_toml(tmp_path, extra_motor="zero_offset = 3")
    with pytest.raises(ConfigError, match=rf"{path}.*\[dynamixel\.motors\.ap\]: unknown key 'zero_offset'"):
        HardwareConfig.from_toml(path)
    path = rig_toml(tmp_path, safety="[safety]\nhome_speed = 3\n")
    with pytest.raises(ConfigError, match=rf"{path} \[safety\]: unknown key 'home_speed'"):
        HardwareConfig.from_toml(path)
    path.write_text(EXAMPLE.read_text() + "\n[extra]\nx = 1\n")
    with pytest.raises(ConfigError, match=rf"{path}: unknown key 'extra'"):
        HardwareConfig.from_toml(path)
    path.write_text("[dynamixel\n")
    with pytest.raises(ConfigError, match="not valid TOML"):
        HardwareConfig.from_toml(path)


def test_one_serial_port_for_both_devices_and_a_bad_latency_are_config_errors(tmp_path):
    # the same device under two names: /dev/serial/by-id/... is a symlink to /dev/ttyUSB0
    device = tmp_path / "ttyUSB0"
    device.touch()
    (tmp_path / "by-id").symlink_to(device)
    path = rig_toml(tmp_path, port=str(device))
    path.write_text(path.read_text().replace("[tracker]\n", f'[tracker]\nserial_port = "{tmp_path / "by-id"}"\n'))
    with pytest.raises(ConfigError, match=rf"{path}: \[dynamixel\] port and \[tracker\] serial_port are both"):
        HardwareConfig.from_toml(path)
    path = rig_toml(tmp_path)
    path.write_text(path.read_text().replace("latency_timer_ms = 500.0", "latency_timer_ms = 0"))
    with pytest.raises(ConfigError, match=r"latency_timer_ms must be in \(0, 1000\] ms, got 0"):
        HardwareConfig.from_toml(path)


def test_config_must_fit_probe_and_register_range(tmp_path):
    config = HardwareConfig.from_toml(EXAMPLE)
    with pytest.raises(ConfigError, match="configures ap, ml but probe 'duodenoscope' bends with ud, lr"):
        HardwareBackend(config, PRESETS["duodenoscope"])
    path = rig_toml(tmp_path)
    path.write_text(path.read_text().replace("zero_ticks = 2048\ndirection = 1", "zero_ticks = 300\ndirection = 1"))
    with pytest.raises(ConfigError, match=r"knob 'ap' limits \(-60\.0, 80\.0\) deg map to ticks -383\.\.1210"):
        HardwareBackend(HardwareConfig.from_toml(path), TEE)


# --- end to end: a hardware run folder through endocal.excite ------------------------------
class RotatedBaseTracker(FakeTracker):
    """Base sensor turned 90 deg about z at (10, 0, 0) mm; tip at (1, 2, 60) mm in the base frame."""

    def get_frame(self):
        handles, stamps, numbers, _, quality = super().get_frame()
        rz90 = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1]], float)
        base_p = np.array([10.0, 0.0, 0.0])
        tip_p = base_p + rz90 @ np.array([1.0, 2.0, 60.0])
        return handles, stamps, numbers, [transform(rz90, tip_p), transform(rz90, base_p)], quality


def test_hardware_run_folder_through_run_excitation(tmp_path):
    from endocal.excite import run_excitation
    from endocal.protocols.trajectory import Trajectory
    from endocal.runs.aligned import read_stream

    fs = 100.0
    t = np.arange(31) / fs
    goal = {d: np.zeros(t.size) for d in TEE.dofs}
    goal["ap"] = 3.0 * np.sin(2 * np.pi * 2.0 * t)  # peak speed 37.7 deg/s < 100 deg/s
    traj = Trajectory(t_s=t, goal=goal, sample_rate_hz=fs, protocol="test")
    with emulated_backend(tmp_path, tracker=RotatedBaseTracker) as (backend, bus, _):
        result = run_excitation(traj, backend, TEE, tmp_path / "run", protocol_info={"name": "test"}, seed=0)
        assert bus.torque() == {1: False, 2: False}
    assert result.status == "complete" and result.motor_rows == t.size
    meta = json.loads((tmp_path / "run" / "run.json").read_text())
    assert meta["backend"]["name"] == "hardware" and meta["backend"]["dynamixel"]["servos"]["ap"]["model_number"] == 1020
    motor = read_stream(tmp_path / "run", "motor")
    np.testing.assert_allclose(motor["ap_goal_deg"], goal["ap"])
    aligned = pd_read(tmp_path / "run" / "aligned.parquet")
    # thesis eq. 1 on tip_in_base = (1, 2, 60) mm: atan2(2, 60) and atan2(1, 60), whatever the base's pose
    np.testing.assert_allclose(aligned["ap_meas_deg"], math.degrees(math.atan2(2.0, 60.0)), atol=1e-9)
    np.testing.assert_allclose(aligned["ml_meas_deg"], math.degrees(math.atan2(1.0, 60.0)), atol=1e-9)


def pd_read(path):
    import pandas as pd

    return pd.read_parquet(path)
