"""Excitation protocols: what the motors are asked to do during a run.

- :mod:`endocal.protocols.signals`: pure signal generators (sines, the duodenoscope paper's
  damped sine, chirps, band-limited random, staircases, circles, ...).
- :mod:`endocal.protocols.protocol`: protocol TOML files (``protocols/`` and the shipped
  set), parameters and overrides, and the :class:`Trajectory` they build for a probe.
- :mod:`endocal.protocols.plot`: goal-versus-time figures (PNG).

>>> from endocal.probe import PRESETS
>>> proto = load_protocol("damped-sine", overrides={"amplitude_deg": 40})
>>> traj = proto.trajectory(PRESETS["tee"])
>>> traj.check_limits(PRESETS["tee"])
>>> round(traj.duration_s, 6)
140.0
"""

from endocal.protocols.protocol import (
    SIGNALS,
    Param,
    Protocol,
    Segment,
    SignalSpec,
    Trajectory,
    list_protocols,
    load_protocol,
    parse_overrides,
    protocol_dirs,
    read_protocol_file,
    shipped_protocols_dir,
)

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
