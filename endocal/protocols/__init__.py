"""Excitation protocols: what the motors are asked to do during a run.

- :mod:`endocal.protocols.signals`: pure signal generators (sines, the duodenoscope paper's
  damped sine, chirps, band-limited random, staircases, circles, ...).
- :mod:`endocal.protocols.params`: typed, bounded protocol parameters.
- :mod:`endocal.protocols.catalogue`: the signal catalogue (:data:`SIGNALS`) a protocol names.
- :mod:`endocal.protocols.trajectory`: the :class:`Trajectory` a protocol builds for a probe,
  and its limit checks.
- :mod:`endocal.protocols.protocol`: protocol TOML files (``protocols/`` and the shipped
  set), overrides, and :class:`Protocol`.
- :mod:`endocal.protocols.plot`: goal-versus-time figures (PNG).

>>> from endocal.probe import PRESETS
>>> proto = load_protocol("damped-sine", overrides={"amplitude_deg": 40})
>>> traj = proto.trajectory(PRESETS["tee"])
>>> traj.check_limits(PRESETS["tee"])
>>> round(traj.duration_s, 6)
140.0
"""

from endocal.protocols.catalogue import SIGNALS, SignalSpec
from endocal.protocols.params import Param
from endocal.protocols.protocol import (
    Protocol,
    list_protocols,
    load_protocol,
    parse_overrides,
    protocol_dirs,
    read_protocol_file,
    shipped_protocols_dir,
)
from endocal.protocols.trajectory import Segment, Trajectory

__all__ = [
    "SIGNALS",
    "Param",
    "Protocol",
    "Segment",
    "SignalSpec",
    "Trajectory",
    "list_protocols",
    "load_protocol",
    "parse_overrides",
    "protocol_dirs",
    "read_protocol_file",
    "shipped_protocols_dir",
]
