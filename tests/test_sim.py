"""Simulator: configuration, stream contract, determinism, and the base tendon-sheath physics.

Tolerances are argued from the physics and the noise floor in comments; runs are seconds to a
minute of simulated time (the whole file takes a few seconds once numba's cache is warm).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from endocal.backends.base import TRACKER_COLUMNS, Backend, motor_columns
from endocal.backends.sim import SimBackend
from endocal.errors import ConfigError, LimitError, ProtocolError
from endocal.kinematics import bending_angles_deg, tip_in_base_mm
from endocal.probe import PRESETS
from endocal.sim import EFFECTS, SimConfig, Simulator

ROOT = Path(__file__).resolve().parents[1]
TEE = PRESETS["tee"]
FS_HZ = 100.0


# -- helpers shared with test_sim_effects.py -----------------------------------------------
def simulate(cfg=None, goals=None, duration_s=20.0, seed=0, probe=TEE, chunks=None):
    """Run ``goals(t) -> {dof: array}`` (missing DoFs held at 0) at 100 Hz; return (t, chunk list)."""
    cfg = cfg or SimConfig.default()
    t = np.arange(int(round(duration_s * FS_HZ))) / FS_HZ
    g = {d: np.zeros_like(t) for d in probe.dofs}
    g.update(goals(t) if goals else {})
    sim = Simulator(cfg, probe, seed=seed)
    bounds = [0, t.size] if chunks is None else chunks
    out = [sim.execute(t[a:b], {k: v[a:b] for k, v in g.items()}) for a, b in zip(bounds[:-1], bounds[1:])]
    return t, out


def concat(chunks, stream):
    keys = getattr(chunks[0], stream).keys()
    return {k: np.concatenate([getattr(c, stream)[k] for c in chunks]) for k in keys}


def run(cfg=None, goals=None, duration_s=20.0, seed=0, probe=TEE):
    t, chunks = simulate(cfg, goals, duration_s, seed, probe)
    return t, chunks[0]


def measured_angles(tracker):
    """Eq.-1 angles (thesis eq. 1) from the tracker stream: frame times, first, second axis (deg)."""
    tip = {k: np.asarray(v)[tracker["sensor"] == "tip"] for k, v in tracker.items()}
    base = {k: np.asarray(v)[tracker["sensor"] == "base"] for k, v in tracker.items()}
    assert np.array_equal(tip["t_s"], base["t_s"])
    ok = tip["valid"] & base["valid"]
    p_tip = np.column_stack([tip["x_mm"], tip["y_mm"], tip["z_mm"]])[ok]
    p_base = np.column_stack([base["x_mm"], base["y_mm"], base["z_mm"]])[ok]
    q_base = np.column_stack([base[k] for k in ("qw", "qx", "qy", "qz")])[ok]
    rel = tip_in_base_mm(p_tip, p_base, q_base)
    a1, a2 = bending_angles_deg(rel)
    return tip["t_s"][ok], a1, a2, rel


def branches(q, y, grid):
    """Ascending and descending branches of ``y`` over knob angle ``q``, interpolated on ``grid``."""
    dq = np.gradient(q)
    out = []
    for mask in (dq > 1e-6, dq < -1e-6):
        o = np.argsort(q[mask])
        out.append(np.interp(grid, q[mask][o], y[mask][o]))
    return out


def sine(axis, amp_deg, f_hz, offset_deg=0.0):
    return lambda t: {axis: offset_deg + amp_deg * np.sin(2 * np.pi * f_hz * t)}


def quiet(cfg=None, **sections):
    """Noise-free, latency-free tracker (for tests of the mechanics through the tracker)."""
    cfg = cfg or SimConfig.default()
    tr = {"noise_mm": 0.0, "orientation_noise_deg": 0.0, "latency_s": 0.0, **sections.pop("tracker", {})}
    mo = {"current_noise_ma": 0.0, **sections.pop("motor", {})}
    return cfg.replace(tracker=tr, motor=mo, **sections)


# -- configuration ---------------------------------------------------------------------------
def test_default_toml_lists_every_parameter_with_its_default():
    import tomllib

    path = ROOT / "configs" / "sim-default.toml"
    assert SimConfig.from_toml(path) == SimConfig.default()
    parsed = tomllib.loads(path.read_text())
    expected = SimConfig.default().to_dict()
    assert set(parsed) == set(expected)
    for section, values in expected.items():
        assert set(parsed[section]) == set(values), section


def test_config_dict_round_trip_and_hash():
    cfg = SimConfig.default().replace(rate={"enabled": True}, tendon={"mu": 0.3})
    d = json.loads(json.dumps(cfg.to_dict()))
    assert SimConfig.from_dict(d) == cfg
    assert cfg.config_hash() != SimConfig.default().config_hash()
    assert SimConfig.default().effects_enabled() == ["deadzone", "envelope"]
    assert cfg.effects_enabled() == ["rate", "deadzone", "envelope"]
    assert set(EFFECTS) == {"rate", "deadzone", "envelope", "coupling", "delay", "drift", "creep", "load"}


@pytest.mark.parametrize(
    "text, fragment",
    [
        ("[tendon]\nmuu = 0.2\n", "tendon.muu"),
        ("[bogus]\nx = 1\n", "bogus"),
        ("deviation_deg = { \"z+\" = 1.0 }\n", "deviation_deg.z+"),
        ("[bending]\nstiffness_nmm_per_rad = -3.0\n", "bending.stiffness_nmm_per_rad"),
        ("[tracker]\nnoise_mm = -0.1\n", "tracker.noise_mm"),
        ("[rate]\nenabled = 1\n", "rate.enabled"),
        ("[tendon]\nn_segments = 3.5\n", "tendon.n_segments"),
        ("[load]\nmode = \"square\"\n", "load.mode"),
        ("[tracker]\nmount_xyz_mm = [1, 2]\n", "tracker.mount_xyz_mm"),
        ("[load]\nenabled = true\namplitude_deg = 300.0\n", "load.amplitude_deg"),
        ("[tendon\nmu = 0.2\n", "not valid TOML"),
        ("tendon = 3\n", "[tendon]"),
    ],
)
def test_bad_config_is_a_config_error_naming_key_and_file(tmp_path, text, fragment):
    path = tmp_path / "bad-sim.toml"
    path.write_text(text)
    with pytest.raises(ConfigError) as info:
        SimConfig.from_toml(path)
    assert fragment in str(info.value)
    assert str(path) in str(info.value)


def test_missing_file_and_bad_contact_axis(tmp_path):
    with pytest.raises(ConfigError, match="does not exist"):
        SimConfig.from_toml(tmp_path / "nope.toml")
    cfg = SimConfig.default().replace(contact={"enabled": True, "axis": "rotation"})
    with pytest.raises(ConfigError, match="contact.axis"):
        Simulator(cfg, TEE)
    # A valid config loads partially: missing keys keep their defaults.
    path = tmp_path / "partial.toml"
    path.write_text("[rate]\nenabled = true\n")
    assert SimConfig.from_toml(path) == SimConfig.default().replace(rate={"enabled": True})


# -- stream contract, chunking, determinism --------------------------------------------------
def test_stream_columns_and_units():
    t, c = run(goals=sine("ap", 30, 0.2), duration_s=2.0)
    assert list(c.motor) == motor_columns(TEE) + ["contact_force_n", "sheath_wrap_deg"]
    assert tuple(c.tracker) == TRACKER_COLUMNS
    assert list(c.truth) == ["t_s", "ap_true_deg", "ml_true_deg", "bend_x_rad", "bend_y_rad", "contact_force_n"]
    assert all(v.shape == t.shape for v in c.motor.values())
    # 40 Hz frames over [0, 1.99] s: frames 0..79, tip then base.
    assert c.tracker["t_s"].size == 2 * 80
    assert list(c.tracker["sensor"][:4]) == ["tip", "base", "tip", "base"]
    np.testing.assert_allclose(c.tracker["t_s"][::2], np.arange(80) / 40.0)
    assert c.tracker["valid"].dtype == bool and c.tracker["valid"].all()
    np.testing.assert_array_equal(c.motor["sheath_wrap_deg"], 180.0)
    np.testing.assert_array_equal(c.motor["contact_force_n"], 0.0)
    # velocity is the derivative of position (deg/s); a 2nd-order loop's velocity is smooth,
    # so central differences at 100 Hz agree to well under 1 deg/s for a 0.2 Hz, 30 deg sine.
    pos, vel = c.motor["ap_pos_deg"], c.motor["ap_vel_degps"]
    np.testing.assert_allclose(np.gradient(pos, t)[5:-5], vel[5:-5], atol=1.0)


ALL_ON = dict(
    rate={"enabled": True}, coupling={"enabled": True}, delay={"enabled": True}, drift={"enabled": True},
    creep={"enabled": True}, load={"enabled": True}, contact={"enabled": True, "wall_deg": 20.0},
    tracker={"invalid_rate": 0.1},
)


def _lissajous(t):
    return {"ap": 60 * np.sin(2 * np.pi * 0.3 * t), "ml": 50 * np.sin(2 * np.pi * 0.23 * t + 1.0),
            "translation": 20 * np.sin(2 * np.pi * 0.1 * t), "rotation": 30 * np.sin(2 * np.pi * 0.07 * t)}


def test_chunked_execution_equals_one_call_exactly():
    cfg = SimConfig.default().replace(**ALL_ON)
    t, whole = simulate(cfg, _lissajous, duration_s=6.0, seed=3)
    rng = np.random.default_rng(0)
    cuts = np.unique(np.concatenate([[0, 1, 2, 3, 150, 151], rng.integers(4, t.size, 40), [t.size]]))
    _, parts = simulate(cfg, _lissajous, duration_s=6.0, seed=3, chunks=list(cuts))
    for stream in ("motor", "tracker", "truth"):
        a, b = getattr(whole[0], stream), concat(parts, stream)
        assert list(a) == list(b)
        for k in a:
            assert np.array_equal(a[k], b[k], equal_nan=a[k].dtype.kind == "f"), (stream, k)


def test_same_seed_same_streams_other_seed_other_noise():
    cfg = SimConfig.default()
    _, a = run(cfg, sine("ap", 40, 0.2), 3.0, seed=1)
    _, b = run(cfg, sine("ap", 40, 0.2), 3.0, seed=1)
    _, c = run(cfg, sine("ap", 40, 0.2), 3.0, seed=2)
    assert np.array_equal(a.tracker["x_mm"], b.tracker["x_mm"])
    assert np.array_equal(a.motor["ap_current_ma"], b.motor["ap_current_ma"])
    assert not np.array_equal(a.tracker["x_mm"], c.tracker["x_mm"])
    # The physics itself is noise-free: the seed changes measurements, not the truth.
    assert np.array_equal(a.truth["ap_true_deg"], c.truth["ap_true_deg"])


def test_bad_input_is_refused():
    sim = Simulator(SimConfig.default(), TEE)
    t = np.arange(5) / FS_HZ
    ok = {d: np.zeros(5) for d in TEE.dofs}
    with pytest.raises(LimitError, match="ap"):
        sim.execute(t, {**ok, "ap": np.full(5, 95.0)})
    with pytest.raises(ProtocolError, match="lacks"):
        sim.execute(t, {k: v for k, v in ok.items() if k != "ml"})
    with pytest.raises(ProtocolError, match="unknown"):
        sim.execute(t, {**ok, "ud": np.zeros(5)})
    with pytest.raises(ProtocolError, match="increasing"):
        sim.execute(t[::-1], ok)
    with pytest.raises(ProtocolError, match="NaN"):
        sim.execute(t, {**ok, "ml": np.full(5, np.nan)})
    sim.execute(t, ok)
    with pytest.raises(ProtocolError, match="previous chunk"):
        sim.execute(t, ok)


def test_backend_contract():
    be = SimBackend(SimConfig.default(), TEE, seed=4)
    assert isinstance(be, Backend) and be.name == "sim" and be.realtime is False
    be.open()
    c = be.execute(np.arange(10) / FS_HZ, {d: np.zeros(10) for d in TEE.dofs})
    assert c.motor["t_s"].size == 10
    be.close()
    be.close()
    d = be.describe()
    assert d["seed"] == 4 and d["config_hash"] == SimConfig.default().config_hash()
    assert d["effects_enabled"] == ["deadzone", "envelope"]
    json.dumps(d)


# -- kinematics and tracker --------------------------------------------------------------------
def test_truth_is_eq1_of_the_noise_free_tracker():
    """With zero noise and latency, eq. 1 on the tracker frames reproduces the truth angles
    (both built from the same CC pose; only float round-off separates them)."""
    cfg = quiet()
    t, c = run(cfg, _lissajous, 5.0)
    tf, a1, a2, _ = measured_angles(c.tracker)
    on_tick = np.abs(tf * FS_HZ - np.round(tf * FS_HZ)) < 1e-9  # every other 40 Hz frame is on a 100 Hz tick
    tf, a1, a2 = tf[on_tick], a1[on_tick], a2[on_tick]
    idx = np.round(tf * FS_HZ).astype(int)
    np.testing.assert_allclose(t[idx], tf, atol=1e-12)
    np.testing.assert_allclose(a1, c.truth["ap_true_deg"][idx], atol=1e-8)
    np.testing.assert_allclose(a2, c.truth["ml_true_deg"][idx], atol=1e-8)


def test_translation_and_rotation_move_the_base_not_the_bend():
    cfg = quiet()
    goals = lambda t: {"ap": np.full_like(t, 40.0), "translation": np.minimum(10 * t, 30.0), "rotation": np.minimum(20 * t, 60.0)}
    t, c = run(cfg, goals, 6.0)
    tr = c.tracker
    base = np.column_stack([tr[k][tr["sensor"] == "base"] for k in ("x_mm", "y_mm", "z_mm")])
    # The base slides 30 mm along the mount's z axis (after the 50 ms loops settle).
    assert np.linalg.norm(base[-1] - base[0]) == pytest.approx(30.0, abs=1e-6)
    _, a1, _, _ = measured_angles(tr)
    late = a1[-40:]
    assert np.ptp(late) < 1e-9  # bend unchanged by translation/rotation once the knob has settled
    assert c.motor["rotation_pos_deg"][-1] == pytest.approx(60.0, abs=1e-6)
    assert c.motor["translation_pos_mm"][-1] == pytest.approx(30.0, abs=1e-6)


def test_tracker_noise_matches_config_and_dropouts():
    cfg = SimConfig.default().replace(tracker={"invalid_rate": 0.05, "latency_s": 0.0})
    t, c = run(cfg, None, 60.0, seed=11)
    tr = c.tracker
    n_frames = tr["t_s"].size // 2
    valid = tr["valid"]
    # Binomial: 4800 sensor frames at p = 0.05 -> std of the rate 0.0031; allow 4 sigma.
    assert abs((~valid).mean() - 0.05) < 4 * np.sqrt(0.05 * 0.95 / (2 * n_frames))
    assert np.isnan(tr["x_mm"][~valid]).all() and np.isfinite(tr["x_mm"][valid]).all()
    sigma = 0.5 / np.sqrt(3.0)  # 0.5 mm RMS in 3-D
    for sensor in ("tip", "base"):
        sel = valid & (tr["sensor"] == sensor)
        for k in ("x_mm", "y_mm", "z_mm"):
            # The probe is static: the spread is the noise. ~2280 samples -> relative SE of a
            # std is 1/sqrt(2n) = 1.5 %; allow 6 % (4 SE).
            assert np.std(tr[k][sel]) == pytest.approx(sigma, rel=0.06), (sensor, k)
    # Orientation noise: RMS rotation angle between frames and their mean ~ 0.1 deg.
    sel = valid & (tr["sensor"] == "base")
    q = np.column_stack([tr[k][sel] for k in ("qw", "qx", "qy", "qz")])
    q *= np.sign(q[:, :1])
    mean = q.mean(axis=0) / np.linalg.norm(q.mean(axis=0))
    ang = 2 * np.degrees(np.arccos(np.clip(np.abs(q @ mean), 0, 1)))
    assert np.sqrt(np.mean(ang**2)) == pytest.approx(0.1, rel=0.08)


@pytest.mark.parametrize("probe_name", ["tee", "duodenoscope"])
def test_single_knob_sweep_stays_in_its_deviated_plane(probe_name):
    """Duodenoscope paper sec. 2.2: one wire pulling bends the tip within one plane, at the
    deviation of sec. 3.2. Fit each half-plane's direction from noisy tracker data."""
    probe = PRESETS[probe_name]
    dev = {"y+": 12.7, "y-": 20.2, "x+": 2.3, "x-": 15.6}
    nominal = {"y+": 90.0, "y-": 270.0, "x+": 0.0, "x-": 180.0}
    for i, axis in enumerate(probe.bending_axes):
        t, c = run(SimConfig.default(), sine(axis, 75, 0.1), 20.0, seed=5, probe=probe)
        _, _, _, rel = measured_angles(c.tracker)
        xy = rel[:, :2]
        for sign, plane in ((1, "y+" if i == 0 else "x+"), (-1, "y-" if i == 0 else "x-")):
            pts = xy[np.linalg.norm(xy, axis=1) > 10.0]  # well away from the noise around straight
            want = np.radians(nominal[plane] + dev[plane])
            pts = pts[(pts @ np.array([np.cos(want), np.sin(want)])) > 0]
            # Least-squares line through the origin (SVD of the points, as in the paper's eq. 1).
            _, _, vt = np.linalg.svd(pts, full_matrices=False)
            d = vt[0] * np.sign(vt[0] @ pts.mean(axis=0))
            got = np.degrees(np.arctan2(d[1], d[0])) % 360
            # ~200 points 10-45 mm out with 0.29 mm noise per coordinate: direction SE ~ 0.02 deg;
            # 0.3 deg is the brief's bound and leaves a wide margin.
            assert abs(got - (nominal[plane] + dev[plane]) % 360) < 0.3, (probe_name, plane, got)


# -- base physics ------------------------------------------------------------------------------
def test_magnitudes_and_uncompensated_error():
    # Knob +-75 deg gives +-40..60 deg of eq.-1 angle (brief), and a knob-equals-desired-angle
    # controller misses a +-40 deg sine by well over 5 deg RMS.
    t, c = run(quiet(deviation_deg={"y+": 0.0, "y-": 0.0, "x+": 0.0, "x-": 0.0}), sine("ap", 75, 0.05), 25.0)
    y = c.truth["ap_true_deg"]
    assert 40.0 < y.max() < 60.0 and -60.0 < y.min() < -40.0
    t, c = run(SimConfig.default(), sine("ap", 40, 0.05), 40.0)
    err = c.truth["ap_true_deg"] - c.motor["ap_goal_deg"]
    assert np.sqrt(np.mean(err[t > 10] ** 2)) > 7.0


def _loop_width(cfg, amp=70.0, f=0.1):
    """Mean vertical width (deg) of the knob-position -> true-angle loop over |q| < 0.8 amp."""
    t, c = run(cfg, sine("ap", amp, f), 2.0 / f)
    sel = t >= 1.0 / f
    up, down = branches(c.motor["ap_pos_deg"][sel], c.truth["ap_true_deg"][sel], np.linspace(-0.8 * amp, 0.8 * amp, 41))
    return np.mean(down - up)


def test_hysteresis_loop_present_in_measurements():
    """Descending branch above the ascending one at the same knob angle, measured through the
    noisy tracker: the branch means over 10-deg knob bins differ by far more than their noise."""
    t, c = run(SimConfig.default(), sine("ap", 70, 0.1), 40.0, seed=2)
    tf, a1, _, _ = measured_angles(c.tracker)
    q = np.interp(tf, t, c.motor["ap_pos_deg"])
    dq = np.interp(tf, t, c.motor["ap_vel_degps"])
    diffs = []
    for lo in range(-50, 50, 10):
        b = (q >= lo) & (q < lo + 10)
        up, dn = a1[b & (dq > 0)], a1[b & (dq < 0)]
        # Compare at equal knob angles: remove the within-bin slope with a linear fit per branch.
        mid = lo + 5.0
        fu = np.polyval(np.polyfit(q[b & (dq > 0)], up, 1), mid)
        fd = np.polyval(np.polyfit(q[b & (dq < 0)], dn, 1), mid)
        diffs.append(fd - fu)
    # Measurement noise of one eq.-1 angle is ~0.5 deg (0.5 mm / 60 mm, two sensors); a fitted
    # value from ~30 frames is ~0.1 deg. Backlash from capstan friction + joint friction is
    # several degrees everywhere on the loop.
    assert min(diffs) > 2.0


def test_loop_width_grows_with_friction_and_wrap():
    cfg = SimConfig.default()
    w_base = _loop_width(cfg)
    w_mu = _loop_width(cfg.replace(tendon={"mu": 0.4}))
    w_wrap = _loop_width(cfg.replace(tendon={"wrap_deg": 360.0}))
    w_frictionless = _loop_width(cfg.replace(tendon={"mu": 0.0}, bending={"friction_nmm": 0.0}))
    # Capstan backlash in tendon length ~ mu*Theta*sum(w)*T_N: doubling mu*Theta doubles the
    # tension-dependent part of the width; the joint-friction part stays. Demand a 30 % rise
    # (the default splits the width roughly evenly between the two).
    assert w_mu > 1.3 * w_base
    # The capstan law depends on mu and the wrap only through mu*Theta.
    assert w_wrap == pytest.approx(w_mu, rel=1e-9)
    # Without any friction there is no loop at all (quasi-static elastic system).
    assert abs(w_frictionless) < 0.01


def test_slack_makes_a_flat_output_region_around_neutral():
    """With slack tendons both are loose near the neutral knob: the bend cannot change there.
    The knob travels through a band of width ~2*(slack - pretension stretch)/r_p with the
    output frozen; compare the frozen knob range with and without slack."""
    def frozen_range(cfg):
        t, c = run(cfg, sine("ap", 40, 0.05), 40.0)
        sel = (t > 20) & (c.motor["ap_vel_degps"] < 0)  # one descending sweep through neutral
        q, y = c.motor["ap_pos_deg"][sel], c.truth["ap_true_deg"][sel]
        dy = np.abs(np.diff(y))
        still = dy < 1e-9
        return np.sum(np.abs(np.diff(q))[still])

    slack_mm = 3.0
    cfg = SimConfig.default().replace(deadzone={"enabled": True, "slack_mm": slack_mm})
    cfg_off = cfg.replace(deadzone={"enabled": False})
    pre_stretch = 4.0 * (1000.0 + 60.0) / 8000.0  # pretension x compliance (mm)
    expected = np.degrees(2 * (slack_mm - pre_stretch) / 10.0)
    on, off = frozen_range(cfg), frozen_range(cfg_off)
    # The frozen band also contains the joint-friction backlash (same with and without slack),
    # so compare the difference; friction in the tendons shifts where each tendon takes up its
    # slack by a little, hence 25 %.
    assert on - off == pytest.approx(expected, rel=0.25)


def test_contact_force_only_past_the_wall_and_it_reduces_the_bend():
    wall = 25.0
    cfg = quiet(deviation_deg={"y+": 0.0, "y-": 0.0, "x+": 0.0, "x-": 0.0})
    cfg_c = cfg.replace(contact={"enabled": True, "axis": "ap", "wall_deg": wall, "stiffness_n_per_mm": 0.05})
    t, free = run(cfg, sine("ap", 80, 0.05), 40.0)
    t, hit = run(cfg_c, sine("ap", 80, 0.05), 40.0)
    f = hit.truth["contact_force_n"]
    y = hit.truth["ap_true_deg"]
    np.testing.assert_array_equal(f, hit.motor["contact_force_n"])
    assert np.all(f >= 0)
    assert np.all(f[y <= wall] == 0.0)  # no force short of the wall (in-plane: eq. 1 = half the bend)
    assert np.all(f[y > wall + 0.01] > 0.0)
    assert f.max() > 0.2
    assert y.max() < free.truth["ap_true_deg"].max() - 3.0
    assert np.all(free.truth["contact_force_n"] == 0.0)
    # The knob feels the wall (duodenoscope paper eq. 12): more current at the same knob angle.
    i_max = np.argmax(hit.motor["ap_pos_deg"][:2000])
    assert hit.motor["ap_current_ma"][i_max] > free.motor["ap_current_ma"][i_max] + 20.0


def test_motor_position_loop_lag():
    cfg = quiet(motor={"knob_time_constant_s": 0.05, "knob_max_speed_dps": 1e4})
    t, c = run(cfg, lambda t: {"ml": np.where(t >= 0.5, 10.0, 0.0)}, 2.0)
    q = c.motor["ml_pos_deg"]
    i = np.searchsorted(t, 0.5 + 0.05)
    # Critically damped step response at t = tau: 1 - 2/e = 0.2642 of the step (exact solution,
    # goal held constant over each tick).
    assert q[i] == pytest.approx(10 * (1 - 2 / np.e), rel=1e-9)
    cfg = quiet(motor={"knob_max_speed_dps": 100.0})
    t, c = run(cfg, lambda t: {"ml": np.where(t >= 0.5, 60.0, 0.0)}, 2.0)
    assert np.abs(c.motor["ml_vel_degps"]).max() <= 100.0 + 1e-9
    assert np.abs(np.diff(c.motor["ml_pos_deg"])).max() <= 1.0 + 1e-9
