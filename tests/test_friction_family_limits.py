"""Two hidden effects of the Bouc-Wen plant, in-sample: where the catalogue's structures reach the noise.

The loop of tests/test_validation_closed_loop_bases.py is judged on what `validate` suggests; these tests
show, on the very records the structures are fitted on, what any scan could find, so that no scan or loop rule
is to blame for a gap.

- ``deadzone``: the simulator's tendon slack lies between a friction element without return-point memory (at
  the knob) and the bending section. On the sweeps (damped sine and chirp, the loop's first records) a smooth
  friction base with `delay`, `envelope` and the slack on the tip's side (`deadzone:tip`) fits them at 1.03x
  the noise; with the slack on the knob's side (`deadzone`) no base gets below 2.5x. Without the slack `dahl`
  with `delay` and `envelope` fits them at 1.1x.
- ``rate``: friction growing with knob speed scales the Bouc-Wen element's holding force. On a speed ladder up to
  the probe's limits (the record `--next` asks for) a smooth friction base with `rate:friction` (the holding force
  times 1 + g |dv/dt|) fits it at 1.16x the noise; with `rate`, a play in front of the base that widens with
  speed, every base stays above 3x. `rate:friction` has no inverse: the last test shows why.
- the bending section's shape: the simulator's stiffening maps the pull past the friction element. With it on the
  bend (`envelope:tip`) both friction bases fit the ladder at 1.13x the noise; with `envelope`, on the command in front
  of the element, `dahl` stays at 1.21x.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest

from endocal.models import make_model
from endocal.sim import SimConfig
from endocal.validation.data import axis_data
from endocal.validation.predict import predict_errors
from tests.test_validation_closed_loop_bases import BOUC_WEN_PLANT
from tests.test_validation_hidden import NO_SLACK, simulate
from tests.test_validation_user_style import HIDDEN

#: The speed ladder `--next` designs for `rate` on this probe: one cycle per frequency up to 288 deg/s.
LADDER = {"axes": ["ap"], "amplitude_deg": 60.0, "cycles": 1,
          "frequencies_hz": [0.06, 0.12, 0.24, 0.45, 0.66, 0.76, 0.66, 0.45, 0.24, 0.12, 0.06]}


def _plant(hidden: str | None) -> SimConfig:
    return SimConfig.default().replace(**NO_SLACK).replace(**BOUC_WEN_PLANT).replace(**HIDDEN.get(hidden, {}))


def _in_sample_ratio(records, noise_deg: float, base: str, effects: list[str]) -> float:
    data = axis_data(records, "ap")
    err = predict_errors(make_model(base, effects, axis="ap").fit(data), data)
    return float(np.sqrt(np.mean(err**2))) / noise_deg


@functools.lru_cache(maxsize=None)
def _sweeps(hidden):
    cfg = _plant(hidden)
    (ds, noise), (chirp, _) = simulate(cfg, "damped-sine", {}, seed=0), simulate(cfg, "chirp", {"amplitude_deg": 50.0}, seed=0)
    return [ds, chirp], noise


def test_without_the_slack_a_friction_base_fits_the_sweeps_to_the_noise():
    records, noise = _sweeps(None)
    # 1.09x (2026-11-28): the Dahl law is not quite the simulator's Bouc-Wen element
    assert _in_sample_ratio(records, noise, "dahl", ["delay", "envelope"]) < 1.2


@pytest.mark.parametrize("base", ["dahl", "bouc-wen", "pi"])
def test_the_slack_on_the_knobs_side_of_a_friction_element_cannot_fit_it(base):
    records, noise = _sweeps("deadzone")
    # 2.66-2.69x (2026-11-28)
    assert _in_sample_ratio(records, noise, base, ["delay", "deadzone", "envelope"]) > 2.5


@pytest.mark.parametrize("base", ["dahl", "bouc-wen"])
def test_the_slack_on_the_tips_side_of_a_friction_element_fits_it_to_the_noise(base):
    """The plant's order: the friction sees the knob, the slack the friction's output. 1.03x (2026-11-29): the
    Dahl and Bouc-Wen laws are not quite the simulator's element, as without the slack."""
    records, noise = _sweeps("deadzone")
    assert _in_sample_ratio(records, noise, base, ["delay", "deadzone:tip", "envelope"]) < 1.1


@functools.lru_cache(maxsize=None)
def _ladder(hidden):
    return simulate(_plant(hidden), "sine-varying", LADDER, seed=0)


def test_without_speed_dependence_a_friction_base_fits_the_ladder_near_the_noise():
    """In-sample on the loop's last record, with the shape on the command: `bouc-wen` + `delay` + `envelope` reaches
    1.15x and `dahl` 1.21x (2026-11-29). The loop changes base to the first base 10 % better than its own, `dahl` on
    this plant (1-4 points ahead of `bouc-wen` on the first records), and no later base is 10 % better: with
    `envelope` its end on this record sat at the bar; `envelope:tip` (below) takes up what it misses."""
    rec, noise = _ladder(None)
    assert _in_sample_ratio([rec], noise, "bouc-wen", ["delay", "envelope"]) < 1.2
    assert 1.18 < _in_sample_ratio([rec], noise, "dahl", ["delay", "envelope"]) < 1.25


@pytest.mark.parametrize("base", ["dahl", "bouc-wen"])
def test_the_bending_sections_shape_past_the_friction_lowers_the_floor_under_the_bar(base):
    """`envelope:tip`, the stiffening on the bend past the friction element (the plant's order: the element at the
    knob, the bending section's static map after it), where `envelope` stretches the element's exponential with it:
    1.126x for both bases on 2026-12-07, against 1.154x (bouc-wen) and 1.209x (dahl) with `envelope`."""
    rec, noise = _ladder(None)
    assert _in_sample_ratio([rec], noise, base, ["delay", "envelope:tip"]) < 1.15


@pytest.mark.parametrize("base, effects", [("dahl", ["delay", "envelope", "rate"]),
                                           ("bouc-wen", ["delay", "envelope", "rate"]),
                                           ("bspline", ["delay", "rate"])])
def test_a_play_widening_with_speed_cannot_fit_a_holding_force_that_grows_with_it(base, effects):
    rec, noise = _ladder("rate")
    # 3.19-3.90x (2026-11-28)
    assert _in_sample_ratio([rec], noise, base, effects) > 3.0


@pytest.mark.parametrize("base, bar", [("bouc-wen", 1.25), ("dahl", 1.35)])
def test_a_friction_whose_holding_force_grows_with_speed_fits_the_ladder(base, bar):
    """`rate:friction` scales the base's one friction state with the knob's speed: 1.16x (bouc-wen) and 1.25x (dahl)
    on 2026-11-29, against 1.15x and 1.21x for the plant without the speed dependence; the Dahl law is further from
    the simulator's element."""
    rec, noise = _ladder("rate")
    assert _in_sample_ratio([rec], noise, base, ["delay", "envelope", "rate:friction"]) < bar


def test_a_friction_growing_with_speed_has_no_unique_command_for_an_angle_at_speed():
    """Why `rate:friction` has no inverse. Its element's bound follows the knob's speed over each step, so within one
    sample a knob that slows lets the bound fall below the friction held, and the element slips: the tip jumps
    ahead. On the fitted model, the angle a sample reaches as a function of its command (the state before it given)
    rises monotonically while the knob moves slowly (20 deg/s), and does not once it slides fast (by 90 deg/s on
    this plant, 2026-11-29; the test checks 168 deg/s): there one angle is reached by several commands, and no sample-by-sample inverse is
    unique. (Without the speed dependence the map is monotone wherever the base's sweep check passes.)"""
    from endocal.models._smooth_friction import _rescaled, scaled_friction_states, speed_factors, state_step

    rec, _ = _ladder("rate")
    data = axis_data([rec], "ap")
    model = make_model("bouc-wen", ["rate:friction"], axis="ap").fit(data)
    base_p, _ = model._grouped(model.params_)
    family, k_lin, c_w, rho, sigma, expo, _ = model._law(model.structure_, base_p)
    gain = model.params_["rate_friction_gain_s_per_deg"]
    v, t = data.cmd_deg, data.t_s
    f = speed_factors(v, t, gain, data.run_starts)
    w = scaled_friction_states(family, v, rho, sigma, expo, data.run_starts, f)
    speed = np.gradient(v, t)

    def step_map(k):
        """The angle (offset aside) at sample k for commands from half a step back to three steps ahead."""
        dt, dv = t[k] - t[k - 1], v[k] - v[k - 1]
        out = []
        for cand in v[k - 1] + np.linspace(-0.5, 3.0, 400) * dv:
            fc = 1.0 + gain * abs(cand - v[k - 1]) / dt
            wc = state_step(family, _rescaled(w[k - 1], f[k - 1], fc), cand - v[k - 1], rho / fc, sigma, expo)
            out.append(k_lin * cand + c_w * fc * wc)
        return np.array(out)

    def sliding_at(s):  # the third sample of a forward slide faster than s, near neutral
        return int(np.flatnonzero((speed > s) & (np.abs(v) < 30))[0]) + 3

    assert np.all(np.diff(step_map(sliding_at(20.0))) >= -1e-12)
    # 2026-11-29: at 168 deg/s the angle falls by up to 0.31 deg where the command rises
    assert np.min(np.diff(step_map(sliding_at(150.0)))) < -0.05
