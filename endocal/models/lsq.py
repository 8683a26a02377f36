"""A fit's least squares on its compressed form: scipy's trust-region steps, without the long Jacobian's SVD.

Every fit here is ``min ||f(x)||²`` over a few tens of parameters ``x`` and thousands of samples (a
residual ``f`` of n rows, a Jacobian ``J`` of n x p). scipy's trust-region reflective method
(:func:`scipy.optimize.least_squares`, ``method="trf"``, ``tr_solver="exact"``) takes the SVD of the
n x p Jacobian at every iteration: in the closed loop of hidden effects that SVD was 30 % of the CPU time
(44 of 150 s of one loop, 2026-12-08).

The trust-region step depends on ``J`` and ``f`` only through the local model
``||f + J s||²``. With ``J = Q R`` (Q: n x p, orthonormal columns; R: p x p, upper triangular)
that model is ``||Qᵀf + R s||² + ||f - Q Qᵀf||²``, the same for every step ``s``; so the problem
handed to scipy is ``f̃ = [Qᵀf, ||f - Q Qᵀf||]`` and ``J̃ = [R; 0]``, p + 1 rows. Its cost
``½||f̃||²`` is ``½||f||²``, its gradient ``J̃ᵀf̃ = Jᵀf``, its Gauss-Newton matrix ``J̃ᵀJ̃ = JᵀJ``, and
the column norms ``x_scale="jac"`` reads are J's: every iterate, stopping test and evaluation count is
the uncompressed problem's, up to rounding (Golub & Van Loan, *Matrix Computations*, 4th ed., §5.3:
least squares through a QR factorisation; Kaufman, BIT 15, 1975, for the same reduction inside
variable projection).

R comes from the Cholesky factor of ``AᵀA``, ``A`` the column-scaled Jacobian (unit columns), and ``Qᵀf`` as
``R⁻ᵀ(Jᵀf)``: two level-3 BLAS products over J, no Q formed. That is exact to 1e-10 while ``A`` is
conditioned better than about 1e3 (the implicit Q's loss of orthogonality is about ``cond(A)² u``); up to about
1e6 the second pass of CholeskyQR2 (Fukaya, Nakatsukasa, Yanagisawa & Yamamoto, ScalA 2014) forms
``Q₁ = J R⁻¹`` and factors again, which restores it; beyond that (a parameter whose column vanishes, two columns
alike) the SVD compresses, exact at any rank, as scipy would have taken it. On 4000 x 33 Jacobians
(``tests/test_models_lsq.py``'s, one core, 2026-12-08): 1.1 ms one pass, 2.7 ms two, 8.1 ms the SVD, where
scipy's own SVD takes 8-10 ms. Of the 1 887 Jacobians of six fits on the demo's records, 37 % took one pass, 52 %
two, 11 % the SVD.

Since ``f̃`` needs J at every point the solver evaluates (also a trial step it rejects), each
evaluation computes the residual and the Jacobian together (one pass of the model's analytic
derivatives, which computes the output anyway); a trial step is rejected in about 5 % of iterations.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np
import scipy.linalg
from scipy.linalg.blas import dtrsm
from scipy.optimize import OptimizeResult, least_squares

#: Smallest ratio of the first Cholesky factor's diagonal (of the column-scaled Jacobian, whose columns
#: have unit norm) to its largest, under which the SVD compresses instead: about 1 / cond(A), kept where
#: CholeskyQR2 is orthogonal to working precision (cond(A) < 1e7, and a margin).
MIN_PIVOT_RATIO = 1e-6
#: Above this ratio (cond(A) under about 1e3) one Cholesky pass is exact enough: the implicit Q's loss of
#: orthogonality, about cond(A)² u, stays under 1e-10; below it CholeskyQR2's second pass restores it.
ONE_PASS_PIVOT_RATIO = 1e-3
#: scipy's solver as every fit runs it: trust-region reflective, each parameter scaled by its Jacobian column's norm.
_TRF = {"method": "trf", "x_scale": "jac"}


def compress(f: np.ndarray, J: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(f̃, J̃)`` of p + 1 rows with ``||f̃ + J̃ s|| = ||f + J s||`` for every ``s`` (the module's docstring).

    Parameters
    ----------
    f : ndarray (n,)
        Residual.
    J : ndarray (n, p)
        Its Jacobian, n >= p.
    """
    if not np.all(np.isfinite(f)):  # a trial step that overflowed: scipy shrinks its trust region, as before
        return np.full(J.shape[1] + 1, np.nan), np.full((J.shape[1] + 1, J.shape[1]), np.nan)
    if not np.all(np.isfinite(J)):
        return np.append(np.zeros(J.shape[1]), np.sqrt(float(f @ f))), np.full((J.shape[1] + 1, J.shape[1]), np.nan)
    ff = float(f @ f)
    G = J.T @ J
    norms = np.sqrt(np.diag(G))
    scale = np.where(norms > 0.0, norms, 1.0)
    try:
        # R₁ of the column-scaled Jacobian A = J / scale (whose AᵀA has a unit diagonal), then R₁ of J itself
        Rs = scipy.linalg.cholesky(G / np.outer(scale, scale), lower=False, check_finite=False)
        piv = np.abs(np.diag(Rs))
        if not (np.all(np.isfinite(Rs)) and piv.min() > MIN_PIVOT_RATIO * piv.max()):
            raise np.linalg.LinAlgError("ill-conditioned")
        R = Rs * scale
        if piv.min() < ONE_PASS_PIVOT_RATIO * piv.max():  # CholeskyQR2's second pass: Q₁ = J R₁⁻¹, orthonormal again
            Q1 = dtrsm(1.0, R, J, side=1, lower=0)
            R2 = scipy.linalg.cholesky(Q1.T @ Q1, lower=False, check_finite=False)
            top = scipy.linalg.solve_triangular(R2, Q1.T @ f, trans="T", lower=False, check_finite=False)
            R = R2 @ R
        else:
            top = scipy.linalg.solve_triangular(R, J.T @ f, trans="T", lower=False, check_finite=False)
    except (np.linalg.LinAlgError, ValueError):
        U, s, Vt = scipy.linalg.svd(J, full_matrices=False, check_finite=False)
        top = U.T @ f
        R = s[:, None] * Vt
    tail = np.sqrt(max(ff - float(top @ top), 0.0))
    return np.append(top, tail), np.vstack([R, np.zeros((1, J.shape[1]))])


class Residuals(NamedTuple):
    """A fit's least-squares problem over its free parameters (``HysteresisModel._residual_fns``).

    Attributes
    ----------
    residual : callable
        ``x -> f`` (n,), model minus measurement (deg).
    jac : callable or "2-point"
        ``x -> J`` (n, p), analytic; else scipy's finite differences.
    both : callable or None
        ``x -> (f, J)`` from one pass of the analytic derivatives (None without them).
    """

    residual: Callable[[np.ndarray], np.ndarray]
    jac: Callable[[np.ndarray], np.ndarray] | str
    both: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]] | None = None


def solve(fns: Residuals, x0: np.ndarray, *, bounds: tuple, ftol: float, max_nfev: int | None) -> OptimizeResult:
    """:func:`scipy.optimize.least_squares`, trust-region reflective within ``bounds`` with ``x_scale="jac"``, as every
    fit runs it: on the compressed form where ``fns`` has analytic derivatives (``both``), else on the full residual.

    The result is scipy's; its ``fun`` and ``jac`` are the full residual and Jacobian at the solution either way.
    """
    if fns.both is None:
        return least_squares(fns.residual, x0, jac=fns.jac, bounds=bounds, ftol=ftol, max_nfev=max_nfev, **_TRF)
    seen: dict[bytes, tuple] = {}  # the last few points evaluated: a trial step, then the Jacobian at it

    def at(x: np.ndarray) -> tuple:
        key = np.asarray(x, float).tobytes()
        if key not in seen:
            if len(seen) >= 3:
                seen.pop(next(iter(seen)))
            f, J = fns.both(x)
            seen[key] = (f, J, *compress(f, J))
        return seen[key]

    res = least_squares(lambda x: at(x)[2], x0, jac=lambda x: at(x)[3], bounds=bounds, ftol=ftol, max_nfev=max_nfev,
                        **_TRF)
    f, J, _, _ = at(res.x)
    res.fun, res.jac = f, J
    return res
