"""The compressed least squares (endocal.models.lsq): the same local model, the same solver path.

The compression replaces the residual ``f`` (n,) and its Jacobian ``J`` (n, p) by ``p + 1`` rows with the
same ``||f + J s||`` for every step ``s``. In exact arithmetic that makes scipy's trust-region iterates
identical; in floating point they differ by rounding: the factorisations used (one Cholesky pass where J is well
conditioned, CholeskyQR2's second pass up to cond 1e6, else the SVD) keep the local model to about 1e-10 relative,
so the checks below hold to 1e-9 relative unless said.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares

import endocal.models.base as base
from endocal.models import make_model
import endocal.models.lsq as lsq
from endocal.models.lsq import MIN_PIVOT_RATIO, ONE_PASS_PIVOT_RATIO, Residuals, compress, solve
from endocal.sim import SimConfig
from endocal.validation.data import axis_data
from tests.test_validation_hidden import simulate


def _jacobian(rng, n: int, p: int, cond: float) -> np.ndarray:
    """An n x p Jacobian with singular values from 1 down to 1 / cond, and columns of unequal scale."""
    U, _ = np.linalg.qr(rng.standard_normal((n, p)))
    V, _ = np.linalg.qr(rng.standard_normal((p, p)))
    s = np.geomspace(1.0, 1.0 / cond, p)
    return np.asfortranarray((U * s) @ V.T * np.geomspace(1e-3, 1e3, p))


@pytest.mark.parametrize("cond, way", [(10.0, "one pass"), (1e5, "two passes"), (1e9, "svd")])
def test_the_compressed_model_is_the_full_one_for_every_step(cond, way, monkeypatch):
    # well conditioned (one Cholesky pass), cond 1e5 (CholeskyQR2's second pass), 1e9 (the SVD)
    assert 0.0 < MIN_PIVOT_RATIO < ONE_PASS_PIVOT_RATIO < 1.0
    rng = np.random.default_rng(int(np.log10(cond)))
    n, p = 3000, 12
    J = _jacobian(rng, n, p, cond)
    f = J @ rng.standard_normal(p) + rng.standard_normal(n)  # partly explained, partly not
    taken = []
    dtrsm, svd = lsq.dtrsm, lsq.scipy.linalg.svd
    monkeypatch.setattr(lsq, "dtrsm", lambda *a, **k: taken.append("two passes") or dtrsm(*a, **k))
    monkeypatch.setattr(lsq.scipy.linalg, "svd", lambda *a, **k: taken.append("svd") or svd(*a, **k))
    ft, Jt = compress(f, J)
    assert taken == ([] if way == "one pass" else [way]), taken
    assert ft.shape == (p + 1,) and Jt.shape == (p + 1, p)
    assert np.dot(ft, ft) == pytest.approx(np.dot(f, f), rel=1e-12)
    assert Jt.T @ ft == pytest.approx(J.T @ f, rel=1e-9, abs=1e-9 * np.abs(J.T @ f).max())
    G = J.T @ J
    assert np.abs(Jt.T @ Jt - G).max() <= 1e-12 * np.abs(G).max() * p
    for _ in range(5):
        s = rng.standard_normal(p) / np.linalg.norm(J, axis=0)
        full = np.linalg.norm(f + J @ s)
        assert np.linalg.norm(ft + Jt @ s) == pytest.approx(full, rel=1e-10)


def test_a_vanishing_column_is_compressed_exactly():
    # a parameter the data does not move (a zero column): the Cholesky factor fails, the SVD takes it
    rng = np.random.default_rng(3)
    J = np.asfortranarray(rng.standard_normal((500, 6)))
    J[:, 2] = 0.0
    f = rng.standard_normal(500)
    ft, Jt = compress(f, J)
    assert np.dot(ft, ft) == pytest.approx(np.dot(f, f), rel=1e-12)
    assert np.abs(Jt[:, 2]).max() < 1e-12
    s = rng.standard_normal(6)
    assert np.linalg.norm(ft + Jt @ s) == pytest.approx(np.linalg.norm(f + J @ s), rel=1e-10)


def test_a_non_finite_trial_stays_non_finite():
    J = np.asfortranarray(np.eye(4, 3))
    ft, Jt = compress(np.array([1.0, np.inf, 0.0, 0.0]), J)
    assert not np.all(np.isfinite(ft))  # scipy then shrinks its trust region, as on the full residual


def _exponentials(x, t):
    return x[0] * np.exp(-x[1] * t) + x[2] * np.exp(-x[3] * t)


def test_the_solver_takes_the_same_path_on_a_nonlinear_fit():
    # two decaying exponentials (a classic ill-conditioned fit): same solution, same evaluation count
    rng = np.random.default_rng(0)
    t = np.linspace(0.0, 10.0, 4000)
    y = _exponentials([2.0, 0.4, 1.0, 2.5], t) + 0.01 * rng.standard_normal(t.size)

    def fun(x):
        return _exponentials(x, t) - y

    def jac(x):
        e1, e2 = np.exp(-x[1] * t), np.exp(-x[3] * t)
        return np.asfortranarray(np.column_stack([e1, -x[0] * t * e1, e2, -x[2] * t * e2]))

    x0 = np.array([1.0, 1.0, 1.0, 3.0])
    bounds = (np.zeros(4), np.full(4, 10.0))
    plain = least_squares(fun, x0, jac=jac, bounds=bounds, method="trf", x_scale="jac", ftol=1e-10)
    comp = solve(Residuals(fun, jac, lambda x: (fun(x), jac(x))), x0, bounds=bounds, ftol=1e-10, max_nfev=None)
    assert comp.x == pytest.approx(plain.x, rel=1e-7)
    assert comp.nfev == plain.nfev and comp.njev == plain.njev
    assert comp.cost == pytest.approx(plain.cost, rel=1e-10)
    # what the fit reads back is the full problem's residual and Jacobian at the solution
    assert comp.fun.shape == (t.size,) and comp.jac.shape == (t.size, 4)
    assert comp.fun == pytest.approx(fun(comp.x), abs=1e-15)


def test_a_model_fit_is_the_plain_solvers_fit(monkeypatch):
    # B-spline with a lag and a slack, on a simulated damped sine: the fit through the compressed form ends where
    # scipy's on the full problem ends (the RMSE to 1e-9 relative, the same evaluations)
    d = axis_data([simulate(SimConfig.default(), "damped-sine", {}, seed=0)[0]], "ap")
    model = make_model("bspline", ["delay", "deadzone"], axis="ap").fit(d)

    compressed = base._solve

    def plain(fns, x0, bounds, max_nfev):  # what every fit ran before the compression: the full residual
        return compressed(fns._replace(both=None), x0, bounds, max_nfev)

    monkeypatch.setattr(base, "_solve", plain)
    ref = make_model("bspline", ["delay", "deadzone"], axis="ap").fit(d)
    assert model.fit_report_.rmse_deg == pytest.approx(ref.fit_report_.rmse_deg, rel=1e-9)
    assert model.fit_report_.nfev == ref.fit_report_.nfev
    for k, v in ref.params_.items():
        assert model.params_[k] == pytest.approx(v, rel=1e-6, abs=1e-9)
