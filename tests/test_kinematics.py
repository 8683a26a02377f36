"""Bending angles (thesis eq. 1), their constant-curvature inverse, and 4-DoF probe FK/IK.

Hand-computed cases use bends whose trigonometry is exact (45, 60, 90 deg). Round trips are
held to 1e-9 (deg or mm): every step is closed form or bisected to machine precision, so the
only error is double rounding through a few trig calls (~1e-13 relative).
"""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from endocal.errors import ConfigError, LimitError
from endocal.kinematics import bending_angles_deg, tip_in_base_mm, tip_pose_in_base
from endocal.kinematics.inverse import (
    MAX_UNIQUE_BEND_RAD,
    angles_from_bend_deg,
    bend_from_angles_rad,
    bend_from_lateral_offset_rad,
    chord_direction_in_base,
    lateral_offset_mm,
    tip_in_base_from_angles_mm,
)
from endocal.kinematics.probe_fk import ProbeKinematics, UnreachableError
from endocal.probe import PRESETS

L = 45.0


# -- thesis eq. 1 and its inverse -----------------------------------------------------------

def test_eq1_hand_cases():
    p = np.array([[0.0, 10.0, 10.0], [10.0, 0.0, 10.0], [10.0, -10.0, 10.0], [0.0, 0.0, 5.0], [0.0, 3.0, -3.0]])
    t1, t2 = bending_angles_deg(p)
    np.testing.assert_allclose(t1, [45.0, 0.0, -45.0, 0.0, 135.0], atol=1e-12)
    np.testing.assert_allclose(t2, [0.0, 45.0, 45.0, 0.0, 180.0], atol=1e-12)  # behind the base: atan2(0, -3)


def test_eq1_of_planar_arc_is_half_the_bend():
    # A planar arc bent by 60 deg towards +y: the chord leaves the base at 30 deg.
    tip, _ = tip_pose_in_base([0.0], [np.radians(60.0)], L)
    t1, t2 = bending_angles_deg(tip)
    assert t1[0] == pytest.approx(30.0, abs=1e-12)
    assert t2[0] == pytest.approx(0.0, abs=1e-12)


def test_tip_in_base_from_tracker_poses():
    base2tracker = Rotation.from_euler("z", 90, degrees=True)
    tip = tip_in_base_mm([[5.0, 12.0, 3.0]], [[5.0, 2.0, 3.0]], base2tracker.as_quat(scalar_first=True)[None])
    # The tip is 10 mm along tracker +y = base +x.
    np.testing.assert_allclose(tip, [[10.0, 0.0, 0.0]], atol=1e-12)


def test_inverse_hand_case_90_degree_bend():
    # Eq. 1 angles (45, 0): chord at 45 deg towards +y, so a 90 deg bend towards +y.
    c = chord_direction_in_base(45.0, 0.0)
    np.testing.assert_allclose(c, [[0.0, np.sqrt(0.5), np.sqrt(0.5)]], atol=1e-15)
    bx, by = bend_from_angles_rad(45.0, 0.0)
    assert bx[0] == pytest.approx(0.0, abs=1e-15) and by[0] == pytest.approx(np.pi / 2, abs=1e-14)
    # Arc of length L bent by 90 deg: radius 2L/pi, tip at (0, 2L/pi, 2L/pi).
    tip = tip_in_base_from_angles_mm(45.0, 0.0, L)
    np.testing.assert_allclose(tip, [[0.0, 2 * L / np.pi, 2 * L / np.pi]], atol=1e-12)


def test_inverse_hand_case_diagonal():
    # (theta1, theta2) = (45, 45): chord along (1, 1, 1)/sqrt(3); bend = 2 * arccos(1/sqrt(3)) towards phi = 45 deg.
    bx, by = bend_from_angles_rad(45.0, 45.0)
    alpha = 2 * np.arccos(1 / np.sqrt(3))
    np.testing.assert_allclose([bx[0], by[0]], [alpha / np.sqrt(2), alpha / np.sqrt(2)], atol=1e-14)


@pytest.mark.parametrize("scale", [1e-9, 1e-4, 1.0, 40.0, 85.0])
def test_angles_tip_round_trip(scale):
    rng = np.random.default_rng(1)
    t1, t2 = rng.uniform(-1, 1, (2, 500)) * scale
    tip = tip_in_base_from_angles_mm(t1, t2, L)
    back1, back2 = bending_angles_deg(tip)
    np.testing.assert_allclose(back1, t1, atol=1e-9, rtol=0)
    np.testing.assert_allclose(back2, t2, atol=1e-9, rtol=0)
    # ... and the tip lies on a constant-curvature arc of length L: |tip| is the chord of that arc.
    bx, by = bend_from_angles_rad(t1, t2)
    alpha = np.hypot(bx, by)
    chord = np.where(alpha > 1e-8, 2 * L * np.sin(alpha / 2) / np.where(alpha > 1e-8, alpha, 1), L)
    np.testing.assert_allclose(np.linalg.norm(tip, axis=1), chord, rtol=1e-12)


def test_beyond_90_degree_chord_round_trip():
    # Bends beyond 180 deg put the tip behind the base (p_z < 0): both angles then exceed 90 deg.
    bx, by = np.radians([150.0, -200.0]), np.radians([170.0, 30.0])
    t1, t2 = angles_from_bend_deg(bx, by)
    assert np.all(np.abs(t1) > 90) and np.all(np.abs(t2) > 90)
    back_x, back_y = bend_from_angles_rad(t1, t2)
    np.testing.assert_allclose(back_x, bx, atol=1e-12)
    np.testing.assert_allclose(back_y, by, atol=1e-12)


def test_inconsistent_angles_rejected():
    with pytest.raises(LimitError, match="same side of"):
        chord_direction_in_base(120.0, 10.0)


def test_max_bend_error_gives_nearest_reachable_angles():
    with pytest.raises(LimitError, match=r"beyond max_bend_deg=90.*nearest reachable angles in the same direction: \(45.000, 0.000\)"):
        tip_in_base_from_angles_mm([10.0, 60.0], [0.0, 0.0], L, max_bend_deg=90.0)


def test_lateral_offset_inverse():
    assert float(lateral_offset_mm(np.pi / 2, L)) == pytest.approx(2 * L / np.pi, rel=1e-15)
    a = np.concatenate([[0.0, 1e-10, 1e-5], np.linspace(0.01, MAX_UNIQUE_BEND_RAD, 50)])
    np.testing.assert_allclose(bend_from_lateral_offset_rad(lateral_offset_mm(a, L), L), a, atol=1e-9)
    with pytest.raises(LimitError, match="out of reach"):
        bend_from_lateral_offset_rad([L], L)


# -- 4-DoF probe kinematics ------------------------------------------------------------------

def _kin(**kw):
    return ProbeKinematics(
        L,
        base_home_in_tracker_mm=(120.0, -40.0, 250.0),
        base_home2tracker_quat_wxyz=Rotation.from_euler("xyz", [30, -50, 110], degrees=True).as_quat(scalar_first=True),
        translation_limits_mm=(-150.0, 150.0),
        rotation_limits_deg=(-180.0, 180.0),
        **kw,
    )


def _random_joints(n, seed):
    rng = np.random.default_rng(seed)
    l, phi = rng.uniform(-140, 140, n), rng.uniform(-179, 179, n)
    # keep bends below the position-IK uniqueness limit (133.56 deg) and away from it
    alpha, az = np.radians(rng.uniform(0, 125, n)), rng.uniform(-np.pi, np.pi, n)
    t1, t2 = angles_from_bend_deg(alpha * np.cos(az), alpha * np.sin(az))
    return l, phi, t1, t2


def test_fk_hand_case():
    kin = ProbeKinematics(L)  # base_home = tracker frame
    # theta2 = 45 deg: 90 deg bend towards +x; rotating the probe 90 deg turns that to +y.
    pose = kin.forward(10.0, 90.0, 0.0, 45.0)
    np.testing.assert_allclose(pose.tip_in_tracker_mm, [[0.0, 2 * L / np.pi, 10.0 + 2 * L / np.pi]], atol=1e-12)
    np.testing.assert_allclose(pose.tip_dir_in_tracker, [[0.0, 1.0, 0.0]], atol=1e-15)
    # straight probe: the tip is L ahead of the translated base and points along z
    pose = kin.forward(-5.0, 33.0, 0.0, 0.0)
    np.testing.assert_allclose(pose.tip_in_tracker_mm, [[0.0, 0.0, L - 5.0]], atol=1e-12)
    np.testing.assert_allclose(pose.tip_dir_in_tracker, [[0.0, 0.0, 1.0]], atol=1e-15)


def test_fk_matches_eq1_in_base_frame():
    # The tip FK puts in the tracker frame, seen from the moved base, has the commanded eq. 1 angles.
    kin = _kin()
    l, phi, t1, t2 = _random_joints(200, 2)
    pose = kin.forward(l, phi, t1, t2)
    base_in_tracker = kin.base_home_in_tracker_mm + kin.base_home2tracker.apply(np.c_[0 * l, 0 * l, l])
    base2tracker = kin.base_home2tracker * Rotation.from_euler("z", phi[:, None], degrees=True)
    got1, got2 = bending_angles_deg(tip_in_base_mm(pose.tip_in_tracker_mm, base_in_tracker, base2tracker.as_quat(scalar_first=True)))
    np.testing.assert_allclose(got1, t1, atol=1e-9)
    np.testing.assert_allclose(got2, t2, atol=1e-9)


def test_ik_position_with_rotation_round_trip():
    kin = _kin()
    l, phi, t1, t2 = _random_joints(500, 3)
    pose = kin.forward(l, phi, t1, t2)
    j = kin.inverse(pose.tip_in_tracker_mm, rotation_deg=phi)
    np.testing.assert_allclose(j.translation_mm, l, atol=1e-9)
    np.testing.assert_allclose(j.rotation_deg, phi, atol=1e-12)
    np.testing.assert_allclose(j.theta_first_deg, t1, atol=1e-9)
    np.testing.assert_allclose(j.theta_second_deg, t2, atol=1e-9)
    again = kin.forward(j.translation_mm, j.rotation_deg, j.theta_first_deg, j.theta_second_deg)
    np.testing.assert_allclose(again.tip_in_tracker_mm, pose.tip_in_tracker_mm, atol=1e-9)


def test_ik_full_pose_round_trip():
    kin = _kin()
    l, phi, t1, t2 = _random_joints(500, 4)
    pose = kin.forward(l, phi, t1, t2)
    j = kin.inverse(pose.tip_in_tracker_mm, tip2tracker=pose.tip2tracker)
    for got, want in ((j.translation_mm, l), (j.rotation_deg, phi), (j.theta_first_deg, t1), (j.theta_second_deg, t2)):
        np.testing.assert_allclose(got, want, atol=1e-9)


def test_ik_straight_probe_pose():
    kin = _kin()
    pose = kin.forward(12.0, -70.0, 0.0, 0.0)
    j = kin.inverse(pose.tip_in_tracker_mm, tip2tracker=pose.tip2tracker)
    np.testing.assert_allclose([j.translation_mm[0], j.rotation_deg[0], j.theta_first_deg[0], j.theta_second_deg[0]],
                               [12.0, -70.0, 0.0, 0.0], atol=1e-9)


def test_unreachable_lateral_reports_nearest_point():
    kin = _kin()
    target_home = np.array([[100.0, 0.0, 40.0], [5.0, 5.0, 50.0]])  # first: 100 mm off axis; second: fine
    target = kin.base_home_in_tracker_mm + kin.base_home2tracker.apply(target_home)
    with pytest.raises(UnreachableError, match=r"row 0\) is more than 32\.6\d* mm off the probe axis") as info:
        kin.inverse(target)
    err = info.value
    assert err.index == 0
    nearest_home = kin.base_home2tracker.inv().apply(err.nearest_tip_in_tracker_mm - kin.base_home_in_tracker_mm)
    # Nearest point: same azimuth (+x) and height, on the edge of the reachable cylinder.
    rho_max = float(lateral_offset_mm(MAX_UNIQUE_BEND_RAD, L))
    np.testing.assert_allclose(nearest_home[0], [rho_max, 0.0, 40.0], atol=1e-9)
    np.testing.assert_allclose(err.nearest_tip_in_tracker_mm[1], target[1], atol=0)
    # and it is reachable
    kin.inverse(err.nearest_tip_in_tracker_mm)


def test_unreachable_translation_reports_nearest_point():
    kin = _kin()
    pose = kin.forward(150.0, 0.0, 10.0, 0.0)
    beyond = pose.tip_in_tracker_mm + kin.base_home2tracker.apply([0.0, 0.0, 20.0])
    with pytest.raises(UnreachableError, match="translation outside") as info:
        kin.inverse(beyond)
    np.testing.assert_allclose(info.value.nearest_tip_in_tracker_mm, pose.tip_in_tracker_mm, atol=1e-9)
    assert info.value.nearest.translation_mm[0] == pytest.approx(150.0)


def test_inconsistent_pose_is_unreachable():
    kin = _kin()
    pose = kin.forward(0.0, 0.0, 20.0, 5.0)
    with pytest.raises(UnreachableError, match="not where the given orientation puts the tip"):
        kin.inverse(pose.tip_in_tracker_mm + [1.0, 0.0, 0.0], tip2tracker=pose.tip2tracker)


def test_fk_refuses_out_of_range_joints():
    kin = _kin(max_bend_deg=100.0)
    with pytest.raises(LimitError, match="translation 200 mm is outside"):
        kin.forward(200.0, 0.0, 0.0, 0.0)
    with pytest.raises(LimitError, match="beyond max_bend_deg=100"):
        kin.forward(0.0, 0.0, 60.0, 0.0)  # 120 deg bend
    with pytest.raises(ConfigError, match="max_bend_deg"):
        ProbeKinematics(L, max_bend_deg=200.0)
    with pytest.raises(ConfigError, match="not both"):
        kin.inverse([0.0, 0.0, L], rotation_deg=0.0, tip2tracker=Rotation.identity())


def test_from_probe_uses_preset_geometry():
    kin = ProbeKinematics.from_probe(PRESETS["tee"])
    assert kin.length_mm == PRESETS["tee"].bending_length_mm
    assert kin.translation_limits_mm == PRESETS["tee"].translation_limits_mm
    np.testing.assert_allclose(kin.forward(0.0, 0.0, 0.0, 0.0).tip_in_tracker_mm, [[0.0, 0.0, 60.0]], atol=1e-12)


# -- against the simulator's ground truth --------------------------------------------------------

def _sim_run(seconds=20.0, seed=0):
    import pandas as pd

    from endocal.sim.config import SimConfig
    from endocal.sim.simulator import Simulator

    probe = PRESETS["duodenoscope"]
    cfg = SimConfig.default().replace(tracker={"latency_s": 0.0})
    t = np.arange(0.01, seconds, 0.01)
    goal = {"ud": 55 * np.sin(2 * np.pi * t / 10), "lr": 45 * np.sin(2 * np.pi * t / 7 + 1.0),
            "translation": 40 * np.sin(2 * np.pi * t / 13), "rotation": 90 * np.sin(2 * np.pi * t / 11)}
    chunk = Simulator(cfg, probe, seed=seed).execute(t, goal)
    return probe, cfg, pd.DataFrame(chunk.motor), pd.DataFrame(chunk.tracker), chunk.truth


@pytest.fixture(scope="module")
def sim_run():
    return _sim_run()


def test_eq1_matches_simulator_truth(sim_run):
    # Tracker noise: 0.5 mm RMS (3-D) per sensor, i.e. 0.41 mm per axis on tip - base, seen from
    # ~40 mm: ~0.6 deg RMS per angle, unbiased. A frame or sign error would be degrees off.
    probe, _, _, tracker, truth = sim_run
    tip, base = tracker[tracker.sensor == "tip"], tracker[tracker.sensor == "base"]
    assert np.array_equal(tip.t_s.to_numpy(), base.t_s.to_numpy())
    p = tip_in_base_mm(tip[["x_mm", "y_mm", "z_mm"]].to_numpy(), base[["x_mm", "y_mm", "z_mm"]].to_numpy(),
                       base[["qw", "qx", "qy", "qz"]].to_numpy())
    measured = bending_angles_deg(p)
    for i, axis in enumerate(probe.bending_axes):
        err = measured[i] - np.interp(tip.t_s, truth["t_s"], truth[f"{axis}_true_deg"])
        assert np.sqrt(np.mean(err**2)) < 0.8
        assert abs(np.mean(err)) < 0.1


def test_fk_matches_simulator_tip_with_translation_and_rotation(sim_run):
    # FK from the simulator's joint positions and true bend must land on the tracked tip to within the
    # tracker's noise (0.5 mm RMS); a wrong translation axis or rotation sign is centimetres off.
    probe, cfg, motor, tracker, truth = sim_run
    kin = ProbeKinematics.from_probe(
        probe,
        base_home_in_tracker_mm=cfg.tracker.mount_xyz_mm,
        base_home2tracker_quat_wxyz=Rotation.from_euler("xyz", cfg.tracker.mount_rpy_deg, degrees=True).as_quat(scalar_first=True),
        max_bend_deg=180.0,
    )
    tip = tracker[tracker.sensor == "tip"]
    t = tip.t_s.to_numpy()
    l = np.interp(t, motor.t_s, motor.translation_pos_mm)
    phi = np.interp(t, motor.t_s, motor.rotation_pos_deg)
    bx, by = np.interp(t, truth["t_s"], truth["bend_x_rad"]), np.interp(t, truth["t_s"], truth["bend_y_rad"])
    t1, t2 = angles_from_bend_deg(bx, by)
    pose = kin.forward(l, phi, t1, t2)
    err = tip[["x_mm", "y_mm", "z_mm"]].to_numpy() - pose.tip_in_tracker_mm
    assert np.sqrt(np.mean(np.sum(err**2, axis=1))) < 0.6
    assert np.linalg.norm(err.mean(axis=0)) < 0.1
    # and IK with the rotation held brings back the joints to within the noise (bend of this run < 133 deg)
    assert np.degrees(np.hypot(bx, by)).max() < np.degrees(MAX_UNIQUE_BEND_RAD)
    j = kin.inverse(pose.tip_in_tracker_mm, rotation_deg=phi)
    np.testing.assert_allclose(j.translation_mm, l, atol=1e-9)
    np.testing.assert_allclose(j.theta_first_deg, t1, atol=1e-9)
