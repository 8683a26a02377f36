"""Backends execute a commanded trajectory and return what the motors and tracker logged.

``sim`` (the default) is the physics simulator in :mod:`endocal.sim`; ``hardware`` drives
Dynamixel knob servos and reads an NDI Aurora tracker.
"""

from endocal.backends.base import Backend, StreamChunk, motor_columns

__all__ = ["Backend", "StreamChunk", "motor_columns"]
