"""Bounded model parameters and their printing with standard errors."""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass
class Parameter:
    """One named, bounded model parameter with a starting value from the data.

    Parameters
    ----------
    name : str
        Full, prefixed name (``envelope_k0``, ``pi_r``, ``delay_s``).
    value : float
        Starting guess (before the fit) or value (after).
    lower, upper : float
        Bounds (``-inf``/``inf`` when unbounded).
    """

    name: str
    value: float
    lower: float = -math.inf
    upper: float = math.inf

    def clipped_start(self) -> float:
        """The start value moved strictly inside the bounds (least_squares needs an interior start)."""
        lo, hi, v = self.lower, self.upper, float(self.value)
        if math.isfinite(lo) and math.isfinite(hi):
            margin = 1e-6 * (hi - lo)
            return min(max(v, lo + margin), hi - margin)
        if math.isfinite(lo) and v <= lo:
            return lo + max(1e-6 * abs(lo), 1e-9)
        if math.isfinite(hi) and v >= hi:
            return hi - max(1e-6 * abs(hi), 1e-9)
        return v


def fmt_value(value: float, stderr: float | None = None, unit: str = "") -> str:
    """``0.1183+-0.0021`` with digits set by the standard error (two significant), else 4 significant;
    an infinite standard error (a direction the data do not pin down) is said in words."""
    suffix = f" {unit}" if unit else ""
    if stderr is not None and math.isfinite(stderr) and stderr > 0:
        decimals = max(0, 1 - int(math.floor(math.log10(stderr))))
        if decimals > 10:
            return f"{value:.4g}+-{stderr:.2g}{suffix}"
        return f"{value:.{decimals}f}+-{stderr:.{decimals}f}{suffix}"
    if stderr is not None and math.isinf(stderr):
        return f"{value:.4g}{suffix} (not identified)"
    return f"{value:.4g}{suffix}"
