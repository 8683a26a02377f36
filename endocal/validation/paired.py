"""Paired tests of two models' errors on the same held-out data, and Holm's correction over candidates.

Both tests compare the per-sample loss differential ``d_t = e_base(t)^2 - e_cand(t)^2``
(Diebold & Mariano, J. Bus. Econ. Stat. 13, 1995), one-sided (the candidate better):

- :func:`unit_test` (estimation/validation scheme): summed over each unit of the validation
  data (a half-cycle or decorrelation block, :mod:`endocal.validation.units`), sign-flip
  randomisation test;
- :func:`paired_test` (rolling origin): averaged over contiguous blocks three times as long
  as the errors' correlation time (:func:`endocal.validation.metrics.block_length`, the
  shorter of the two models'), Wilcoxon signed-rank test on the block means.

The p-values of all candidates are Holm-corrected (Holm, Scand. J. Statist. 6, 1979).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from scipy.special import ndtr  # norm.cdf, without scipy.stats' import (0.5 s)

from endocal.validation.metrics import block_length
from endocal.validation.units import Units


def paired_test(err_base: np.ndarray, err_cand: np.ndarray) -> tuple[float, int]:
    """One-sided p-value that ``err_cand`` is smaller than ``err_base``, and the number of blocks used.

    Block means of the loss differential ``e_base^2 - e_cand^2`` (blocks three times the
    errors' correlation time), Wilcoxon signed-rank test, alternative "greater".
    """
    d = err_base**2 - err_cand**2
    if not np.any(d):
        return 1.0, 0
    # Blocks of three correlation times: neighbouring block means are then nearly independent
    # (one correlation time leaves them correlated by ~1/e and the test rejects too often).
    # The correlation time is the errors', the shorter of the two models': a systematic error
    # that one model removes (a drift, a lag) makes the other's error and the differential
    # correlated over the whole record, which measures the signal, not the dependence of the noise.
    L = 3 * min(block_length(err_base), block_length(err_cand))
    L = min(L, max(1, d.size // 6))
    nb = d.size // L
    means = d[: nb * L].reshape(nb, L).mean(axis=1)
    if nb < 2 or not np.any(means):
        return 1.0, nb
    return signed_rank_greater(means), nb


def signed_rank_greater(d: np.ndarray) -> float:
    """One-sided p-value of the Wilcoxon signed-rank test that ``d`` is centred above zero.

    The p-value :func:`scipy.stats.wilcoxon` gives for ``wilcoxon(d, alternative="greater")``
    (its defaults: zeros dropped, no continuity correction, method "auto"), without importing
    scipy.stats, which takes half a second (the docstrings of its hundred distributions are
    parsed on import): a tenth of ``validate`` on the demo's records. The same three cases as
    scipy's "auto", and a test holds the two equal (tests/test_paired_signed_rank.py):

    - over 50 values, or over 13 with ties or zeros: the normal approximation, with the tie
      correction of the variance (Hollander & Wolfe, Nonparametric Statistical Methods, 1999, 3.1);
    - 50 or fewer, no ties and no zeros: the exact null distribution of the positive rank sum
      (every sign pattern equally likely);
    - 13 or fewer with ties or zeros: the exact sign-flip distribution of the statistic itself.
    """
    d = np.asarray(d, dtype=float)
    n_all = d.size
    nonzero = d[d != 0]
    n = nonzero.size
    if n == 0:  # no difference anywhere: nothing in favour
        return 1.0
    ranks, ties = _average_ranks(np.abs(nonzero))
    r_plus = float(np.sum((nonzero > 0) * ranks))
    tied = bool(np.any(ties > 1)) or n < n_all
    if n_all <= 50 and not tied:
        # the exact distribution of r_plus: counts of subsets of the ranks 1..n by their sum, halved per rank
        pmf = np.ones(1)
        for k in range(1, n + 1):
            prev, pmf = pmf, np.zeros(k * (k + 1) // 2 + 1)
            pmf[:prev.size] = prev * 0.5
            pmf[-prev.size:] += prev * 0.5
        k = int(np.floor(r_plus))
        return float(pmf[k:].sum() if k <= n * (n + 1) / 4 else 1.0 - pmf[:k].sum())
    if n_all <= 13:
        # every sign pattern of the values (a zero's sign changes nothing), the statistic recomputed
        flips = 1 - 2 * ((np.arange(2**n_all)[:, None] >> np.arange(n_all)) & 1)
        null = np.sum(((flips * d) > 0)[:, d != 0] * ranks, axis=-1)
        return float(np.clip(np.count_nonzero(null >= r_plus - abs(100 * np.finfo(float).eps * r_plus)) / 2**n_all,
                             0.0, 1.0))
    mean = n * (n + 1.0) * 0.25
    se = math.sqrt((n * (n + 1.0) * (2.0 * n + 1.0) - float(np.sum(ties**3 - ties)) / 2) / 24)
    return float(ndtr(-(r_plus - mean) / se))


def _average_ranks(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ranks 1..n of ``x``, ties given their average rank, and the size of each group of tied values."""
    order = np.argsort(x, kind="stable")
    y = x[order]
    first = np.concatenate([[True], y[:-1] != y[1:]])
    starts = np.flatnonzero(first)
    sizes = np.diff(np.append(starts, x.size))
    ranks = np.empty(x.size)
    ranks[order] = np.repeat(starts + 1 + (sizes - 1) / 2.0, sizes)
    return ranks, sizes.astype(float)


def holm(p: Sequence[float]) -> np.ndarray:
    """Holm step-down adjusted p-values (same order as ``p``)."""
    p = np.asarray(p, dtype=float)
    m = p.size
    order = np.argsort(p)
    adj = np.empty(m)
    running = 0.0
    for rank, i in enumerate(order):
        running = max(running, min(1.0, (m - rank) * p[i]))
        adj[i] = running
    return adj


def min_units_for(n_candidates: int, alpha: float) -> int:
    """Fewest paired units with which the best of ``n_candidates`` can reach Holm-corrected ``alpha``.

    The smallest one-sided p-value of the exact sign-flip test on ``n`` units
    (:func:`unit_test`) is ``2**-n`` (every unit in favour); Holm multiplies the smallest
    p-value by the number of candidates.
    """
    return max(1, int(math.ceil(math.log2(max(n_candidates, 1) / alpha))))


def unit_test(err_base: np.ndarray, err_cand: np.ndarray, units: Units, n_flips: int = 20000) -> float:
    """One-sided p-value that ``err_cand``'s mean squared error is smaller than ``err_base``'s, unit by unit.

    The loss differential ``d_t = e_base(t)^2 - e_cand(t)^2`` (Diebold & Mariano 1995) is
    summed over each unit (a half-cycle or decorrelation block of the validation data,
    :func:`~endocal.validation.units.make_units`); the units are nearly independent, the
    samples within one are not. Under the null hypothesis that neither model is better,
    each unit's sum is as likely positive as negative, so the observed total
    ``sum_u D_u`` (which is ``n`` times the MSE difference, the quantity the gain reports)
    is compared with its sign-flip randomisation distribution (Fisher's paired
    randomisation test): exact over all ``2**n`` flips for ``n <= 16`` units, else
    ``n_flips`` seeded random flips. Unlike a rank test on the units it tests the total
    error, so a candidate that removes a large error on a few units and costs a little on
    many is judged by what it does to the RMSE.
    """
    d = err_base**2 - err_cand**2
    sums = np.array([d[a:b].sum() for a, b in units.bounds])
    observed = float(sums.sum())
    if sums.size < 1 or observed <= 0 or not np.any(sums):
        return 1.0
    n = sums.size
    if n <= 16:
        signs = 1 - 2 * ((np.arange(2**n)[:, None] >> np.arange(n)) & 1)
        return float(np.mean(signs @ sums >= observed * (1 - 1e-12)))
    rng = np.random.default_rng(0)
    # drawn 1000 flips at a time (an even count of draws per call keeps the generator's stream, so the
    # p-value is the one a single (n_flips, n) draw gives): the whole matrix would hold 16 bytes per flip
    # and unit (int64 draws and their float signs), 300 MB for an hour's record of 1000 half-cycles
    hits = 0
    for a in range(0, n_flips, 1000):
        flips = rng.choice(np.array([-1.0, 1.0]), size=(min(1000, n_flips - a), n)) @ sums
        hits += np.count_nonzero(flips >= observed * (1 - 1e-12))
    return float((1 + hits) / (1 + n_flips))
