"""Comparing models on autocorrelated tracking errors: units, paired tests, effect sizes.

Why not test on samples. A tracking error sampled at 100 Hz is strongly autocorrelated: a
model that is off at a reversal is off for the whole reversal, so the 14 000 samples of a
damped sine carry far fewer than 14 000 independent pieces of evidence. A test that treats
samples as independent finds "significant" differences between any two models. So every model
is scored on the same *units* of the record, and the tests compare those per-unit scores:

``half-cycle``
    the stretch between two consecutive reversals of the command (and run starts) (one branch of the
    hysteresis loop). This is the natural unit of a tendon-sheath drive: each branch starts
    from a reversal where backlash and dead zone act, and errors decorrelate across reversals.
``block``
    when the command reverses too rarely (staircases, holds), equal consecutive blocks whose
    length is the error's decorrelation length (where its autocorrelation falls below 1/e, see
    :func:`endocal.validation.metrics.block_length`), the longest over the compared models.

The per-unit score is the RMSE of the unit (:func:`endocal.validation.metrics.error_metrics`).
Every model is scored on the same units, so the scores are *paired* and the tests are the
paired, rank-based ones that assume neither normality nor equal variances:

* two models: the **Wilcoxon signed-rank test** on the per-unit differences, with the
  matched-pairs **rank-biserial correlation** ``r = (R+ - R-) / (R+ + R-)`` as effect size
  (Kerby 2014; ``r = +1``: the first model is worse on every unit);
* three or more: the **Friedman test** (the rank-based repeated-measures ANOVA) with
  **Kendall's W** ``= chi2_F / (n (k - 1))`` as effect size, followed by pairwise Wilcoxon
  tests whose p-values are corrected for multiple comparisons with **Holm's** step-down
  method (it controls the family-wise error rate without Bonferroni's loss of power).

With ``n`` units the smallest two-sided p-value an exact signed-rank test can reach is
``2 / 2**n``; below six units no difference can reach p < 0.05, and the comparison says so
instead of pretending to test.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import combinations

import numpy as np
from scipy import stats as sps

from endocal.validation.metrics import error_metrics
from endocal.validation.units import MIN_UNITS, Units, make_units  # noqa: F401  (re-exported)

ALPHA = 0.05


def unit_rmse(desired_deg: np.ndarray, reached_deg: np.ndarray, units: Units) -> np.ndarray:
    """RMSE of each unit (deg), through :func:`~endocal.validation.metrics.error_metrics`.

    Returns
    -------
    (n_units,) array
    """
    d = np.asarray(desired_deg, float)
    r = np.asarray(reached_deg, float)
    return np.array([error_metrics(d[a:b], r[a:b], n_boot=0).rmse_deg for a, b in units.bounds])


def holm(p_values: list[float] | np.ndarray) -> np.ndarray:
    """Holm's step-down adjusted p-values (family-wise error control).

    ``p_adj(i) = max_{j <= i} min(1, (m - j + 1) p_(j))`` over the p-values sorted increasingly.
    """
    p = np.asarray(p_values, float)
    m = p.size
    if m == 0:
        return p
    order = np.argsort(p, kind="stable")
    adj_sorted = np.minimum(1.0, np.maximum.accumulate((m - np.arange(m)) * p[order]))
    out = np.empty(m)
    out[order] = adj_sorted
    return out


def rank_biserial(a: np.ndarray, b: np.ndarray) -> float:
    """Matched-pairs rank-biserial correlation of ``a - b`` (Kerby 2014), in [-1, 1].

    ``(R+ - R-) / (R+ + R-)`` with ``R+``/``R-`` the sums of the ranks of |a - b| over the
    positive/negative differences (zero differences dropped, like the Wilcoxon test).
    Positive: ``a`` tends to be larger (worse, for errors). 0 when every difference is zero.
    """
    d = np.asarray(a, float) - np.asarray(b, float)
    d = d[d != 0]
    if d.size == 0:
        return 0.0
    ranks = sps.rankdata(np.abs(d))
    r_plus, r_minus = float(ranks[d > 0].sum()), float(ranks[d < 0].sum())
    return (r_plus - r_minus) / (r_plus + r_minus)


@dataclass(frozen=True)
class PairTest:
    """Wilcoxon signed-rank test of two models' per-unit errors.

    Attributes
    ----------
    a, b : str
        Model labels; differences are ``a - b``.
    n : int
        Units compared (pairs).
    n_nonzero : int
        Pairs with a non-zero difference (the others carry no rank).
    statistic : float
        Wilcoxon's T (smaller of the signed rank sums).
    p_value : float
        Two-sided p-value (exact when scipy can, normal approximation otherwise).
    p_adjusted : float
        After Holm correction over all pairs of the comparison (equals ``p_value`` for two models).
    rank_biserial : float
        Effect size, see :func:`rank_biserial`.
    median_diff_deg : float
        Median of the per-unit RMSE differences ``a - b``.
    """

    a: str
    b: str
    n: int
    n_nonzero: int
    statistic: float
    p_value: float
    p_adjusted: float
    rank_biserial: float
    median_diff_deg: float

    def significant(self, alpha: float = ALPHA) -> bool:
        return bool(self.p_adjusted < alpha)

    @property
    def better(self) -> str | None:
        """The model with the smaller errors by the median difference (None on a tie)."""
        if self.median_diff_deg < 0 or (self.median_diff_deg == 0 and self.rank_biserial < 0):
            return self.a
        if self.median_diff_deg > 0 or (self.median_diff_deg == 0 and self.rank_biserial > 0):
            return self.b
        return None

    def to_dict(self) -> dict:
        return {"a": self.a, "b": self.b, "n": self.n, "n_nonzero": self.n_nonzero, "statistic": self.statistic,
                "p_value": self.p_value, "p_adjusted": self.p_adjusted, "rank_biserial": self.rank_biserial,
                "median_diff_deg": self.median_diff_deg, "better": self.better}


def wilcoxon_pair(a_label: str, a: np.ndarray, b_label: str, b: np.ndarray) -> PairTest:
    """Two-sided Wilcoxon signed-rank test on paired per-unit errors ``a``, ``b`` (zero differences dropped).

    Identical errors give p = 1 and effect 0 (scipy would warn and return NaN).
    """
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    d = a - b
    nz = int(np.count_nonzero(d))
    med = float(np.median(d)) if d.size else 0.0
    if nz == 0:
        stat, p = 0.0, 1.0
    else:
        res = sps.wilcoxon(a, b, zero_method="wilcox", alternative="two-sided")
        stat, p = float(res.statistic), float(res.pvalue)
    return PairTest(a_label, b_label, int(d.size), nz, stat, p, p, rank_biserial(a, b), med)


@dataclass(frozen=True)
class Comparison:
    """The statistical comparison of the models evaluated on one record and axis.

    Attributes
    ----------
    models : list of str
    unit_kind : str
        ``half-cycle`` or ``block``.
    n_units : int
    test : {"wilcoxon", "friedman", "none"}
    why : str
        Which test was done and why, in words (or why none could be).
    statistic, p_value : float
        Wilcoxon's T or Friedman's chi-square, and its p-value (NaN when no test).
    effect_size : float
        Rank-biserial r (two models) or Kendall's W (more), NaN when no test.
    effect_name : str
    pairs : list of PairTest
        Every pair (Holm-adjusted when there are more than two models).
    alpha : float
    """

    models: list[str]
    unit_kind: str
    n_units: int
    test: str
    why: str
    statistic: float = float("nan")
    p_value: float = float("nan")
    effect_size: float = float("nan")
    effect_name: str = ""
    pairs: list[PairTest] = field(default_factory=list)
    alpha: float = ALPHA

    def pair(self, a: str, b: str) -> PairTest | None:
        """The test of ``a`` against ``b`` (either order), or None."""
        for p in self.pairs:
            if {p.a, p.b} == {a, b}:
                return p
        return None

    @property
    def significant(self) -> bool:
        """Whether the omnibus test (or the single pair) rejects 'all models are equal'."""
        return bool(np.isfinite(self.p_value) and self.p_value < self.alpha)

    def to_dict(self) -> dict:
        return {"models": list(self.models), "unit_kind": self.unit_kind, "n_units": self.n_units,
                "test": self.test, "why": self.why, "statistic": self.statistic, "p_value": self.p_value,
                "effect_size": self.effect_size, "effect_name": self.effect_name, "alpha": self.alpha,
                "significant": self.significant, "pairs": [p.to_dict() for p in self.pairs]}


def kendall_w(chi2: float, n: int, k: int) -> float:
    """Kendall's coefficient of concordance from Friedman's statistic: ``chi2 / (n (k - 1))``."""
    return float(chi2 / (n * (k - 1))) if n > 0 and k > 1 else float("nan")


def compare_models(unit_errors: dict[str, np.ndarray], units: Units, alpha: float = ALPHA) -> Comparison:
    """Compare models on their per-unit errors with the test that fits their number.

    Parameters
    ----------
    unit_errors : dict of str to (n_units,) array
        Per-unit RMSE of each model (deg), all on the same units.
    units : Units
        The units (for their kind, count and the reason they were chosen).
    alpha : float
        Significance level.

    Returns
    -------
    Comparison
    """
    names = list(unit_errors)
    k, n = len(names), units.n
    unit_text = f"{n} {units.kind}s ({units.reason})"
    if k < 2:
        return Comparison(names, units.kind, n, "none", "only one model was evaluated here: nothing to compare", alpha=alpha)
    if n < MIN_UNITS:
        return Comparison(names, units.kind, n, "none",
                          f"only {n} units: with fewer than {MIN_UNITS} the smallest p-value a signed-rank test can "
                          f"reach is {2 / 2 ** n:.3f} (>= {alpha}), so no difference could be shown; record more "
                          "cycles to compare these models", alpha=alpha)
    mat = np.column_stack([np.asarray(unit_errors[m], float) for m in names])
    if k == 2:
        p = wilcoxon_pair(names[0], mat[:, 0], names[1], mat[:, 1])
        why = (f"Wilcoxon signed-rank test (two-sided, paired) on per-{units.kind} RMSE over {unit_text}. "
               "Samples are autocorrelated, so the models are compared unit by unit, not sample by sample; the "
               "signed-rank test needs no normality of the differences. Effect size: matched-pairs rank-biserial r.")
        return Comparison(names, units.kind, n, "wilcoxon", why, p.statistic, p.p_value, p.rank_biserial,
                          "rank-biserial r", [p], alpha)
    if np.all(mat == mat[:, :1]):
        chi2, pf = 0.0, 1.0
    else:
        res = sps.friedmanchisquare(*[mat[:, j] for j in range(k)])
        chi2, pf = float(res.statistic), float(res.pvalue)
        if not np.isfinite(chi2):
            chi2, pf = 0.0, 1.0
    raw = [wilcoxon_pair(names[i], mat[:, i], names[j], mat[:, j]) for i, j in combinations(range(k), 2)]
    adj = holm([p.p_value for p in raw])
    pairs = [PairTest(p.a, p.b, p.n, p.n_nonzero, p.statistic, p.p_value, float(q), p.rank_biserial, p.median_diff_deg)
             for p, q in zip(raw, adj)]
    why = (f"Friedman test on per-{units.kind} RMSE of {k} models over {unit_text}, then pairwise Wilcoxon "
           f"signed-rank tests with Holm's correction for the {len(pairs)} pairs. Samples are autocorrelated, so "
           "models are compared unit by unit; both tests are rank-based and paired. Effect sizes: Kendall's W "
           "(overall), rank-biserial r (pairs).")
    return Comparison(names, units.kind, n, "friedman", why, chi2, pf, kendall_w(chi2, n, k), "Kendall's W", pairs, alpha)


def stars(p: float) -> str:
    """Significance stars as in the thesis's fig. 7: ``***`` p<0.001, ``**`` p<0.01, ``*`` p<0.05, ``ns``."""
    if not np.isfinite(p):
        return "n/a"
    return "***" if p < 0.001 else "**" if p < 0.01 else "*" if p < 0.05 else "ns"
