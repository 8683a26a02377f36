"""The backend contract shared by the simulator and real hardware.

An excitation is played in *chunks*: the caller hands the backend the motor-clock times
``t_s`` and the goal of every degree of freedom at those times, the backend executes
them (the simulator computes them; hardware plays them tick by tick in real time) and
returns one :class:`StreamChunk`. The caller logs each chunk before asking for the next,
so a crash loses at most the chunk in flight.

The stream layouts and :class:`StreamChunk` live in :mod:`endocal.streams` (the simulator and
the run logger use them too); they are re-exported here for backends.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np

from endocal.streams import SENSORS, TRACKER_COLUMNS, StreamChunk, motor_columns

__all__ = ["Backend", "SENSORS", "TRACKER_COLUMNS", "StreamChunk", "motor_columns"]


@runtime_checkable
class Backend(Protocol):
    """What :func:`endocal.excite.run_excitation` needs from a backend.

    ``open`` connects (hardware: checks the devices, enables torque); ``execute`` plays
    one chunk; ``close`` must be safe to call more than once and, on hardware, always
    turns torque off. ``realtime`` tells whether ``execute`` already paces itself to the
    wall clock. ``describe`` returns what ``run.json`` records about the backend.
    """

    name: str
    realtime: bool

    def open(self) -> None: ...

    def execute(self, t_s: np.ndarray, goal: dict[str, np.ndarray]) -> StreamChunk: ...

    def close(self) -> None: ...

    def describe(self) -> dict: ...
