"""Tracking-error metrics and their block-bootstrap intervals."""

import numpy as np
import pytest

from endocal.validation.metrics import block_length, error_metrics


def test_metrics_by_hand():
    desired = np.array([-10.0, 0.0, 10.0, 0.0])
    reached = desired + np.array([1.0, -2.0, 0.0, 3.0])
    m = error_metrics(desired, reached, n_boot=0)
    assert m.rmse_deg == pytest.approx(np.sqrt((1 + 4 + 0 + 9) / 4))
    assert m.mae_deg == pytest.approx(1.5)
    assert m.max_deg == pytest.approx(3.0)
    assert m.median_deg == pytest.approx(1.5)
    assert m.median_pct == pytest.approx(100 * 1.5 / 10)  # amplitude 10 deg


def test_block_bootstrap_covers_truth_for_correlated_errors():
    # AR(1) errors with correlation time ~50 samples: iid intervals would be ~10x too narrow.
    rng = np.random.default_rng(1)
    phi, sigma = np.exp(-1 / 50), 1.0
    hits = 0
    for trial in range(40):
        e = np.empty(5000)
        e[0] = rng.normal()
        innov = rng.normal(size=e.size) * np.sqrt(1 - phi**2)
        for i in range(1, e.size):
            e[i] = phi * e[i - 1] + innov[i]
        m = error_metrics(np.zeros_like(e) + np.linspace(-1, 1, e.size), np.linspace(-1, 1, e.size) + sigma * e, n_boot=200, seed=trial)
        lo, hi = m.ci["rmse_deg"]
        hits += lo <= sigma <= hi
    assert 40 <= block_length(e) <= 120
    assert hits >= 30  # nominal 95 %: 38 of 40; the block bootstrap runs a little narrow
