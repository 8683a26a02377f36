"""An emulated bus of Dynamixel XM430-W350 servos on a pseudo-terminal, speaking Protocol 2.0.

The host opens the pty's slave path (:attr:`ServoBus.port`) as it would a U2D2 and talks to
it through the real ``dynamixel-sdk``; this module answers byte for byte
(:mod:`endocal.emulate.dxl_wire`): ping, read, write, sync read, sync write, fast sync read
and reboot, with status packets carrying error numbers and the hardware alert bit.

Each servo holds the control table the backend uses (XM430-W350 e-manual, "Control Table"):
model number, firmware, ID, operating mode, position limits, torque enable, hardware error
status, goal position, and the present current, velocity and position, with their widths,
signs and access (EEPROM fields refuse writes while torque is on, as real servos do). With
torque on, the present position follows the goal as a first-order lag limited to the servo's
no-load speed, advanced in time whenever the bus is asked; :meth:`ServoBus.positions_ticks`
gives the knobs' positions to whatever emulates the probe behind them.

Faults, switchable at construction and at run time (:class:`BusFaults`): drop replies,
corrupt them (a wrong CRC), delay them, raise a servo's hardware error (overload,
overheating; alert bit in every status packet after), or unplug the bus after some seconds.

Every write instruction a servo receives (Write and Sync Write, refused ones included) is kept
in order in :meth:`ServoBus.writes`, so a test can prove what reached the wire and what never
did; :meth:`ServoBus.torque` reports each servo's Torque Enable.
"""

from __future__ import annotations

import math
import os
import random
import select
import termios
import threading
import time
from dataclasses import dataclass, field

from endocal.emulate import dxl_wire as w
from endocal.emulate._serving import Served, close_fds, open_raw_pty

MODEL_XM430_W350 = 1020
FIRMWARE = 46
TICKS_PER_REV = 4096
RPM_PER_UNIT = 0.229
MA_PER_UNIT = 2.69
NO_LOAD_RPM = 46.0  # XM430-W350 at 12 V

# address: (size, signed, writable, eeprom)
CONTROL_TABLE = {
    0: (2, False, False, True),    # Model Number
    6: (1, False, False, True),    # Firmware Version
    7: (1, False, True, True),     # ID
    8: (1, False, True, True),     # Baud Rate
    11: (1, False, True, True),    # Operating Mode
    48: (4, False, True, True),    # Max Position Limit
    52: (4, False, True, True),    # Min Position Limit
    64: (1, False, True, False),   # Torque Enable
    65: (1, False, True, False),   # LED
    70: (1, False, False, False),  # Hardware Error Status
    116: (4, True, True, False),   # Goal Position
    126: (2, True, False, False),  # Present Current
    128: (4, True, False, False),  # Present Velocity
    132: (4, True, False, False),  # Present Position
}
TABLE_SIZE = 147
HW_OVERHEATING, HW_OVERLOAD = 0x04, 0x20
HW_ERRORS = {"overheating": HW_OVERHEATING, "overload": HW_OVERLOAD}
ADDR_TORQUE_ENABLE = 64


@dataclass(frozen=True)
class WireWrite:
    """One write instruction as a servo received it.

    Attributes
    ----------
    t_s : float
        When it arrived, seconds on the bus's monotonic clock (0 when the bus started).
    id : int
        The servo it addressed.
    address : int
        First control-table address written.
    data : bytes
        The bytes written (little endian).
    error : int
        The Protocol 2.0 error number the servo answered (0: applied; ``ERR_ACCESS``: an EEPROM
        field while torque is on, ``ERR_DATA_LIMIT``: a goal beyond the Position Limit
        registers, both not applied). A Sync Write gets no reply; its error is what the servo
        would have answered.
    sync : bool
        Part of a Sync Write (the goal stream) rather than a Write.
    """

    t_s: float
    id: int
    address: int
    data: bytes
    error: int
    sync: bool

    @property
    def value(self) -> int:
        """The value written, read as the control-table field at :attr:`address` reads it (signed or not)."""
        size, signed, _, _ = CONTROL_TABLE.get(self.address, (len(self.data), False, True, False))
        return int.from_bytes(self.data[:size], "little", signed=signed)


@dataclass
class BusFaults:
    """Faults of the emulated bus.

    Attributes
    ----------
    drop_probability : float
        Each reply is lost with this probability (seeded).
    corrupt_probability : float
        Each reply is sent with a wrong CRC with this probability.
    delay_s : float
        Every reply is held back this long.
    unplug_after_s : float or None
        The bus goes silent this long after the first packet (a pulled cable).
    hardware_error : dict
        Servo ID -> ``"overload"`` or ``"overheating"``, raised after ``hardware_error_after_s``.
    hardware_error_after_s : float
    """

    drop_probability: float = 0.0
    corrupt_probability: float = 0.0
    delay_s: float = 0.0
    unplug_after_s: float | None = None
    hardware_error: dict = field(default_factory=dict)
    hardware_error_after_s: float = 0.0


class Servo:
    """One XM430-W350: its control table and a first-order position servo."""

    def __init__(self, dxl_id: int, *, model_number: int = MODEL_XM430_W350, present_ticks: int = 2048,
                 time_constant_s: float = 0.03) -> None:
        self.table = bytearray(TABLE_SIZE)
        self.time_constant_s = time_constant_s
        self._set(0, model_number)
        self._set(6, FIRMWARE)
        self._set(7, dxl_id)
        self._set(8, 1)  # 57600 bd
        self._set(11, 3)  # position control
        self._set(48, 4095)
        self._set(52, 0)
        self.pos = float(present_ticks)
        self.vel_tps = 0.0
        self._set(116, present_ticks)
        self._sync_present()

    @property
    def id(self) -> int:
        return self.table[7]

    @property
    def torque(self) -> bool:
        return bool(self.table[64])

    def _set(self, addr: int, value: int) -> None:
        size, signed, _, _ = CONTROL_TABLE[addr]
        self.table[addr:addr + size] = int(value).to_bytes(size, "little", signed=signed)

    def get(self, addr: int) -> int:
        size, signed, _, _ = CONTROL_TABLE[addr]
        return int.from_bytes(self.table[addr:addr + size], "little", signed=signed)

    def _sync_present(self) -> None:
        self._set(132, int(round(self.pos)))
        self._set(128, int(round(self.vel_tps * 60.0 / TICKS_PER_REV / RPM_PER_UNIT)))
        current_ma = 0.0 if not self.torque else 300.0 * math.tanh((self.get(116) - self.pos) / 200.0)
        self._set(126, int(round(current_ma / MA_PER_UNIT)))

    def advance(self, dt: float) -> None:
        """Move towards the goal for ``dt`` seconds (torque on), at most at the no-load speed."""
        if dt <= 0:
            return
        if self.torque and not self.get(70):
            goal = self.get(116)
            lo, hi = (self.get(52), self.get(48)) if self.get(11) == 3 else (-1_048_575, 1_048_575)
            goal = min(max(goal, lo), hi)
            gap = goal - self.pos
            step = gap * (1.0 - math.exp(-dt / self.time_constant_s)) if self.time_constant_s > 0 else gap
            vmax = NO_LOAD_RPM * TICKS_PER_REV / 60.0
            step = max(-vmax * dt, min(vmax * dt, step))
            self.pos += step
            self.vel_tps = step / dt
        else:
            self.vel_tps = 0.0
        self._sync_present()

    def write(self, addr: int, data: bytes) -> int:
        """Write ``data`` at ``addr``; returns a Protocol 2.0 error number (0: done)."""
        end = addr + len(data)
        fields = [a for a in CONTROL_TABLE if addr <= a < end]
        if not fields or end > TABLE_SIZE:
            return w.ERR_DATA_RANGE
        for a in fields:
            size, _, writable, eeprom = CONTROL_TABLE[a]
            if not writable or a + size > end or (eeprom and self.torque):
                return w.ERR_ACCESS
        if 64 in fields and self.get(70) and data[64 - addr]:
            return w.ERR_ACCESS  # a servo in hardware error refuses torque until rebooted
        if 116 in fields and self.get(11) == 3:
            goal = int.from_bytes(data[116 - addr:120 - addr], "little", signed=True)
            if not self.get(52) <= goal <= self.get(48):
                return w.ERR_DATA_LIMIT  # beyond the Position Limit registers: refused, not applied
        self.table[addr:end] = data
        self._sync_present()
        return 0

    def read(self, addr: int, length: int) -> bytes | None:
        if addr < 0 or length <= 0 or addr + length > TABLE_SIZE:
            return None
        return bytes(self.table[addr:addr + length])

    def reboot(self) -> None:
        self.table[64] = 0
        self.table[70] = 0
        self._sync_present()


class ServoBus(Served):
    """Servos on one pseudo-terminal, served by a background thread (``with ServoBus(...) as bus``).

    Parameters
    ----------
    ids : sequence of int
        Servo IDs on the bus.
    model_number : int
        What every servo answers a ping with (1020: XM430-W350).
    present_ticks : int or dict
        Starting position (ticks), for all or per ID.
    baudrate : int
        Speed the servos answer at (a host that set its line to another speed gets no reply).
    torque_on : bool
        Start with torque on, holding the starting position (as a crashed program leaves them:
        their EEPROM fields refuse writes until torque is switched off).
    faults : BusFaults, optional
    seed : int
        Seed of the dropped and corrupted replies.
    on_event : callable, optional
        Called with one line per event: ``servo 1 torque on``, ``servo 2 hardware error: overload``,
        ``bus unplugged``.
    """

    thread_name = "dynamixel-bus"

    def __init__(self, ids=(1, 2), *, model_number: int = MODEL_XM430_W350, present_ticks=2048,
                 baudrate: int = 57600, torque_on: bool = False, faults: BusFaults | None = None, seed: int = 0,
                 on_event=None) -> None:
        super().__init__()
        start = present_ticks if isinstance(present_ticks, dict) else {i: present_ticks for i in ids}
        self.servos = {i: Servo(i, model_number=model_number, present_ticks=start.get(i, 2048)) for i in ids}
        for s in self.servos.values():
            s.table[ADDR_TORQUE_ENABLE] = int(torque_on)
        self.faults = faults or BusFaults()
        self.on_event = on_event or (lambda line: None)
        self._rng = random.Random(seed)
        self._lock = threading.Lock()
        self._parser = w.PacketParser()
        self._master: int | None = None
        self._slave: int | None = None
        self._t_last = self._t_start = time.monotonic()
        self._t_first: float | None = None
        self._writes: list[WireWrite] = []
        self._unplugged = False
        self._hw_raised = False
        self.baudrate = baudrate
        self.port = ""
        self.packets = 0
        self.dropped = 0
        self.corrupted = 0

    # -- life cycle -------------------------------------------------------------------
    def _open(self) -> None:
        """Open the pty in raw mode; :attr:`port` is the path to give the host."""
        self._master, self._slave, self.port = open_raw_pty()

    def _release(self) -> None:
        close_fds(self._master, self._slave)
        self._master = self._slave = None

    # -- what the probe behind the knobs sees -----------------------------------------
    def positions_ticks(self) -> dict[int, float]:
        """Present position of every servo (ticks), advanced to now."""
        with self._lock:
            self._advance()
            return {i: s.pos for i, s in self.servos.items()}

    def torque(self) -> dict[int, bool]:
        """Torque Enable of every servo, now."""
        with self._lock:
            return {i: s.torque for i, s in self.servos.items()}

    def writes(self, address: int | None = None) -> list[WireWrite]:
        """Every write instruction the servos received so far, in order (those at ``address`` only, if given)."""
        with self._lock:
            return [x for x in self._writes if address is None or x.address == address]

    def torque_line(self) -> str:
        """Each servo's torque state in words, e.g. ``servo 1 torque off, servo 2 torque off``."""
        return ", ".join(f"servo {i} torque {'on' if on else 'off'}" for i, on in self.torque().items())

    # -- serving ----------------------------------------------------------------------
    def _advance(self) -> None:
        now = time.monotonic()
        dt, self._t_last = now - self._t_last, now
        for s in self.servos.values():
            s.advance(dt)

    def _serve(self) -> None:
        while not self._stop.is_set():
            try:
                ready, _, _ = select.select([self._master], [], [], 0.02)
                if not ready:
                    continue
                data = os.read(self._master, 4096)
            except OSError:
                return
            if not self._baud_matches():
                continue  # at another baud rate the servos see only noise: no reply
            for ins in self._parser.feed(data):
                reply = self._handle(ins)
                if reply:
                    self._send(reply)

    def _baud_matches(self) -> bool:
        """Whether the host set the line to the servos' baud rate (the pty carries the termios speed)."""
        try:
            speed = termios.tcgetattr(self._slave)[5]
        except (termios.error, OSError):
            return True
        want = getattr(termios, f"B{self.baudrate}", None)
        return want is None or speed == want

    def _send(self, reply: bytes) -> None:
        f = self.faults
        if f.drop_probability and self._rng.random() < f.drop_probability:
            self.dropped += 1
            return
        if f.corrupt_probability and self._rng.random() < f.corrupt_probability:
            self.corrupted += 1
            reply = reply[:-1] + bytes(((reply[-1] ^ 0x5A) & 0xFF,))
        if f.delay_s:
            time.sleep(f.delay_s)
        try:
            os.write(self._master, reply)
        except OSError:
            pass

    def _faults_now(self) -> bool:
        """Apply time-triggered faults; False when the bus is unplugged (no reply)."""
        now = time.monotonic()
        if self._t_first is None:
            self._t_first = now
        f = self.faults
        if f.unplug_after_s is not None and now - self._t_first >= f.unplug_after_s:
            if not self._unplugged:
                self._unplugged = True
                self.on_event("bus unplugged (fault)")
            return False
        if f.hardware_error and not self._hw_raised and now - self._t_first >= f.hardware_error_after_s:
            self._hw_raised = True
            for i, kind in f.hardware_error.items():
                s = self.servos.get(int(i))
                if s is not None:
                    s.table[70] = HW_ERRORS[kind]
                    if s.torque:
                        s.table[64] = 0  # a real XM430 drops torque on a hardware error
                    self.on_event(f"servo {s.id} hardware error: {kind} (fault)")
                    self.on_event(f"servo {s.id} torque off")
        return True

    def _err(self, s: Servo, code: int = 0) -> int:
        return code | (w.ERR_ALERT if s.get(70) else 0)

    def _handle(self, ins: w.Instruction) -> bytes | None:
        with self._lock:
            self.packets += 1
            if not self._faults_now():
                return None
            self._advance()
            p = ins.params
            if ins.instruction == w.SYNC_WRITE and ins.id == w.BROADCAST_ID and len(p) >= 4:
                addr, size = p[0] | p[1] << 8, p[2] | p[3] << 8
                for k in range(4, len(p) - size + 1, size + 1):
                    s = self.servos.get(p[k])
                    if s is not None:
                        self._write(s, addr, p[k + 1:k + 1 + size], sync=True)
                return None
            if ins.instruction in (w.SYNC_READ, w.FAST_SYNC_READ) and ins.id == w.BROADCAST_ID and len(p) >= 4:
                addr, size = p[0] | p[1] << 8, p[2] | p[3] << 8
                present = [self.servos[i] for i in p[4:] if i in self.servos]
                if ins.instruction == w.SYNC_READ:
                    return b"".join(w.status(s.id, self._err(s), s.read(addr, size) or b"") for s in present)
                return self._fast_sync_reply(present, addr, size)
            s = self.servos.get(ins.id)
            if s is None:
                return None  # nobody with that ID: the host times out
            if ins.instruction == w.PING:
                return w.status(s.id, self._err(s), s.get(0).to_bytes(2, "little") + bytes((FIRMWARE,)))
            if ins.instruction == w.READ and len(p) == 4:
                data = s.read(p[0] | p[1] << 8, p[2] | p[3] << 8)
                return w.status(s.id, self._err(s, w.ERR_DATA_RANGE if data is None else 0), data or b"")
            if ins.instruction == w.WRITE and len(p) >= 3:
                return w.status(s.id, self._err(s, self._write(s, p[0] | p[1] << 8, p[2:])))
            if ins.instruction == w.REBOOT:
                was_on = s.torque
                s.reboot()
                self.on_event(f"servo {s.id} rebooted")
                if was_on:
                    self.on_event(f"servo {s.id} torque off")
                return w.status(s.id, 0)
            return w.status(s.id, self._err(s, w.ERR_INSTRUCTION))

    def _write(self, s: Servo, addr: int, data: bytes, sync: bool = False) -> int:
        before = s.torque
        code = s.write(addr, bytes(data))
        self._writes.append(WireWrite(time.monotonic() - self._t_start, s.id, addr, bytes(data), code, sync))
        if s.torque != before:
            self.on_event(f"servo {s.id} torque {'on' if s.torque else 'off'}")
        return code

    def _fast_sync_reply(self, servos: list[Servo], addr: int, size: int) -> bytes:
        """One status packet for all (Protocol 2.0 Fast Sync Read): per servo its error, ID, data
        and a CRC of the packet so far, the first servo's error in the usual error slot."""
        if not servos:
            return b""
        body = bytearray()
        for k, s in enumerate(servos):
            body += bytes((self._err(s), s.id))
            body += s.read(addr, size) or bytes(size)
            if k < len(servos) - 1:
                crc = w.crc16(w.HEADER + bytes((w.BROADCAST_ID, 0, 0, w.STATUS)) + bytes(body))
                body += bytes((crc & 0xFF, crc >> 8))
        return w.packet(w.BROADCAST_ID, w.STATUS, bytes(body))
