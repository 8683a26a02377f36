"""The life cycle every emulator shares: open its endpoint, serve it from a daemon thread, stop."""

from __future__ import annotations

import threading
from abc import ABC, abstractmethod


class Served(ABC):
    """Base of the emulators: :meth:`start` opens the endpoint (``_open``) and runs ``_serve``
    in a daemon thread until :meth:`close` (idempotent) sets ``_stop`` and releases it
    (``_release``); usable as a context manager. Each emulator (servo bus, tracker, stage,
    rig) implements the three hooks; the base cannot be instantiated."""

    thread_name = "emulator"

    def __init__(self) -> None:
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    @abstractmethod
    def _open(self) -> None:
        """Create the endpoint (a pseudo-terminal, a socket) the host will connect to."""

    @abstractmethod
    def _serve(self) -> None:
        """Answer the host until ``_stop`` is set (runs in the daemon thread)."""

    @abstractmethod
    def _release(self) -> None:
        """Close the endpoint; called once serving has stopped, possibly more than once."""

    def start(self):
        """Open the endpoint and serve it in the background; returns self."""
        self._stop.clear()
        self._open()
        self._thread = threading.Thread(target=self._serve, name=self.thread_name, daemon=True)
        self._thread.start()
        return self

    def close(self) -> None:
        """Stop serving and release the endpoint. Idempotent."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
        self._thread = None
        self._release()

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc) -> None:
        self.close()


def open_raw_pty() -> tuple[int, int, str]:
    """A pseudo-terminal in raw mode (no echo, no line editing): ``(master, slave, slave_path)``.

    The emulator reads and writes the master; the host opens the slave path as a serial port.
    """
    import os
    import tty

    master, slave = os.openpty()
    tty.setraw(slave)
    return master, slave, os.ttyname(slave)


def close_fds(*fds) -> None:
    """Close file descriptors, ignoring those already closed (or None)."""
    import os

    for fd in fds:
        if fd is not None:
            try:
                os.close(fd)
            except OSError:
                pass
