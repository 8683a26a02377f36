"""Dynamixel knob servos (XM430-W350-R on RS-485 through a U2D2, Protocol 2.0).

The thesis drives the TEE probe's two bending knobs with one Dynamixel XM430-W350-R
each, 1:1 through a spur gear and disc (thesis summary, section 2.1), over RS-485 via a
U2D2 (section 2.2). This module converts between knob angles and the servo's own units,
and talks to the servos with ``dynamixel_sdk``: one GroupSyncWrite of Goal Position per
tick for all knobs, one GroupSyncRead of Present Current, Velocity and Position (a single
contiguous block, addresses 126-135) per tick.

Units (XM430-W350 e-manual, control table)
------------------------------------------
- position: 4096 ticks per motor revolution (0.088 deg/tick);
- velocity: 0.229 rev/min per unit, i.e. 1.374 deg/s per unit;
- current: 2.69 mA per unit (signed 16-bit).

A knob angle is ``knob_deg = direction * (ticks - zero_ticks) * 360 / 4096 / gear_ratio``
with ``gear_ratio`` motor turns per knob turn (1 on the thesis rig). ``direction`` (+1 or
-1) makes a positive knob angle bend towards the positive half-plane of the probe's axis
convention (see :mod:`endocal.probe`); velocities and currents get the same sign so that
a positive current pushes the knob towards positive angles.

This module never decides what is safe: :mod:`endocal.backends.hardware` checks every
goal against the probe's limits and speeds before it reaches :meth:`KnobServos.write_goals_deg`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from endocal.errors import ConfigError, HardwareError

# --- XM430-W350 control table (e-manual, "Control Table of EEPROM/RAM Area") -------------
ADDR_MODEL_NUMBER = 0  # 2 bytes, R
ADDR_FIRMWARE_VERSION = 6  # 1 byte, R
ADDR_OPERATING_MODE = 11  # 1 byte, RW (EEPROM)
ADDR_MAX_POSITION_LIMIT = 48  # 4 bytes, RW (EEPROM), position control mode only
ADDR_MIN_POSITION_LIMIT = 52  # 4 bytes, RW (EEPROM), position control mode only
ADDR_TORQUE_ENABLE = 64  # 1 byte, RW
ADDR_HARDWARE_ERROR_STATUS = 70  # 1 byte, R
ADDR_GOAL_POSITION = 116  # 4 bytes, RW
ADDR_PRESENT_CURRENT = 126  # 2 bytes, R, signed
ADDR_PRESENT_VELOCITY = 128  # 4 bytes, R, signed
ADDR_PRESENT_POSITION = 132  # 4 bytes, R, signed in extended position mode
LEN_GOAL_POSITION = 4
LEN_PRESENT_BLOCK = 10  # current(2) + velocity(4) + position(4), one sync read

MODEL_XM430_W350 = 1020
#: What an X-series servo's Baud Rate register (address 8, values 0-7) can be set to, bit/s
SERVO_BAUDRATES = (9600, 57600, 115200, 1_000_000, 2_000_000, 3_000_000, 4_000_000, 4_500_000)
SDK_LATENCY_TIMER_MS = 16.0  # what dynamixel-sdk assumes of the USB adapter's latency timer
MODEL_NAMES = {1020: "XM430-W350", 1030: "XM430-W210", 1060: "XL430-W250", 1120: "XM540-W270", 1130: "XM540-W150"}

OPERATING_MODES = {"position": 3, "extended_position": 4}
POSITION_MODE_TICKS = (0, 4095)  # range of Goal Position in position control mode (0-360 deg)
EXTENDED_MODE_TICKS = (-1_048_575, 1_048_575)  # Goal Position range in extended position mode

TICKS_PER_REV = 4096
DEG_PER_TICK = 360.0 / TICKS_PER_REV
RPM_PER_VELOCITY_UNIT = 0.229
DPS_PER_VELOCITY_UNIT = RPM_PER_VELOCITY_UNIT * 360.0 / 60.0  # 1.374 deg/s per unit
MA_PER_CURRENT_UNIT = 2.69

COMM_SUCCESS = 0  # dynamixel_sdk.COMM_SUCCESS
ERRBIT_ALERT = 0x80  # status packet error byte: the servo has a hardware error
TORQUE_OFF_ATTEMPTS = 3
READ_ATTEMPTS = 2  # a sync read is retried once within the tick: a lost reply is recovered, and counted
HARDWARE_ERRORS = {0x01: "input voltage", 0x04: "overheating", 0x08: "motor encoder", 0x10: "electrical shock",
                   0x20: "overload"}


def _hardware_error_text(status: int) -> str:
    """The Hardware Error Status bits in words (XM430 e-manual, address 70)."""
    if status == 0xFF:
        return "unreadable"
    named = [text for bit, text in HARDWARE_ERRORS.items() if status & bit]
    return ", ".join(named) or "no bit set"


# --- unit conversions ---------------------------------------------------------------------
def ticks_to_knob_deg(ticks, zero_ticks: int, direction: int = 1, gear_ratio: float = 1.0) -> np.ndarray:
    """Knob angle in degrees from servo position ticks.

    Parameters
    ----------
    ticks : array_like of int
        Present Position register values (4096 per motor revolution).
    zero_ticks : int
        Register value at which the knob is at 0 deg (probe straight).
    direction : {1, -1}
        Sign turning motor-positive into knob-positive.
    gear_ratio : float
        Motor revolutions per knob revolution (1 on the thesis rig).

    Returns
    -------
    ndarray of float
        Knob angle in deg, same shape as ``ticks``.
    """
    return direction * (np.asarray(ticks, dtype=float) - zero_ticks) * DEG_PER_TICK / gear_ratio


def knob_deg_to_ticks(knob_deg, zero_ticks: int, direction: int = 1, gear_ratio: float = 1.0) -> np.ndarray:
    """Servo Goal Position ticks (rounded to the nearest tick) for knob angles in degrees.

    The inverse of :func:`ticks_to_knob_deg`; the rounding error is at most half a tick,
    0.044 deg of motor angle.
    """
    ticks = zero_ticks + direction * np.asarray(knob_deg, dtype=float) * gear_ratio / DEG_PER_TICK
    return np.rint(ticks).astype(np.int64)


def velocity_units_to_knob_dps(raw, direction: int = 1, gear_ratio: float = 1.0) -> np.ndarray:
    """Knob speed in deg/s from Present Velocity units (0.229 rev/min each)."""
    return direction * np.asarray(raw, dtype=float) * DPS_PER_VELOCITY_UNIT / gear_ratio


def current_units_to_ma(raw, direction: int = 1) -> np.ndarray:
    """Motor current in mA from Present Current units (2.69 mA each), signed like the knob angle."""
    return direction * np.asarray(raw, dtype=float) * MA_PER_CURRENT_UNIT


def to_signed(value: int, n_bytes: int) -> int:
    """Two's-complement reading of an unsigned register value of ``n_bytes`` bytes."""
    bits = 8 * n_bytes
    value &= (1 << bits) - 1
    return value - (1 << bits) if value >= 1 << (bits - 1) else value


def _le_bytes(value: int, n_bytes: int) -> list[int]:
    """Little-endian bytes of a (possibly negative) register value, as Dynamixel packets want."""
    value &= (1 << (8 * n_bytes)) - 1
    return [(value >> (8 * k)) & 0xFF for k in range(n_bytes)]


# --- configuration ------------------------------------------------------------------------
MOTOR_KEYS = {"id", "zero_ticks", "direction", "gear_ratio", "limits_deg", "max_speed_dps"}
DYNAMIXEL_KEYS = {"port", "baudrate", "model_number", "operating_mode", "fast_sync_read",
                  "write_limit_registers", "latency_timer_ms", "motors"}


@dataclass(frozen=True)
class MotorConfig:
    """One knob servo.

    Parameters
    ----------
    axis : str
        Bending axis the servo turns (``ap``, ``ml``, ``ud``, ``lr``, ...).
    id : int
        Dynamixel ID on the bus (0-252).
    zero_ticks : int
        Present Position at which the knob is at 0 deg (probe straight).
    direction : {1, -1}
        +1 when increasing ticks bend the tip towards the axis' positive half-plane.
    gear_ratio : float
        Motor revolutions per knob revolution (1.0 on the thesis rig).
    limits_deg : tuple of float or None
        ``(min, max)`` knob angle in deg for this rig; the tighter of these and the
        probe's knob limits is enforced in software and written to the servo's
        Min/Max Position Limit registers.
    max_speed_dps : float or None
        Fastest knob speed in deg/s this rig allows (the probe's ``max_knob_speed_dps``
        when None, the smaller of the two otherwise).
    """

    axis: str
    id: int
    zero_ticks: int = 2048
    direction: int = 1
    gear_ratio: float = 1.0
    limits_deg: tuple[float, float] | None = None
    max_speed_dps: float | None = None

    def __post_init__(self) -> None:
        where = f"motor '{self.axis}'"
        if not 0 <= self.id <= 252:
            raise ConfigError(f"{where}: id must be 0-252, got {self.id}")
        if self.direction not in (1, -1):
            raise ConfigError(f"{where}: direction must be 1 or -1, got {self.direction}")
        if not (math.isfinite(self.gear_ratio) and self.gear_ratio > 0):
            raise ConfigError(f"{where}: gear_ratio must be positive, got {self.gear_ratio}")
        if self.limits_deg is not None:
            lo, hi = self.limits_deg
            if not lo < 0 < hi:
                raise ConfigError(f"{where}: limits_deg must bracket 0, got ({lo}, {hi})")
        if self.max_speed_dps is not None and not self.max_speed_dps > 0:
            raise ConfigError(f"{where}: max_speed_dps must be positive, got {self.max_speed_dps}")

    def to_ticks(self, knob_deg) -> np.ndarray:
        """Goal Position ticks for knob angles in deg."""
        return knob_deg_to_ticks(knob_deg, self.zero_ticks, self.direction, self.gear_ratio)

    def to_deg(self, ticks) -> np.ndarray:
        """Knob angles in deg for Present Position ticks."""
        return ticks_to_knob_deg(ticks, self.zero_ticks, self.direction, self.gear_ratio)

    def limit_ticks(self, limits_deg: tuple[float, float]) -> tuple[int, int]:
        """``(min, max)`` Position Limit register values for knob limits in deg (direction-aware)."""
        a, b = (int(t) for t in self.to_ticks(np.asarray(limits_deg, dtype=float)))
        return (min(a, b), max(a, b))


@dataclass(frozen=True)
class DynamixelConfig:
    """The servo bus: serial port, baud rate, expected model and one :class:`MotorConfig` per knob.

    Parameters
    ----------
    port : str
        Serial device of the U2D2 (``/dev/ttyUSB0``, ``COM3``).
    baudrate : int
        Bus speed in bit/s; must match every servo's Baud Rate register.
    model_number : int
        Model number every servo must answer a ping with (1020 = XM430-W350).
    operating_mode : {"position", "extended_position"}
        Servo operating mode written at open. Position Limit registers only act in
        ``position`` mode (one turn, ticks 0-4095).
    fast_sync_read : bool
        Use Protocol 2.0 Fast Sync Read (one status packet for all servos; needs recent
        firmware) instead of Sync Read.
    write_limit_registers : bool
        Write the knob limits into Min/Max Position Limit (position mode only).
    latency_timer_ms : float
        The USB adapter's latency timer as the wait for each status packet assumes it: a reply
        is awaited ``2 * latency_timer_ms + 2`` ms plus its bytes' time (dynamixel-sdk's rule,
        which assumes 16 ms, the FTDI default). Raise it for a slow USB hub or a loaded PC (the
        emulated rig, served by a process that shares the CPU, writes 500).
    motors : dict
        Axis name -> :class:`MotorConfig`.
    """

    port: str
    baudrate: int = 57600
    model_number: int = MODEL_XM430_W350
    operating_mode: str = "position"
    fast_sync_read: bool = False
    write_limit_registers: bool = True
    latency_timer_ms: float = SDK_LATENCY_TIMER_MS
    motors: dict[str, MotorConfig] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.operating_mode not in OPERATING_MODES:
            raise ConfigError(
                f"dynamixel: operating_mode must be one of {sorted(OPERATING_MODES)}, got '{self.operating_mode}'"
            )
        if not self.motors:
            raise ConfigError("dynamixel: no [dynamixel.motors.<axis>] section; configure one motor per bending knob")
        seen: dict[int, str] = {}
        for axis, m in self.motors.items():
            if m.id in seen:
                raise ConfigError(f"dynamixel: ID {m.id} is given to both '{seen[m.id]}' and '{axis}'; every servo "
                                  "needs its own ID (set them with Dynamixel Wizard)")
            seen[m.id] = axis
        if self.baudrate not in SERVO_BAUDRATES:
            raise ConfigError(
                f"dynamixel: baudrate {self.baudrate} is not a rate the servos speak; an X-series servo's Baud Rate "
                f"register sets {', '.join(map(str, SERVO_BAUDRATES))} bit/s (factory default 57600): use the one "
                "your servos are set to"
            )
        if not (math.isfinite(self.latency_timer_ms) and 0 < self.latency_timer_ms <= 1000):
            raise ConfigError(f"dynamixel: latency_timer_ms must be in (0, 1000] ms, got {self.latency_timer_ms}")

    @property
    def tick_range(self) -> tuple[int, int]:
        """Goal Position register range of the configured operating mode."""
        return POSITION_MODE_TICKS if self.operating_mode == "position" else EXTENDED_MODE_TICKS

    @classmethod
    def from_dict(cls, d: dict, where: str) -> DynamixelConfig:
        """Build from the ``[dynamixel]`` table of a rig TOML; unknown keys raise :class:`ConfigError`."""
        _reject_unknown(d, DYNAMIXEL_KEYS, f"{where} [dynamixel]")
        if "port" not in d:
            raise ConfigError(f"{where} [dynamixel]: missing key 'port' (the U2D2 serial device, e.g. /dev/ttyUSB0)")
        motors = {}
        for axis, m in d.get("motors", {}).items():
            if not isinstance(m, dict):
                raise ConfigError(f"{where} [dynamixel.motors.{axis}]: must be a table")
            _reject_unknown(m, MOTOR_KEYS, f"{where} [dynamixel.motors.{axis}]")
            if "id" not in m:
                raise ConfigError(f"{where} [dynamixel.motors.{axis}]: missing key 'id'")
            try:
                limits = m.get("limits_deg")
                motors[axis] = MotorConfig(
                    axis=axis,
                    id=int(m["id"]),
                    zero_ticks=int(m.get("zero_ticks", 2048)),
                    direction=int(m.get("direction", 1)),
                    gear_ratio=float(m.get("gear_ratio", 1.0)),
                    limits_deg=None if limits is None else (float(limits[0]), float(limits[1])),
                    max_speed_dps=None if m.get("max_speed_dps") is None else float(m["max_speed_dps"]),
                )
            except ConfigError as exc:
                raise ConfigError(f"{where}: {exc}") from None
            except (TypeError, ValueError, IndexError) as exc:
                raise ConfigError(f"{where} [dynamixel.motors.{axis}]: {exc}") from None
        try:
            return cls(
                port=str(d["port"]),
                baudrate=int(d.get("baudrate", 57600)),
                model_number=int(d.get("model_number", MODEL_XM430_W350)),
                operating_mode=str(d.get("operating_mode", "position")),
                fast_sync_read=_as_bool(d.get("fast_sync_read", False), f"{where} [dynamixel] fast_sync_read"),
                write_limit_registers=_as_bool(
                    d.get("write_limit_registers", True), f"{where} [dynamixel] write_limit_registers"
                ),
                latency_timer_ms=float(d.get("latency_timer_ms", SDK_LATENCY_TIMER_MS)),
                motors=motors,
            )
        except ConfigError as exc:
            raise ConfigError(f"{where}: {exc}") from None
        except (TypeError, ValueError) as exc:
            raise ConfigError(f"{where} [dynamixel]: {exc}") from None


def _reject_unknown(d: dict, known: set[str], where: str) -> None:
    unknown = sorted(set(d) - known)
    if unknown:
        raise ConfigError(f"{where}: unknown key '{unknown[0]}' (known keys: {', '.join(sorted(known))})")


def _as_bool(value: Any, where: str) -> bool:
    if not isinstance(value, bool):
        raise ConfigError(f"{where}: must be true or false, got {value!r}")
    return value


# --- the bus ------------------------------------------------------------------------------
@dataclass
class ServoState:
    """Present state of every knob at one tick (knob units, signed like the knob angle)."""

    pos_deg: dict[str, float]
    vel_dps: dict[str, float]
    current_ma: dict[str, float]


class KnobServos:
    """The knob servos on one Dynamixel bus.

    Parameters
    ----------
    config : DynamixelConfig
        Port, baud rate and motors.
    port_handler, packet_handler : object, optional
        ``dynamixel_sdk`` objects to use instead of ``PortHandler(config.port)`` and
        ``PacketHandler(2.0)`` (tests inject a simulated bus here).

    Notes
    -----
    :meth:`close` turns torque off on every servo (retrying each up to three times,
    clearing a transaction an interrupt left half-done) and is safe to call any number
    of times; it raises :class:`HardwareError` only when a servo could not be reached,
    because the user must then cut its power by hand.
    """

    def __init__(self, config: DynamixelConfig, *, port_handler: Any = None, packet_handler: Any = None) -> None:
        self.config = config
        self._port = port_handler
        self._ph = packet_handler
        self._is_open = False
        self._torque_on = False
        self._sync_write = None
        self._sync_read = None
        self.info: dict[str, dict] = {}
        #: Sync reads that succeeded on their retry (a reply lost or corrupted on the bus).
        self.recovered_reads = 0

    # -- helpers -----------------------------------------------------------------------
    def _where(self, motor: MotorConfig) -> str:
        return f"Dynamixel ID {motor.id} (knob '{motor.axis}') on {self.config.port} at {self.config.baudrate} baud"

    def _comm_text(self, result: int, error: int) -> str:
        parts = []
        if result != COMM_SUCCESS:
            parts.append(str(self._ph.getTxRxResult(result)))
        if error:
            parts.append(str(self._ph.getRxPacketError(error)))
        return "; ".join(parts)

    def _check(self, motor: MotorConfig, what: str, result: int, error: int) -> None:
        if result != COMM_SUCCESS or error:
            raise HardwareError(f"{self._where(motor)}: {what} failed ({self._comm_text(result, error)})")

    def _read(self, motor: MotorConfig, address: int, n_bytes: int, what: str) -> int:
        fn = {1: self._ph.read1ByteTxRx, 2: self._ph.read2ByteTxRx, 4: self._ph.read4ByteTxRx}[n_bytes]
        value, result, error = fn(self._port, motor.id, address)
        self._check(motor, f"reading {what} (address {address})", result, error)
        return int(value)

    def _write(self, motor: MotorConfig, address: int, n_bytes: int, value: int, what: str) -> None:
        fn = {1: self._ph.write1ByteTxRx, 4: self._ph.write4ByteTxRx}[n_bytes]
        raw = value & ((1 << (8 * n_bytes)) - 1)
        result, error = fn(self._port, motor.id, address, raw)
        self._check(motor, f"writing {what} = {value} (address {address})", result, error)

    # -- life cycle --------------------------------------------------------------------
    def open(self) -> None:
        """Open the port, ping every servo, check its model, turn torque off and set the operating mode.

        Raises
        ------
        HardwareError
            The port cannot be opened, a servo does not answer, or answers with another model.
        """
        import dynamixel_sdk as sdk

        if self._port is None:
            self._port = _port_handler(sdk, self.config.port, self.config.latency_timer_ms)
        if self._ph is None:
            self._ph = sdk.PacketHandler(2.0)
        hint = "check the U2D2 is plugged in, the port name, and that you may use it (Linux: the 'dialout' group)"
        try:
            opened = self._port.openPort()
        except Exception as exc:  # pyserial raises SerialException (an OSError) for a missing device
            raise HardwareError(f"cannot open Dynamixel port {self.config.port}: {exc}; {hint}") from None
        if not opened:
            raise HardwareError(f"cannot open Dynamixel port {self.config.port}; {hint}")
        self._is_open = True
        if not self._port.setBaudRate(self.config.baudrate):
            raise HardwareError(
                f"cannot set {self.config.port} to {self.config.baudrate} baud (the U2D2 supports 9600 to 4.5M)"
            )
        expected = self.config.model_number
        for motor in self.config.motors.values():
            model, result, error = self._ph.ping(self._port, motor.id)
            if result != COMM_SUCCESS:
                raise HardwareError(
                    f"{self._where(motor)} did not answer a ping ({self._comm_text(result, error)}): check the "
                    "servo power (12 V), the RS-485 cable, and its ID and baud rate (e.g. with Dynamixel Wizard)"
                )
            if model != expected:
                raise HardwareError(
                    f"{self._where(motor)} answered with model number {model} "
                    f"({MODEL_NAMES.get(model, 'unknown model')}), expected {expected} "
                    f"({MODEL_NAMES.get(expected, 'as configured')}): check the ID or set dynamixel.model_number"
                )
            self.info[motor.axis] = {"id": motor.id, "model_number": int(model),
                                     "model_name": MODEL_NAMES.get(int(model), "unknown")}
        # Torque may have been left on by a crashed program; EEPROM writes below need it off.
        for motor in self.config.motors.values():
            self._write(motor, ADDR_TORQUE_ENABLE, 1, 0, "Torque Enable")
        mode = OPERATING_MODES[self.config.operating_mode]
        for motor in self.config.motors.values():
            info = self.info[motor.axis]
            info["firmware_version"] = self._read(motor, ADDR_FIRMWARE_VERSION, 1, "Firmware Version")
            info["hardware_error_status"] = self._read(motor, ADDR_HARDWARE_ERROR_STATUS, 1, "Hardware Error Status")
            if info["hardware_error_status"]:
                raise HardwareError(
                    f"{self._where(motor)} reports hardware error status {info['hardware_error_status']:#04x} "
                    "(overload, overheating, voltage or encoder): power-cycle or reboot the servo and check the load"
                )
            if self._read(motor, ADDR_OPERATING_MODE, 1, "Operating Mode") != mode:
                self._write(motor, ADDR_OPERATING_MODE, 1, mode, "Operating Mode")
            info["operating_mode"] = self.config.operating_mode
        group = sdk.GroupSyncRead(self._port, self._ph, ADDR_PRESENT_CURRENT, LEN_PRESENT_BLOCK)
        if self.config.fast_sync_read and not hasattr(group, "fastSyncRead"):
            raise HardwareError(
                f"dynamixel.fast_sync_read needs dynamixel-sdk >= 3.8 (installed: {sdk_version()}); "
                "upgrade it or set fast_sync_read = false"
            )
        for motor in self.config.motors.values():
            group.addParam(motor.id)
        self._sync_read = group
        self._sync_write = sdk.GroupSyncWrite(self._port, self._ph, ADDR_GOAL_POSITION, LEN_GOAL_POSITION)

    def write_limit_registers(self, limits_deg: dict[str, tuple[float, float]]) -> dict[str, tuple[int, int]]:
        """Write knob limits into each servo's Min/Max Position Limit registers (torque must be off).

        Only in ``position`` operating mode, where the control table uses them; in extended
        position mode the servo ignores them and only the software check protects the probe.

        Parameters
        ----------
        limits_deg : dict
            Axis -> ``(min, max)`` knob angle in deg.

        Returns
        -------
        dict
            Axis -> ``(min_ticks, max_ticks)`` written (empty when nothing was written).
        """
        if not self.config.write_limit_registers or self.config.operating_mode != "position":
            return {}
        written = {}
        for axis, limits in limits_deg.items():
            motor = self.config.motors[axis]
            lo, hi = motor.limit_ticks(limits)
            self._write(motor, ADDR_MIN_POSITION_LIMIT, 4, lo, "Min Position Limit")
            self._write(motor, ADDR_MAX_POSITION_LIMIT, 4, hi, "Max Position Limit")
            written[axis] = (lo, hi)
            self.info[axis]["position_limit_ticks"] = [lo, hi]
        return written

    def read_state(self) -> ServoState:
        """Present position (deg), velocity (deg/s) and current (mA) of every knob, in one sync read.

        A reply lost or corrupted on the bus is retried once (:data:`READ_ATTEMPTS`), within
        the tick; each recovery is counted (:attr:`recovered_reads`, in :meth:`describe`). A
        status packet with the hardware alert bit (overload, overheating, ...) stops the run:
        the servo has dropped its torque.

        Raises
        ------
        HardwareError
            The sync read failed twice, a servo's data is missing, or a servo raised its alert.
        """
        last = ""
        for attempt in range(READ_ATTEMPTS):
            self._port.is_using = False
            raw, result, alert = (self._fast_sync_read() if self.config.fast_sync_read else self._sync_read_each())
            if result == COMM_SUCCESS:
                if attempt:
                    self.recovered_reads += 1
                break
            last = str(self._ph.getTxRxResult(result))
        else:
            raise HardwareError(
                f"sync read of present position/velocity/current on {self.config.port} failed "
                f"({last}, {READ_ATTEMPTS} tries): check cables and power"
            )
        for axis in alert:
            motor = self.config.motors[axis]
            # the alert bit rides on every status packet now: only the error number counts here
            status, result, error = self._ph.read1ByteTxRx(self._port, motor.id, ADDR_HARDWARE_ERROR_STATUS)
            if result != COMM_SUCCESS or error & ~ERRBIT_ALERT:
                status = 0xFF
            raise HardwareError(
                f"{self._where(motor)} raised its hardware alert (Hardware Error Status {status:#04x}: "
                f"{_hardware_error_text(status)}); the servo has switched its torque off: check the load and the "
                "supply, then reboot it"
            )
        pos, vel, cur = {}, {}, {}
        for axis, motor in self.config.motors.items():
            data = raw.get(axis)
            if data is None or len(data) < LEN_PRESENT_BLOCK:
                raise HardwareError(f"{self._where(motor)}: no data in the sync read reply")
            raw_cur = to_signed(int.from_bytes(bytes(data[0:2]), "little"), 2)
            raw_vel = to_signed(int.from_bytes(bytes(data[2:6]), "little"), 4)
            raw_pos = to_signed(int.from_bytes(bytes(data[6:10]), "little"), 4)
            pos[axis] = float(motor.to_deg(raw_pos))
            vel[axis] = float(velocity_units_to_knob_dps(raw_vel, motor.direction, motor.gear_ratio))
            cur[axis] = float(current_units_to_ma(raw_cur, motor.direction))
        return ServoState(pos, vel, cur)

    def _sync_read_each(self) -> tuple[dict, int, list]:
        """Sync Read: one instruction, one status packet per servo (its error byte checked)."""
        result = self._sync_read.txPacket()
        if result != COMM_SUCCESS:
            return {}, result, []
        raw, alert = {}, []
        for axis, motor in self.config.motors.items():
            data, result, error = self._ph.readRx(self._port, motor.id, LEN_PRESENT_BLOCK)
            if result != COMM_SUCCESS:
                return {}, result, []
            raw[axis] = data
            if error & ERRBIT_ALERT:
                alert.append(axis)
        return raw, COMM_SUCCESS, alert

    def _fast_sync_read(self) -> tuple[dict, int, list]:
        """Fast Sync Read: one status packet for all, ``ERR ID DATA CRC`` per servo."""
        group = self._sync_read
        result = group.fastSyncReadTxPacket()
        if result != COMM_SUCCESS:
            return {}, result, []
        n = len(self.config.motors)
        data, result, _ = self._ph.fastSyncReadRx(self._port, 0xFE, (LEN_PRESENT_BLOCK + 4) * n)
        if result != COMM_SUCCESS:
            return {}, result, []
        by_id = {}
        for k in range(n):
            chunk = data[k * (LEN_PRESENT_BLOCK + 4):(k + 1) * (LEN_PRESENT_BLOCK + 4)]
            if len(chunk) >= 2 + LEN_PRESENT_BLOCK:
                by_id[chunk[1]] = (chunk[0], chunk[2:2 + LEN_PRESENT_BLOCK])
        raw, alert = {}, []
        for axis, motor in self.config.motors.items():
            if motor.id in by_id:
                error, block = by_id[motor.id]
                raw[axis] = block
                if error & ERRBIT_ALERT:
                    alert.append(axis)
        return raw, COMM_SUCCESS, alert

    def write_goals_deg(self, goal_deg: dict[str, float]) -> None:
        """Send one Goal Position per knob in a single GroupSyncWrite.

        The caller has already checked the goals against the probe's limits and speeds.
        """
        group = self._sync_write
        group.clearParam()
        lo, hi = self.config.tick_range
        for axis, motor in self.config.motors.items():
            ticks = int(motor.to_ticks(goal_deg[axis]))
            if not lo <= ticks <= hi:  # the safety check should make this unreachable
                raise HardwareError(f"{self._where(motor)}: goal {ticks} ticks outside the register range {lo}..{hi}")
            group.addParam(motor.id, _le_bytes(ticks, LEN_GOAL_POSITION))
        result = group.txPacket()
        if result != COMM_SUCCESS:
            raise HardwareError(
                f"sync write of goal positions on {self.config.port} failed ({self._ph.getTxRxResult(result)})"
            )

    def torque_on(self) -> None:
        """Hold every knob where it is: Goal Position := Present Position, then Torque Enable := 1."""
        for motor in self.config.motors.values():
            present = to_signed(self._read(motor, ADDR_PRESENT_POSITION, 4, "Present Position"), 4)
            self._write(motor, ADDR_GOAL_POSITION, 4, present, "Goal Position")
        self._torque_on = True  # set before the writes: a failure half-way must still turn torque off
        for motor in self.config.motors.values():
            self._write(motor, ADDR_TORQUE_ENABLE, 1, 1, "Torque Enable")

    def torque_off(self) -> None:
        """Turn torque off on every servo, trying all of them even when one fails.

        Raises
        ------
        HardwareError
            Naming every servo that could not be switched off, when torque had been
            switched on by :meth:`torque_on`.
        """
        if self._port is None or self._ph is None or not self._is_open:
            return
        # Only a failure to switch off a torque we switched on is an emergency; before torque_on
        # (e.g. a servo that never answered its ping) there is nothing to switch off.
        must_succeed = self._torque_on
        # An interrupt (Ctrl-C, SIGTERM) inside a transaction leaves the SDK's port marked busy
        # and half a packet in the buffers; clear both so the torque-off packets go out.
        self._port.is_using = False
        try:
            self._port.clearPort()
        except Exception:  # noqa: BLE001 - clearing is best effort; the writes below report failures
            pass
        failed = []
        # a torque we switched on is retried; before that one try each (a servo that never answered
        # its ping would only make the caller wait out every timeout)
        attempts = TORQUE_OFF_ATTEMPTS if must_succeed else 1
        for motor in self.config.motors.values():
            last = ""
            for _ in range(attempts):
                self._port.is_using = False
                try:
                    result, error = self._ph.write1ByteTxRx(self._port, motor.id, ADDR_TORQUE_ENABLE, 0)
                except Exception as exc:  # noqa: BLE001 - keep trying the other servos
                    last = str(exc)
                    continue
                if result == COMM_SUCCESS:
                    break
                last = self._comm_text(result, error)
            else:
                failed.append(f"ID {motor.id} ('{motor.axis}'): {last}")
        self._torque_on = False
        if failed and must_succeed:
            raise HardwareError(
                f"could not turn torque off on {self.config.port} ({'; '.join(failed)}): CUT THE SERVO POWER NOW"
            )

    @property
    def torque_is_on(self) -> bool:
        return self._torque_on

    def close(self) -> None:
        """Torque off on every servo, then close the port. Idempotent."""
        if not self._is_open:
            return
        try:
            self.torque_off()
        finally:
            self._is_open = False
            try:
                self._port.closePort()
            except Exception:  # noqa: BLE001 - the port may already be gone (unplugged)
                pass

    def describe(self) -> dict:
        """Port, baud rate, operating mode and per-servo model / firmware as read at open."""
        return {
            "port": self.config.port,
            "baudrate": self.config.baudrate,
            "operating_mode": self.config.operating_mode,
            "fast_sync_read": self.config.fast_sync_read,
            "latency_timer_ms": self.config.latency_timer_ms,
            "recovered_reads": self.recovered_reads,
            "servos": {axis: dict(info) for axis, info in self.info.items()},
        }


def _port_handler(sdk, port: str, latency_timer_ms: float):
    """``sdk.PortHandler(port)`` whose wait for a status packet assumes ``latency_timer_ms``.

    dynamixel-sdk waits ``bytes' time + 2 * LATENCY_TIMER + 2`` ms with ``LATENCY_TIMER = 16``
    fixed for the process; this port handler puts the configured latency in that rule.
    """

    class PortHandler(sdk.PortHandler):
        def setPacketTimeout(self, packet_length):
            self.packet_start_time = self.getCurrentTime()
            self.packet_timeout = self.tx_time_per_byte * packet_length + 2.0 * latency_timer_ms + 2.0

    return PortHandler(port)


def sdk_version() -> str:
    """Installed ``dynamixel-sdk`` version (``"unknown"`` when its metadata is missing)."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("dynamixel-sdk")
    except PackageNotFoundError:
        return "unknown"
