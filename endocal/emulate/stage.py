"""An emulated translation/rotation stage on loopback UDP, speaking endocal's stage protocol (version 1).

The thesis's translation and rotation motors are run by a LabVIEW PC that endocal reaches over
UDP (:class:`endocal.backends.hardware.UdpStage`). The datagram format, version 1 (ASCII, one
message per datagram, numbers in the DoF's unit, ``<seq>`` a positive integer the reply echoes):

================================================  =============================================
host -> stage                                     stage -> host
================================================  =============================================
``READ <seq>``                                    ``POS <seq> <translation_mm> <rotation_deg>
                                                  <translation_current_ma> <rotation_current_ma>``
``GOAL <seq> <translation_mm> <rotation_deg>``    ``POS ...`` as above (position after the goal)
``STOP <seq>``                                    none: the stage holds (drives disabled)
================================================  =============================================

A reply whose ``<seq>`` is older than the request's is stale and skipped by the host; a
request that gets no reply within the host's ``timeout_s`` counts as missed, and more than
``max_missed_replies`` missed in a row stop the run (the host's watchdog). The two current
fields may be absent (read as 0). This emulator follows goals with a first-order lag bounded
by a top speed, and can drop replies or fall silent after a time, to test that watchdog.
"""

from __future__ import annotations

import math
import random
import socket
import threading
import time
from dataclasses import dataclass

from endocal.emulate._serving import Served

PROTOCOL_VERSION = 1


@dataclass
class StageFaults:
    """Faults of the emulated stage.

    Attributes
    ----------
    drop_probability : float
        Each reply is dropped with this probability (seeded).
    silent_after_s : float or None
        Stop answering anything this long after the first request.
    delay_s : float
        Hold every reply back this long.
    """

    drop_probability: float = 0.0
    silent_after_s: float | None = None
    delay_s: float = 0.0


class StageEmulator(Served):
    """The stage on ``127.0.0.1:<port>`` (an ephemeral port unless given), in a background thread.

    Parameters
    ----------
    port : int
        UDP port to listen on (0: any free port; read :attr:`port` after :meth:`start`).
    time_constant_s : float
        First-order lag of both axes.
    max_translation_speed_mmps, max_rotation_speed_dps : float
        Top speeds of the emulated drives.
    faults : StageFaults, optional
    seed : int
        Seed of the dropped replies.
    on_event : callable, optional
        Called with one line per event (``stage stopped``, ``stage silent``).
    """

    thread_name = "stage-emulator"

    def __init__(self, port: int = 0, *, time_constant_s: float = 0.05, max_translation_speed_mmps: float = 20.0,
                 max_rotation_speed_dps: float = 60.0, faults: StageFaults | None = None, seed: int = 0,
                 on_event=None) -> None:
        super().__init__()
        self.requested_port = port
        self.time_constant_s = time_constant_s
        self.max_speed = (max_translation_speed_mmps, max_rotation_speed_dps)
        self.faults = faults or StageFaults()
        self.on_event = on_event or (lambda line: None)
        self._rng = random.Random(seed)
        self._sock: socket.socket | None = None
        self._lock = threading.Lock()
        self.position = [0.0, 0.0]
        self.goal = [0.0, 0.0]
        self._t_last: float | None = None
        self._t_first: float | None = None
        self.requests = 0
        self.dropped = 0
        self.stopped = False

    @property
    def port(self) -> int:
        if self._sock is None:
            raise RuntimeError("the stage emulator is not started")
        return self._sock.getsockname()[1]

    def _open(self) -> None:
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.bind(("127.0.0.1", self.requested_port))
        self._sock.settimeout(0.05)

    def _release(self) -> None:
        if self._sock is not None:
            self._sock.close()
        self._sock = None

    def _advance(self, now: float) -> None:
        """Move both axes towards their goals over the time since the last request."""
        if self._t_last is not None and not self.stopped:
            dt = now - self._t_last
            for k in range(2):
                gap = self.goal[k] - self.position[k]
                step = gap * (1.0 - math.exp(-dt / self.time_constant_s)) if self.time_constant_s > 0 else gap
                bound = self.max_speed[k] * dt
                self.position[k] += max(-bound, min(bound, step))
        self._t_last = now

    def _serve(self) -> None:
        silent_said = False
        while not self._stop.is_set():
            try:
                data, addr = self._sock.recvfrom(512)
            except (TimeoutError, socket.timeout):
                continue
            except OSError:
                return
            now = time.monotonic()
            if self._t_first is None:
                self._t_first = now
            f = self.faults
            if f.silent_after_s is not None and now - self._t_first >= f.silent_after_s:
                if not silent_said:
                    self.on_event("stage silent (fault)")
                    silent_said = True
                continue
            reply = self._handle(data.decode("ascii", errors="replace").split(), now)
            if reply is None:
                continue
            if f.drop_probability > 0 and self._rng.random() < f.drop_probability:
                self.dropped += 1
                continue
            if f.delay_s > 0:
                time.sleep(f.delay_s)
            try:
                self._sock.sendto(reply.encode("ascii"), addr)
            except OSError:
                return

    def _handle(self, parts: list[str], now: float) -> str | None:
        with self._lock:
            self.requests += 1
            if len(parts) < 2 or not parts[1].isdigit():
                return None  # not this protocol: a real stage ignores it too
            cmd, seq = parts[0], parts[1]
            self._advance(now)
            if cmd == "GOAL" and len(parts) == 4:
                try:
                    self.goal = [float(parts[2]), float(parts[3])]
                except ValueError:
                    return None
                self.stopped = False
            elif cmd == "STOP":
                self.stopped = True
                self.goal = list(self.position)
                self.on_event("stage stopped")
                return None
            elif cmd != "READ":
                return None
            currents = [40.0 * (g - p) for g, p in zip(self.goal, self.position)]  # a drive pushing towards its goal
            return (f"POS {seq} {self.position[0]:.6f} {self.position[1]:.6f} {currents[0]:.3f} {currents[1]:.3f}")
