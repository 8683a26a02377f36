"""The streams a run is made of, shared by every producer (simulator, backends, importers) and the run logger.

Stream columns (the run format, see README "Run format"):

motor stream
    ``t_s`` and, per degree of freedom ``<dof>`` with unit ``<u>`` (``deg`` for knobs
    and rotation, ``mm`` for translation): ``<dof>_goal_<u>``, ``<dof>_pos_<u>``,
    ``<dof>_vel_<u>ps`` and ``<dof>_current_ma``. A backend may add further numeric
    columns (the simulator logs ``contact_force_n`` and ``sheath_wrap_deg``).
tracker stream (long format, one row per sensor frame)
    ``t_s``, ``sensor`` (``tip`` / ``base``), ``x_mm y_mm z_mm``, ``qw qx qy qz``
    (sensor-to-tracker rotation, scalar first) and ``valid`` (bool). The hardware backend adds
    ``status`` (``ok``, ``missing``, ``out_of_volume``, ``partly_out_of_volume``: what the NDI
    Aurora's port status said of that sensor in that frame; only ``ok`` rows are valid) and
    ``port_status`` (the port status bits as reported, -1 when none was).
truth stream (simulator only)
    ``t_s`` and noise-free quantities for tests, e.g. ``<axis>_true_deg``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from endocal.probe import ProbeConfig

TRACKER_COLUMNS = ("t_s", "sensor", "x_mm", "y_mm", "z_mm", "qw", "qx", "qy", "qz", "valid")
SENSORS = ("tip", "base")
#: ``status`` values of a hardware tracker row that is not valid (see the module docstring)
DROPOUT_STATUSES = ("missing", "out_of_volume", "partly_out_of_volume")


def motor_columns(probe: ProbeConfig) -> list[str]:
    """The motor-stream columns every backend must return for ``probe``, in order."""
    cols = ["t_s"]
    for dof in probe.dofs:
        u = probe.unit(dof)
        cols += [f"{dof}_goal_{u}", f"{dof}_pos_{u}", f"{dof}_vel_{u}ps", f"{dof}_current_ma"]
    return cols


@dataclass
class StreamChunk:
    """What one executed chunk produced. Every value is a 1-D array; columns of a stream share a length."""

    motor: dict[str, np.ndarray]
    tracker: dict[str, np.ndarray]
    truth: dict[str, np.ndarray] = field(default_factory=dict)
