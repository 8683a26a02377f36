"""Units, paired tests and effect sizes of :mod:`endocal.report.stats`, against hand-computed cases."""

from __future__ import annotations

import numpy as np
import pytest

from endocal.models import HysteresisData
from endocal.report.stats import (
    MIN_UNITS,
    Units,
    compare_models,
    holm,
    kendall_w,
    make_units,
    rank_biserial,
    stars,
    unit_rmse,
    wilcoxon_pair,
)
from endocal.validation.metrics import error_metrics


def _triangle(n_periods=4, period_s=20.0, dt_s=0.01, amp=45.0):
    t = np.arange(0.0, n_periods * period_s, dt_s)
    phase = (t / period_s + 0.25) % 1.0
    return t, amp * (4 * np.abs(phase - 0.5) - 1.0)


def test_half_cycles_of_a_triangle_cut_at_its_reversals():
    t, u = _triangle()
    units = make_units(HysteresisData(cmd_deg=u, meas_deg=u, t_s=t))
    assert units.kind == "half-cycle"
    # 4 periods -> 8 reversals (every 10 s from t = 5 s); the leading and trailing pieces are
    # half a half-cycle (only pieces under a quarter are merged), so 9 units tile the record.
    assert units.n == 9
    assert units.bounds[0][0] == 0 and units.bounds[-1][1] == u.size
    assert all(a[1] == b[0] for a, b in zip(units.bounds, units.bounds[1:]))
    cuts = np.array([a for a, _ in units.bounds[1:]])
    assert np.allclose(t[cuts], 5.0 + 10.0 * np.arange(8), atol=0.011)  # one sample


def test_wiggles_below_tolerance_are_not_reversals():
    t, u = _triangle()
    noisy = u + 0.5 * np.sin(2 * np.pi * 3.0 * t)  # 0.5 deg wiggle: ~0.6 % of the 90 deg span
    assert make_units(HysteresisData(cmd_deg=noisy, t_s=t)).n == 9


def test_rarely_reversing_record_falls_back_to_decorrelation_blocks():
    t = np.arange(0.0, 100.0, 0.01)
    u = np.floor(t / 20.0) * 10.0  # staircase: never reverses
    rng = np.random.default_rng(0)
    err = np.convolve(rng.normal(size=t.size), np.ones(100) / 10, mode="same")  # ~1 s correlation
    units = make_units(HysteresisData(cmd_deg=u + 1e-9 * t, t_s=t), [err])
    assert units.kind == "block"
    assert units.n >= MIN_UNITS
    lengths = np.diff([a for a, _ in units.bounds] + [t.size])
    # moving average of 100 samples: autocorrelation falls below 1/e near lag 63
    assert 40 <= np.median(lengths) <= 120


def test_unit_rmse_is_error_metrics_on_each_unit():
    rng = np.random.default_rng(1)
    d, r = rng.normal(size=300), rng.normal(size=300)
    units = Units("block", [(0, 100), (100, 250), (250, 300)], "test")
    got = unit_rmse(d, r, units)
    want = [error_metrics(d[a:b], r[a:b], n_boot=0).rmse_deg for a, b in units.bounds]
    assert got.tolist() == want


def test_holm_matches_hand_computation():
    # sorted 0.01, 0.03, 0.04 -> 3*0.01, max(0.03, 2*0.03), max(0.06, 1*0.04)
    assert holm([0.01, 0.04, 0.03]).tolist() == pytest.approx([0.03, 0.06, 0.06])
    assert holm([0.5, 0.9]).tolist() == pytest.approx([1.0, 1.0])


def test_rank_biserial_and_wilcoxon_on_known_pairs():
    a = np.arange(1.0, 11.0)
    assert rank_biserial(a + 1, a) == 1.0
    assert rank_biserial(a, a + 1) == -1.0
    assert rank_biserial(a, a) == 0.0
    # differences +1, -2, +3: ranks 1, 2, 3 -> (1 + 3 - 2) / 6
    assert rank_biserial([1.0, 0.0, 3.0], [0.0, 2.0, 0.0]) == pytest.approx(2 / 6)
    p = wilcoxon_pair("a", a + 0.1 * a, "b", a)
    assert p.p_value == pytest.approx(2 / 2**10)  # exact test, every difference positive
    assert p.better == "b" and p.rank_biserial == 1.0
    same = wilcoxon_pair("a", a, "b", a)
    assert same.p_value == 1.0 and same.n_nonzero == 0 and same.better is None


def test_two_models_get_wilcoxon_three_get_friedman_with_holm():
    units = Units("half-cycle", [(i, i + 1) for i in range(12)], "test")
    rng = np.random.default_rng(2)
    base = rng.uniform(1.0, 2.0, 12)
    two = compare_models({"a": base, "b": base * 0.5}, units)
    assert two.test == "wilcoxon" and two.significant
    assert two.p_value == pytest.approx(2 / 2**12)
    three = compare_models({"a": base, "b": base * 0.7, "c": base * 0.4}, units)
    assert three.test == "friedman" and three.significant
    # every unit ranks the models the same way: perfect concordance
    assert three.effect_size == pytest.approx(1.0)
    assert kendall_w(three.statistic, 12, 3) == pytest.approx(1.0)
    assert len(three.pairs) == 3
    raw = sorted(p.p_value for p in three.pairs)
    assert sorted(p.p_adjusted for p in three.pairs) == pytest.approx(holm(raw).tolist())
    assert "Holm" in three.why and "autocorrelated" in three.why


def test_identical_models_are_not_different_and_few_units_are_not_tested():
    units = Units("half-cycle", [(i, i + 1) for i in range(10)], "test")
    x = np.linspace(1, 2, 10)
    same = compare_models({"a": x, "b": x.copy(), "c": x.copy()}, units)
    assert same.p_value == 1.0 and same.effect_size == 0.0 and not same.significant
    assert all(p.p_adjusted == 1.0 for p in same.pairs)
    few = compare_models({"a": x[:5], "b": x[:5] * 2}, Units("block", [(i, i + 1) for i in range(5)], "t"))
    assert few.test == "none" and not few.significant and "0.062" in few.why


def test_stars():
    assert [stars(p) for p in (0.0005, 0.005, 0.02, 0.2, float("nan"))] == ["***", "**", "*", "ns", "n/a"]
