"""Limits that always apply (endocal/backends/limits.py, Trajectory.check_limits, slew_limit):
knob angle, speed and acceleration of the probe configuration, on every backend, whatever
produced the goals."""

from __future__ import annotations

import numpy as np
import pytest

from endocal.backends.registry import make_backend
from endocal.errors import LimitError
from endocal.probe import PRESETS
from endocal.protocols.trajectory import Trajectory
from endocal.validation.playback import slew_limit

TEE = PRESETS["tee"]
FS = 100.0


def _goals(ap: np.ndarray) -> dict:
    return {"ap": ap, "ml": np.zeros_like(ap), "translation": np.zeros_like(ap), "rotation": np.zeros_like(ap)}


def test_a_step_to_full_speed_is_refused_for_its_acceleration():
    t = np.arange(50) / FS
    ap = np.where(t > 0.1, (t - 0.1) * 200.0, 0.0)  # 0 -> 200 deg/s in one tick: 20 000 deg/s^2
    traj = Trajectory(t, _goals(ap), FS, "step")
    with pytest.raises(LimitError, match=r"20000 deg/s\^2 exceeds the max_knob_accel_dps2 10000"):
        traj.check_limits(TEE)
    smooth = Trajectory(t, _goals(np.where(t > 0.1, (t - 0.1) * 50.0, 0.0)), FS, "ramp")  # 5 000 deg/s^2
    smooth.check_limits(TEE)


@pytest.mark.parametrize("ap, fragment", [
    (np.linspace(0, 95, 2000), "beyond its limit 90.000 deg"),
    (np.r_[np.zeros(10), np.full(10, 30.0)], "faster than the limit 360 deg/s"),
    (np.r_[np.zeros(10), np.arange(1, 11) * 2.0], r"above the limit 10000 deg/s\^2"),
])
def test_the_simulator_backend_refuses_what_the_hardware_backend_would(ap, fragment):
    be = make_backend("sim", TEE, seed=0)
    be.open()
    t = np.arange(ap.size) / FS
    with pytest.raises(LimitError, match=fragment):
        be.execute(t, _goals(ap))


def test_limits_carry_across_chunks():
    be = make_backend("sim", TEE, seed=0)
    be.open()
    t = np.arange(20) / FS
    be.execute(t, _goals(np.zeros(20)))
    with pytest.raises(LimitError, match="above the limit 10000"):  # 2 deg in the first tick of the next chunk
        be.execute(t + 0.2, _goals(np.full(20, 2.0)))


def test_slew_limit_keeps_both_limits_and_leaves_a_feasible_command_alone():
    t = np.arange(400) / FS
    smooth = 30 * np.sin(2 * np.pi * 0.2 * t)  # 38 deg/s, 47 deg/s^2
    np.testing.assert_array_equal(slew_limit(smooth, t, 360.0, 10000.0), smooth)
    jumpy = np.where((t > 1) & (t < 2.5), 40.0, -40.0)  # an inverse backlash model's jumps
    out = slew_limit(jumpy, t, 360.0, 10000.0)
    v = np.diff(out) * FS
    assert np.abs(v).max() <= 360.0 + 1e-9
    assert np.abs(np.diff(v)).max() * FS <= 10000.0 * (1 + 1e-9)
    # it arrives: a 80 deg jump takes 80/360 + 360/10000 = 0.26 s at these limits; 0.4 s later it is there
    assert out[t > 1.5][0] == pytest.approx(40.0, abs=1e-6)
    assert out.max() <= 40.0 + 1e-9  # braking to arrive: no overshoot
