"""The real rig: Dynamixel knob servos + NDI Aurora tracker (+ an optional UDP translation/rotation stage).

:class:`HardwareBackend` implements the backend contract of :mod:`endocal.backends.base`
on the thesis rig (summary, section 2.2): the two bending knobs on Dynamixel XM430
servos (:mod:`endocal.backends.dynamixel`), two Aurora 6-DoF sensors at the tip and base
of the bending section (:mod:`endocal.backends.aurora`), and translation/rotation on
motors run by a LabVIEW PC reached over UDP (:class:`UdpStage`), or absent.

Safety
------
- A whole run is checked before the rig is opened (:meth:`HardwareBackend.check_plan`,
  which ``endocal excite`` calls), and every chunk again *before any of it moves*: finite
  values, the tighter of the probe's and the rig's limits, and the fastest speed allowed per
  DoF (including the step from the previous chunk's last goal, and from the present position
  at the first chunk); a violation refuses the whole chunk with
  :class:`~endocal.errors.LimitError` naming the axis, time, value and limit.
- Knob limits are also written into the servos' Min/Max Position Limit registers
  (position control mode), so the servo itself refuses goals beyond them.
- Torque goes off on every exit path: :meth:`HardwareBackend.close` (idempotent), the
  context manager, and, while open, an ``atexit`` hook and SIGTERM/SIGHUP handlers that
  turn torque off, then unwind with :class:`~endocal.errors.StopSignal` (a ``SystemExit``
  with code 128 + the signal number) so the caller's ``finally`` blocks still run. Ctrl-C
  raises ``KeyboardInterrupt`` as usual, and the caller's ``finally``/``with`` closes the
  backend.

UDP stage protocol, version 1 (ASCII, one datagram per message, numbers in the DoF's unit)
------------------------------------------------------------------------------------------
host -> stage: ``GOAL <seq> <translation_mm> <rotation_deg>``, ``READ <seq>`` or ``STOP <seq>``;
stage -> host: ``POS <seq> <translation_mm> <rotation_deg> [<translation_current_ma> <rotation_current_ma>]``
answering ``GOAL`` and ``READ`` (``STOP`` needs no answer: the stage holds or disables its drives).
Documented in full, with an emulator, in :mod:`endocal.emulate.stage`.
"""

from __future__ import annotations

import atexit
import math
import signal
import socket
import threading
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from endocal.backends.aurora import AuroraConfig, AuroraTracker, tracker_package_version
from endocal.backends.base import StreamChunk, motor_columns
from endocal.backends.dynamixel import DynamixelConfig, KnobServos, sdk_version
from endocal.backends.limits import check_goals, probe_accel_limits
from endocal.errors import ConfigError, HardwareError, LimitError, ProtocolError, StopSignal
from endocal.files import read_text_document
from endocal.probe import ROTATION, TRANSLATION, ProbeConfig

TOP_KEYS = {"name", "dynamixel", "tracker", "stage", "safety"}
STAGE_KEYS = {"mode", "host", "port", "local_port", "timeout_s", "max_missed_replies", "translation_limits_mm",
              "rotation_limits_deg", "max_translation_speed_mmps", "max_rotation_speed_dps"}
SAFETY_KEYS = {"start_tolerance_deg", "start_tolerance_mm", "home_on_open", "home_speed_dps"}
STAGE_DOFS = (TRANSLATION, ROTATION)
SPIN_S = 0.001  # sleep until this close to a tick, then spin: sleep() alone overshoots by up to ~1 ms


def _reject_unknown(d: dict, known: set[str], where: str) -> None:
    unknown = sorted(set(d) - known)
    if unknown:
        raise ConfigError(f"{where}: unknown key '{unknown[0]}' (known keys: {', '.join(sorted(known))})")


def _pair(value: Any, where: str) -> tuple[float, float] | None:
    if value is None:
        return None
    try:
        lo, hi = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ConfigError(f"{where}: expected [min, max], got {value!r}") from None
    if not lo <= 0 <= hi:
        raise ConfigError(f"{where}: [min, max] must bracket 0, got [{lo}, {hi}]")
    return (lo, hi)


@dataclass(frozen=True)
class StageConfig:
    """Translation/rotation motors: ``absent`` (both DoFs must stay at 0) or a UDP stage.

    Parameters
    ----------
    mode : {"absent", "udp"}
    host, port : str, int
        Address of the LabVIEW PC's UDP listener.
    local_port : int
        Local UDP port to bind (0: any).
    timeout_s : float
        How long to wait for each ``POS`` reply.
    max_missed_replies : int
        Consecutive missing replies tolerated (the last position is held meanwhile)
        before the run stops with :class:`HardwareError`.
    translation_limits_mm, rotation_limits_deg : tuple of float or None
        Rig limits; the tighter of these and the probe's are enforced.
    max_translation_speed_mmps, max_rotation_speed_dps : float
        Fastest commanded speeds.
    """

    mode: str = "absent"
    host: str = "127.0.0.1"
    port: int = 5005
    local_port: int = 0
    timeout_s: float = 0.05
    max_missed_replies: int = 5
    translation_limits_mm: tuple[float, float] | None = None
    rotation_limits_deg: tuple[float, float] | None = None
    max_translation_speed_mmps: float = 10.0
    max_rotation_speed_dps: float = 30.0

    def __post_init__(self) -> None:
        if self.mode not in ("absent", "udp"):
            raise ConfigError(f"stage: mode must be 'absent' or 'udp', got '{self.mode}'")
        if not 0 < self.port < 65536 or not 0 <= self.local_port < 65536:
            raise ConfigError(f"stage: port numbers must be 1-65535, got port {self.port}, local_port {self.local_port}")
        if not self.timeout_s > 0 or self.max_missed_replies < 0:
            raise ConfigError("stage: timeout_s must be positive and max_missed_replies >= 0")
        if not (self.max_translation_speed_mmps > 0 and self.max_rotation_speed_dps > 0):
            raise ConfigError("stage: max speeds must be positive")

    @classmethod
    def from_dict(cls, d: dict, where: str) -> StageConfig:
        _reject_unknown(d, STAGE_KEYS, f"{where} [stage]")
        w = f"{where} [stage]"
        try:
            return cls(
                mode=str(d.get("mode", "absent")),
                host=str(d.get("host", "127.0.0.1")),
                port=int(d.get("port", 5005)),
                local_port=int(d.get("local_port", 0)),
                timeout_s=float(d.get("timeout_s", 0.05)),
                max_missed_replies=int(d.get("max_missed_replies", 5)),
                translation_limits_mm=_pair(d.get("translation_limits_mm"), f"{w} translation_limits_mm"),
                rotation_limits_deg=_pair(d.get("rotation_limits_deg"), f"{w} rotation_limits_deg"),
                max_translation_speed_mmps=float(d.get("max_translation_speed_mmps", 10.0)),
                max_rotation_speed_dps=float(d.get("max_rotation_speed_dps", 30.0)),
            )
        except ConfigError as exc:
            raise ConfigError(f"{where}: {exc}") from None
        except (TypeError, ValueError) as exc:
            raise ConfigError(f"{w}: {exc}") from None


@dataclass(frozen=True)
class SafetyConfig:
    """How a run may start.

    Parameters
    ----------
    start_tolerance_deg, start_tolerance_mm : float
        Largest distance between the present position and the first goal of a run
        (deg for knobs and rotation, mm for translation); beyond it the first chunk is
        refused, because reaching it would be a jump at unbounded speed.
    home_on_open : bool
        After torque on, ramp the knobs to 0 deg at ``home_speed_dps`` (the stage is
        never homed automatically).
    home_speed_dps : float
        Knob speed of that ramp and of :meth:`HardwareBackend.move_to`.
    """

    start_tolerance_deg: float = 2.0
    start_tolerance_mm: float = 1.0
    home_on_open: bool = False
    home_speed_dps: float = 10.0

    def __post_init__(self) -> None:
        if not (self.start_tolerance_deg >= 0 and self.start_tolerance_mm >= 0 and self.home_speed_dps > 0):
            raise ConfigError("safety: tolerances must be >= 0 and home_speed_dps > 0")

    @classmethod
    def from_dict(cls, d: dict, where: str) -> SafetyConfig:
        _reject_unknown(d, SAFETY_KEYS, f"{where} [safety]")
        home = d.get("home_on_open", False)
        if not isinstance(home, bool):
            raise ConfigError(f"{where} [safety] home_on_open: must be true or false, got {home!r}")
        try:
            return cls(
                start_tolerance_deg=float(d.get("start_tolerance_deg", 2.0)),
                start_tolerance_mm=float(d.get("start_tolerance_mm", 1.0)),
                home_on_open=home,
                home_speed_dps=float(d.get("home_speed_dps", 10.0)),
            )
        except ConfigError as exc:
            raise ConfigError(f"{where}: {exc}") from None
        except (TypeError, ValueError) as exc:
            raise ConfigError(f"{where} [safety]: {exc}") from None


@dataclass(frozen=True)
class HardwareConfig:
    """A rig: servo bus, tracker, translation/rotation stage and start-up safety (one TOML file).

    See ``configs/hardware-example.toml`` for every key, and ``docs/how-to/connect-the-rig.md``.
    """

    dynamixel: DynamixelConfig
    tracker: AuroraConfig
    stage: StageConfig = field(default_factory=StageConfig)
    safety: SafetyConfig = field(default_factory=SafetyConfig)
    name: str = "rig"
    source: str = "<dict>"
    raw: dict = field(default_factory=dict, compare=False)

    @classmethod
    def from_dict(cls, d: dict, where: str = "hardware config", base_dir: Path | None = None) -> HardwareConfig:
        """Build from a parsed TOML document; unknown keys raise :class:`ConfigError` naming key and file."""
        _reject_unknown(d, TOP_KEYS, where)
        for section in ("dynamixel", "tracker"):
            if section not in d:
                raise ConfigError(f"{where}: missing section [{section}]")
        for section in ("dynamixel", "tracker", "stage", "safety"):
            if section in d and not isinstance(d[section], dict):
                raise ConfigError(f"{where}: [{section}] must be a table")
        try:
            dynamixel = DynamixelConfig.from_dict(d["dynamixel"], where)
            tracker = AuroraConfig.from_dict(d["tracker"], where, base_dir=base_dir)
            if tracker.serial_port != "auto" and _same_port(dynamixel.port, tracker.serial_port):
                raise ConfigError(
                    f"{where}: [dynamixel] port and [tracker] serial_port are both {dynamixel.port}: the servos' U2D2 "
                    "and the Aurora each need their own serial port (list them with `python -m serial.tools.list_ports`)"
                )
            return cls(
                dynamixel=dynamixel,
                tracker=tracker,
                stage=StageConfig.from_dict(d.get("stage", {}), where),
                safety=SafetyConfig.from_dict(d.get("safety", {}), where),
                name=str(d.get("name", "rig")),
                source=where,
                raw=d,
            )
        except ConfigError:
            raise
        except (TypeError, ValueError, KeyError, IndexError, OverflowError, AttributeError) as exc:
            # a value of the wrong type or size that a section's own checks did not name
            raise ConfigError(f"{where}: a value has the wrong type or size ({type(exc).__name__}: {exc}); "
                              "compare with configs/hardware-example.toml") from None

    @classmethod
    def from_toml(cls, path: str | Path) -> HardwareConfig:
        """Read a rig TOML file.

        Raises
        ------
        ConfigError
            Missing file, invalid TOML, unknown or malformed key (named with the file).
        """
        path = Path(path)
        text = read_text_document(path, "hardware config", ConfigError)
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise ConfigError(f"hardware config {path} is not valid TOML: {exc}") from None
        return cls.from_dict(data, where=str(path), base_dir=path.parent)


def _same_port(a: str, b: str) -> bool:
    """Whether two serial port names are one device (``COM3``/``com3``; a symlink such as
    ``/dev/serial/by-id/...`` and the ``/dev/ttyUSB0`` it points at)."""
    import os

    return a.strip().lower() == b.strip().lower() or os.path.realpath(a) == os.path.realpath(b)


# --- safety check -------------------------------------------------------------------------
# --- translation / rotation over UDP ------------------------------------------------------
class UdpStage:
    """Client for the translation/rotation motors' controller (a LabVIEW PC in the thesis).

    See the module docstring for the datagram protocol. One request, one reply; replies
    carrying an older sequence number are stale and skipped.
    """

    def __init__(self, config: StageConfig) -> None:
        self.config = config
        self._sock: socket.socket | None = None
        self._seq = 0
        self.missed = 0
        self.last: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)

    @property
    def address(self) -> str:
        return f"{self.config.host}:{self.config.port}"

    def open(self) -> tuple[float, float, float, float]:
        """Bind, ask for the present position, and return ``(translation_mm, rotation_deg, i_t_ma, i_r_ma)``.

        Raises
        ------
        HardwareError
            No (valid) reply within ``timeout_s``.
        """
        try:
            self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            self._sock.bind(("", self.config.local_port))
            self._sock.connect((self.config.host, self.config.port))
        except OSError as exc:
            raise HardwareError(f"translation/rotation stage at {self.address}: cannot open a UDP socket ({exc})") from None
        self._sock.settimeout(self.config.timeout_s)
        reply = None
        for _ in range(3):
            reply = self._request(f"READ {self._next_seq()}")
            if reply is not None:
                break
        if reply is None:
            raise HardwareError(
                f"no reply from the translation/rotation stage at {self.address} within "
                f"{self.config.timeout_s:g} s (3 tries): is the LabVIEW VI running and listening on that UDP port, "
                "and does the firewall let UDP through? Use stage.mode = 'absent' to run without it"
            )
        self.last = reply
        return reply

    def _next_seq(self) -> int:
        self._seq += 1
        return self._seq

    def _request(self, message: str) -> tuple[float, float, float, float] | None:
        seq = int(message.split()[1])
        try:
            self._sock.send(message.encode("ascii"))
        except OSError as exc:
            raise HardwareError(f"translation/rotation stage at {self.address}: send failed ({exc})") from None
        deadline = time.monotonic() + self.config.timeout_s
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                return None
            self._sock.settimeout(remaining)
            try:
                data = self._sock.recv(512)
            except (TimeoutError, socket.timeout):
                return None
            except ConnectionRefusedError:  # ICMP port unreachable from a previous send
                return None
            parts = data.decode("ascii", errors="replace").split()
            if len(parts) not in (4, 6) or parts[0] != "POS":
                raise HardwareError(
                    f"translation/rotation stage at {self.address} sent {data[:60]!r}; expected "
                    "'POS <seq> <translation_mm> <rotation_deg> [<i_translation_ma> <i_rotation_ma>]'"
                )
            try:
                r_seq = int(parts[1])
                values = [float(p) for p in parts[2:]] + [0.0] * (6 - len(parts))
            except ValueError:
                raise HardwareError(f"translation/rotation stage at {self.address} sent malformed numbers: {data[:60]!r}") from None
            if r_seq == seq:
                return (values[0], values[1], values[2], values[3])
            # an older reply that arrived late: skip it

    def command(self, translation_mm: float, rotation_deg: float) -> tuple[float, float, float, float]:
        """Send one goal and return the reply; a missing reply holds the last one.

        Raises
        ------
        HardwareError
            More than ``max_missed_replies`` consecutive replies missing.
        """
        reply = self._request(f"GOAL {self._next_seq()} {translation_mm:.6f} {rotation_deg:.6f}")
        if reply is None:
            self.missed += 1
            if self.missed > self.config.max_missed_replies:
                raise HardwareError(
                    f"translation/rotation stage at {self.address} stopped answering "
                    f"({self.missed} replies missing in a row); check the LabVIEW PC and the network"
                )
            return self.last
        self.missed = 0
        self.last = reply
        return reply

    def close(self) -> None:
        """Tell the stage to stop, close the socket. Idempotent."""
        sock, self._sock = self._sock, None
        if sock is None:
            return
        try:
            sock.send(f"STOP {self._next_seq()}".encode("ascii"))
        except OSError:
            pass
        finally:
            sock.close()


# --- the backend --------------------------------------------------------------------------
class LoopTiming:
    """The control loop's timing: set rate, achieved rate, overruns.

    A tick *overruns* when it begins more than :data:`OVERRUN_FRACTION` of a period after its
    deadline (the previous tick's servo and stage traffic took too long, or the process was
    not scheduled); the schedule then slides (``slip_s``) rather than hurrying the next goals.
    """

    #: A tick beginning this fraction of a period late is an overrun.
    OVERRUN_FRACTION = 0.5

    def __init__(self) -> None:
        self.period_s: float | None = None
        self.ticks = 0
        self.overruns = 0
        self.max_late_s = 0.0
        self._first: float | None = None
        self._last: float | None = None

    def set_period(self, period_s: float) -> None:
        self.period_s = period_s

    def tick(self, late_s: float) -> None:
        """Record one tick that began ``late_s`` after its deadline (0 when on time)."""
        now = time.monotonic()
        self._first = now if self._first is None else self._first
        self._last = now
        self.ticks += 1
        self.max_late_s = max(self.max_late_s, late_s)
        if self.period_s is not None and late_s > self.OVERRUN_FRACTION * self.period_s:
            self.overruns += 1

    def describe(self) -> dict:
        achieved = ((self.ticks - 1) / (self._last - self._first)
                    if self.ticks > 1 and self._last > self._first else None)
        return {"set_rate_hz": None if not self.period_s else 1.0 / self.period_s, "achieved_rate_hz": achieved,
                "overruns": self.overruns, "overrun_pct": 100.0 * self.overruns / self.ticks if self.ticks else 0.0,
                "overrun_threshold_s": None if not self.period_s else self.OVERRUN_FRACTION * self.period_s,
                "max_late_ms": 1000.0 * self.max_late_s}


class HardwareBackend:
    """The rig as a :class:`~endocal.backends.base.Backend`: plays goals in real time, logs motors and tracker.

    Parameters
    ----------
    config : HardwareConfig
        The rig (``HardwareConfig.from_toml(path)``).
    probe : ProbeConfig
        The probe mounted on it; its bending axes must be the configured motors' axes.
    port_handler, packet_handler : object, optional
        ``dynamixel_sdk`` port and packet handlers to use instead of the real ones.
    tracker_factory : callable, optional
        ``settings -> NDITracker-like`` object to use instead of ``NDITracker``.

    Attributes
    ----------
    limits : dict
        DoF -> ``(min, max)`` enforced (the tighter of probe and rig).
    max_speed : dict
        DoF -> fastest goal speed enforced (unit/s).
    slip_s : float
        How far the played schedule has slid behind the requested times (s); it grows
        only when the bus or the stage could not keep up, never to catch up by moving faster.

    Examples
    --------
    >>> with HardwareBackend(HardwareConfig.from_toml("rig.toml"), load_probe("tee")) as rig:  # doctest: +SKIP
    ...     chunk = rig.execute(t_s, goal)
    """

    name = "hardware"
    realtime = True

    def __init__(
        self,
        config: HardwareConfig,
        probe: ProbeConfig,
        *,
        port_handler: Any = None,
        packet_handler: Any = None,
        tracker_factory: Callable[[dict], Any] | None = None,
    ) -> None:
        self.config = config
        self.probe = probe
        where = config.source
        motors = config.dynamixel.motors
        if set(motors) != set(probe.bending_axes):
            raise ConfigError(
                f"{where}: [dynamixel.motors] configures {', '.join(sorted(motors))} but probe '{probe.name}' "
                f"bends with {', '.join(probe.bending_axes)}; name one motor per bending axis"
            )
        self.units = {dof: probe.unit(dof) for dof in probe.dofs}
        self.limits: dict[str, tuple[float, float]] = {}
        self.max_speed: dict[str, float] = {}
        lo_t, hi_t = config.dynamixel.tick_range
        for axis in probe.bending_axes:
            m = motors[axis]
            self.limits[axis] = _intersect(probe.limits(axis), m.limits_deg, f"{where}: knob '{axis}'")
            self.max_speed[axis] = min(probe.max_knob_speed_dps, m.max_speed_dps or math.inf)
            a, b = m.limit_ticks(self.limits[axis])
            if a < lo_t or b > hi_t:
                raise ConfigError(
                    f"{where}: knob '{axis}' limits {self.limits[axis]} deg map to ticks {a}..{b} (zero_ticks "
                    f"{m.zero_ticks}), outside {lo_t}..{hi_t} of {config.dynamixel.operating_mode} mode; set "
                    "zero_ticks nearer 2048, narrow limits_deg, or use operating_mode = 'extended_position'"
                )
        stage = config.stage
        self.limits[TRANSLATION] = _intersect(probe.limits(TRANSLATION), stage.translation_limits_mm,
                                              f"{where}: translation")
        self.limits[ROTATION] = _intersect(probe.limits(ROTATION), stage.rotation_limits_deg, f"{where}: rotation")
        self.max_speed[TRANSLATION] = stage.max_translation_speed_mmps
        self.max_speed[ROTATION] = stage.max_rotation_speed_dps
        self.max_accel = probe_accel_limits(probe)
        self.servos = KnobServos(config.dynamixel, port_handler=port_handler, packet_handler=packet_handler)
        self.tracker = AuroraTracker(config.tracker, tracker_factory=tracker_factory)
        self.stage = UdpStage(stage) if stage.mode == "udp" else None
        self.slip_s = 0.0
        self.timing = LoopTiming()
        self.ticks_played = 0
        #: Per-tick hook (:class:`endocal.force.guard.ForceGuard`) or None; see :meth:`attach_guard`.
        self.force_guard = None
        self._guard_reading: tuple | None = None
        self._open = False
        self._t0: float | None = None
        self._previous: tuple | None = None  # (t_s, goals, speeds) of the last tick played
        self._present: dict[str, float] = {}
        self._prev_handlers: dict[int, Any] = {}
        self._atexit_registered = False
        self._stage_prev: dict[str, tuple[float, float]] = {}

    # -- clock ---------------------------------------------------------------------------
    def clock(self) -> float:
        """Seconds on the run's monotonic clock (0 at the end of :meth:`open`)."""
        if self._t0 is None:
            raise HardwareError("the hardware backend is not open")
        return time.monotonic() - self._t0

    # -- life cycle ----------------------------------------------------------------------
    def open(self) -> None:
        """Check every device, write the servo limits, enable torque and start the tracker thread.

        The order keeps the probe unpowered until every check has passed: servos (ping,
        model, torque off, limits), tracker (both sensors seen), stage, then torque on.
        On any failure everything opened so far is closed (torque off) and the error raised.

        Raises
        ------
        HardwareError
            A device is missing, answers wrongly, or a knob rests outside its limits.
        """
        if self._open:
            return
        self._install_safety_net()
        self._open = True
        try:
            self.servos.open()
            self.servos.write_limit_registers({a: self.limits[a] for a in self.probe.bending_axes})
            state = self.servos.read_state()
            for axis, pos in state.pos_deg.items():
                lo, hi = self.limits[axis]
                if not lo <= pos <= hi:
                    raise HardwareError(
                        f"knob '{axis}' rests at {pos:.1f} deg, outside its limits {lo:g}..{hi:g} deg; with the "
                        "power off, turn it back inside by hand (or check zero_ticks and direction)"
                    )
            self.tracker.open()
            present = dict(state.pos_deg)
            if self.stage is not None:
                tr, rot, _, _ = self.stage.open()
                present[TRANSLATION], present[ROTATION] = tr, rot
            else:
                present[TRANSLATION] = present[ROTATION] = 0.0
            self.servos.torque_on()
            self._t0 = time.monotonic()
            self._present = present
            if self.config.safety.home_on_open:
                self.move_to({a: 0.0 for a in self.probe.bending_axes})
            self._t0 = time.monotonic()
            self.tracker.start(self.clock)
        except BaseException:
            self.close()
            raise

    def move_to(self, target: dict[str, float], speed_dps: float | None = None, rate_hz: float = 50.0) -> None:
        """Ramp knobs from their present position to ``target`` (deg) at ``speed_dps``; nothing is logged.

        Use it to bring the knobs to a protocol's first goal before a run. Every ramp goal
        passes the same limit and speed check as a run.

        Parameters
        ----------
        target : dict
            Bending axis -> knob angle in deg.
        speed_dps : float, optional
            Ramp speed (default ``safety.home_speed_dps``), at most the knob's max speed.
        rate_hz : float
            Goal update rate of the ramp.
        """
        self._require_open()
        unknown = set(target) - set(self.probe.bending_axes)
        if unknown:
            raise ProtocolError(f"move_to: {sorted(unknown)} are not bending axes of probe '{self.probe.name}'")
        speed = speed_dps or self.config.safety.home_speed_dps
        state = self.servos.read_state()
        start = {a: state.pos_deg[a] for a in self.probe.bending_axes}
        end = {a: float(target.get(a, start[a])) for a in self.probe.bending_axes}
        distance = max(abs(end[a] - start[a]) for a in start)
        n = max(2, int(math.ceil(distance / speed * rate_hz)) + 1)
        frac = np.linspace(0.0, 1.0, n)
        t = frac * max(distance / speed, 1.0 / rate_hz)
        goals = {a: start[a] + frac * (end[a] - start[a]) for a in start}
        check_goals(t, goals, self.limits, {a: min(speed * 1.01, self.max_speed[a]) for a in start}, self.units)
        t_begin = time.monotonic()
        for i in range(n):
            _wait_until(t_begin + t[i])
            self.servos.write_goals_deg({a: float(goals[a][i]) for a in start})
        self._present.update(end)

    def check_plan(self, t_s: np.ndarray, goal: dict[str, np.ndarray]) -> None:
        """Check a whole run against this rig before it is opened: nothing is sent on any bus.

        The same checks as every chunk of :meth:`execute` gets (finite goals, the tighter of
        the probe's and the rig's limits, speeds and accelerations, no translation/rotation
        without a stage), over the whole run at once, so that a goal beyond the rig's limits
        late in a protocol is refused before the probe moves at all rather than mid-run. Only
        the start check (the first goal against where each DoF rests) waits for :meth:`open`.

        Parameters
        ----------
        t_s : ndarray, shape (n,)
            The run's tick times, s.
        goal : dict
            Every DoF of the probe -> goals, shape (n,), in deg or mm.

        Raises
        ------
        LimitError, ProtocolError
        """
        t = np.asarray(t_s, dtype=float)
        goals = self._validated_goals(t, goal)
        check_goals(t, goals, self.limits, self.max_speed, self.units, None, self.max_accel,
                    refused=f"the run was refused before the rig was opened (limits: the tighter of probe "
                            f"'{self.probe.name}' and {self.config.source})")

    def attach_guard(self, guard) -> None:
        """Step ``guard`` (a :class:`endocal.force.guard.ForceGuard`) at every tick; None detaches.

        Before each goal is written the guard sees the guarded knob's last reading (time,
        angle, speed, current) and may hold that knob's goal back; the motor stream logs the
        goal written.
        """
        self.force_guard = guard
        self._guard_reading = None

    def execute(self, t_s: np.ndarray, goal: dict[str, np.ndarray]) -> StreamChunk:
        """Play one chunk tick by tick, paced to the run clock, and return what was logged.

        Parameters
        ----------
        t_s : ndarray, shape (n,)
            Tick times in s relative to the run start (the end of :meth:`open`).
        goal : dict
            Every DoF of the probe -> goals, shape (n,), in deg (knobs, rotation) or mm
            (translation).

        Returns
        -------
        StreamChunk
            ``motor`` has ``motor_columns(probe)`` and ``tick_late_ms`` (how late each tick
            began against its schedule); its ``t_s`` is when each tick's present state was
            read (run clock); ``tracker`` holds every frame received since the previous chunk.

        Raises
        ------
        LimitError, ProtocolError
            The chunk was refused before any of it moved.
        HardwareError
            A device failed during the chunk (the caller must :meth:`close`).
        """
        self._require_open()
        t = np.asarray(t_s, dtype=float)
        goals = self._validated_goals(t, goal)
        previous = self._previous
        if previous is None:
            self._check_start(t, goals)
        check_goals(t, goals, self.limits, self.max_speed, self.units, previous, self.max_accel)

        n = t.size
        cols = {c: np.zeros(n) for c in motor_columns(self.probe)}
        cols["tick_late_ms"] = np.zeros(n)  # how late each tick began against its schedule
        if n > 1:
            self.timing.set_period(float(np.median(np.diff(t))))
        knobs = self.probe.bending_axes
        for i in range(n):
            deadline = self._t0 + t[i] + self.slip_s
            late_s = time.monotonic() - deadline
            if late_s > 0:
                # Behind schedule: slide the rest of the schedule instead of hurrying, so that no
                # goal step happens faster than the (checked) planned one.
                self.slip_s += late_s
            else:
                _wait_until(deadline)
                late_s = max(0.0, time.monotonic() - deadline)  # the wake-up's own jitter
            self.timing.tick(late_s)
            cols["tick_late_ms"][i] = 1000.0 * late_s
            self.tracker.check()
            knob_goals = {a: float(goals[a][i]) for a in knobs}
            guard = self.force_guard
            if guard is not None and self._guard_reading is not None:  # the last reading decides this goal
                knob_goals[guard.axis] = guard.step(*self._guard_reading, knob_goals[guard.axis])
            self.servos.write_goals_deg(knob_goals)
            if self.stage is not None:
                stage_reply = self.stage.command(float(goals[TRANSLATION][i]), float(goals[ROTATION][i]))
            t_before = self.clock()
            state = self.servos.read_state()
            cols["t_s"][i] = 0.5 * (t_before + self.clock())
            for a in knobs:
                cols[f"{a}_goal_deg"][i] = knob_goals[a]
                cols[f"{a}_pos_deg"][i] = state.pos_deg[a]
                cols[f"{a}_vel_degps"][i] = state.vel_dps[a]
                cols[f"{a}_current_ma"][i] = state.current_ma[a]
            if guard is not None:
                ga = guard.axis
                self._guard_reading = (cols["t_s"][i], state.pos_deg[ga], state.vel_dps[ga], state.current_ma[ga])
            for dof in STAGE_DOFS:
                cols[f"{dof}_goal_{self.units[dof]}"][i] = goals[dof][i]
            if self.stage is not None:
                tr, rot, i_tr, i_rot = stage_reply
                cols["translation_pos_mm"][i], cols["rotation_pos_deg"][i] = tr, rot
                cols["translation_current_ma"][i], cols["rotation_current_ma"][i] = i_tr, i_rot
            last = self._previous
            now_goals = {d: float(goals[d][i]) for d in self.probe.dofs}
            speeds = ({d: (now_goals[d] - last[1][d]) / (float(t[i]) - last[0]) for d in now_goals} if last is not None
                      else dict.fromkeys(now_goals, 0.0))
            self._previous = (float(t[i]), now_goals, speeds)
            self.ticks_played += 1
        if self.stage is not None and n:
            self._stage_velocity(cols)
        self.tracker.check()
        return StreamChunk(motor=cols, tracker=self.tracker.drain())

    def _stage_velocity(self, cols: dict[str, np.ndarray]) -> None:
        """Translation/rotation speeds by finite differences of the reported positions (the stage sends none)."""
        for dof in STAGE_DOFS:
            u = self.units[dof]
            pos, tt = cols[f"{dof}_pos_{u}"], cols["t_s"]
            prev = self._stage_prev.get(dof)
            p = np.concatenate(([prev[1]], pos)) if prev else np.concatenate(([pos[0]], pos))
            q = np.concatenate(([prev[0]], tt)) if prev else np.concatenate(([tt[0] - 1.0], tt))
            cols[f"{dof}_vel_{u}ps"] = np.diff(p) / np.diff(q)
        self._stage_prev = {dof: (cols["t_s"][-1], cols[f"{dof}_pos_{self.units[dof]}"][-1]) for dof in STAGE_DOFS}

    def _validated_goals(self, t: np.ndarray, goal: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        unknown = sorted(set(goal) - set(self.probe.dofs))
        if unknown:
            raise ProtocolError(f"goal names unknown axis '{unknown[0]}' for probe '{self.probe.name}' "
                                f"(it has {', '.join(self.probe.dofs)})")
        missing = [d for d in self.probe.dofs if d not in goal]
        if missing:
            raise ProtocolError(f"goal has no '{missing[0]}' column; the hardware backend needs every DoF "
                                f"({', '.join(self.probe.dofs)})")
        goals = {d: np.asarray(goal[d], dtype=float) for d in self.probe.dofs}
        for d, g in goals.items():
            if g.shape != t.shape:
                raise ProtocolError(f"goal '{d}' has shape {g.shape}, t_s has {t.shape}")
        if self.stage is None:
            for d in STAGE_DOFS:
                moving = np.abs(goals[d]) > 0
                if moving.any():
                    k = int(np.argmax(moving))
                    raise ProtocolError(
                        f"the protocol moves '{d}' (to {goals[d][k]:g} {self.units[d]} at t = {t[k]:.3f} s) but this "
                        f"rig has no translation/rotation stage (stage.mode = 'absent' in {self.config.source}); "
                        "use a protocol on the bending axes only, or configure [stage] mode = 'udp'"
                    )
        return goals

    def _check_start(self, t: np.ndarray, goals: dict[str, np.ndarray]) -> None:
        if not t.size:
            return
        for dof in self.probe.dofs:
            u = self.units[dof]
            tol = self.config.safety.start_tolerance_mm if u == "mm" else self.config.safety.start_tolerance_deg
            here, first = self._present[dof], float(goals[dof][0])
            if abs(first - here) > tol:
                raise LimitError(
                    f"'{dof}' is at {here:.2f} {u} but the first goal (t = {t[0]:.3f} s) is {first:.2f} {u}, more "
                    f"than the start tolerance {tol:g} {u} away: jumping there would exceed the speed limit; "
                    "bring it there first (HardwareBackend.move_to, or safety.home_on_open = true for 0 deg)"
                )

    def _require_open(self) -> None:
        if not self._open or self._t0 is None:
            raise HardwareError("the hardware backend is not open; call open() (or use it as a context manager)")

    def close(self) -> None:
        """Torque off, stop the stage and the tracker, remove the safety net. Safe to call any number of times.

        Torque goes off first, whatever state the other devices are in. The tracker's part
        returns within :data:`endocal.backends.aurora.CLOSE_TIMEOUT_S` even when the Aurora does
        not answer, and never raises: what it could not do is in :attr:`close_notes`.

        Raises
        ------
        HardwareError
            Torque could not be turned off on some servo (cut its power).
        """
        errors: list[BaseException] = []
        try:
            try:
                self.servos.close()  # torque off first: it is what keeps the probe safe
            except BaseException as exc:  # noqa: BLE001 - the stage and tracker must still be closed
                errors.append(exc)
            for device in (self.stage, self.tracker):
                if device is None:
                    continue
                try:
                    device.close()
                except Exception as exc:  # noqa: BLE001
                    errors.append(exc)
        finally:
            self._open = False
            self._remove_safety_net()
        if errors:
            first = errors[0]
            if isinstance(first, HardwareError) or not isinstance(first, Exception):
                raise first
            raise HardwareError(f"closing the hardware backend: {first}") from first

    @property
    def close_notes(self) -> list[str]:
        """What closing could not do without failing the run (an Aurora that did not answer), in words."""
        return list(self.tracker.close_notes)

    def __enter__(self) -> HardwareBackend:
        self.open()
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()

    # -- safety net ----------------------------------------------------------------------
    def _install_safety_net(self) -> None:
        if not self._atexit_registered:
            atexit.register(self._close_at_exit)
            self._atexit_registered = True
        if threading.current_thread() is not threading.main_thread():
            return  # signal handlers can only be set from the main thread; atexit still covers us
        for name in ("SIGTERM", "SIGHUP"):
            signum = getattr(signal, name, None)
            if signum is not None and signum not in self._prev_handlers:
                self._prev_handlers[signum] = signal.signal(signum, self._on_signal)

    def _remove_safety_net(self) -> None:
        if self._atexit_registered:
            atexit.unregister(self._close_at_exit)
            self._atexit_registered = False
        if self._prev_handlers and threading.current_thread() is threading.main_thread():
            for signum, handler in self._prev_handlers.items():
                signal.signal(signum, handler if handler is not None else signal.SIG_DFL)
            self._prev_handlers.clear()

    def _close_at_exit(self) -> None:
        self.close()

    def _on_signal(self, signum: int, frame: Any) -> None:
        # Torque off right here (the interrupted bus transaction is abandoned, close() clears it),
        # then unwind like sys.exit so the caller's finally blocks still flush the run. If torque
        # could not be switched off, that HardwareError ("cut the power") is what propagates.
        self.close()
        raise StopSignal(signum)

    # -- record --------------------------------------------------------------------------
    def describe(self) -> dict:
        """Rig configuration, servo models and firmware, tracker tools and package versions, for ``run.json``."""
        from endocal import __version__

        return {
            "name": self.name,
            "rig": self.config.name,
            "config_file": self.config.source,
            "config": self.config.raw,
            "probe": self.probe.name,
            "limits": {d: list(v) for d, v in self.limits.items()},
            "max_speed": dict(self.max_speed),
            "max_accel": dict(self.max_accel),
            "dynamixel": self.servos.describe(),
            "tracker": self.tracker.describe(),
            "stage": {"mode": self.config.stage.mode,
                      **({"address": self.stage.address} if self.stage is not None else {})},
            "timing": {"ticks_played": self.ticks_played, "slip_s": self.slip_s, **self.timing.describe()},
            "packages": {"endocal-toolkit": __version__, "dynamixel-sdk": sdk_version(),
                         "scikit-surgerynditracker": tracker_package_version()},
        }


def _intersect(probe_limits: tuple[float, float], rig: tuple[float, float] | None, where: str) -> tuple[float, float]:
    lo, hi = probe_limits
    if rig is not None:
        lo, hi = max(lo, rig[0]), min(hi, rig[1])
    if not lo <= 0 <= hi:
        raise ConfigError(f"{where}: limits {lo:g}..{hi:g} do not bracket 0")
    return (float(lo), float(hi))


def _wait_until(deadline: float) -> None:
    """Sleep, then spin the last millisecond, until ``time.monotonic() >= deadline``."""
    while True:
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            return
        if remaining > SPIN_S:
            time.sleep(remaining - SPIN_S)
