"""Protocol files, parameters, overrides and trajectories (endocal/protocols/protocol.py).

Each shipped protocol is checked for its exact shape on the motor clock. Tolerances:
samples computed from the same closed form agree to ~1e-12 deg; shapes recovered from
samples (periods, frequencies) are exact to interpolation error as argued in
tests/test_signals.py; durations are exact to one sample (10 ms at 100 Hz).
"""

from __future__ import annotations

import hashlib
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from endocal.errors import EndocalError, LimitError, ProtocolError
from endocal.probe import PRESETS, ProbeConfig
from endocal.protocols import SIGNALS, Protocol, Trajectory, list_protocols, load_protocol, parse_overrides
from endocal.protocols.protocol import shipped_protocols_dir

REPO = Path(__file__).resolve().parents[1]
TEE, DUO = PRESETS["tee"], PRESETS["duodenoscope"]
REQUIRED = ["sine-set", "sine-varying", "damped-sine", "triangle", "chirp", "random", "staircase", "circle",
            "lissajous", "planes"]


def shipped_names():
    return sorted(p.stem for p in (REPO / "protocols").glob("*.toml"))


def nonzero_runs(x: np.ndarray, tol: float = 1e-9) -> list[tuple[int, int]]:
    """(first, last) indices of maximal runs of samples with |x| > tol.

    ``tol`` sits far above the rounding of sin(k pi) at the end of whole cycles (~1e-14 deg)
    and far below one sample's move (>= 1e-3 deg for every shipped protocol).
    """
    nz = np.concatenate([[False], np.abs(x) > tol, [False]])
    d = np.diff(nz.astype(int))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1) - 1))


def active_blocks(x: np.ndarray, fs: float, min_gap_s: float = 0.5, tol: float = 1e-9) -> list[tuple[int, int]]:
    """(first, last) indices of stretches of motion separated by rests at 0 of at least ``min_gap_s``.

    A sine passes through 0 at single samples; only a rest holds 0 for many samples.
    """
    idx = np.flatnonzero(np.abs(x) > tol)
    if idx.size == 0:
        return []
    cut = np.flatnonzero(np.diff(idx) > min_gap_s * fs)
    return list(zip(idx[np.concatenate([[0], cut + 1])], idx[np.concatenate([cut, [idx.size - 1]])]))


def zero_crossings(t, x):
    s = np.sign(x)
    idx = np.flatnonzero(s[:-1] * s[1:] < 0)
    return t[idx] - x[idx] * (t[idx + 1] - t[idx]) / (x[idx + 1] - x[idx])


# ------------------------------------------------------------------------ every shipped protocol


def test_required_protocols_are_shipped_and_listed():
    names = [n for n, _, _ in list_protocols()]
    for name in REQUIRED + ["chirp-log"]:
        assert name in names
    for name, desc, path in list_protocols():
        assert desc and Path(path).is_file()


@pytest.mark.parametrize("name", shipped_names())
def test_shipped_protocol_plays_on_both_probes_from_rest_to_rest(name):
    proto = load_protocol(name)
    text = (REPO / "protocols" / f"{name}.toml").read_text()
    # Shipped files name axes by the probe-independent aliases so they run on both probes.
    assert set(proto.params["axes"]) <= {"axis1", "axis2"}, text
    for probe in (TEE, DUO):
        traj = proto.trajectory(probe)
        traj.check_limits(probe)
        assert set(traj.goal) == set(probe.dofs)
        n = traj.n_samples
        np.testing.assert_allclose(traj.t_s, np.arange(n) / traj.sample_rate_hz, rtol=0, atol=1e-12)
        assert traj.sample_rate_hz == 100.0
        assert traj.duration_s == pytest.approx(proto.duration_s, abs=1e-9)
        for dof, g in traj.goal.items():
            assert g.shape == (n,)
            # From rest and back to rest: no jump from the resting knob at 0 on either end.
            assert abs(g[0]) < 1e-9 and abs(g[-1]) < 1e-9, dof
            # A servo can follow: no step larger than the probe's speed limit allows.
            assert np.abs(np.diff(g)).max() <= probe.max_knob_speed_dps / traj.sample_rate_hz
        assert traj.goal["translation"].max() == 0 and traj.goal["rotation"].max() == 0


# ------------------------------------------------------------------------ shapes


def test_damped_sine_is_the_duodenoscope_papers_input_at_every_sample():
    proto = load_protocol("damped-sine")
    assert (proto.params["frequency_hz"], proto.params["period_s"]) == (0.05, 20.0)
    traj = proto.trajectory(TEE)
    A, f, T = proto.params["amplitude_deg"], 0.05, 20.0
    assert traj.n_samples == 14001 and traj.duration_s == pytest.approx(140.0, abs=1e-12)
    expected = np.array([
        A * math.sin(2 * math.pi * f * t) * (1.0 if t < 2 * T else math.exp(-(t - 2 * T) / (5 * T)))
        for t in traj.t_s
    ])
    np.testing.assert_allclose(traj.goal["ap"], expected, rtol=0, atol=1e-12)
    for dof in ("ml", "translation", "rotation"):
        assert np.all(traj.goal[dof] == 0.0)


def test_sine_set_periods_amplitudes_and_each_motor_in_turn():
    proto = load_protocol("sine-set")
    p = proto.params
    amps, periods, cycles = p["amplitudes_deg"], p["periods_s"], p["cycles"]
    assert len(periods) == 4 and len(amps) == 2  # the thesis: four periods x two amplitudes
    traj = proto.trajectory(TEE)
    t, fs = traj.t_s, traj.sample_rate_hz
    a1, a2 = traj.goal["ap"], traj.goal["ml"]
    # Each motor in turn: never both moving; ap entirely before ml.
    assert not np.any((a1 != 0) & (a2 != 0))
    assert t[np.flatnonzero(a1)[-1]] < t[np.flatnonzero(a2)[0]]
    for g in (a1, a2):
        blocks = active_blocks(g, fs)
        combos = [(A, T) for A in amps for T in periods]
        assert len(blocks) == len(combos)
        for (i0, i1), (A, T) in zip(blocks, combos):
            # Block starts one sample after its zero crossing at t0 and lasts `cycles` periods.
            t0 = t[i0] - 1 / fs
            n_samples = i1 - i0 + 2
            assert n_samples / fs == pytest.approx(cycles * T, abs=1.5 / fs)
            seg = slice(i0, i1 + 1)
            np.testing.assert_allclose(g[seg], A * np.sin(2 * np.pi * (t[seg] - t0) / T), rtol=0, atol=1e-9)
            assert np.abs(g[seg]).max() == pytest.approx(A, rel=1e-9)


def test_sine_varying_two_frequencies_two_periods_each_phase_continuous():
    proto = load_protocol("sine-varying")
    freqs, cycles, A = proto.params["frequencies_hz"], proto.params["cycles"], proto.params["amplitude_deg"]
    assert len(freqs) == 2 and cycles == 2 and freqs[0] != freqs[1]
    traj = proto.trajectory(DUO)
    t, g = traj.t_s, traj.goal["ud"]
    i0, i1 = active_blocks(g, traj.sample_rate_hz)[0]
    seg_t, seg_g = t[i0 - 1 : i1 + 2], g[i0 - 1 : i1 + 2]
    assert seg_t[-1] - seg_t[0] == pytest.approx(sum(cycles / f for f in freqs), abs=1e-9)
    tc = zero_crossings(seg_t, seg_g) - seg_t[0]
    switch = cycles / freqs[0]
    for lo, hi, f in ((0, switch, freqs[0]), (switch, switch + cycles / freqs[1], freqs[1])):
        inside = tc[(tc > lo + 1e-6) & (tc < hi - 1e-6)]
        assert inside.size == 2 * cycles - 1
        np.testing.assert_allclose(np.diff(inside), 1 / (2 * f), rtol=1e-4)
    # Phase continuity: across the frequency switch no step exceeds what the faster sine's slope allows.
    assert np.abs(np.diff(seg_g)).max() <= 2 * np.pi * max(freqs) * A / traj.sample_rate_hz * (1 + 1e-9)
    k = int(round((seg_t[0] + switch) * traj.sample_rate_hz))
    assert abs(g[k]) < 1e-9  # the switch falls on a zero crossing
    # Then the second knob, the first holding still.
    assert not np.any((traj.goal["ud"] != 0) & (traj.goal["lr"] != 0)) and np.any(traj.goal["lr"] != 0)


def test_triangle_slopes():
    proto = load_protocol("triangle", overrides={"period_s": 16.0, "amplitude_deg": 40.0, "cycles": 2})
    traj = proto.trajectory(TEE)
    g, fs = traj.goal["ap"], traj.sample_rate_hz
    slope = np.diff(g) * fs
    assert traj.duration_s == pytest.approx(32.0)
    np.testing.assert_allclose(np.sort(np.unique(np.round(np.abs(slope), 6)))[-1], 4 * 40.0 / 16.0, rtol=1e-9)
    away = np.abs(np.abs(slope) - 10.0) > 1e-6
    assert away.sum() <= 2 * 4  # only the sample pairs straddling the 4 reversals differ
    assert g.max() == pytest.approx(40.0) and g.min() == pytest.approx(-40.0)


@pytest.mark.parametrize("name,method", [("chirp", "linear"), ("chirp-log", "log")])
def test_chirp_frequency_at_start_and_end(name, method):
    proto = load_protocol(name)
    p = proto.params
    assert p["method"] == method
    traj = proto.trajectory(TEE)
    t, g = traj.t_s, traj.goal["ap"]
    tc = np.concatenate([[0.0], zero_crossings(t[1:], g[1:])])
    mid, dt = 0.5 * (tc[1:] + tc[:-1]), np.diff(tc)
    f_mean = 1 / (2 * dt)
    f0, f1, D = p["f0_hz"], p["f1_hz"], p["duration_s"]
    if method == "linear":
        slope, f_start = np.polyfit(mid, f_mean, 1)  # exact: mean of a linear f is f(midpoint)
        f_end = f_start + slope * D
    else:
        u = math.log(f1 / f0) * dt / (2 * D)  # mean of an exponential f over a half cycle
        slope, lf = np.polyfit(mid, np.log(f_mean * u / np.sinh(u)), 1)
        f_start, f_end = math.exp(lf), math.exp(lf + slope * D)
    assert f_start == pytest.approx(f0, rel=1e-3)
    assert f_end == pytest.approx(f1, rel=1e-3)


class TestRandom:
    def test_seeded_reproducible_and_different_seeds_differ(self):
        proto = load_protocol("random")
        assert proto.params["seed"] is None  # follows the run's seed
        a = proto.trajectory(TEE, seed=4).goal["ap"]
        b = proto.trajectory(TEE, seed=4).goal["ap"]
        c = proto.trajectory(TEE, seed=5).goal["ap"]
        np.testing.assert_array_equal(a, b)
        assert abs(np.corrcoef(a, c)[0, 1]) < 0.5  # independent phases; 3 sigma with 23 lines
        # A seed set in the protocol (or as an override) wins over the run's seed.
        pinned = load_protocol("random", overrides={"seed": 11})
        np.testing.assert_array_equal(pinned.trajectory(TEE, seed=1).goal["ap"], pinned.trajectory(TEE, seed=2).goal["ap"])
        np.testing.assert_array_equal(pinned.trajectory(TEE, seed=1).goal["ap"], proto.trajectory(TEE, seed=11).goal["ap"])

    def test_band_limit_and_amplitude(self):
        proto = load_protocol("random")
        p = proto.params
        traj = proto.trajectory(TEE, seed=0)
        g = traj.goal["ap"]
        spec = np.abs(np.fft.rfft(g[:-1])) ** 2
        f = np.fft.rfftfreq(g.size - 1, 1 / traj.sample_rate_hz)
        inside = (f >= p["f_lo_hz"] - 1e-12) & (f <= p["f_hi_hz"] + 1e-12)
        assert spec[~inside].sum() / spec.sum() < 0.01  # the brief's bound; the design gives ~1e-25
        assert spec[~inside].sum() / spec.sum() < 1e-9
        assert np.abs(g).max() == pytest.approx(p["amplitude_deg"], rel=1e-4)
        assert np.abs(g).max() <= p["amplitude_deg"] * (1 + 1e-9)

    def test_two_axes_get_different_draws(self):
        traj = load_protocol("random", overrides={"axes": ["axis1", "axis2"]}).trajectory(TEE, seed=0)
        runs = [nonzero_runs(traj.goal[d]) for d in ("ap", "ml")]
        a = traj.goal["ap"][runs[0][0][0] : runs[0][-1][1] + 1]
        b = traj.goal["ml"][runs[1][0][0] : runs[1][-1][1] + 1]
        n = min(a.size, b.size)
        assert abs(np.corrcoef(a[:n], b[:n])[0, 1]) < 0.5


def test_staircase_levels_and_hold_durations():
    proto = load_protocol("staircase")
    p = proto.params
    traj = proto.trajectory(TEE)
    g, fs = traj.goal["ap"], traj.sample_rate_hz
    assert 5.0 <= p["hold_s"] <= 10.0  # long enough to expose creep
    # Holds: maximal runs of exactly equal samples. A run spans the hold, plus the ramps'
    # boundary samples that land exactly on it (+2/fs at most), minus one sample when the
    # hold's edges fall between samples (ramps last (pi/2) h / rate, off the sample grid).
    change = np.flatnonzero(np.diff(g) != 0.0)
    bounds = np.concatenate([[0], change + 1, [g.size]])
    runs = [(g[a], (b - a - 1) / fs) for a, b in zip(bounds[:-1], bounds[1:]) if b - a > 1]
    h = p["amplitude_deg"] / p["steps"]
    levels = [h * k for k in (1, 2, 3, 2, 1, 0, -1, -2, -3, -2, -1, 0)]
    assert [lv for lv, _ in runs] == pytest.approx(levels, abs=1e-9)
    for _, dur in runs:
        assert p["hold_s"] - 1 / fs - 1e-9 <= dur <= p["hold_s"] + 2 / fs
    # Steps are rate-limited to step_rate_dps (raised cosine, so the peak speed is that rate).
    speed = np.abs(np.diff(g)) * fs
    assert speed.max() <= p["step_rate_dps"] * (1 + 1e-9)
    assert speed.max() >= p["step_rate_dps"] * 0.999


def test_circle_radius_and_both_axes_at_once():
    proto = load_protocol("circle")
    p = proto.params
    traj = proto.trajectory(DUO)
    r = np.hypot(traj.goal["ud"], traj.goal["lr"])
    steady = (traj.t_s >= p["spiral_s"]) & (traj.t_s <= traj.duration_s - p["spiral_s"])
    np.testing.assert_allclose(r[steady], p["amplitude_deg"], rtol=0, atol=1e-9)
    assert steady.sum() / traj.sample_rate_hz == pytest.approx(p["cycles"] / p["frequency_hz"], abs=1.5 / 100)
    assert np.all(r[~steady] <= p["amplitude_deg"] + 1e-9)
    moving_together = (traj.goal["ud"] != 0) & (traj.goal["lr"] != 0)
    assert moving_together.mean() > 0.9


def test_lissajous_moves_both_axes_at_their_own_frequencies():
    proto = load_protocol("lissajous")
    p = proto.params
    traj = proto.trajectory(TEE)
    t = traj.t_s
    mid = (t > p["fade_s"]) & (t < traj.duration_s - p["fade_s"])
    for dof, f in zip(("ap", "ml"), p["frequencies_hz"]):
        tc = zero_crossings(t[mid], traj.goal[dof][mid])
        np.testing.assert_allclose(np.diff(tc), 1 / (2 * f), rtol=1e-4)


def test_planes_sweeps_cover_all_four_half_planes():
    proto = load_protocol("planes")
    p = proto.params
    A, reps = p["amplitude_deg"], p["repetitions"]
    assert reps >= 2
    traj = proto.trajectory(DUO)
    g1, g2 = traj.goal["ud"], traj.goal["lr"]
    assert not np.any((g1 != 0) & (g2 != 0))  # single-knob sweeps: the other knob holds at 0
    for g in (g1, g2):
        runs = nonzero_runs(g)
        assert len(runs) == 2 * reps
        for k, (i0, i1) in enumerate(runs):
            sweep = g[i0 : i1 + 1]
            sign = 1.0 if k % 2 == 0 else -1.0  # +max first, then -max, repeated
            assert np.all(np.sign(sweep) == sign)
            assert np.abs(sweep).max() == pytest.approx(A, abs=1e-9)
            # Out and back, slowly: covers every angle of the half-plane with gaps < rate/fs.
            out = np.abs(sweep[: int(np.argmax(np.abs(sweep))) + 1])
            assert np.all(np.diff(out) >= -1e-12)
            assert np.diff(np.concatenate([[0.0], out])).max() <= p["sweep_rate_dps"] / traj.sample_rate_hz * (1 + 1e-9)
    # ud first, then lr; the segments name every half-plane sweep.
    assert traj.t_s[np.flatnonzero(g1)[-1]] < traj.t_s[np.flatnonzero(g2)[0]]
    labels = [s.label for s in traj.segments]
    for axis in ("ud", "lr"):
        for sign in "+-":
            assert sum(lbl.startswith(f"{axis}{sign} sweep") for lbl in labels) == reps
    assert np.abs(np.diff(g1)).max() * traj.sample_rate_hz <= p["sweep_rate_dps"] * (1 + 1e-9)


def test_hold_is_still_and_offset_hold_ramps():
    traj = load_protocol("hold").trajectory(TEE)
    assert traj.moving_dofs == () and traj.duration_s == pytest.approx(30.0)
    traj = load_protocol("hold", overrides={"offset_deg": 20.0, "duration_s": 5.0}).trajectory(TEE)
    assert traj.goal["ap"].max() == 20.0 and traj.goal["ap"][0] == 0.0 and traj.goal["ap"][-1] == 0.0
    assert traj.duration_s == pytest.approx(5.0 + 2 * 2.0)


# ------------------------------------------------------------------------ overrides


def test_overrides_change_the_trajectory_and_are_recorded():
    base = load_protocol("damped-sine")
    proto = load_protocol("damped-sine", overrides={"amplitude_deg": 40, "axes": ["ml"]})
    assert proto.params["amplitude_deg"] == 40.0 and isinstance(proto.params["amplitude_deg"], float)
    assert proto.overrides == {"amplitude_deg": 40, "axes": ["ml"]}
    assert proto.sha256 == base.sha256 == hashlib.sha256((REPO / "protocols/damped-sine.toml").read_bytes()).hexdigest()
    traj = proto.trajectory(TEE)
    assert traj.moving_dofs == ("ml",)
    np.testing.assert_allclose(traj.goal["ml"], base.trajectory(TEE).goal["ap"] * 40.0 / 60.0, rtol=0, atol=1e-12)
    json.dumps(proto.to_dict())  # run.json-ready
    again = Protocol.from_dict(proto.to_dict())
    assert again.params == proto.params and again.signal == "damped-sine"


def test_axis_aliases_resolve_per_probe_and_unknown_axis_is_refused():
    proto = load_protocol("sine-set", overrides={"axes": ["axis2"]})
    assert proto.trajectory(TEE).moving_dofs == ("ml",)
    assert proto.trajectory(DUO).moving_dofs == ("lr",)
    assert load_protocol("sine", overrides={"axes": "rotation"}).trajectory(TEE).moving_dofs == ("rotation",)
    bad = load_protocol("sine", overrides={"axes": ["zz"]})
    with pytest.raises(ProtocolError, match=r"unknown axis 'zz' for probe 'tee'"):
        bad.trajectory(TEE)
    with pytest.raises(ProtocolError, match=r"unknown axis 'ml' for probe 'duodenoscope'"):
        load_protocol("sine", overrides={"axes": ["ml"]}).trajectory(DUO)
    with pytest.raises(ProtocolError, match="translation"):
        load_protocol("sine", overrides={"axes": ["translation"]}).trajectory(TEE)
    with pytest.raises(ProtocolError, match="already listed"):
        load_protocol("sine-set", overrides={"axes": ["axis1", "ap"]}).trajectory(TEE)


@pytest.mark.parametrize(
    "overrides,match",
    [
        ({"amplitude": 40}, r"unknown parameter\(s\) 'amplitude'.*amplitude_deg"),
        ({"duration_s": 10}, r"unknown parameter\(s\) 'duration_s' for signal 'damped-sine'"),
        ({"amplitude_deg": "big"}, r"'amplitude_deg' must be a number > 0"),
        ({"amplitude_deg": -5}, r"'amplitude_deg' must be a number > 0"),
        ({"amplitude_deg": float("nan")}, r"'amplitude_deg' must be a number"),
        ({"axes": []}, r"'axes' must be a non-empty list"),
        ({"sample_rate_hz": 0}, r"'sample_rate_hz' must be a number > 0"),
        ({"frequency_hz": 0.06}, r"multiple of 0.5"),  # would end at exp(-1) A sin(..) != 0: a jump
        ({"frequency_hz": 0.1, "sample_rate_hz": 0.15}, r"below half the sample rate"),
        ({"offset_deg": 10, "ramp_s": 0}, r"needs 'ramp_s' > 0"),
    ],
)
def test_bad_overrides_are_refused_naming_the_parameter(overrides, match):
    with pytest.raises(ProtocolError, match=match):
        load_protocol("damped-sine", overrides=overrides)


def test_other_bad_parameters():
    with pytest.raises(ProtocolError, match="'cycles' must be an integer >= 1"):
        load_protocol("triangle", overrides={"cycles": 1.5})
    with pytest.raises(ProtocolError, match="'method' must be one of 'linear', 'log'"):
        load_protocol("chirp", overrides={"method": "cubic"})
    with pytest.raises(ProtocolError, match="'f_lo_hz' must be below 'f_hi_hz'"):
        load_protocol("random", overrides={"f_lo_hz": 0.3})
    with pytest.raises(ProtocolError, match="no multiple of 1/duration_s"):
        load_protocol("random", overrides={"f_lo_hz": 0.101, "f_hi_hz": 0.102, "duration_s": 10.0})
    with pytest.raises(ProtocolError, match="'frequencies_hz' must be 2 numbers"):
        load_protocol("lissajous", overrides={"frequencies_hz": [0.1]})
    with pytest.raises(ProtocolError, match="'seed' must be an integer >= 0"):
        load_protocol("random", overrides={"seed": -1})


def test_offset_is_reached_and_left_by_ramps():
    proto = load_protocol("triangle", overrides={"offset_deg": 10.0, "cycles": 1})
    traj = proto.trajectory(TEE)
    g, t = traj.goal["ap"], traj.t_s
    ramp = proto.params["ramp_s"]
    assert g[0] == 0.0 and g[-1] == 0.0
    assert traj.duration_s == pytest.approx(2 * ramp + proto.params["period_s"])
    body = (t >= ramp) & (t <= traj.duration_s - ramp)
    assert g[body].max() == pytest.approx(10.0 + 45.0) and g[body].min() == pytest.approx(10.0 - 45.0)
    assert g[np.argmin(np.abs(t - ramp))] == pytest.approx(10.0)


def test_parse_overrides():
    assert parse_overrides(["amplitude_deg=40", "axes=['ml']", "method=log", "seed = 3"]) == {
        "amplitude_deg": 40, "axes": ["ml"], "method": "log", "seed": 3}
    with pytest.raises(ProtocolError, match="key=value"):
        parse_overrides(["amplitude_deg"])


# ------------------------------------------------------------------------ limits


def test_goal_beyond_knob_limits_raises_before_anything_moves():
    traj = load_protocol("damped-sine", overrides={"amplitude_deg": 95.0}).trajectory(TEE)
    with pytest.raises(LimitError) as exc:
        traj.check_limits(TEE)
    msg = str(exc.value)
    assert "ap" in msg and "90" in msg and "t = " in msg and "95.000" in msg
    # The duodenoscope's ud knob reaches 100 deg: the same protocol is fine there.
    load_protocol("damped-sine", overrides={"amplitude_deg": 95.0}).trajectory(DUO).check_limits(DUO)
    neg = load_protocol("staircase", overrides={"offset_deg": -40.0}).trajectory(TEE)
    with pytest.raises(LimitError, match=r"min limit -90 deg"):
        neg.check_limits(TEE)


def test_knob_speed_beyond_the_probe_raises():
    # 45 deg at 2 Hz peaks at 2 pi 2 45 = 565 deg/s > 360 deg/s.
    traj = load_protocol("sine", overrides={"frequency_hz": 2.0}).trajectory(TEE)
    with pytest.raises(LimitError, match=r"ap knob speed .* exceeds the max_knob_speed_dps 360"):
        traj.check_limits(TEE)
    slow = ProbeConfig(name="slow", bending_axes=("ap", "ml"), knob_limits_deg={"ap": (-90, 90), "ml": (-90, 90)},
                       bending_length_mm=60.0, max_knob_speed_dps=5.0)
    with pytest.raises(LimitError, match="slow"):
        load_protocol("planes").trajectory(slow).check_limits(slow)


def test_check_limits_needs_the_probe_it_was_built_for():
    traj = load_protocol("sine").trajectory(TEE)
    with pytest.raises(LimitError, match="build it with this probe"):
        traj.check_limits(DUO)
    assert isinstance(traj, Trajectory) and traj.goal_array().shape == (traj.n_samples, 4)


# ------------------------------------------------------------------------ files and lookup


def write(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


def test_unknown_protocol_lists_the_known_ones():
    with pytest.raises(ProtocolError) as exc:
        load_protocol("dampd-sine")
    assert "unknown protocol 'dampd-sine'" in str(exc.value)
    for name in REQUIRED:
        assert name in str(exc.value)
    assert isinstance(exc.value, EndocalError) and isinstance(exc.value, ValueError)


def test_malformed_toml_names_file_and_line(tmp_path):
    path = write(tmp_path / "bad.toml", 'description = "x"\nsignal = "sine"\n[params\namplitude_deg = 3\n')
    with pytest.raises(ProtocolError) as exc:
        load_protocol(str(path))
    assert str(path) in str(exc.value) and "line 3" in str(exc.value)


@pytest.mark.parametrize(
    "text,match",
    [
        ('signal = "sine"\n', "missing field 'description'"),
        ('description = "x"\n', "missing field 'signal'"),
        ('description = "x"\nsignal = "square"\n', "field 'signal' must be one of .*damped-sine"),
        ('description = "x"\nsignal = "sine"\nspeed = 3\n', "unknown field\\(s\\) 'speed'"),
        ('description = "x"\nsignal = "sine"\n[params]\namplitud_deg = 3\n', "unknown parameter\\(s\\) 'amplitud_deg'"),
        ('description = "x"\nsignal = "sine"\n[params]\namplitude_deg = "3"\n', "'amplitude_deg' must be a number"),
        ('description = "x"\nsignal = "sine"\nparams = 3\n', "'params' must be a table"),
        ('description = ""\nsignal = "sine"\n', "'description' must be a non-empty string"),
    ],
)
def test_invalid_files_name_the_field_and_file(tmp_path, text, match):
    path = write(tmp_path / "p.toml", text)
    with pytest.raises(ProtocolError, match=match) as exc:
        load_protocol(path)
    assert str(path) in str(exc.value)


def test_missing_path_is_refused(tmp_path):
    with pytest.raises(ProtocolError, match="does not exist"):
        load_protocol(str(tmp_path / "nope.toml"))


def test_user_file_by_path_uses_defaults_and_its_stem_as_name(tmp_path):
    path = write(tmp_path / "mine.toml", 'description = "my sine"\nsignal = "sine"\n')
    proto = load_protocol(path)
    assert proto.name == "mine" and proto.params == {q.name: q.default for q in SIGNALS["sine"].params}
    assert proto.source_path == path.resolve()


def test_local_protocols_folder_shadows_the_shipped_one(tmp_path, monkeypatch):
    write(tmp_path / "protocols" / "damped-sine.toml",
          'description = "local variant"\nsignal = "damped-sine"\n[params]\namplitude_deg = 10.0\n')
    write(tmp_path / "protocols" / "extra.toml", 'description = "extra"\nsignal = "hold"\n')
    monkeypatch.chdir(tmp_path)
    proto = load_protocol("damped-sine")
    assert proto.description == "local variant" and proto.params["amplitude_deg"] == 10.0
    names = {n: d for n, d, _ in list_protocols()}
    assert names["damped-sine"] == "local variant" and "extra" in names and "planes" in names


def test_shipped_folder_is_found_from_anywhere(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # no ./protocols here
    assert shipped_protocols_dir() == REPO / "protocols"
    assert load_protocol("planes").source_path == (REPO / "protocols" / "planes.toml").resolve()


def test_readme_documents_every_signal_and_parameter():
    readme = (REPO / "protocols" / "README.md").read_text()
    for name, spec in SIGNALS.items():
        assert re.search(rf"`{re.escape(name)}`", readme), name
        for q in spec.params:
            assert f"`{q.name}`" in readme, (name, q.name)
    for name in shipped_names():
        assert f"`{name}`" in readme, name
