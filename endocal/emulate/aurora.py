"""An emulated NDI Aurora System Control Unit on a pseudo-terminal, speaking NDI's serial API.

The host opens the pty's slave path (:attr:`AuroraEmulator.port`) as the Aurora's serial port
and talks to it through ``scikit-surgerynditracker`` and NDI's C library ``ndicapi``. This
emulator answers the commands they send (NDI Combined API, ASCII form): ``INIT``, the probe's
``GETINFO``, ``COMM``, ``VER``, ``PHSR``, ``PINIT``, ``PENA``, ``TSTART``, ``TX`` and
``TSTOP``. Every command and reply carries NDI's CRC-16 (polynomial x^16 + x^15 + x^2 + 1,
computed as ndicapi's ``CalcCRC16``) as four hex digits before the carriage return. Frames
come as ``TX:0801`` (ASCII: per port handle the rotation quaternion, 4 x 6 characters at
1e-4, the position, 3 x 7 characters at 0.01 mm, the RMS error, the port status and the frame
number, or ``MISSING``) or ``BX:0801`` (binary: the same as float32 and uint32 with a header,
a header CRC and a final CRC), whichever the firmware ``VER`` reports makes the driver ask for.
Like the real unit it serves session after session: each ``INIT`` (every connection opens
with one) stops tracking and offers every port handle again for ``PINIT`` and ``PENA``.

Each handle's port status (NDI Combined API, "TX", reply option 0001) is ``0x31`` (occupied,
initialised, enabled) for a sensor seen, ``0x01`` for one missing; a sensor out of the field
generator's volume (the :class:`AuroraFaults` ``out_of_volume`` fault) sets bit 6 (``0x40``),
one partly out of it bit 7 (``0x80``). Out of volume (or partly) its transform is still sent,
displaced by :data:`DEGRADED_MM` as a distorted reading would be, when the host asks for such
transforms (reply option ``0800``, which scikit-surgerynditracker sets), and ``MISSING``
otherwise.

It runs in a process of its own: ndicapi holds Python's interpreter lock while it waits
for a reply, so an emulator thread in the host's process could never answer. The sensor
poses (mm, quaternion w, x, y, z) are set from the host process through shared memory
(:meth:`AuroraEmulator.set_poses`); frame numbers advance at 40 Hz from ``TSTART``.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import select
import struct
import time
from dataclasses import dataclass

from endocal.emulate._serving import close_fds, open_raw_pty

SENSOR_SLOTS = ("tip", "base")
PORT_SEEN, PORT_MISSING = 0x31, 0x01  # occupied | initialised | enabled; occupied only
PORT_OUT_OF_VOLUME, PORT_PARTLY_OUT_OF_VOLUME = 0x40, 0x80  # port status bits 6 and 7
REPLY_OUT_OF_VOLUME = 0x0800  # TX/BX reply option: report transforms out of volume too
DEGRADED_MM = (10.0, 0.0, 0.0)  # how far off the emulated unit reports a sensor out of volume
_ODD_PARITY = (0, 1, 1, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0, 1, 1, 0)


def ndi_crc16(text: str | bytes) -> int:
    """NDI's CRC-16 of a command or reply (ndicapi's ``CalcCRC16``, run over every character)."""
    crc = 0
    for ch in (text.encode("ascii") if isinstance(text, str) else text):
        data = (ch ^ (crc & 0xFF)) & 0xFF
        crc >>= 8
        if _ODD_PARITY[data & 0x0F] ^ _ODD_PARITY[data >> 4]:
            crc ^= 0xC001
        data <<= 6
        crc ^= data
        data <<= 1
        crc ^= data
        crc &= 0xFFFF
    return crc


def reply(text: str) -> bytes:
    """``text`` + its CRC (4 hex digits) + carriage return."""
    return f"{text}{ndi_crc16(text):04X}\r".encode("ascii")


def _signed(value: float, scale: float, width: int) -> str:
    """NDI's fixed-width signed decimal: sign then ``width - 1`` digits of ``value / scale``."""
    n = int(round(value / scale))
    limit = 10 ** (width - 1) - 1
    n = max(-limit, min(limit, n))
    return f"{'+' if n >= 0 else '-'}{abs(n):0{width - 1}d}"


def tx_transform(pos_mm, quat_wxyz, rms_error: float = 0.0) -> str:
    """The 51 characters of one TX transform: q0 qx qy qz (1e-4), x y z (0.01 mm), error (1e-4)."""
    return ("".join(_signed(q, 1e-4, 6) for q in quat_wxyz) + "".join(_signed(p, 0.01, 7) for p in pos_mm)
            + _signed(rms_error, 1e-4, 6))


@dataclass
class AuroraFaults:
    """Faults of the emulated Aurora.

    Attributes
    ----------
    missing : tuple of str
        Sensors (``tip``, ``base``) reported ``MISSING``...
    missing_after_s : float
        ...from this long after ``TSTART`` on (0: from the start, even before tracking).
    silent_after_s : float or None
        Stop answering this long after ``TSTART``, for good: the System Control Unit lost power,
        or the cable came out at its end. Commands still arrive and none is answered, from either
        sensor's frame to ``TSTOP`` and a new session's ``INIT``, so the host's driver times out
        on each (ndicapi: 5 s). 0: silent from power-on, not even the probe at connection is
        answered. None: always answers.
    out_of_volume, partly_out_of_volume : tuple of str
        Sensors out of the field generator's volume (port status bit 6), or partly out of it
        (bit 7)...
    out_of_volume_after_s : float
        ...from this long after ``TSTART``...
    out_of_volume_for_s : float or None
        ...for this long (None: to the end).
    """

    missing: tuple = ()
    missing_after_s: float = 0.0
    silent_after_s: float | None = None
    out_of_volume: tuple = ()
    partly_out_of_volume: tuple = ()
    out_of_volume_after_s: float = 0.0
    out_of_volume_for_s: float | None = None

    def volume_bits(self, sensor: str, since_start_s: float | None) -> int:
        """Port status bits 6/7 of ``sensor`` at ``since_start_s`` after ``TSTART`` (None: not tracking)."""
        if since_start_s is None or since_start_s < self.out_of_volume_after_s or (
                self.out_of_volume_for_s is not None
                and since_start_s >= self.out_of_volume_after_s + self.out_of_volume_for_s):
            return 0
        return ((PORT_OUT_OF_VOLUME if sensor in self.out_of_volume else 0)
                | (PORT_PARTLY_OUT_OF_VOLUME if sensor in self.partly_out_of_volume else 0))


class _Unit:
    """The System Control Unit's state machine (runs in the emulator's process)."""

    def __init__(self, handles: dict[str, int], shared, faults: AuroraFaults, rate_hz: float,
                 firmware: str = "AURORA Rev 008") -> None:
        self.firmware = firmware
        self.handles = handles
        self.shared = shared
        self.faults = faults
        self.rate_hz = rate_hz
        self.dead = False
        self.reset()

    def reset(self) -> None:
        """Back to setup mode with every port handle offered again, as after power-up.

        Every session opens with ``INIT`` (ndicapi's ``ndiOpen`` sends it, after a serial
        break if the unit does not answer), so a unit that kept the last session's
        initialised and enabled handles would list none to the next one (``PHSR:02`` and
        ``PHSR:03`` empty) and the host would find no tools.
        """
        self.initialised: set[int] = set()
        self.enabled: set[int] = set()
        self.t_start: float | None = None

    def frame(self) -> int:
        return 0 if self.t_start is None else int((time.monotonic() - self.t_start) * self.rate_hz)

    def handle(self, line: str) -> bytes | None:
        name, sep, rest = line.partition(":")
        if not sep:
            return reply("ERROR01")  # invalid command
        if name == "GETINFO":  # the probe asks for the firmware feature list
            return reply("Features.Firmware.Version=008")
        body = f"{name}:{rest[:-4]}"
        if len(rest) < 4 or ndi_crc16(body) != int(rest[-4:], 16):
            return reply("ERROR04")  # bad CRC
        arg = rest[:-4]
        if name == "INIT":  # a new session: nothing of the previous one's set-up survives
            self.reset()
            return reply("OKAY")
        if name in ("COMM", "TSTOP"):
            if name == "TSTOP":
                self.t_start = None
            return reply("OKAY")
        if name == "VER":
            return reply(f"Aurora Control Unit\nFreeze Tag: {self.firmware}\nendocal emulator\n")
        if name == "PHSR":
            kind = arg[:2] or "00"
            all_h = sorted(self.handles.values())
            pick = {"00": all_h, "01": [], "02": [h for h in all_h if h not in self.initialised],
                    "03": [h for h in all_h if h in self.initialised and h not in self.enabled],
                    "04": sorted(self.enabled)}.get(kind, all_h)
            return reply(f"{len(pick):02X}" + "".join(f"{h:02X}001" for h in pick))
        if name == "PINIT":
            self.initialised.add(int(arg[:2], 16))
            return reply("OKAY")
        if name == "PENA":
            self.enabled.add(int(arg[:2], 16))
            return reply("OKAY")
        if name == "TSTART":
            self.t_start = time.monotonic()
            return reply("OKAY")
        if name == "TX":
            return reply(self._tx(_reply_option(arg)))
        if name == "BX":
            return self._bx(_reply_option(arg))
        return reply("ERROR01")

    def _tx(self, option: int) -> str:
        n = self.frame()
        parts = [f"{len(self.handles):02X}"]
        for h, seen, pos, quat, bits in self._poses(option):
            pose = tx_transform(pos, quat, 0.0 if not bits else 0.5) if seen else "MISSING"
            parts.append(f"{h:02X}{pose}{(PORT_SEEN if seen else PORT_MISSING) | bits:08X}{n:08X}\n")
        parts.append("0000")  # system status
        return "".join(parts)

    def _poses(self, option: int):
        """Per sensor: handle, whether a transform is sent, position (3), quaternion (4) and the
        out-of-volume bits of its port status."""
        values = list(self.shared)
        since = None if self.t_start is None else time.monotonic() - self.t_start
        out = []
        for k, sensor in enumerate(SENSOR_SLOTS):
            h = self.handles[sensor]
            chunk = values[8 * k:8 * k + 8]
            lost = sensor in self.faults.missing and (
                self.faults.missing_after_s <= 0 or (since is not None and since >= self.faults.missing_after_s))
            seen = chunk[7] > 0 and not lost and h in self.enabled
            bits = self.faults.volume_bits(sensor, since) if seen else 0
            pos = chunk[0:3]
            if bits:  # a distorted reading, or none unless the host asked for transforms out of volume
                seen = bool(option & REPLY_OUT_OF_VOLUME)
                pos = [p + d for p, d in zip(pos, DEGRADED_MM)]
            out.append((h, seen, pos, chunk[3:7], bits))
        return out

    def _bx(self, option: int) -> bytes:
        """A BX reply (binary): header ``C4 A5``, body length, header CRC; per handle its handle,
        status (1 valid, 2 missing), q0 qx qy qz x y z error as float32, port status and frame
        number (uint32); system status (uint16); CRC of everything before (all little endian)."""
        n = self.frame()
        body = bytearray((len(self.handles),))
        for h, seen, pos, quat, bits in self._poses(option):
            body += bytes((h, 0x01 if seen else 0x02))
            if seen:
                body += struct.pack("<8f", *quat, *pos, 0.0 if not bits else 0.5)
            body += struct.pack("<II", (PORT_SEEN if seen else PORT_MISSING) | bits, n)
        body += struct.pack("<H", 0)
        head = b"\xc4\xa5" + struct.pack("<H", len(body))
        frame = head + struct.pack("<H", ndi_crc16(head)) + bytes(body)
        return frame + struct.pack("<H", ndi_crc16(frame))

    def silent(self) -> bool:
        f = self.faults.silent_after_s
        if f is None:
            return False
        if f <= 0:  # off from power-on: not even INIT is answered
            return True
        if self.t_start is not None and time.monotonic() - self.t_start >= f:
            self.dead = True  # it stays off: no later command (TSTOP, INIT) brings it back
        return self.dead


def _reply_option(arg: str) -> int:
    """The reply option of a ``TX``/``BX`` command (four hex digits; 0001 when absent or unreadable)."""
    try:
        return int(arg[:4], 16) if arg else 0x0001
    except ValueError:
        return 0x0001


def _serve(master: int, handles: dict, shared, faults: AuroraFaults, rate_hz: float, firmware: str, stop,
           ready) -> None:
    unit = _Unit(handles, shared, faults, rate_hz, firmware)
    buf = b""
    ready.set()
    while not stop.is_set():
        try:
            r, _, _ = select.select([master], [], [], 0.05)
            if not r:
                continue
            buf += os.read(master, 4096)
        except OSError:
            return
        while b"\r" in buf:
            line, buf = buf.split(b"\r", 1)
            if unit.silent():
                continue
            out = unit.handle(line.decode("ascii", errors="replace").strip())
            if out:
                try:
                    os.write(master, out)
                except OSError:
                    return


class AuroraEmulator:
    """An Aurora with a tip and a base 6-DoF sensor, served from a child process.

    Parameters
    ----------
    tip_port_handle, base_port_handle : int
        Port handles the sensors appear on (the rig TOML's ``tracker.*_port_handle``).
    rate_hz : float
        Frame rate (the Aurora's: 40 Hz).
    faults : AuroraFaults, optional
    firmware : str
        What ``VER`` reports after "Freeze Tag:". scikit-surgerynditracker reads frames with
        ``TX`` (ASCII) from "AURORA Rev 007/008" and with ``BX`` (binary, float32) otherwise;
        both are served.
    """

    def __init__(self, tip_port_handle: int = 0x0A, base_port_handle: int = 0x0B, *, rate_hz: float = 40.0,
                 faults: AuroraFaults | None = None, firmware: str = "AURORA Rev 008") -> None:
        self.firmware = firmware
        self.handles = {"tip": tip_port_handle, "base": base_port_handle}
        self.rate_hz = rate_hz
        self.faults = faults or AuroraFaults()
        ctx = mp.get_context("fork")
        self._shared = ctx.Array("d", 8 * len(SENSOR_SLOTS), lock=False)  # x y z qw qx qy qz seen, per sensor
        self._stop = ctx.Event()
        self._ready = ctx.Event()
        self._ctx = ctx
        self._proc = None
        self._master = self._slave = None
        self.port = ""
        self.set_poses({"tip": ((0.0, 0.0, 60.0), (1.0, 0.0, 0.0, 0.0)), "base": ((0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0))})

    def set_poses(self, poses: dict) -> None:
        """Sensor -> ``(position_mm (3,), quaternion_wxyz (4,))``, or None for a sensor not seen."""
        for k, sensor in enumerate(SENSOR_SLOTS):
            pose = poses.get(sensor)
            if pose is None:
                self._shared[8 * k + 7] = 0.0
                continue
            pos, quat = pose
            self._shared[8 * k:8 * k + 7] = [*map(float, pos), *map(float, quat)]
            self._shared[8 * k + 7] = 1.0

    def start(self) -> AuroraEmulator:
        self._master, self._slave, self.port = open_raw_pty()
        self._proc = self._ctx.Process(target=_serve, name="aurora-emulator", daemon=True,
                                       args=(self._master, self.handles, self._shared, self.faults, self.rate_hz,
                                             self.firmware, self._stop, self._ready))
        self._proc.start()
        self._ready.wait(5.0)
        return self

    def close(self) -> None:
        self._stop.set()
        if self._proc is not None:
            self._proc.join(timeout=2.0)
            if self._proc.is_alive():
                self._proc.kill()
        close_fds(self._master, self._slave)
        self._proc = self._master = self._slave = None

    def __enter__(self) -> AuroraEmulator:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.close()
