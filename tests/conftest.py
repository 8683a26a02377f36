"""Shared fixtures: a tiny deterministic backend that follows the backend contract.

It lets the run-format tests check the logger, the alignment and eq. 1 against a known
geometry without depending on the physics simulator.
"""

from __future__ import annotations

import os

import numpy as np
import pytest

from endocal.streams import StreamChunk, motor_columns
from endocal.kinematics import tip_pose_in_base
from endocal.probe import PRESETS

# pytest-xdist already runs one worker per core: the effect scan's fits stay in each worker
# (see endocal/validation/parallel.py).
os.environ.setdefault("ENDOCAL_JOBS", "1")


class GeometryBackend:
    """Bends the tip by exactly ``gain * knob`` (total angle, radians from degrees) per axis.

    Tracker frames at ``tracker_hz`` on the motor clock, no noise, base at the tracker origin
    rotated by ``base_rot`` so that frames matter.
    """

    name = "geometry"
    realtime = False

    def __init__(self, probe, gain=1.0, tracker_hz=40.0, invalid_every=0, base_quat_wxyz=(0.9238795, 0.0, 0.3826834, 0.0)):
        self.probe, self.gain, self.tracker_hz = probe, gain, tracker_hz
        self.invalid_every = invalid_every
        self.base_q = np.asarray(base_quat_wxyz, float)
        self.closed = 0
        self._next_frame = 0.0
        self._frame_no = 0

    def open(self):
        pass

    def close(self):
        self.closed += 1

    def describe(self):
        return {"gain": self.gain}

    def bend(self, goal):
        a1, a2 = self.probe.bending_axes
        return np.radians(self.gain * goal[a2]), np.radians(self.gain * goal[a1])  # (b_x, b_y)

    def execute(self, t_s, goal):
        from scipy.spatial.transform import Rotation

        motor = {"t_s": np.asarray(t_s, float)}
        for c in motor_columns(self.probe)[1:]:
            dof, kind = c.split("_")[0], c.split("_")[1]
            motor[c] = np.asarray(goal[dof], float).copy() if kind in ("goal", "pos") else np.zeros(len(t_s))
        motor["sheath_wrap_deg"] = np.full(len(t_s), 90.0)
        frames = []
        while self._next_frame <= t_s[-1] + 1e-12:
            frames.append(self._next_frame)
            self._frame_no += 1
            self._next_frame = self._frame_no / self.tracker_hz
        frames = np.asarray(frames)
        g = {k: np.interp(frames, t_s, v) for k, v in goal.items()} if len(t_s) > 1 else {k: np.full(frames.size, v[0]) for k, v in goal.items()}
        bx, by = self.bend(g)
        tip_in_base, tip2base = tip_pose_in_base(bx, by, self.probe.bending_length_mm)
        base2tracker = Rotation.from_quat(self.base_q, scalar_first=True)
        base_pos = np.array([10.0, -20.0, 30.0])
        tip_pos = base_pos + base2tracker.apply(tip_in_base)
        tip_q = (base2tracker * tip2base).as_quat(scalar_first=True)
        n = frames.size
        tr = {
            "t_s": np.repeat(frames, 2),
            "sensor": np.tile(np.array(["tip", "base"], dtype=object), n),
            "x_mm": np.ravel(np.column_stack([tip_pos[:, 0], np.full(n, base_pos[0])])),
            "y_mm": np.ravel(np.column_stack([tip_pos[:, 1], np.full(n, base_pos[1])])),
            "z_mm": np.ravel(np.column_stack([tip_pos[:, 2], np.full(n, base_pos[2])])),
        }
        for i, k in enumerate(("qw", "qx", "qy", "qz")):
            tr[k] = np.ravel(np.column_stack([tip_q[:, i], np.full(n, self.base_q[i])]))
        valid = np.ones(2 * n, bool)
        if self.invalid_every:
            idx = (np.arange(n) + self._frame_no - n) % self.invalid_every == 0
            valid[0::2][idx] = False
        tr["valid"] = valid
        return StreamChunk(motor=motor, tracker=tr)


@pytest.fixture
def tee():
    return PRESETS["tee"]


@pytest.fixture
def geometry_backend(tee):
    return GeometryBackend(tee)


# The longest test files, longest first (summed durations on 2 cores, 2026-11: 25-200 s each; the
# rest take under 25 s). `make test` runs `--dist loadfile --no-loadscope-reorder`: pytest-xdist
# hands out whole files in collection order, so these start first and the short files fill in at
# the end (longest processing time first). By default xdist orders files by their number of tests,
# which left a long file with few tests to start last, on one worker, while the other one idled.
# A file missing here, or a stale order, only changes when a file runs, never how.
LONGEST_FIRST = (
    "test_validation_hidden.py", "test_tip_path.py", "test_validation_user_style.py", "test_models_effects_catalog.py",
    "test_validate_split.py", "test_emulate_rig.py", "test_validate_thesis.py", "test_mutations.py",
    "test_validate_split_conditions.py", "test_import_csv_variety.py", "test_cli_excite.py", "test_real_data.py", "test_real_data_followed.py",
    "test_compensation.py", "test_api.py", "test_validate_dirty.py", "test_tutorial_notebook.py",
    "test_hardware_wire.py", "test_mutations_commands.py", "test_next_experiment.py", "test_validation_units.py",
    "test_user_effects.py", "test_validate_promise.py", "test_validation_bases.py", "test_effects_contract.py",
    "test_export_c.py", "test_check_wear.py", "test_models_boucwen.py",
)


def pytest_collection_modifyitems(config, items):
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))  # stable: a file's tests keep their order
