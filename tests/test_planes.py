"""Bending-plane calibration on synthetic planes runs with known twisted half-planes.

The synthetic run follows the duodenoscope paper's hypotheses exactly (each knob bends along
its twisted half-plane, bends add as vectors, constant curvature), then adds tracker noise:
0.5 mm RMS (3-D) on each sensor position and 0.1 deg RMS on each orientation.

Why 0.5 deg is a meaningful bound for the deviation angles: the paper fits distal-end
directions; with 0.1 deg orientation noise on tip and base, each direction is off its plane by
about 0.1 * sqrt(2/3) = 0.08 deg RMS, and a sweep reaching a 45-60 deg bend spreads its
~600 directions over sin(bend) ~ 0.5 RMS, so a half-plane's normal is known to about
0.0014 rad / (0.5 * sqrt(600)) ~ 0.005 deg. Half a degree is ~100 standard errors: a wrong
equation, sign or frame (all of which move the answer by degrees) fails it, noise cannot.
From positions the plane is ~10x noisier (0.41 mm per axis over ~10 mm RMS lateral offset, SE
~0.1 deg), still well inside 0.5 deg with six repeats.
"""

import json

import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation

from endocal.errors import EndocalError, LimitError, ModelError, OutputExistsError, RunFormatError
from endocal.kinematics import tip_pose_in_base
from endocal.planes import (
    HALF_PLANES,
    CalibrationError,
    OrthogonalCompensator,
    PlanesCalibration,
    Segmentation,
    Sweep,
    compensation_matrix,
    fit_delta,
    fit_half_plane,
    fit_planes,
    load_planes,
    residual_deviation,
    save_planes,
    segment_planes_run,
    twisted_plane_bend_rad,
)
from endocal.planes.halfplanes import knob_half_plane
from endocal.probe import PRESETS

PAPER = {"y+": 12.7, "y-": 20.2, "x+": 2.3, "x-": 15.6}  # duodenoscope paper, section 3.2 (before compensation)
NOMINAL = {"y+": 90.0, "y-": 270.0, "x+": 0.0, "x-": 180.0}
DUO = PRESETS["duodenoscope"]
KNOB_TO_EQ1 = 0.75  # eq. 1 degrees per knob degree in the synthetic plant (a 40 deg knob -> 60 deg bend)


def planes_run(dev, *, reps=4, amp_deg=40.0, rate_hz=40.0, pos_noise_mm=0.5, rot_noise_deg=0.1, seed=0,
               invalid_frac=0.0, sensors=("tip", "base"), compensator=None, length_mm=45.0):
    """Aligned table and raw tracker stream of a synthetic ``planes`` run.

    Each repeat sweeps ud+, ud-, lr+, lr- (triangle out to 85-100 % of ``amp_deg`` and back,
    then one second at rest). With ``compensator`` the desired standard-plane sweep is passed
    through it, so both knobs move (a run recorded with orthogonal compensation on).
    """
    rng = np.random.default_rng(seed)
    ramp = np.concatenate([np.linspace(0, 1, int(2 * rate_hz)), np.linspace(1, 0, int(2 * rate_hz)), np.zeros(int(rate_hz))])
    c1, c2 = [np.zeros(int(rate_hz))], [np.zeros(int(rate_hz))]
    for _ in range(reps):
        for knob, sign in ((0, 1), (0, -1), (1, 1), (1, -1)):
            amp = amp_deg.get(knob_half_plane(knob, sign), 40.0) if isinstance(amp_deg, dict) else amp_deg
            a = sign * amp * ramp * rng.uniform(0.85, 1.0)
            c1.append(a if knob == 0 else 0 * a)
            c2.append(a if knob == 1 else 0 * a)
    c1, c2 = np.concatenate(c1), np.concatenate(c2)
    if compensator is not None:
        c1, c2 = compensator.compensate(c1, c2)
    t = np.arange(len(c1)) / rate_hz
    bx, by = twisted_plane_bend_rad(KNOB_TO_EQ1 * c1, KNOB_TO_EQ1 * c2, dev)
    tip_b, tip2base = tip_pose_in_base(bx, by, length_mm)
    base2tracker = Rotation.from_euler("xyz", [30, -50, 110], degrees=True)
    base_t = np.array([120.0, -40.0, 250.0])
    n = len(t)
    sig, rs = pos_noise_mm / np.sqrt(3), np.radians(rot_noise_deg) / np.sqrt(3)
    poses = {
        "base": (base_t + rng.normal(0, sig, (n, 3)),
                 Rotation.from_rotvec(rng.normal(0, rs, (n, 3))) * base2tracker),
        "tip": (base_t + base2tracker.apply(tip_b) + rng.normal(0, sig, (n, 3)),
                Rotation.from_rotvec(rng.normal(0, rs, (n, 3))) * base2tracker * tip2base),
    }
    frames = []
    for sensor in sensors:
        pos, rot = poses[sensor]
        q = rot.as_quat(scalar_first=True)
        df = pd.DataFrame({"t_s": t, "sensor": sensor, "x_mm": pos[:, 0], "y_mm": pos[:, 1], "z_mm": pos[:, 2],
                           "qw": q[:, 0], "qx": q[:, 1], "qy": q[:, 2], "qz": q[:, 3], "valid": True})
        bad = rng.random(n) < invalid_frac
        df.loc[bad, "valid"] = False
        df.loc[bad, ["x_mm", "y_mm", "z_mm"]] = 9999.0  # what a flagged frame may hold: garbage
        frames.append(df)
    tracker = pd.concat(frames).sort_values(["t_s", "sensor"], kind="stable").reset_index(drop=True)
    aligned = pd.DataFrame({"t_s": t, "ud_cmd_deg": c1, "lr_cmd_deg": c2})
    return aligned, tracker


@pytest.fixture(scope="module")
def paper_run():
    return planes_run(PAPER, seed=1, invalid_frac=0.02)


@pytest.fixture(scope="module")
def paper_cal(paper_run):
    seg = segment_planes_run(*paper_run, DUO, run="sim-1")
    return seg, fit_planes(seg, n_bootstrap=200, seed=0)


# -- segmentation ----------------------------------------------------------------------------

def test_segmentation_finds_every_sweep_and_counts_drops(paper_run, paper_cal):
    seg, _ = paper_cal
    assert [len(v) for v in seg.by_half_plane().values()] == [4, 4, 4, 4]
    assert [s.half_plane for s in seg.sweeps[:4]] == ["y+", "y-", "x+", "x-"]  # protocol order
    tracker = paper_run[1]
    n_tip_bad = int((~tracker.loc[tracker.sensor == "tip", "valid"]).sum())
    n_base_bad = int((~tracker.loc[tracker.sensor == "base", "valid"]).sum())
    assert seg.dropped["tip_invalid"] == n_tip_bad > 0
    assert seg.dropped["base_invalid"] == n_base_bad > 0
    # a valid frame whose partner was flagged is lost too: one per flagged frame, less the instants where both were
    both_bad = int(((~tracker.loc[tracker.sensor == "tip", "valid"]).to_numpy()
                    & (~tracker.loc[tracker.sensor == "base", "valid"]).to_numpy()).sum())
    assert seg.dropped["unpaired"] == n_tip_bad + n_base_bad - 2 * both_bad
    for s in seg.sweeps:  # no flagged garbage reached a sweep
        assert np.all(np.linalg.norm(s.tip_in_base_mm, axis=1) < 50.0)


def test_missing_base_sensor_is_a_run_format_error():
    aligned, tracker = planes_run(PAPER, reps=1, sensors=("tip",))
    with pytest.raises(RunFormatError, match=r"no 'base' sensor frames \(sensors seen: tip\)"):
        segment_planes_run(aligned, tracker, DUO, run="r")


def test_missing_command_column_is_a_run_format_error():
    aligned, tracker = planes_run(PAPER, reps=1)
    with pytest.raises(RunFormatError, match="lr_cmd_deg"):
        segment_planes_run(aligned.drop(columns="lr_cmd_deg"), tracker, DUO)


# -- half-plane fits and deviation angles (duodenoscope eqs. 1-2) -------------------------------

def test_fit_half_plane_hand_case():
    # Directions in the plane spanned by z and (cos 100, sin 100, 0): y+ twisted by +10 deg.
    a = np.radians(np.linspace(5, 60, 12))
    u = np.array([np.cos(np.radians(100)), np.sin(np.radians(100)), 0.0])
    v = np.sin(a)[:, None] * u + np.cos(a)[:, None] * np.array([0.0, 0.0, 1.0])
    f = fit_half_plane(v, "y+")
    assert f.deviation_deg == pytest.approx(10.0, abs=1e-9)
    assert f.deviation_signed_deg == pytest.approx(10.0, abs=1e-9)
    assert f.azimuth_deg == pytest.approx(100.0, abs=1e-9)
    assert f.excursion_deg == pytest.approx(60.0, abs=1e-9)
    assert f.tilt_deg == pytest.approx(0.0, abs=1e-9)
    # The same directions read as an x- sweep would be 80 deg off its standard plane.
    g = fit_half_plane(-v * [1, 1, -1], "x-")  # mirrored through the x-y plane: trace at 280 deg
    assert g.deviation_deg == pytest.approx(80.0, abs=1e-9)


@pytest.mark.parametrize("h", HALF_PLANES)
def test_deviations_recovered_within_half_degree(paper_cal, h):
    _, cal = paper_cal
    assert abs(cal.deviation_signed_deg[h] - PAPER[h]) < 0.5
    assert abs(cal.deviation_deg[h] - PAPER[h]) < 0.5  # the paper's unsigned angle (eq. 2)
    lo, hi = cal.deviation_signed_ci_deg[h]
    assert lo < cal.deviation_signed_deg[h] < hi
    assert hi - lo < 0.5  # informative at this noise level (coverage: test_confidence_intervals_cover_the_truth)
    assert cal.tilt_deg[h] < 0.2
    assert cal.ci_method[h] == "sweeps"


def test_confidence_intervals_cover_the_truth():
    # 16 independent runs x 4 half-planes = 64 intervals at 95 %: expect ~61 to cover. Fewer
    # than 56 has probability ~0.5 % for calibrated intervals, while plain percentile intervals
    # over 4 sweeps (which under-cover, ~85 %) would usually land there.
    covered, widths = 0, []
    for i in range(16):
        seg = segment_planes_run(*planes_run(PAPER, seed=100 + i), DUO)
        cal = fit_planes(seg, n_bootstrap=60, seed=i)
        for h in HALF_PLANES:
            lo, hi = cal.deviation_signed_ci_deg[h]
            covered += lo <= PAPER[h] <= hi
            widths.append(hi - lo)
    assert covered >= 56
    assert np.mean(widths) < 0.3


def test_positions_also_recover_deviations():
    seg = segment_planes_run(*planes_run(PAPER, seed=5, reps=6), DUO)
    cal = fit_planes(seg, source="position", n_bootstrap=100)
    for h in HALF_PLANES:
        assert abs(cal.deviation_signed_deg[h] - PAPER[h]) < 0.5
        lo, hi = cal.deviation_signed_ci_deg[h]
        assert lo <= PAPER[h] <= hi


def test_too_little_excursion_names_the_half_plane():
    # x- only reaches 3 knob deg (a 4.5 deg bend): below the 5 deg needed to define a plane.
    seg = segment_planes_run(*planes_run(PAPER, reps=2, amp_deg={"x-": 3.0}), DUO)
    assert len(seg.by_half_plane()["x-"]) == 2  # the sweeps are there, just small
    with pytest.raises(CalibrationError, match=r"half-plane 'x-': the tip directions move only 4\.\d\d deg"):
        fit_planes(seg, n_bootstrap=0)


def test_missing_half_plane_is_named():
    aligned, tracker = planes_run(PAPER, reps=1)
    aligned = aligned.copy()
    aligned.loc[aligned["ud_cmd_deg"] < 0, "ud_cmd_deg"] = 0.0  # y- never commanded
    seg = segment_planes_run(aligned, tracker, DUO)
    with pytest.raises(CalibrationError, match=r"no sweep of half-plane\(s\) y-"):
        fit_planes(seg, n_bootstrap=0)


# -- orthogonal compensation (duodenoscope eqs. 3-4) --------------------------------------------

def test_compensation_hand_case():
    # y+ twisted by +10 deg, x+ straight. To bend 10 deg along standard +y the first knob must do
    # 10/cos 10 = 10.154 deg, and the second cancel the x leak: 10.154 * sin 10 = 1.763 deg.
    comp = OrthogonalCompensator({"y+": 10.0, "y-": 0.0, "x+": 0.0, "x-": 0.0})
    first, second = comp.compensate(10.0, 0.0)
    assert first[0] == pytest.approx(10.0 / np.cos(np.radians(10)), abs=1e-12)
    assert second[0] == pytest.approx(10.0 / np.cos(np.radians(10)) * np.sin(np.radians(10)), abs=1e-12)
    np.testing.assert_allclose(compensation_matrix(10.0, 0.0) @ [first[0], second[0]], [10.0, 0.0], atol=1e-12)


def test_quadrant_rule_picks_the_bracketing_half_planes():
    # y+ twisted by -10 deg (actual azimuth 80), x- by +20 (actual 200), others straight. A target at
    # azimuth 85 deg lies between actual y+ (80) and x- (200): the rule must use y+ with x- and command
    # a negative second knob; a target at 75 deg lies between x+ (0) and y+ (80): y+ with x+.
    dev = {"y+": -10.0, "y-": 0.0, "x+": 0.0, "x-": 20.0}
    comp = OrthogonalCompensator(dev)
    for az, second_sign in ((85.0, -1), (75.0, 1)):
        t_first, t_second = 10 * np.sin(np.radians(az)), 10 * np.cos(np.radians(az))
        first, second = comp.compensate(t_first, t_second)
        assert first[0] > 0 and np.sign(second[0]) == second_sign
        # hand solve with the pair the rule should pick
        d_x = dev["x-"] if second_sign < 0 else dev["x+"]
        want = np.linalg.solve(compensation_matrix(dev["y+"], d_x), [t_first, t_second])
        np.testing.assert_allclose([first[0], second[0]], want, atol=1e-12)


def test_compensator_inverts_the_twisted_plant_everywhere():
    comp = OrthogonalCompensator(PAPER)
    rng = np.random.default_rng(7)
    desired = rng.uniform(-45, 45, (2, 2000))
    out = comp.forward(*comp.compensate(*desired))
    np.testing.assert_allclose(out, desired, atol=1e-10)
    # and across the sector boundaries the compensated command is continuous
    az = np.radians(np.linspace(0, 360, 3601))
    first, second = comp.compensate(30 * np.sin(az), 30 * np.cos(az))
    assert np.max(np.hypot(np.diff(first), np.diff(second))) < 0.1  # 0.1 deg of azimuth on a 30 deg circle: 0.05 deg


def test_uncompensated_plant_shows_the_paper_deviations():
    straight = OrthogonalCompensator({h: 0.0 for h in HALF_PLANES})
    before = residual_deviation(straight, PAPER)
    for h in HALF_PLANES:
        assert before[h].deviation_deg == pytest.approx(PAPER[h], abs=1e-9)


@pytest.mark.parametrize("h", HALF_PLANES)
def test_residual_after_compensation_below_one_degree(paper_cal, h):
    _, cal = paper_cal
    # Play the fitted compensator on the true plant and refit the planes (the paper's figure 8, after;
    # the paper still had 13.8 deg on y-).
    after = residual_deviation(cal.compensator, PAPER)
    assert after[h].deviation_deg < 1.0
    # the calibration's own (cross-validated) prediction agrees
    assert cal.residual_source == "cross-validated"
    assert cal.residual_deviation_deg[h] < 1.0


def test_measured_residual_from_a_compensated_run(paper_cal):
    _, cal = paper_cal
    aligned, tracker = planes_run(PAPER, seed=9, reps=2, compensator=cal.compensator)
    after = segment_planes_run(aligned, tracker, DUO, other_max_deg=None)
    assert [len(v) for v in after.by_half_plane().values()] == [2, 2, 2, 2]
    seg = segment_planes_run(*planes_run(PAPER, seed=1, reps=2), DUO)
    measured = fit_planes(seg, n_bootstrap=0, compensated=after)
    assert measured.residual_source == "measured"
    for h in HALF_PLANES:
        assert measured.residual_deviation_deg[h] < 1.0


def test_paper_sine_rule_agrees_to_first_order():
    bend = OrthogonalCompensator(PAPER)
    sine = OrthogonalCompensator(PAPER, combine="direction_sine")
    small = np.array([0.5, -0.3]), np.array([0.2, 0.4])
    np.testing.assert_allclose(sine.compensate(*small), bend.compensate(*small), atol=1e-4)  # O(theta^3)
    with pytest.raises(LimitError, match="exceed 1"):
        sine.compensate(85.0, 85.0)


def test_bad_deviations_rejected():
    with pytest.raises(CalibrationError, match="missing"):
        OrthogonalCompensator({"y+": 1.0})
    with pytest.raises(CalibrationError, match="do not alternate"):
        OrthogonalCompensator({"y+": -89.0, "y-": 0.0, "x+": 5.0, "x-": 0.0})  # y+ at 1 deg, before x+ at 5
    with pytest.raises(CalibrationError, match="unknown combine"):
        OrthogonalCompensator(PAPER, combine="magic")


# -- delta (thesis) -------------------------------------------------------------------------------

@pytest.mark.parametrize("twist", [-8.0, 7.5, 25.0])
def test_delta_recovers_a_uniform_twist(twist):
    # Perpendicular planes twisted together: the thesis's hypothesis holds exactly. Noise moves the
    # cross-talk minimum by about (direction noise / RMS lateral offset) ~ 0.41 mm / (10 mm * sqrt(1300))
    # ~ 0.07 deg, and the symmetry term adds the peak-amplitude jitter of the sweeps (ratios drawn
    # within 85-100 %), which cancels only on average; 0.5 deg bounds both with room.
    seg = segment_planes_run(*planes_run({h: twist for h in HALF_PLANES}, seed=4), DUO)
    fit = fit_delta(seg.sweeps)
    assert fit.delta_deg == pytest.approx(twist, abs=0.5)
    assert fit.crosstalk_first_rms_deg < 1.0 and fit.crosstalk_second_rms_deg < 1.0
    no_symmetry = fit_delta(seg.sweeps, symmetry_weight=0.0)
    assert no_symmetry.delta_deg == pytest.approx(twist, abs=0.2)


def test_delta_noise_free_is_exact():
    seg = segment_planes_run(*planes_run({h: 12.0 for h in HALF_PLANES}, pos_noise_mm=0.0, rot_noise_deg=0.0, seed=2), DUO)
    assert fit_delta(seg.sweeps, symmetry_weight=0.0).delta_deg == pytest.approx(12.0, abs=1e-5)


def test_delta_in_calibration_with_interval(paper_cal):
    _, cal = paper_cal
    lo, hi = cal.delta_ci_deg
    # the paper's four twists have no common value: delta is a compromise inside their range
    assert min(PAPER.values()) < cal.delta_deg < max(PAPER.values())
    assert lo < cal.delta_deg < hi


def test_aligned_bending_angles_use_delta(paper_cal):
    _, cal = paper_cal
    p = np.array([[-np.sin(np.radians(cal.delta_deg)), np.cos(np.radians(cal.delta_deg)), 1.0]])  # 45 deg along the twisted y
    t1, t2 = cal.aligned_bending_angles_deg(p)
    assert t1[0] == pytest.approx(45.0, abs=1e-9) and t2[0] == pytest.approx(0.0, abs=1e-9)


# -- results and planes.json ------------------------------------------------------------------------

def test_json_keys_and_round_trip(paper_cal, tmp_path):
    _, cal = paper_cal
    d = cal.to_json()
    for key in ("deviation_deg", "residual_deviation_deg"):
        assert list(d[key]) == ["y+", "y-", "x+", "x-"]
    assert isinstance(d["delta_deg"], float)
    assert d["sweeps_used"][0] == {**d["sweeps_used"][0], "run": "sim-1", "index": 0, "half_plane": "y+"}
    assert sum(1 for s in d["sweeps_used"]) == 16
    path = save_planes(cal, tmp_path / "planes.json")
    raw = json.loads(path.read_text())
    assert raw["format"] == "endocal-planes" and raw["version"] == 1
    back = load_planes(path)
    assert back.to_json() == d
    first, second = np.array([10.0, -20.0]), np.array([5.0, 0.0])
    np.testing.assert_allclose(back.compensate(first, second), cal.compensate(first, second), atol=0)
    with pytest.raises(OutputExistsError):
        save_planes(cal, path)
    save_planes(cal, path, force=True)


def test_load_rejects_bad_files(paper_cal, tmp_path):
    _, cal = paper_cal
    bad = tmp_path / "bad.json"
    for content, pattern in (
        ({"format": "endocal-model", "version": 1}, "not an endocal planes file"),
        ({"format": "endocal-planes", "version": 2}, "version 2 is not supported"),
        ({"format": "endocal-planes", "version": 1}, "lacks key 'deviation_deg'"),
    ):
        bad.write_text(json.dumps(content))
        with pytest.raises(ModelError, match=pattern):
            load_planes(bad)
    broken = cal.to_json()
    broken["deviation_signed_deg"]["y+"] = -85.0  # y+ at 5 deg, x- at 195.6: a sector over 180 deg, no compensator
    bad.write_text(json.dumps({"format": "endocal-planes", "version": 1, **broken}))
    with pytest.raises(ModelError, match="do not alternate"):
        load_planes(bad)
    bad.write_text("{not json")
    with pytest.raises(ModelError, match="not valid JSON"):
        load_planes(bad)
    with pytest.raises(ModelError, match="does not exist"):
        load_planes(tmp_path / "nope.json")


def test_errors_are_endocal_errors():
    assert issubclass(CalibrationError, EndocalError) and issubclass(CalibrationError, ValueError)


def test_single_sweep_per_half_plane_falls_back_to_frames():
    seg = segment_planes_run(*planes_run(PAPER, reps=1, seed=11), DUO)
    cal = fit_planes(seg, n_bootstrap=50)
    assert set(cal.ci_method.values()) == {"frames"}
    assert cal.residual_source == "in-sample"
    for h in HALF_PLANES:
        assert abs(cal.deviation_signed_deg[h] - PAPER[h]) < 0.5
        assert cal.residual_deviation_deg[h] < 1e-6  # the bend-vector rule is exact on its own plant


def test_sweeps_built_from_arrays():
    # The library also takes plain arrays (no run format): one Sweep per half-plane.
    sweeps = []
    for i, h in enumerate(HALF_PLANES):
        knob, sign = (0, 1.0) if h == "y+" else (0, -1.0) if h == "y-" else (1, 1.0) if h == "x+" else (1, -1.0)
        a = np.linspace(1, 40, 30) * sign
        cmd = np.zeros((30, 2))
        cmd[:, knob] = a
        bx, by = twisted_plane_bend_rad(cmd[:, 0], cmd[:, 1], PAPER)
        tip, rot = tip_pose_in_base(bx, by, 45.0)
        sweeps.append(Sweep(h, "arrays", i, np.arange(30.0), tip, rot.apply([0.0, 0.0, 1.0]), cmd))
    cal = fit_planes(Segmentation(sweeps), n_bootstrap=0)
    for h in HALF_PLANES:
        assert cal.deviation_signed_deg[h] == pytest.approx(PAPER[h], abs=1e-9)
    assert isinstance(cal, PlanesCalibration)


# -- the paper's plane model versus the bend-line model ------------------------------------------------

def _offset_sweeps(offset_deg):
    """Noise-free sweeps where the other knob keeps a residual bend ``offset_deg`` (backlash)."""
    sweeps = []
    for i, h in enumerate(HALF_PLANES):
        beta = np.linspace(0.0, 40.0, 40) * (1 if h.endswith("+") else -1)
        zero = np.zeros_like(beta)
        first, second = (beta, zero) if h.startswith("y") else (zero, beta)
        bx, by = twisted_plane_bend_rad(first, second, PAPER)
        # the other knob's residual bend, along its own positive half-plane
        other = "x+" if h.startswith("y") else "y+"
        psi = np.radians({"x+": 0.0, "y+": 90.0}[other] + PAPER[other])
        bx, by = bx + np.radians(offset_deg) * np.cos(psi), by + np.radians(offset_deg) * np.sin(psi)
        tip, rot = tip_pose_in_base(bx, by, 45.0)
        sweeps.append(Sweep(h, "offset", i, np.arange(40.0), tip, rot.apply([0.0, 0.0, 1.0]), np.c_[first, second]))
    return Segmentation(sweeps)


def test_plane_model_is_the_paper_and_exact_without_residual_bend():
    cal = fit_planes(_offset_sweeps(0.0), model="plane", n_bootstrap=0)
    for h in HALF_PLANES:
        assert cal.deviation_signed_deg[h] == pytest.approx(PAPER[h], abs=1e-9)
        assert cal.tilt_deg[h] == pytest.approx(0.0, abs=1e-9)


def test_bend_line_model_survives_a_residual_bend_of_the_other_knob():
    seg = _offset_sweeps(8.0)  # the simulator's default backlash leaves 8-12 deg
    line = fit_planes(seg, n_bootstrap=0)
    plane = fit_planes(seg, model="plane", n_bootstrap=0)
    for h in HALF_PLANES:
        assert line.deviation_signed_deg[h] == pytest.approx(PAPER[h], abs=1e-9)  # exact: a line in bend space
        other = "x+" if h.startswith("y") else "y+"
        angle = np.radians((NOMINAL[h] + PAPER[h]) - (NOMINAL[other] + PAPER[other]))
        assert line.offset_deg[h] == pytest.approx(8.0 * abs(np.sin(angle)), abs=1e-9)  # distance across the line
    # The through-axis plane is tilted by the offset and its deviation biased by degrees.
    assert max(abs(plane.deviation_signed_deg[h] - PAPER[h]) for h in HALF_PLANES) > 2.0
    assert min(plane.tilt_deg[h] for h in HALF_PLANES) > 1.0


def test_simulator_planes_run():
    # The physics simulator (tendon-sheath friction, dead zone, envelope; tracker noise 0.5 mm, 0.1 deg)
    # with the paper's deviations: every angle within 0.5 deg and under 1 deg after compensation.
    from endocal.sim.config import SimConfig
    from endocal.sim.simulator import Simulator

    cfg = SimConfig.default()
    truth = cfg.deviation_deg
    rate = 100.0
    ramp = np.concatenate([np.linspace(0, 1, int(3 * rate)), np.linspace(1, 0, int(3 * rate)), np.zeros(int(1.5 * rate))])
    c1, c2 = [np.zeros(100)], [np.zeros(100)]
    for _ in range(3):
        for knob, sign in ((0, 1), (0, -1), (1, 1), (1, -1)):
            c1.append(sign * 80 * ramp if knob == 0 else 0 * ramp)
            c2.append(sign * 80 * ramp if knob == 1 else 0 * ramp)
    c1, c2 = np.concatenate(c1), np.concatenate(c2)
    t = np.arange(len(c1)) / rate + 0.01
    chunk = Simulator(cfg, DUO, seed=3).execute(t, {"ud": c1, "lr": c2, "translation": 0 * t, "rotation": 0 * t})
    seg = segment_planes_run(pd.DataFrame({"t_s": t, "ud_cmd_deg": c1, "lr_cmd_deg": c2}), pd.DataFrame(chunk.tracker), DUO)
    cal = fit_planes(seg, n_bootstrap=50)
    after = residual_deviation(cal.compensator, truth)
    for h in HALF_PLANES:
        assert abs(cal.deviation_signed_deg[h] - truth[h]) < 0.5
        assert after[h].deviation_deg < 1.0
        assert cal.residual_deviation_deg[h] < 1.0


def test_calibration_prints_as_a_report(paper_cal):
    _, cal = paper_cal
    text = str(cal)
    assert "alpha_y- =  20.1" in text or "alpha_y- =  20.2" in text
    assert "16 sweeps" in text and "cross-validated" in text
