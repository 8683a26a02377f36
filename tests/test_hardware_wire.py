"""The hardware backend's safety promises on the wire, as a user meets them.

``endocal excite PROTOCOL --backend hardware --hardware-config RIG.toml`` runs in a child
process, through the real dynamixel-sdk, scikit-surgerynditracker and ndicapi, against the
emulated rig (endocal/emulate/rig.py) served from this process. The emulated servo bus keeps
every write a servo received (``ServoBus.writes``: Write and Sync Write, address, bytes, and
the error the servo answered) and reports each servo's torque, so every assertion here is on
what reached the wire, or never did. Bad rig files are refused before any packet is sent.
"""

from __future__ import annotations

import itertools
import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from endocal.backends.dynamixel import DynamixelConfig, KnobServos, MotorConfig
from endocal.emulate import dxl_wire
from endocal.emulate.rig import EmulatedRig
from endocal.emulate.servos import ServoBus
from endocal.errors import HardwareError
from endocal.probe import PRESETS
from endocal.runs.aligned import read_stream
from tests._cli import ROOT, endocal, one_line_exit_2
from tests._wire import assert_torque_off_last, goal_syncs

pytest.importorskip("sksurgerynditracker")
TEE = PRESETS["tee"]
TICKS_PER_DEG = 4096 / 360.0
# One second of a 10 deg sine on ap (starts at 0 deg, 63 deg/s at most)...
SINE = ["sine", "--set", "frequency_hz=1.0", "--set", "cycles=1", "--amplitude", "10", "--seed", "1"]
# ...and thirty, for runs a signal stops early.
LONG = ["sine", "--set", "frequency_hz=1.0", "--set", "cycles=30", "--amplitude", "10", "--seed", "1"]
TIMEOUT_S = 180.0  # a child's start and a run's end on a loaded machine; never a measure of speed


def _rig_file(rig: EmulatedRig, tmp: Path, *replacements: tuple[str, str], extra: str = "") -> Path:
    """The rig TOML ``endocal emulate rig`` writes, with text replaced (first occurrence) and ``extra`` appended."""
    path = rig.write_config(tmp / "rig.toml")
    text = path.read_text()
    for old, new in replacements:
        assert old in text, old
        text = text.replace(old, new, 1)
    path.write_text(text + extra)
    return path


def _excite(args, rig_file: Path, out: Path, **kw):
    return endocal("excite", *args, "--backend", "hardware", "--hardware-config", rig_file, "--out", out, "-q", **kw)


def _ticks(deg: float) -> int:
    return 2048 + round(deg * TICKS_PER_DEG)


# --- limits: refused before a byte reaches the bus ----------------------------------------
@pytest.mark.parametrize("args, limits, fragments, child", [
    # the probe's own limit (90 deg): excite refuses the protocol before it builds the backend
    (["sine", "--amplitude", "95", "--set", "cycles=1"], None, ("95", "90"), False),
    # the rig's tighter limit, reached 0.17 s in: refused before the rig is opened, not mid-run
    (SINE, "[-5, 5]", ("'ap'", "beyond its limit 5.000 deg", "refused before the rig was opened"), True),
])
def test_a_run_beyond_the_limits_is_refused_before_any_byte_reaches_the_bus(tmp_path, args, limits, fragments,
                                                                             child):
    with EmulatedRig(TEE, seed=1) as rig:
        swap = [("limits_deg = [-90, 90]", f"limits_deg = {limits}")] if limits else []
        proc = _excite(args, _rig_file(rig, tmp_path, *swap), tmp_path / "run", process=child, timeout=TIMEOUT_S)
        packets = rig.bus.packets
    one_line_exit_2(proc, *fragments)
    assert packets == 0  # not a ping, not a read: the servos saw nothing
    assert not (tmp_path / "run").exists()


def test_a_first_goal_far_from_rest_is_refused_with_the_knobs_held(tmp_path):
    # ap rests at +10 deg; the sine starts at 0 deg: reaching it would be a jump at unbounded speed
    with EmulatedRig(TEE, seed=1, present_ticks={1: _ticks(10.0)}) as rig:
        proc = _excite(SINE, _rig_file(rig, tmp_path), tmp_path / "run", process=True, timeout=TIMEOUT_S)
        bus = rig.bus
        assert_torque_off_last(bus)
        assert goal_syncs(bus) == []  # no goal of the protocol reached a servo
        # torque on held each knob where it rested: the only goals written are the present positions
        assert {(w.id, w.value) for w in bus.writes(116)} == {(1, _ticks(10.0)), (2, 2048)}
    one_line_exit_2(proc, "'ap' is at 10.02 deg but the first goal", "start tolerance 2 deg")
    assert json.loads((tmp_path / "run" / "run.json").read_text())["status"] == "failed"


# --- torque off however the run ends ------------------------------------------------------
@pytest.mark.parametrize("signame, code, fragment, stopped_by", [
    ("SIGINT", 130, "interrupted: the run in", None),  # Ctrl-C
    ("SIGTERM", 143, "stopped by SIGTERM: torque is off", "SIGTERM"),  # kill, systemd, a scheduler
])
def test_a_signal_mid_run_switches_torque_off_and_keeps_the_run(tmp_path, signame, code, fragment, stopped_by):
    with EmulatedRig(TEE, seed=1) as rig:
        cmd = [sys.executable, "-m", "endocal", "excite", *LONG, "--backend", "hardware", "--hardware-config",
               str(_rig_file(rig, tmp_path)), "--out", str(tmp_path / "run"), "-q"]
        proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            deadline = time.monotonic() + TIMEOUT_S
            while len(goal_syncs(rig.bus)) < 2 * 30 and proc.poll() is None and time.monotonic() < deadline:
                time.sleep(0.05)  # until 30 ticks (0.3 s) of goals have reached both servos
            assert proc.poll() is None, proc.communicate()
            proc.send_signal(getattr(signal, signame))
            _, errors = proc.communicate(timeout=TIMEOUT_S)
        finally:
            proc.kill()
        assert_torque_off_last(rig.bus)
        ticks_sent = len(goal_syncs(rig.bus)) // 2
    assert proc.returncode == code, errors
    lines = [ln for ln in errors.splitlines() if ln.strip()]
    assert len(lines) == 1 and fragment in lines[0], errors
    meta = json.loads((tmp_path / "run" / "run.json").read_text())
    assert meta["status"] == "interrupted" and meta.get("stopped_by") == stopped_by
    assert ticks_sent < 30 * 100  # stopped, long before the 30 s protocol's end
    # the run so far is readable: every tick whose goal reached the servos is logged but those of the
    # chunk the signal cut short (a chunk is 0.1 s, 10 ticks)
    assert ticks_sent - 10 <= len(read_stream(tmp_path / "run", "motor")) <= ticks_sent


# --- the EEPROM lock, the limit registers and homing ---------------------------------------
def test_torque_left_on_is_switched_off_before_the_eeprom_is_written_then_the_knobs_are_homed(tmp_path):
    # servos as a crashed program leaves them: torque on, ap at +10 deg; the rig homes the knobs at 20 deg/s
    start = {1: _ticks(10.0), 2: 2048}
    with EmulatedRig(TEE, seed=1, present_ticks=start, torque_on=True) as rig:
        cfg = _rig_file(rig, tmp_path, extra="\n[safety]\nhome_on_open = true\nhome_speed_dps = 20.0\n")
        proc = _excite(SINE, cfg, tmp_path / "run", process=True, timeout=TIMEOUT_S)
        bus = rig.bus
        writes = bus.writes()
        assert_torque_off_last(bus)
    assert proc.returncode == 0, proc.stderr
    assert all(w.error == 0 for w in writes)  # the servos refused nothing: no EEPROM write with torque on
    for i in (1, 2):
        mine = [w for w in writes if w.id == i]
        assert (mine[0].address, mine[0].value) == (64, 0)  # torque off comes first
        on = next(k for k, w in enumerate(mine) if w.address == 64 and w.value == 1)
        eeprom = [k for k, w in enumerate(mine) if w.address < 64]
        assert eeprom and max(eeprom) < on  # operating mode and limit registers written with torque off
        limits = {w.address: w.value for w in mine if w.address in (48, 52)}
        assert limits == {48: _ticks(90.0), 52: _ticks(-90.0)}  # the knob limits, in the servo's EEPROM
        assert bus.servos[i].get(48) == _ticks(90.0) and bus.servos[i].get(52) == _ticks(-90.0)
        hold = [w.value for w in mine[:on] if w.address == 116]
        assert hold == [start[i]]  # before torque on, the goal := where the knob rests: nothing jumps
    # homing: ap ramps from +10 deg to 0 at 20 deg/s (50 goals a second), then the sine starts at 0
    ap = [w.value for w in goal_syncs(bus) if w.id == 1]
    home = ap[:ap.index(2048) + 1]
    steps_deg = [abs(b - a) / TICKS_PER_DEG for a, b in itertools.pairwise([start[1], *home])]
    assert len(home) >= 25 and max(steps_deg) <= 20.0 / 50.0 + 1.0 / TICKS_PER_DEG  # plus a tick of rounding
    assert all(b <= a for a, b in itertools.pairwise(home))  # straight down, no overshoot
    meta = json.loads((tmp_path / "run" / "run.json").read_text())
    assert meta["status"] == "complete" and meta["backend"]["dynamixel"]["servos"]["ap"]["position_limit_ticks"] == [
        _ticks(-90.0), _ticks(90.0)]


def test_the_servo_itself_refuses_eeprom_writes_with_torque_on_and_goals_beyond_its_limit_registers():
    # what the backend relies on when software misbehaves, through the real SDK: the emulated XM430
    # answers as the e-manual says (Access Error; Data Limit Error, the goal not applied)
    motors = {"ap": MotorConfig("ap", 1), "ml": MotorConfig("ml", 2)}
    with ServoBus([1, 2], baudrate=1_000_000) as bus:
        ks = KnobServos(DynamixelConfig(port=bus.port, baudrate=1_000_000, latency_timer_ms=500.0, motors=motors))
        ks.open()
        ks.write_limit_registers({"ap": (-30.0, 30.0), "ml": (-30.0, 30.0)})
        ks.torque_on()
        with pytest.raises(HardwareError, match=r"ID 1 \(knob 'ap'\).*writing Min Position Limit.*failed"):
            ks.write_limit_registers({"ap": (-90.0, 90.0), "ml": (-90.0, 90.0)})
        assert bus.writes(52)[-1].error == dxl_wire.ERR_ACCESS and bus.servos[1].get(52) == _ticks(-30.0)
        for _ in range(30):  # 0.3 s of a goal at 60 deg, beyond the 30 deg register (the backend would refuse it)
            ks.write_goals_deg({"ap": 60.0, "ml": 0.0})
            state = ks.read_state()
            time.sleep(0.01)
        ks.close()
    refused = [w for w in goal_syncs(bus) if w.id == 1]
    assert refused and all(w.error == dxl_wire.ERR_DATA_LIMIT for w in refused)
    assert bus.servos[1].get(116) == 2048 and abs(state.pos_deg["ap"]) < 0.1  # held at 0 deg: not applied


# --- bad rig files: one line, exit code 2, nothing on the bus ------------------------------
@pytest.mark.parametrize("swap, fragments", [
    (("serial_port = ", "serial_port = \"{dxl}\"\n# "), ("[dynamixel] port and [tracker] serial_port are both",
                                                        "each need their own serial port")),
    (("id = 2", "id = 1"), ("ID 1 is given to both 'ap' and 'ml'", "every servo needs its own ID")),
    (("baudrate = 57600", "baudrate = 56000"), ("baudrate 56000 is not a rate the servos speak", "57600")),
])
def test_a_bad_rig_file_is_one_line_and_moves_nothing(tmp_path, swap, fragments):
    with EmulatedRig(TEE, seed=1) as rig:
        old, new = swap
        cfg = _rig_file(rig, tmp_path, (old, new.format(dxl=rig.bus.port)))
        proc = _excite(SINE, cfg, tmp_path / "run")
        packets = rig.bus.packets
    one_line_exit_2(proc, str(cfg), *fragments)
    assert packets == 0 and not (tmp_path / "run").exists()


def test_a_baud_rate_the_servos_are_not_set_to_is_a_hardware_fault_that_moves_nothing(tmp_path):
    # 1 Mbd is a rate the servos speak, but these are set to 57600: at another speed they see only
    # noise and never answer, which the host cannot tell from unpowered servos (exit code 3, not 2)
    with EmulatedRig(TEE, seed=1) as rig:
        cfg = _rig_file(rig, tmp_path, ("baudrate = 57600", "baudrate = 1000000"))
        proc = _excite(SINE, cfg, tmp_path / "run")
        packets, writes = rig.bus.packets, rig.bus.writes()
    assert proc.returncode == 3, proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "at 1000000 baud did not answer a ping" in lines[0] and "baud rate" in lines[0]
    assert packets == 0 and writes == [] and not (tmp_path / "run").exists()
