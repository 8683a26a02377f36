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
    return float(import_paired_test()(means, alternative="greater").pvalue), nb


def import_paired_test():
    """:func:`scipy.stats.wilcoxon`, imported on first use: scipy.stats takes 0.27 s to import, which the
    split scan spends while its candidates fit (:func:`~endocal.validation.scan.scan_split`) and most
    commands never."""
    from scipy.stats import wilcoxon

    return wilcoxon


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
