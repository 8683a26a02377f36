"""The signed-rank test of the rolling-origin scan and the look-alike notes (:func:`paired.signed_rank_greater`)
gives scipy.stats.wilcoxon's p-value, in each of the three cases of its method "auto"."""

import numpy as np
import pytest
from scipy.stats import wilcoxon

from endocal.validation.paired import paired_test, signed_rank_greater


def _cases():
    rng = np.random.default_rng(7)
    for n in (2, 3, 5, 8, 13, 14, 20, 33, 50, 51, 80, 200):
        # at 13 values with ties scipy enumerates 8192 sign patterns in Python (1.5 s a case): one shift there
        for shift in ((0.3,) if n == 13 else (-0.5, 0.0, 0.3, 1.0)):
            yield f"n{n}-shift{shift}", rng.normal(shift, 1.0, n)  # no ties: exact up to 50, then normal
            tied = np.round(rng.normal(shift, 1.0, n), 1)  # ties, and a zero now and then
            yield f"n{n}-shift{shift}-tied", tied
            zeros = rng.normal(shift, 1.0, n)
            zeros[rng.choice(n, size=max(1, n // 4), replace=False)] = 0.0
            if np.any(zeros):
                yield f"n{n}-shift{shift}-zeros", zeros


CASES = dict(_cases())


@pytest.mark.parametrize("name", list(CASES))
def test_signed_rank_matches_scipy(name):
    d = CASES[name]
    want = float(wilcoxon(d, alternative="greater").pvalue)
    assert signed_rank_greater(d) == pytest.approx(want, rel=1e-12, abs=1e-15)


def test_the_cases_reach_every_branch():
    """Exact (no ties, n <= 50), sign flips (ties or zeros, n <= 13) and the normal approximation are all held."""
    def branch(d):
        tied = np.unique(np.abs(d[d != 0])).size < np.count_nonzero(d) or np.any(d == 0)
        return "exact" if d.size <= 50 and not tied else "flips" if d.size <= 13 else "normal"

    assert {branch(d) for d in CASES.values()} == {"exact", "flips", "normal"}


def test_paired_test_reads_a_clear_gain_and_no_gain():
    """Block means of a candidate that halves the error are significant; of the same errors swapped, not."""
    rng = np.random.default_rng(3)
    base = rng.normal(0.0, 1.0, 3000)
    cand = 0.5 * base + rng.normal(0.0, 0.05, 3000)
    p_gain, nb = paired_test(base, cand)
    p_loss, _ = paired_test(cand, base)
    assert nb >= 6
    assert p_gain < 0.01 < 0.99 < p_loss


def test_no_difference_at_all_is_p_one():
    """All differences zero (two models alike on every block): nothing favours the candidate."""
    assert signed_rank_greater(np.zeros(8)) == 1.0
    assert signed_rank_greater(np.zeros(60)) == 1.0
