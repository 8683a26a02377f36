"""The power of the paired sign-flip test (endocal/validation/power.py), checked on simulated differentials.

The length the evidence line names must be the one at which the very test validate runs
(:func:`endocal.validation.paired.unit_test`, Holm at any rank: raw p below alpha / m)
reaches significance with the power it claims (80 %). Simulated per-unit differentials of a
known mean and spread, symmetric and skewed (a candidate that removes a large error on a few
units and costs a little on many), are tested at that length many times: the share of
significant outcomes must be 80 % within what 300 repetitions can tell (binomial standard
error 2.3 %; the normal approximation of the randomisation distribution adds a few per cent at
twenty units), and at half that length clearly less.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from endocal.validation.power import POWER, estimate_power, evidence_phrase, units_for_power, unit_differentials
from endocal.validation.paired import min_units_for, unit_test
from endocal.validation.units import Units

REPS = 300


def _significant_share(draw, n_units: int, level: float, seed: int) -> float:
    """Share of REPS simulated records of ``n_units`` units whose exact sign-flip p-value is below ``level``."""
    rng = np.random.default_rng(seed)
    units = Units("half-cycle", [(i, i + 1) for i in range(n_units)], "simulated")
    hits = 0
    for _ in range(REPS):
        d = draw(rng, n_units)
        # one sample per unit whose squared errors differ by d: e_base^2 - e_cand^2 = d
        k = float(np.abs(d).max()) + 1.0
        hits += unit_test(np.sqrt(k + d), np.full(n_units, np.sqrt(k)), units, n_flips=4000) < level
    return hits / REPS


#: Per-unit differentials of mean 1 and standard deviation 2 (deg^2), three shapes: symmetric; a long
#: tail of large gains (a term that fixes a large error on a few units); a long tail of losses.
SHAPES = {
    "normal": lambda rng, n: rng.normal(1.0, 2.0, n),
    "gains tail": lambda rng, n: rng.exponential(2.0, n) - 1.0,
    "losses tail": lambda rng, n: 3.0 - rng.exponential(2.0, n),
}


@pytest.mark.parametrize("shape", list(SHAPES))
@pytest.mark.parametrize("n_candidates", [1, 7])
def test_the_length_named_reaches_significance_with_the_power_claimed(shape, n_candidates):
    """Measured (seeds as here): normal 81 / 84 %, losses tail 78 / 79 %, gains tail 93 / 97 % (1 / 7
    candidates): the estimate is close where the differentials are symmetric and errs on the long side
    where a term fixes large errors on a few units (the randomisation variance counts those gains)."""
    alpha, draw = 0.05, SHAPES[shape]
    n = units_for_power(1.0, 2.0, alpha, n_candidates)
    level = alpha / n_candidates
    share = _significant_share(draw, n, level, seed=n_candidates)
    assert share >= POWER - 0.07, (n, share)
    if shape == "normal":
        assert share <= POWER + 0.07, (n, share)
    assert _significant_share(draw, max(2, n // 2), level, seed=10 + n_candidates) <= POWER - 0.15


def test_units_grow_as_the_effect_shrinks_and_none_when_it_does_not_lower_the_error():
    # N ~ ((z_b + z_a) sd / mean)^2 for a small effect: a quarter of the mean, about sixteen times the
    # units (a little less: the effect's own share of the randomisation variance shrinks with it)
    big, small = units_for_power(1.0, 2.0, 0.05), units_for_power(0.25, 2.0, 0.05)
    assert 12 <= small / big <= 16
    assert units_for_power(0.0, 1.0, 0.05) is None and units_for_power(-0.3, 1.0, 0.05) is None
    # an effect the same on every unit needs only the exact test's floor (2^-N below alpha / m)
    assert units_for_power(1.0, 0.0, 0.05, 9) == min_units_for(9, 0.05) == 8


def test_estimate_from_two_models_errors_and_its_words():
    rng = np.random.default_rng(0)
    bounds = [(i * 50, (i + 1) * 50) for i in range(14)]
    base = rng.normal(0.0, 1.0, 700)
    cand = 0.9 * base + rng.normal(0.0, 0.35, 700)  # removes about a tenth of the error, noisily
    d = unit_differentials(base, cand, bounds)
    assert d.shape == (14,) and np.isclose(d.sum(), np.sum(base**2 - cand**2))
    est = estimate_power(base, cand, bounds, alpha=0.05, n_candidates=6)
    assert est.units_seen == 14 and est.units_needed == units_for_power(d.mean(), d.std(ddof=1), 0.05, 6)
    gain = 100 * (1 - np.sqrt(np.mean(cand**2) / np.mean(base**2)))
    assert evidence_phrase(est, "half-cycle", 12.0, 10.0).startswith(f"about {est.units_needed} half-cycles")
    assert "under the 10 % bar" in evidence_phrase(est, "half-cycle", gain if gain < 10 else 5.0, 10.0)
    worse = estimate_power(cand, base, bounds, alpha=0.05)
    assert worse.units_needed is None and "does not lower the error" in evidence_phrase(worse, "block", -3.0, 10.0)


def test_the_evidence_line_names_a_length_that_settles_the_candidate():
    """validate's evidence line, end to end: on a sine of 7 half-cycles the envelope candidate (-17 % against
    a B-spline with the rig's lag, on the default probe whose slack it partly stands for) is not
    significant, and the line names the half-cycles that would make it so at that gain; the same sine
    recorded that long (with another seed) makes it significant (p = 0.001-0.0015 on seeds 1-3).

    At alpha = 0.01: over 7 half-cycles the sign-flip test's smallest p-value is 2/128 = 0.016, so no candidate
    can be significant there, whatever the fits. At 0.05 the Holm correction decided it (the envelope's
    adjusted p went from 0.063 to 0.047 when another candidate's fit stopped 1e-3 lower, the scan's stopping
    rule), which is not what this test is about."""
    from endocal.models import make_model
    from endocal.sim import SimConfig
    from endocal.validation.data import axis_data
    from endocal.validation.offline import validate_offline
    from tests.test_validation_hidden import simulate

    cfg = SimConfig.default()
    est = [simulate(cfg, "damped-sine", {"period_s": 10.0}, seed=0)[0]]
    model = make_model("bspline", ["delay"], axis="ap").fit(axis_data(est, "ap"))

    def envelope(cycles: int, seed: int):
        val = [simulate(cfg, "sine", {"amplitude_deg": 45.0, "frequency_hz": 0.1, "cycles": cycles}, seed=seed)[0]]
        res = validate_offline(model, val, train=est, max_scan_samples=3000, alpha=0.01)
        return next(s for s in res.scan.tested if s.effect == "envelope")

    short = envelope(3, seed=1)
    n = short.power.units_needed
    assert short.gain_pct >= 10.0 and not short.significant and short.n_blocks == 7
    # "not enough evidence (7 units, 10 needed; about N half-cycles would make it significant at this gain ...)"
    assert "(7 units" in short.evidence and f"about {n} half-cycles would make it significant at this gain" \
        in short.evidence, short.evidence
    long = envelope(math.ceil(n / 2), seed=2)  # whole cycles: 2 half-cycles each, and the run's start
    assert long.n_blocks >= n and long.significant, (n, long.n_blocks, long.p_value, long.evidence)
