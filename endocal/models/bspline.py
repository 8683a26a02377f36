"""``bspline``: direction-dependent B-spline hysteresis, as in the thesis.

Thesis, section 2.3: the loop is modelled by one B-spline for increasing and one for
decreasing command (:class:`scipy.interpolate.BSpline`, shared knots at quantiles of
the moving command, continued along their end tangents beyond them). At a reversal the output leaves the branch it
was on along a backlash transition of slope ``s`` until it meets the other branch
(:mod:`endocal.models._directional`), so the switch is continuous. Fitting adjusts
both splines' coefficients and ``s`` jointly by least squares, from per-direction
linear least-squares splines as the start.

Each branch is parameterised by its first coefficient and non-negative increments,
``c_i = c_0 + Σ_{j<=i} Δc_j`` with ``Δc_j >= 0``: a B-spline with non-decreasing
coefficients is non-decreasing (de Boor, *A Practical Guide to Splines*, ch. IX), so
a branch rises with the command as the tip does, also at the ends of the range where
few samples lie on it (just after a reversal the output is on the transition, not the
branch), and the numerical inverse always has a unique answer.
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import BSpline
from scipy.optimize import lsq_linear
from scipy.sparse import csr_matrix

from endocal.errors import ModelError
from endocal.models._directional import DirectionalModel, direction_masks
from endocal.models.data import HysteresisData
from endocal.models.effects.base import Effect
from endocal.models.params import Parameter, fmt_value


def _design_matrix(x: np.ndarray, t: np.ndarray, k: int):
    """:meth:`BSpline.design_matrix` (sparse, ``(n, len(t) - k - 1)``) at points ``x`` already clipped to the
    base interval ``[t[k], t[-k - 1]]``.

    There ``extrapolate=True`` finds the same knot intervals, so the matrix is the same to the bit;
    it skips scipy's bounds check, whose Python ``min``/``max`` over the array took a tenth of a
    B-spline fit's time (every evaluation of a model with a delay or a rate term builds the matrix).
    """
    return BSpline.design_matrix(x, t, k, extrapolate=True)


def _lsq_spline(t: np.ndarray, k: int, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """A non-decreasing spline by bounded linear least squares, lightly regularised.

    Returns ``(c_0, Δc_1, ..., Δc_{m-1})`` with ``Δc >= 0`` (coefficients ``cumsum``); a small
    penalty on the increments' differences (the coefficients' second differences)
    settles empty knot spans.
    """
    B = _design_matrix(np.clip(x, t[k], t[-k - 1]), t, k).toarray()
    m = B.shape[1]
    A = B @ np.tril(np.ones((m, m)))
    lam = 1e-8 * max(1.0, float(np.trace(B.T @ B)) / m)
    D = np.diff(np.eye(m), 1, axis=0)
    D[:, 0] = 0.0
    A = np.vstack([A, np.sqrt(lam) * D])
    lower = np.r_[-np.inf, np.zeros(m - 1)]
    return lsq_linear(A, np.r_[y, np.zeros(D.shape[0])], bounds=(lower, np.inf), method="bvls").x


def _knots_inside(v: np.ndarray, a: float, b: float, n_knots: int) -> np.ndarray:
    """Interior knots at quantiles of the command while it moves, at least a quarter of an even
    spacing apart and from the ends.

    A hold is many samples at one value: counted, it pulls quantiles onto itself, and a knot
    4.5e-8 deg from the end (a record that began with a hold at 0) gave the spline an interval
    only the hold's samples lie in, where it took any value (-16.8 deg at 0, -5.4 just after).
    """
    if not n_knots:
        return np.array([])
    step = np.abs(np.diff(v, prepend=v[0]))
    moving = v[step > 1e-6 * (b - a)]
    q = np.quantile(moving if moving.size > 2 * n_knots else v, np.linspace(0, 1, n_knots + 2)[1:-1])
    gap = 0.25 * (b - a) / (n_knots + 1)
    out: list[float] = []
    for x in q:
        if x - (out[-1] if out else a) >= gap and b - x >= gap:
            out.append(float(x))
    return np.array(out)


class BSplineModel(DirectionalModel):
    """Direction-dependent B-spline hysteresis model (thesis).

    Parameters (prefix ``bspline_``): ``up_c0``, ``up_dc1``… and ``down_c0``,
    ``down_dc1``… (each branch's first spline coefficient and its non-negative
    increments, deg) and ``transition_slope``.

    Parameters
    ----------
    n_knots : int
        Interior knots of each spline, at quantiles of the command while it moves (default 6).
    degree : int
        Spline degree (default 3, cubic).
    effects, fixed, axis, out_of_range
        See :class:`~endocal.models.base.HysteresisModel`.

    Notes
    -----
    The inverse is numerical (bisection per sample on the monotone step map).
    """

    base_name = "bspline"

    def __init__(self, n_knots: int = 6, degree: int = 3, *, effects=(), fixed=None, axis=None,
                 out_of_range="error"):
        self.n_knots = n_knots
        self.degree = degree
        self.effects = effects
        self.fixed = fixed
        self.axis = axis
        self.out_of_range = out_of_range

    def _resolve_structure(self, effects: list[Effect], v, data) -> dict:
        for name, val, lo, hi in (("n_knots", self.n_knots, 0, 100), ("degree", self.degree, 1, 5)):
            if not isinstance(val, (int, np.integer)) or isinstance(val, bool) or not lo <= val <= hi:
                raise ModelError(f"{name} must be an integer in {lo}..{hi}, got {val!r}")
        st = {"degree": int(self.degree), "knots": None}
        if v is not None:
            a, b = float(v.min()), float(v.max())
            if not b > a:
                raise ModelError("the command reaching the B-spline model is constant: nothing to fit")
            inner = _knots_inside(v, a, b, self.n_knots)
            k = self.degree
            st["knots"] = [a] * (k + 1) + [float(x) for x in inner] + [b] * (k + 1)
        return st

    def _n_coef(self, structure: dict) -> int:
        if structure["knots"] is None:
            raise ModelError("a B-spline model needs structure={'knots': [...]} in set_parameters")
        return len(structure["knots"]) - structure["degree"] - 1

    def _base_names(self, structure: dict) -> list[str]:
        m = self._n_coef(structure)
        inc = [f"dc{i}" for i in range(1, m)]
        return ["up_c0"] + [f"up_{n}" for n in inc] + ["down_c0"] + [f"down_{n}" for n in inc] + ["transition_slope"]

    def _base_initial(self, structure: dict, v: np.ndarray, data: HysteresisData) -> list[Parameter]:
        t = np.asarray(structure["knots"])
        k = structure["degree"]
        inc, dec = direction_masks(v, data.run_starts)
        if inc.sum() < 2 or dec.sum() < 2:
            raise ModelError("backlash cannot be identified: the command never reverses")
        y = data.meas_deg
        x_up = _lsq_spline(t, k, v[inc], y[inc])
        x_dn = _lsq_spline(t, k, v[dec], y[dec])
        slope = float(np.polyfit(v, y, 1)[0])
        out = []
        for branch, x in (("up", x_up), ("down", x_dn)):
            out.append(Parameter(f"{branch}_c0", float(x[0])))
            out += [Parameter(f"{branch}_dc{i}", float(x[i]), 0.0, np.inf) for i in range(1, x.size)]
        out.append(Parameter("transition_slope", 0.2 * max(slope, 1e-6), 0.0, np.inf))
        return out

    def _coefs(self, structure: dict, p: dict) -> tuple[np.ndarray, np.ndarray]:
        m = self._n_coef(structure)
        return tuple(np.cumsum([p[f"{b}_c0"]] + [p[f"{b}_dc{i}"] for i in range(1, m)]) for b in ("up", "down"))

    def _branches(self, structure: dict, p: dict):
        t = np.asarray(structure["knots"], dtype=float)
        c_up, c_dn = self._coefs(structure, p)
        return t, c_up, t.copy(), c_dn, structure["degree"]

    def _eval_branches(self, structure: dict, p: dict, v: np.ndarray):
        t = np.asarray(structure["knots"], dtype=float)
        c_up, c_dn = self._coefs(structure, p)
        k = structure["degree"]
        B, ext = self._design(t, k, v)
        C = B @ np.column_stack([c_up, c_dn])
        if ext is not None:
            C += ext @ np.column_stack([c_up, c_dn])
        return np.ascontiguousarray(C[:, 0]), np.ascontiguousarray(C[:, 1])

    def _branch_jac(self, structure: dict, p: dict, v: np.ndarray):
        t = np.asarray(structure["knots"], dtype=float)
        k = structure["degree"]
        c_up, c_dn = self._coefs(structure, p)
        m = c_up.size
        B, ext = self._design(t, k, v)
        D = B.toarray() if ext is None else (B + ext).toarray()
        J = D @ np.tril(np.ones((m, m)))  # the coefficients are cumulative sums of the parameters
        # slopes in v: f' = Σ k (c_{i+1} - c_i)/(t_{i+k+1} - t_{i+1}) B_{i,k-1} (de Boor), at v
        # clipped to the base interval: beyond it the branches continue along their end tangents
        vc = np.clip(v, t[k], t[-k - 1])
        B1 = _design_matrix(vc, t[1:-1], k - 1)  # t[1:-1] has the same base interval
        scale = k / (t[k + 1:k + m] - t[1:m])
        d_up = B1 @ (scale * np.diff(c_up))
        d_dn = B1 @ (scale * np.diff(c_dn))
        zero = np.zeros_like(J)
        return (D @ c_up, D @ c_dn, np.hstack([J, zero]), np.hstack([zero, J]),
                np.asarray(d_up, dtype=float).ravel(), np.asarray(d_dn, dtype=float).ravel())

    def _design(self, t: np.ndarray, k: int, v: np.ndarray):
        """Design matrix at ``v`` (clipped to the base interval) and the linear-extension correction.

        Cached for the last ``v``: during a fit without input effects every evaluation
        sees the same command, and the branches are linear in their coefficients.
        """
        cache = getattr(self, "_design_cache", None)
        if cache is not None and cache[0] is not None and cache[0].shape == v.shape and np.array_equal(cache[0], v) \
                and np.array_equal(cache[1], t):
            return cache[2], cache[3]
        a, b = t[k], t[-k - 1]
        vc = np.clip(v, a, b)
        B = _design_matrix(vc, t, k).tocsr()
        m = len(t) - k - 1
        # end tangents: f'(a) = k (c1 - c0)/(t[k+1] - t[1]),  f'(b) = k (c[m-1] - c[m-2])/(t[m+k-1] - t[m-1])
        # built sparse from the samples beyond the interval (two entries each): a dense (n, m) array
        # would take m * 8 bytes per sample on every prediction
        lo = np.flatnonzero(v < a)
        hi = np.flatnonzero(v > b)
        ext = None
        if lo.size or hi.size:
            g_lo = k / (t[k + 1] - t[1]) * (v[lo] - a)
            g_hi = k / (t[m + k - 1] - t[m - 1]) * (v[hi] - b)
            rows = np.concatenate([lo, lo, hi, hi])
            cols = np.concatenate([np.zeros(lo.size, np.int64), np.ones(lo.size, np.int64),
                                   np.full(hi.size, m - 2, np.int64), np.full(hi.size, m - 1, np.int64)])
            vals = np.concatenate([-g_lo, g_lo, -g_hi, g_hi])
            ext = csr_matrix((vals, (rows, cols)), shape=(v.size, m))
            ext.sum_duplicates()  # canonical: each row's columns sorted, as the dense conversion gave them
        self._design_cache = (v.copy(), t.copy(), B, ext)
        return B, ext

    def _base_describe(self, structure: dict, p: dict, se: dict, inner: str) -> str:
        t = structure["knots"]
        k = structure["degree"]
        m = self._n_coef(structure)
        return (f"BSpline{k}({inner}) [up/down: {m} coefficients each, knots {t[k]:.4g}..{t[-k - 1]:.4g} "
                f"{self.drive_unit_}, "
                f"transition={fmt_value(p['transition_slope'], se.get('transition_slope'))}]")
