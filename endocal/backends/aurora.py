"""NDI Aurora electromagnetic tracker: two 6-DoF sensors at the tip and base of the bending section.

The thesis places one Aurora 6-DoF sensor at each end of the bending section (summary,
section 2.2) and turns their positions into bending angles with its equation 1. This
module reads the tracker through ``scikit-surgerynditracker`` (an optional extra:
``pip install 'endocal-toolkit[aurora]'``), converts each ``sensor2tracker`` 4x4 matrix
into a position in mm and a unit quaternion ``(qw, qx, qy, qz)``, and delivers frames
in the tracker-stream layout of :mod:`endocal.backends.base`.

Frames are read by a background thread at the tracker rate (Aurora: 40 Hz) and stamped
on the run's monotonic clock (the midpoint of the ``get_frame`` call, so half the serial
round trip is the stamp's uncertainty); a frame whose frame number did not change since
the last read is a repeat and is dropped.

Every row also carries the sensor's port status as the Aurora reported it in the same reply
(NDI Combined API, "TX" and "BX" replies: bit 6 out of the field generator's volume, bit 7
partly out of it), which scikit-surgerynditracker leaves out of its frames and
:class:`PortStatusTracker` reads from ndicapi, and its meaning in words: ``status`` is
``ok``, ``missing`` (no transform, or NaN), ``out_of_volume`` or ``partly_out_of_volume``.
Out of volume the Aurora still sends a transform (scikit-surgerynditracker asks for those,
reply option ``0800``), degraded; only ``ok`` rows are ``valid``, every other row is kept
in the stream, flagged, and left out of the aligned table.

A tracker that stops answering altogether (the System Control Unit loses power, a cable comes
out) is told apart from a lost sensor: no frame at all, from either sensor, for
``tracker.max_lost_s`` stops the run naming the tracker, not a sensor. ndicapi waits 5 s for
each reply before it gives up (``Error 0x0103: Device->host communication timeout``), so a dead
unit would hold :meth:`AuroraTracker.close` for a reply per command it sends (14 s were
measured); the close is run in a daemon thread and waited for :data:`CLOSE_TIMEOUT_S` only, and
what it could not finish is logged (logger ``endocal.backends.aurora``) and kept in
:attr:`AuroraTracker.close_notes`, never raised.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from endocal.backends.base import SENSORS, TRACKER_COLUMNS
from endocal.errors import ConfigError, HardwareError
from endocal.streams import DROPOUT_STATUSES

#: The hardware tracker stream: the run format's columns, then each sensor's ``status`` in words
#: and the ``port_status`` bits the Aurora reported (-1: none reported)
HARDWARE_TRACKER_COLUMNS = (*TRACKER_COLUMNS, "status", "port_status")
INSTALL_HINT = "pip install 'endocal-toolkit[aurora]'"
# Port status bits of a TX/BX reply (NDI Combined API; ndicapi's NDI_OUT_OF_VOLUME, NDI_PARTIALLY_IN_VOLUME)
PORT_OUT_OF_VOLUME = 0x40
PORT_PARTLY_OUT_OF_VOLUME = 0x80
PORT_STATUS_UNKNOWN = -1  # the tracker object gave none (a stand-in without ndicapi)
#: ``status`` of a tracker row: what the sensor's pose and port status say, in words
STATUS_OK = "ok"
STATUS_MISSING, STATUS_OUT, STATUS_PARTLY = DROPOUT_STATUSES
STATUS_REASONS = {STATUS_MISSING: "missing: no transform", STATUS_OUT: "out of the field generator's volume",
                  STATUS_PARTLY: "partly out of the field generator's volume",
                  STATUS_OK: "no frame read since its last valid pose"}
#: How long :meth:`AuroraTracker.close` waits for the tracker to stop and its port to close (s); a unit
#: that does not answer is left to ndicapi's own timeouts in a daemon thread
CLOSE_TIMEOUT_S = 1.0
#: What to check when the tracker stops answering (the NDI Aurora's user guide: the System Control
#: Unit's power switch and its USB/serial link to the host)
SILENT_ADVICE = ("check the System Control Unit's power (is it switched on, its lights lit?) and the USB or serial "
                 "cable between it and this computer")
_log = logging.getLogger(__name__)
_log.addHandler(logging.NullHandler())  # a library logs; the application decides where it goes
TRACKER_KEYS = {"serial_port", "tip_port_handle", "base_port_handle", "rom_files", "rate_hz", "detect_timeout_s",
                "max_lost_s"}


def matrix_to_pose(sensor2tracker) -> tuple[np.ndarray, np.ndarray]:
    """Position (mm) and unit quaternion ``(qw, qx, qy, qz)`` of homogeneous 4x4 transforms.

    Parameters
    ----------
    sensor2tracker : array_like, shape (4, 4) or (n, 4, 4)
        Rigid transforms with translation in mm (the Aurora reports mm).

    Returns
    -------
    pos_mm : ndarray, shape (n, 3)
    quat_wxyz : ndarray, shape (n, 4)
        Scalar first, normalised, with ``qw >= 0`` (``q`` and ``-q`` are the same rotation;
        the sign is fixed so that logged streams do not flip). Rows whose matrix holds a
        NaN are NaN.

    Notes
    -----
    Shepperd's method: take the square root of the largest of ``1 + trace`` and
    ``1 + 2 R_ii - trace`` so the division never goes through a small number.
    """
    m = np.asarray(sensor2tracker, dtype=float)
    if m.ndim == 2:
        m = m[None]
    if m.shape[1:] != (4, 4):
        raise ValueError(f"expected (n, 4, 4) transforms, got shape {m.shape}")
    pos = m[:, :3, 3].copy()
    r = m[:, :3, :3]
    n = m.shape[0]
    q = np.full((n, 4), np.nan)
    ok = np.isfinite(m).all(axis=(1, 2))
    tr = np.trace(r, axis1=1, axis2=2)
    for k in np.flatnonzero(ok):
        rk = r[k]
        cand = (tr[k], rk[0, 0], rk[1, 1], rk[2, 2])
        i = int(np.argmax(cand))
        if i == 0:
            s = 2.0 * math.sqrt(max(1.0 + tr[k], 0.0))
            w, x, y, z = 0.25 * s, (rk[2, 1] - rk[1, 2]) / s, (rk[0, 2] - rk[2, 0]) / s, (rk[1, 0] - rk[0, 1]) / s
        elif i == 1:
            s = 2.0 * math.sqrt(max(1.0 + 2.0 * rk[0, 0] - tr[k], 0.0))
            w, x, y, z = (rk[2, 1] - rk[1, 2]) / s, 0.25 * s, (rk[0, 1] + rk[1, 0]) / s, (rk[0, 2] + rk[2, 0]) / s
        elif i == 2:
            s = 2.0 * math.sqrt(max(1.0 + 2.0 * rk[1, 1] - tr[k], 0.0))
            w, x, y, z = (rk[0, 2] - rk[2, 0]) / s, (rk[0, 1] + rk[1, 0]) / s, 0.25 * s, (rk[1, 2] + rk[2, 1]) / s
        else:
            s = 2.0 * math.sqrt(max(1.0 + 2.0 * rk[2, 2] - tr[k], 0.0))
            w, x, y, z = (rk[1, 0] - rk[0, 1]) / s, (rk[0, 2] + rk[2, 0]) / s, (rk[1, 2] + rk[2, 1]) / s, 0.25 * s
        qk = np.array([w, x, y, z])
        qk /= np.linalg.norm(qk)
        q[k] = qk if qk[0] >= 0 else -qk
    pos[~ok] = np.nan
    return pos, q


@dataclass(frozen=True)
class AuroraConfig:
    """Which tracker port and which tool is which sensor.

    Parameters
    ----------
    serial_port : str
        Serial device of the Aurora System Control Unit, or ``"auto"`` to probe the ports.
    tip_port_handle, base_port_handle : int
        NDI port handles of the tip and base sensors (as listed by
        ``NDITracker.get_tool_descriptions()``; wired Aurora tools are found automatically).
    rom_files : tuple of str
        Tool definition (.rom) files, for tools that carry no SROM of their own. Each must
        exist; they are handed to the tracker as ``romfiles`` and recorded in ``run.json``.
    rate_hz : float
        How often the background thread asks for a frame (the Aurora measures at 40 Hz).
    detect_timeout_s : float
        How long :meth:`AuroraTracker.open` waits for both sensors to report a valid pose.
    max_lost_s : float
        A sensor that reports no valid pose for this long during a run (unplugged, out of the
        field volume) stops the run: bending angles cannot be measured without it.
    """

    tip_port_handle: int
    base_port_handle: int
    serial_port: str = "auto"
    rom_files: tuple[str, ...] = ()
    rate_hz: float = 40.0
    detect_timeout_s: float = 2.0
    max_lost_s: float = 1.0

    def __post_init__(self) -> None:
        if self.tip_port_handle == self.base_port_handle:
            raise ConfigError(f"tracker: tip and base use the same port handle {self.tip_port_handle}")
        if not 0 < self.rate_hz <= 1000:
            raise ConfigError(f"tracker: rate_hz must be in (0, 1000], got {self.rate_hz}")
        if not self.detect_timeout_s > 0:
            raise ConfigError(f"tracker: detect_timeout_s must be positive, got {self.detect_timeout_s}")
        if not self.max_lost_s > 0:
            raise ConfigError(f"tracker: max_lost_s must be positive, got {self.max_lost_s}")

    @property
    def handles(self) -> dict[str, int]:
        """Sensor name (``tip``, ``base``) -> port handle."""
        return {"tip": self.tip_port_handle, "base": self.base_port_handle}

    def settings(self) -> dict:
        """The ``NDITracker`` configuration dictionary."""
        s: dict[str, Any] = {"tracker type": "aurora", "use quaternions": False}
        if self.serial_port != "auto":
            s["serial port"] = self.serial_port
        if self.rom_files:
            s["romfiles"] = list(self.rom_files)
        return s

    @classmethod
    def from_dict(cls, d: dict, where: str, base_dir: Path | None = None) -> AuroraConfig:
        """Build from the ``[tracker]`` table of a rig TOML; relative ROM paths are relative to the file."""
        unknown = sorted(set(d) - TRACKER_KEYS)
        if unknown:
            raise ConfigError(
                f"{where} [tracker]: unknown key '{unknown[0]}' (known keys: {', '.join(sorted(TRACKER_KEYS))})"
            )
        for key in ("tip_port_handle", "base_port_handle"):
            if key not in d:
                raise ConfigError(
                    f"{where} [tracker]: missing key '{key}' (the NDI port handle of that sensor, e.g. 0x0A)"
                )
        roms = []
        for rom in d.get("rom_files", []):
            path = Path(rom)
            if base_dir is not None and not path.is_absolute():
                path = base_dir / path
            if not path.is_file():
                raise ConfigError(f"{where} [tracker]: ROM file {path} does not exist")
            roms.append(str(path))
        try:
            return cls(
                tip_port_handle=int(d["tip_port_handle"]),
                base_port_handle=int(d["base_port_handle"]),
                serial_port=str(d.get("serial_port", "auto")),
                rom_files=tuple(roms),
                rate_hz=float(d.get("rate_hz", 40.0)),
                detect_timeout_s=float(d.get("detect_timeout_s", 2.0)),
                max_lost_s=float(d.get("max_lost_s", 1.0)),
            )
        except ConfigError as exc:
            raise ConfigError(f"{where}: {exc}") from None
        except (TypeError, ValueError) as exc:
            raise ConfigError(f"{where} [tracker]: {exc}") from None


#: How scikit-surgerynditracker (1.0) begins the error of a port on which ndiProbe got no NDI reply
_NO_ANSWER = ("Could not connect to an NDI device on", "Could not find any NDI device in")


def default_tracker_factory(settings: dict) -> Any:
    """Import ``scikit-surgerynditracker`` lazily and connect an ``NDITracker``.

    Raises
    ------
    HardwareError
        The package is not installed (with the command that installs it), or the
        tracker cannot be reached.
    """
    try:
        from sksurgerynditracker.nditracker import NDITracker
    except ImportError as exc:
        raise HardwareError(
            f"the NDI Aurora backend needs scikit-surgerynditracker, which is not installed ({exc}): {INSTALL_HINT}"
        ) from None
    try:
        tracker = NDITracker(settings)
    except (OSError, ValueError, KeyError) as exc:
        port = settings.get("serial port", "any serial port (auto)")
        msg = " ".join(str(exc).split())
        if msg.startswith(_NO_ANSWER):  # the driver's probe got no reply: its own advice list follows
            raise HardwareError(
                f"NDI Aurora: no answer on {port}: the tracker did not reply to the driver's probe; "
                f"{SILENT_ADVICE}, and that [tracker] serial_port names its port (Linux: the 'dialout' group)"
            ) from None
        raise HardwareError(
            f"cannot connect to the NDI Aurora on {port}: {msg}; check the System Control Unit is on, "
            "the USB/serial cable, and the port (Linux: 'dialout' group)"
        ) from None
    try:
        return PortStatusTracker(tracker)
    except BaseException:
        tracker.close()
        raise


class PortStatusTracker:
    """An ``NDITracker`` whose frames also carry each tool's port status.

    scikit-surgerynditracker reads every frame with ndicapi (``TX:0801`` or ``BX:0801``) and
    returns the transforms only; the port status of each tool in that same reply is read here,
    right after each ``get_frame``, from ndicapi's parse of it (``ndiGetTXPortStatus`` or
    ``ndiGetBXPortStatus``, whichever reply the tracker asked for).

    Parameters
    ----------
    tracker : NDITracker
        Connected. Everything but ``get_frame`` is passed through to it.

    Raises
    ------
    HardwareError
        The installed scikit-surgerynditracker does not keep the ndicapi device, reply kind and
        tools this reads (its 1.0 releases do): frames out of the field volume could not be
        told from good ones, so the tracker is refused rather than read without them.
    """

    def __init__(self, tracker: Any) -> None:
        import ndicapy

        self._tracker = tracker
        device = getattr(tracker, "_device", None)
        capture = getattr(tracker, "_capture_string", None)
        tools = getattr(tracker, "_tool_descriptors", None)
        if device is None or not isinstance(capture, str) or not isinstance(tools, list):
            raise HardwareError(
                f"scikit-surgerynditracker {tracker_package_version()} does not expose the ndicapi device endocal "
                "reads each sensor's port status from (out of the field volume or not): install a 1.0 release "
                f"({INSTALL_HINT})"
            )
        self._status = ndicapy.ndiGetBXPortStatus if capture.startswith("BX") else ndicapy.ndiGetTXPortStatus

    def get_frame(self) -> tuple:
        """``NDITracker.get_frame()``'s five lists and a sixth: port handle -> port status (int)."""
        frame = self._tracker.get_frame()
        t = self._tracker
        status = {int(d["port handle"]): _port_status_bits(self._status(t._device, d["c_str port handle"]))
                  for d in t._tool_descriptors}
        return (*frame, status)

    def shutdown(self) -> None:
        """Stop tracking and close the port, the port exactly once whatever the unit answers.

        ``NDITracker.close`` stops tracking first and closes the port only if that succeeded: on a
        unit that does not answer, ``TSTOP`` times out (5 s), the port stays open, and each later
        ``close`` sends ``TSTOP`` again. Here ``TSTOP`` is sent once (its failure ignored: the
        unit is being let go) and ``ndiClose`` always follows.
        """
        import ndicapy

        t = self._tracker
        device, t._device = t._device, None
        if device is None:
            return
        try:
            if t._state == "tracking":
                ndicapy.ndiCommand(device, "TSTOP:")
        finally:
            t._state = None
            ndicapy.ndiClose(device)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._tracker, name)


def _port_status_bits(raw: int) -> int:
    """The port status as ndicapi returns it, made exact where it can be.

    ndicapi (3.7) assembles a BX reply's 4-byte port status from signed chars, so a byte of
    0x80 or more (partly out of volume sets bit 7) sign-extends over the bytes above it:
    0xB1 comes back as 2**64 - 79. The low byte, which holds bits 0-7 (occupied ... out of
    volume, partly out of volume), is always exact; the others are kept only when intact.
    """
    raw = int(raw)
    return raw & 0xFF if raw < 0 or raw > 0x7FFFFFFF else raw


def sensor_status(port_status: int, pose_ok: bool) -> str:
    """A sensor's frame in words: ``out_of_volume``, ``partly_out_of_volume``, ``missing`` or ``ok``.

    Parameters
    ----------
    port_status : int
        The port status of the TX/BX reply (bit 6 out of volume, bit 7 partly out of volume),
        or :data:`PORT_STATUS_UNKNOWN`.
    pose_ok : bool
        A finite transform was reported.
    """
    if port_status != PORT_STATUS_UNKNOWN and port_status & PORT_OUT_OF_VOLUME:
        return STATUS_OUT
    if port_status != PORT_STATUS_UNKNOWN and port_status & PORT_PARTLY_OUT_OF_VOLUME:
        return STATUS_PARTLY
    return STATUS_OK if pose_ok else STATUS_MISSING


def tracker_package_version() -> str:
    """Installed ``scikit-surgerynditracker`` version, or ``"not installed"``."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("scikit-surgerynditracker")
    except PackageNotFoundError:
        return "not installed"


def _frame_rows(frame, handles: dict[str, int], t_s: float) -> tuple[list[tuple], tuple]:
    """Tracker-stream rows (one per sensor, :data:`HARDWARE_TRACKER_COLUMNS`) and the frame
    numbers of one ``get_frame`` result (a sixth element, handle -> port status, when the
    tracker reports it: :class:`PortStatusTracker`)."""
    port_handles, _timestamps, frame_numbers, tracking, _quality = frame[:5]
    port_status = frame[5] if len(frame) > 5 else {}
    index = {int(h): k for k, h in enumerate(port_handles)}
    rows, numbers = [], []
    for sensor in SENSORS:
        k = index.get(handles[sensor])
        if k is None:
            rows.append((t_s, sensor, *([math.nan] * 7), False, STATUS_MISSING, PORT_STATUS_UNKNOWN))
            numbers.append(None)
            continue
        numbers.append(frame_numbers[k])
        pos, quat = matrix_to_pose(np.asarray(tracking[k], dtype=float).reshape(4, 4))
        bits = int(port_status.get(handles[sensor], PORT_STATUS_UNKNOWN))
        status = sensor_status(bits, bool(np.isfinite(pos).all() and np.isfinite(quat).all()))
        if status == STATUS_MISSING:
            pos[:], quat[:] = math.nan, math.nan
        rows.append((t_s, sensor, *pos[0].tolist(), *quat[0].tolist(), status == STATUS_OK, status, bits))
    return rows, tuple(numbers)


class AuroraTracker:
    """The Aurora with its tip and base sensors, read in a background thread.

    Parameters
    ----------
    config : AuroraConfig
    tracker_factory : callable, optional
        ``settings -> tracker`` with the ``NDITracker`` methods ``start_tracking``,
        ``get_frame``, ``get_tool_descriptions``, ``stop_tracking`` and ``close``
        (default: :func:`default_tracker_factory`; tests inject a fake).
    """

    def __init__(self, config: AuroraConfig, *, tracker_factory: Callable[[dict], Any] | None = None) -> None:
        self.config = config
        self._factory = tracker_factory or default_tracker_factory
        self._tracker = None
        self._tracking = False
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._lock = threading.Lock()
        self._rows: list[tuple] = []
        self._round_trips: list[float] = []  # get_frame durations (s), for the stamp uncertainty
        self._last_valid: dict[str, float] = {}  # sensor -> monotonic time of its last valid pose
        self._last_status: dict[str, str] = {}  # sensor -> status of its last frame
        self._error: BaseException | None = None
        self._last_numbers: tuple | None = None
        self._last_reply = 0.0  # monotonic time of the last frame the tracker answered with
        self._asked_at: float | None = None  # monotonic time of the frame request in flight, if any
        self._driver_error = ""  # the last communication error of a frame request, in words
        self.info: dict = {}
        #: What closing could not do (a unit that did not answer), in words; also logged
        self.close_notes: list[str] = []

    def open(self) -> None:
        """Connect, start tracking and wait until both sensors report a valid pose.

        Raises
        ------
        HardwareError
            Package missing, tracker unreachable, a configured port handle absent, or a
            sensor never seen inside the field volume within ``detect_timeout_s``.
        """
        self._tracker = self._factory(self.config.settings())
        try:
            handles_seen, descriptions = self._tracker.get_tool_descriptions()
        except Exception as exc:  # noqa: BLE001 - any driver failure is a hardware problem here
            raise HardwareError(f"NDI Aurora: cannot list the tools ({exc})") from None
        seen = [int(h) for h in handles_seen]
        self.info = {"port_handles": seen, "tool_descriptions": [str(d) for d in descriptions]}
        for sensor, handle in self.config.handles.items():
            if handle not in seen:
                listed = ", ".join(f"{h} ({h:#04x})" for h in seen) or "none"
                raise HardwareError(
                    f"NDI Aurora: no tool on port handle {handle} ({handle:#04x}) for the {sensor} sensor "
                    f"(tools seen: {listed}); check the sensor is plugged into the Sensor Interface Unit "
                    f"and set tracker.{sensor}_port_handle"
                )
        asked = time.monotonic()
        try:
            self._tracker.start_tracking()
        except OSError as exc:  # ndicapi: no reply (or none it could read) within its timeout
            raise self._silent_error(time.monotonic() - asked, f"TSTART unanswered: {_words(exc)}") from None
        except Exception as exc:  # noqa: BLE001
            raise HardwareError(f"NDI Aurora: cannot start tracking ({exc})") from None
        self._tracking = True
        seen_valid = {s: False for s in SENSORS}
        deadline = time.monotonic() + self.config.detect_timeout_s
        while not all(seen_valid.values()):
            asked = time.monotonic()
            try:
                frame = self._tracker.get_frame()
            except OSError as exc:
                raise self._silent_error(time.monotonic() - asked, f"frame request unanswered: {_words(exc)}") from None
            rows, _ = _frame_rows(frame, self.config.handles, 0.0)
            for row in rows:
                seen_valid[row[1]] = seen_valid[row[1]] or row[9]
                self._last_status[row[1]] = row[10]
            if all(seen_valid.values()):
                break
            if time.monotonic() > deadline:
                lost = [s for s, ok in seen_valid.items() if not ok]
                named = ", ".join(f"{s} (port handle {self.config.handles[s]:#04x})" for s in lost)
                why = "; ".join(f"{s}: {STATUS_REASONS.get(self._last_status.get(s, STATUS_MISSING))}" for s in lost)
                raise HardwareError(
                    f"NDI Aurora: {named} reported no valid pose within {self.config.detect_timeout_s:g} s ({why}); "
                    "check the sensor lies inside the field generator's measurement volume, away from metal"
                )
            time.sleep(1.0 / self.config.rate_hz)

    def start(self, clock: Callable[[], float]) -> None:
        """Start the reader thread; ``clock()`` returns the run's monotonic time in s."""
        if self._thread is not None:
            return
        self._stop.clear()
        self._last_valid = {s: time.monotonic() for s in SENSORS}  # both were seen at open
        self._last_reply = time.monotonic()
        self._thread = threading.Thread(target=self._run, args=(clock,), name="endocal-aurora", daemon=True)
        self._thread.start()

    def _run(self, clock: Callable[[], float]) -> None:
        period = 1.0 / self.config.rate_hz
        next_t = time.monotonic()
        try:
            while not self._stop.is_set():
                t_before = clock()
                self._asked_at = time.monotonic()
                try:
                    frame = self._tracker.get_frame()
                except OSError as exc:
                    # ndicapi found no reply, or none it could read (timeout, bad CRC, a port gone):
                    # ask again; check() names the tracker once nothing has come for max_lost_s
                    self._driver_error = _words(exc)
                    self._asked_at = None
                    self._stop.wait(period)
                    continue
                self._asked_at = None
                self._last_reply = time.monotonic()
                t_after = clock()
                t_s = 0.5 * (t_before + t_after)
                self._round_trips.append(t_after - t_before)
                rows, numbers = _frame_rows(frame, self.config.handles, t_s)
                for row in rows:  # the last valid pose of each sensor, and its last status, for check()
                    self._last_status[row[1]] = row[10]
                    if row[9]:
                        self._last_valid[row[1]] = time.monotonic()
                if numbers != self._last_numbers or None in numbers:
                    self._last_numbers = numbers
                    with self._lock:
                        self._rows.extend(rows)
                next_t += period
                delay = next_t - time.monotonic()
                if delay < 0:  # fell behind (slow serial): re-anchor instead of bursting
                    next_t = time.monotonic()
                    delay = 0.0
                self._stop.wait(delay)
        except BaseException as exc:  # noqa: BLE001 - handed to the main thread by check()
            self._error = exc

    def check(self) -> None:
        """Raise :class:`HardwareError` if the tracker stopped answering, the reader thread died or a
        sensor is lost.

        The tracker stopped answering when no frame at all, from either sensor, has come for
        ``max_lost_s`` (a request still waiting for its reply, or requests that failed): the
        message names the tracker and what to check, not a sensor. A sensor is lost when the
        tracker answers but that sensor has reported no valid pose for ``max_lost_s``: missing,
        out of the field generator's volume or partly out of it (the message says which).
        """
        if self._error is not None:  # not a communication error (those are retried): the reader died
            raise HardwareError(f"NDI Aurora: reading frames failed ({self._error}); check the tracker cable and power")
        now = time.monotonic()
        silent_s = now - self._last_reply
        if self._thread is not None and silent_s > self.config.max_lost_s:
            asked = self._asked_at
            detail = (f"a frame request has waited {now - asked:.1f} s for its reply" if asked is not None
                      else f"the driver: {self._driver_error}" if self._driver_error else "")
            raise self._silent_error(silent_s, detail)
        for sensor, last in self._last_valid.items():
            if now - last > self.config.max_lost_s:
                handle = self.config.handles[sensor]
                reason = STATUS_REASONS.get(self._last_status.get(sensor, STATUS_MISSING))
                raise HardwareError(
                    f"NDI Aurora: the {sensor} sensor (port handle {handle:#04x}) has reported no valid pose for "
                    f"{now - last:.1f} s ({reason}; tracker.max_lost_s = {self.config.max_lost_s:g}): check its cable "
                    "and that it stays inside the field generator's volume"
                )

    def drain(self) -> dict[str, np.ndarray]:
        """Every frame received since the last drain, as tracker-stream columns."""
        with self._lock:
            rows, self._rows = self._rows, []
        return rows_to_columns(rows)

    def _silent_error(self, silent_s: float, detail: str) -> HardwareError:
        """The tracker stopped answering: no frame from either sensor for ``silent_s``."""
        port = self.config.serial_port
        return HardwareError(
            f"NDI Aurora: the tracker stopped answering: no frame from either sensor for {silent_s:.1f} s "
            f"(tracker.max_lost_s = {self.config.max_lost_s:g}; {detail + '; ' if detail else ''}serial port "
            f"{port}): {SILENT_ADVICE}"
        )

    def close(self) -> None:
        """Stop the thread, stop tracking, close the tracker; return within :data:`CLOSE_TIMEOUT_S`. Idempotent.

        The reader thread is joined, tracking stopped and the port closed in a daemon thread, in
        that order (one request at a time on the port: the reader's may still be waiting for its
        reply), which is waited for :data:`CLOSE_TIMEOUT_S`. A tracker that does not answer
        keeps that thread in ndicapi's timeouts (5 s a command) after this returns; it ends with
        them, or with the process. What could not be done is logged and added to
        :attr:`close_notes`; closing never raises for the device, so a run's own error is the
        one that reaches the user.
        """
        self._stop.set()
        thread, self._thread = self._thread, None
        tracker, self._tracker = self._tracker, None
        tracking, self._tracking = self._tracking, False
        if tracker is None and thread is None:
            return
        failures: list[str] = []
        closer = threading.Thread(target=_shut_down, args=(tracker, thread, tracking, failures),
                                  name="endocal-aurora-close", daemon=True)
        started = time.monotonic()
        closer.start()
        closer.join(CLOSE_TIMEOUT_S)
        if closer.is_alive():
            failures.append(f"no answer within {CLOSE_TIMEOUT_S:g} s of closing (stopping tracking, then the "
                            f"port {self.config.serial_port}): left to the driver's timeouts in the background")
        for text in list(failures):
            note = f"NDI Aurora: {text}"
            _log.warning("%s (after %.2f s)", note, time.monotonic() - started)
            self.close_notes.append(note)

    def alignment(self) -> dict:
        """How well frames sit on the motor clock: each is stamped at the middle of its
        ``get_frame`` round trip, so half the round trip bounds the stamp's error."""
        rt = np.asarray(self._round_trips, float)
        if rt.size == 0:
            return {}
        return {"frames_read": int(rt.size), "round_trip_ms_mean": float(1000 * rt.mean()),
                "round_trip_ms_max": float(1000 * rt.max()),
                "stamp_uncertainty_ms": float(500 * np.percentile(rt, 99))}

    def describe(self) -> dict:
        """Configuration, tools seen at open, frame-stamp uncertainty and package version, for ``run.json``."""
        return {
            "serial_port": self.config.serial_port,
            "port_handles": {s: h for s, h in self.config.handles.items()},
            "rom_files": list(self.config.rom_files),
            "rate_hz": self.config.rate_hz,
            "tools_seen": dict(self.info),
            **self.alignment(),
            "scikit-surgerynditracker": tracker_package_version(),
        }


def _words(exc: BaseException) -> str:
    """An exception's message on one line."""
    return " ".join(str(exc).split()) or type(exc).__name__


def _shut_down(tracker: Any, reader: threading.Thread | None, tracking: bool, failures: list[str]) -> None:
    """Join the reader, stop tracking, close the port (in :meth:`AuroraTracker.close`'s daemon thread);
    every failure is appended to ``failures`` in words."""
    if reader is not None:
        reader.join()  # its request in flight ends with a reply or ndicapi's timeout
    if tracker is None:
        return
    try:
        shutdown = getattr(tracker, "shutdown", None)
        if shutdown is not None:  # PortStatusTracker: TSTOP once, the port closed whatever happens
            shutdown()
            return
        try:
            if tracking:
                tracker.stop_tracking()
        finally:
            tracker.close()
    except Exception as exc:  # noqa: BLE001 - let go of the tracker, say what failed
        failures.append(f"closing failed ({_words(exc)})")


_TEXT_COLUMNS = ("sensor", "status")


def rows_to_columns(rows: list[tuple]) -> dict[str, np.ndarray]:
    """Tracker rows ``(t_s, sensor, x, y, z, qw, qx, qy, qz, valid, status, port_status)`` -> column
    arrays (:data:`HARDWARE_TRACKER_COLUMNS`)."""
    kinds = {"valid": bool, "port_status": np.int64, **dict.fromkeys(_TEXT_COLUMNS, object)}
    if not rows:
        return {c: np.empty(0, dtype=kinds.get(c, float)) for c in HARDWARE_TRACKER_COLUMNS}
    by_col = dict(zip(HARDWARE_TRACKER_COLUMNS, zip(*rows)))
    return {c: np.asarray(by_col[c], dtype=kinds.get(c, float)) for c in HARDWARE_TRACKER_COLUMNS}
