"""Units of a record for paired comparison of two models' errors: half-cycles or decorrelation blocks.

A tracking error sampled at 100 Hz is strongly autocorrelated: a model that is off at a
reversal is off for the whole reversal. Comparing two models sample by sample would treat
thousands of correlated samples as independent evidence, so records are cut into *units*
and models are compared on per-unit scores (see :mod:`endocal.report.stats` for the tests):

``half-cycle``
    the stretch between two consecutive reversals of the command (and run starts): one
    branch of the hysteresis loop, where backlash and dead zone act anew;
``block``
    when the command reverses too rarely, equal consecutive blocks of the errors'
    decorrelation length (:func:`endocal.validation.metrics.block_length`).

Used by ``endocal validate`` (the estimation/validation scan's paired test) and by the
report's comparisons.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from endocal.models import HysteresisData
from endocal.validation.metrics import block_length
from endocal.validation.regimes import turning_points

#: Fewest units a comparison needs: with 5 the exact signed-rank test cannot reach p < 0.05.
MIN_UNITS = 6


@dataclass(frozen=True)
class Units:
    """How a record is cut into units for paired comparison.

    Attributes
    ----------
    kind : {"half-cycle", "block"}
    bounds : list of (int, int)
        ``[start, stop)`` sample ranges, covering the record in order.
    reason : str
        Why this kind of unit was chosen, in words.
    """

    kind: str
    bounds: list[tuple[int, int]]
    reason: str

    @property
    def n(self) -> int:
        return len(self.bounds)

    def to_dict(self) -> dict:
        return {"kind": self.kind, "n": self.n, "bounds": [list(b) for b in self.bounds], "reason": self.reason}


def _merge_short(cuts: list[int], n: int) -> list[tuple[int, int]]:
    """Segments between cuts; a leading or trailing piece shorter than a quarter of the median joins its neighbour."""
    edges = [0] + [c for c in cuts if 0 < c < n] + [n]
    segs = [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:]) if b > a]
    if len(segs) >= 3:
        med = float(np.median([b - a for a, b in segs[1:-1]]))
        if segs[0][1] - segs[0][0] < med / 4:
            segs = [(0, segs[1][1])] + segs[2:]
        if len(segs) >= 2 and segs[-1][1] - segs[-1][0] < med / 4:
            segs = segs[:-2] + [(segs[-2][0], n)]
    return segs


def make_units(
    data: HysteresisData,
    errors_deg: list[np.ndarray] | None = None,
    *,
    tol_frac: float = 0.05,
    min_units: int = MIN_UNITS,
) -> Units:
    """Cut one record into half-cycles, or into decorrelation-length blocks when it rarely reverses.

    Parameters
    ----------
    data : HysteresisData
        The record; its command's reversals (:func:`endocal.validation.regimes.turning_points`)
        and run starts cut the half-cycles.
    errors_deg : list of (n,) arrays, optional
        Errors of the models to be compared; their decorrelation length sizes the blocks.
    tol_frac : float
        A reversal must be left by more than this fraction of the command's span (ignores
        wiggles; coarser than validation's regime boundaries because a unit needs a real branch).
    min_units : int
        Fewest half-cycles for them to be used.

    Returns
    -------
    Units
    """
    n = data.n_samples
    rev = turning_points(data, tol_frac)
    segs = _merge_short(sorted(set(int(r) for r in rev) | set(int(s) for s in data.run_starts)), n)
    if len(segs) >= min_units:
        return Units("half-cycle", segs,
                     f"{len(rev)} command reversals: each branch of the loop (reversal to reversal) is one unit, "
                     "so errors are compared where hysteresis acts and units are nearly independent")
    L = max([block_length(np.asarray(e, float)) for e in (errors_deg or [])] + [1])
    n_blocks = max(1, n // L)
    edges = np.linspace(0, n, n_blocks + 1).round().astype(int)
    segs = [(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:]) if b > a]
    return Units("block", segs,
                 f"only {len(rev)} command reversals: the record is cut into {len(segs)} blocks of about "
                 f"{L} samples, the error's decorrelation length (autocorrelation below 1/e)")
