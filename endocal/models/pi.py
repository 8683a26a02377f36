"""``pi``: the Prandtl–Ishlinskii model (play operators) and its analytic inverse.

Duodenoscope paper (Cheng et al., Machines 2024), section 2.3:

- eq. 5, play operator: ``Phi_i(t_0) = max(f(θ_0) - r_i, min(f(θ_0) + r_i, 0))``,
  ``Phi_i(t_k) = max(f(θ_k) - r_i, min(f(θ_k) + r_i, Phi_i(t_{k-1})))``;
- eq. 7, output: ``θ_out(t_k) = sum_{i=0}^{n} ω_i Phi_i[θ_in](t_k)`` (n + 1 operators, r_0 = 0);
- eq. 8, ``r_i = r·i`` and ``ω_i = ω·exp(-β r_i)`` (``weights="exponential"``);
- eq. 9, inverse: ``θ_in = f⁻¹( sum_i ω'_i Phi'_i[θ_out](t_k) )`` with plays of threshold r'_i on θ_out;
- eq. 11, ``ω'_0 = 1/ω_0``, ``ω'_i = -ω_i / ((ω_0+...+ω_i)(ω_0+...+ω_{i-1}))``,
  ``r'_i = sum_{j=0}^{i} ω_j (r_i - r_j)``, and the initial loading
  ``Phi'_i(t_0) = sum_{j=0}^{i} ω_j Phi_i(t_0) + sum_{j=i+1}^{n} ω_j Phi_j(t_0)``.

Without effects the envelope is linear (``f(θ) = θ``): the classic PI, with free
non-negative weights by default. With the ``envelope`` effect (eqs. 6, 10) it is the
paper's modified PI, with the exponential weights of eq. 8 by default (free weights
when the data clearly reject that law). Both weight laws have an analytic Jacobian
(:func:`~endocal.models._kernels.pi_exp_forward_jac`, ``pi_free_forward_jac``).
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np
from scipy.optimize import least_squares, lsq_linear

from endocal.errors import ModelError
from endocal.messages import Message
from endocal.models._kernels import (_EXP_MAX, pi_exp_forward_jac, pi_free_forward_jac, play_bank_forward,
                                     play_bank_states, play_bank_step)
from endocal.models.base import HysteresisModel
from endocal.models.data import HysteresisData, as_data
from endocal.models.effects.base import Effect
from endocal.models.params import Parameter, fmt_value

WEIGHT_CHOICES = ("auto", "free", "exponential")

#: ``weights="auto"`` with the envelope keeps the paper's exponential law unless free
#: weights fit the start data with a residual RMS this much smaller (a law that fits
#: leaves only noise, which free weights cannot reduce by more than ~sqrt(1 - n/N))
AUTO_RMS_RATIO = 1.1

#: fractions of the input's half range covered by the n plays, tried for the threshold step
_STEP_FRACTIONS = (0.05, 0.1, 0.2, 0.35, 0.5, 0.8)


def pi_thresholds(r: float, n_operators: int) -> np.ndarray:
    """``r_i = r·i`` for ``i = 0..n`` (duodenoscope paper, eq. 8)."""
    return r * np.arange(n_operators + 1, dtype=float)


def pi_exp_weights(w: float, beta: float, thresholds: np.ndarray) -> np.ndarray:
    """``ω_i = ω·exp(-β r_i)`` (duodenoscope paper, eq. 8)."""
    # exponent clipped where exp would overflow (only an optimiser's wild trial step gets there)
    return w * np.exp(np.clip(-beta * np.asarray(thresholds, dtype=float), -_EXP_MAX, _EXP_MAX))


def pi_inverse_parameters(thresholds: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Thresholds ``r'_i`` and weights ``ω'_i`` of the inverse PI (duodenoscope paper, eq. 11).

    Parameters
    ----------
    thresholds : ndarray (n+1,)
        Increasing forward thresholds, ``r_0 = 0``.
    weights : ndarray (n+1,)
        Forward weights; ``ω_0 > 0`` and all partial sums positive.

    Returns
    -------
    r_inv, w_inv : ndarray (n+1,)
    """
    w = np.asarray(weights, dtype=float)
    r = np.asarray(thresholds, dtype=float)
    csum = np.cumsum(w)
    if not w[0] > 0 or np.any(csum <= 0):
        raise ModelError(f"the PI model cannot be inverted: the weight of its linear operator is {w[0]:.3g} "
                         "(it must be positive, and every partial sum of weights too)")
    w_inv = np.empty_like(w)
    w_inv[0] = 1.0 / w[0]
    w_inv[1:] = -w[1:] / (csum[1:] * csum[:-1])
    # r'_i = sum_{j<=i} ω_j (r_i - r_j) = r_i * csum_i - sum_{j<=i} ω_j r_j
    r_inv = r * csum - np.cumsum(w * r)
    return r_inv, w_inv


def pi_inverse_initial_state(weights: np.ndarray, forward_state: np.ndarray) -> np.ndarray:
    """Initial loading of the inverse plays from the forward plays' state (duodenoscope paper, eq. 11).

    ``Phi'_i = sum_{j=0}^{i} ω_j Phi_i + sum_{j=i+1}^{n} ω_j Phi_j``.
    """
    w = np.asarray(weights, dtype=float)
    z = np.asarray(forward_state, dtype=float)
    csum = np.cumsum(w)
    tail = np.concatenate([np.cumsum((w * z)[::-1])[::-1][1:], [0.0]])
    return csum * z + tail


class _PIStepper:
    """One-sample analytic inverse: holds the inverse plays' state."""

    def __init__(self, r_inv, w_inv, offset):
        self.r_inv = np.ascontiguousarray(r_inv)
        self.w_inv = np.ascontiguousarray(w_inv)
        self.offset = float(offset)
        self.state = np.zeros_like(self.r_inv)

    def reset(self) -> None:
        self.state[:] = 0.0

    def prime(self, v_history: np.ndarray, thresholds: np.ndarray, weights: np.ndarray) -> None:
        """Load the inverse plays from the forward plays after ``v_history`` (eq. 11, initial loading)."""
        z = np.zeros_like(thresholds)
        for x in np.asarray(v_history, dtype=float):
            play_bank_step(float(x), thresholds, weights, z)
        self.state[:] = pi_inverse_initial_state(weights, z)

    def step(self, y: float) -> float:
        return play_bank_step(y - self.offset, self.r_inv, self.w_inv, self.state)


class PIModel(HysteresisModel):
    """Prandtl–Ishlinskii hysteresis model (duodenoscope paper, eqs. 5, 7, 8; inverse eqs. 9, 11).

    Parameters
    ----------
    n_operators : int
        ``n`` of the paper: operators ``i = 0..n`` (``n + 1`` plays, the first with
        threshold 0). Default 20, as in the paper.
    weights : {"auto", "free", "exponential"}
        ``free``: one non-negative weight per operator (``pi_w0``…``pi_wn``), thresholds
        ``r·i`` with ``r`` chosen from the data; ``exponential``: eq. 8 with fitted
        ``pi_r``, ``pi_w``, ``pi_beta``. ``auto``: with the envelope effect (the modified
        PI) the paper's exponential law, unless free weights fit the start data with a
        residual RMS more than ``AUTO_RMS_RATIO`` (1.1) times smaller (weights the law
        cannot shape, e.g. one large backlash at a middle threshold); free without the
        envelope. Resolved into ``structure_["weights"]`` (and ``threshold_step``).
    offset : {"auto", True, False}
        Add a constant ``pi_offset_deg`` to the output. ``auto``: only without the
        envelope (whose θ1 already places the neutral). Resolved into ``structure_``.
    effects, fixed, axis, out_of_range
        See :class:`~endocal.models.base.HysteresisModel`.

    Notes
    -----
    The inverse is analytic (eqs. 9-11): exact to rounding for any sequence the model
    can produce, no iteration.
    """

    base_name = "pi"
    inverse_kind: ClassVar[str] = "analytic (duodenoscope paper, eqs. 9-11)"

    def __init__(self, n_operators: int = 20, weights: str = "auto", offset="auto", *, effects=(),
                 fixed=None, axis=None, out_of_range="error"):
        self.n_operators = n_operators
        self.weights = weights
        self.offset = offset
        self.effects = effects
        self.fixed = fixed
        self.axis = axis
        self.out_of_range = out_of_range

    # ------------------------------------------------------------------ fit
    def _fit(self, data, meas_deg, *, t_s, extras, max_nfev, warm_start=None):
        """The fit, with ``weights="auto"`` checked against two straight branches.

        ``auto`` chooses the weights from start values (``_resolve_structure``); with the
        envelope, when the chosen weights' fit then ends worse than a straight line per
        direction of motion (a loop they cannot draw, or a local minimum: free weights on one
        real piezo cycle, 3.4 against 1.7), the other weights are fitted too and the better fit
        is kept; the fit report says when that is the other.
        """
        super()._fit(data, meas_deg, t_s=t_s, extras=extras, max_nfev=max_nfev, warm_start=warm_start)
        if self.weights != "auto" or not any(e.shapes_base() for e in self.effects_):
            return self
        d, _ = as_data(data, meas_deg, t_s=t_s, extras=extras)
        line = _branch_lines_rmse(d)
        first, chosen = self.fit_report_.rmse_deg, self.structure_["weights"]
        if not first > line:
            return self
        fitted_first = dict(self.__dict__)
        other = "free" if chosen == "exponential" else "exponential"
        self.weights = other
        try:
            super()._fit(data, meas_deg, t_s=t_s, extras=extras, max_nfev=max_nfev, warm_start=warm_start)
        finally:
            self.weights = "auto"
        if not self.fit_report_.rmse_deg < first:
            self.__dict__.update(fitted_first)
            return self
        words = {"exponential": "the paper's weight law (eq. 8)", "free": "free weights"}
        self.fit_report_.warnings.insert(0, Message(
            f"{words[chosen]} fitted worse ({first:.3g} deg RMSE) than a straight line per direction of motion "
            f"({line:.3g} deg): {words[other]} taken ({self.fit_report_.rmse_deg:.3g} deg)", "pi-weights"))
        return self

    # ------------------------------------------------------------------ structure
    def _resolve_structure(self, effects: list[Effect], v, data) -> dict:
        if not isinstance(self.n_operators, (int, np.integer)) or isinstance(self.n_operators, bool) \
                or not 1 <= self.n_operators <= 500:
            raise ModelError(f"n_operators must be an integer in 1..500, got {self.n_operators!r}")
        if self.weights not in WEIGHT_CHOICES:
            raise ModelError(f"weights must be one of {WEIGHT_CHOICES}, got {self.weights!r}")
        if self.offset not in ("auto", True, False):
            raise ModelError(f"offset must be 'auto', True or False, got {self.offset!r}")
        # an effect that shapes the loop (the envelope of the modified PI) resolves the "auto" settings
        shaped = next((sh for e in effects if (sh := e.shapes_base())), {})
        weights = self.weights if self.weights != "auto" else shaped.get("weights", "free")
        offset = self.offset if self.offset != "auto" else shaped.get("offset", True)
        st = {"n_operators": int(self.n_operators), "weights": weights, "offset": bool(offset)}
        # start values found while choosing are kept for _base_initial on the same command (it ran
        # both searches again: a fifth of a pi + envelope fit's time on the thesis's sine-set)
        if weights == "free" and v is not None:
            step = self._choose_step(v, data, st)
            st["threshold_step"] = step[0]
            self._start_memo = {"free": (v, data, step)}
        elif weights == "free":
            st["threshold_step"] = None
        elif self.weights == "auto" and v is not None:
            # The paper's law (eq. 8) ties all weights to three numbers. When the data put
            # the weight where no exponential can (e.g. one large backlash at a middle
            # threshold) the law leaves a clearly larger residual than free non-negative
            # weights on the same plays; those then describe the loop, with the same exact
            # inverse (eq. 11). Only a clear gap switches: free weights also fit noise and
            # other effects' signatures, which would blur the diagnosis of effects.
            free = self._choose_step(v, data, {**st, "weights": "free"})
            exp = self._exp_start(v, data, st)
            self._start_memo = {"free": (v, data, free), "exponential": (v, data, exp)}
            if not exp[0] <= AUTO_RMS_RATIO ** 2 * free[2]:
                st["weights"] = "free"
                st["threshold_step"] = free[0]
        return st

    def _base_names(self, structure: dict) -> list[str]:
        n = structure["n_operators"]
        names = ["r", "w", "beta"] if structure["weights"] == "exponential" else [f"w{i}" for i in range(n + 1)]
        if structure["offset"]:
            names.append("offset_deg")
        return names

    def _thresholds_weights(self, structure: dict, p: dict) -> tuple[np.ndarray, np.ndarray]:
        n = structure["n_operators"]
        if structure["weights"] == "exponential":
            r = pi_thresholds(p["r"], n)
            return r, pi_exp_weights(p["w"], p["beta"], r)
        step = structure.get("threshold_step")
        if step is None:
            raise ModelError("a PI model with free weights needs structure={'threshold_step': r} in set_parameters")
        return pi_thresholds(step, n), np.array([p[f"w{i}"] for i in range(n + 1)])

    # ------------------------------------------------------------------ start values
    def _choose_step(self, v: np.ndarray, data: HysteresisData, st: dict, steps=None) -> tuple[float, np.ndarray, float]:
        """Pick the threshold step r on a small grid by bounded linear least squares on free weights.

        The plays' span must cover the input's half range (larger thresholds never move);
        the grid tries several fractions of it. Returns ``(r, weights[, offset], cost)``.
        """
        n = st["n_operators"]
        y = data.meas_deg
        half_span = 0.5 * float(np.ptp(v))
        if half_span <= 0:
            raise ModelError("the command reaching the PI model is constant: nothing to fit")
        stride = max(1, v.size // 5000)
        best = None
        if steps is None:
            steps = [frac * half_span / n for frac in _STEP_FRACTIONS]
        for r in steps:
            phi = play_bank_states(v, pi_thresholds(r, n), data.run_starts)[::stride]
            A = phi if not st["offset"] else np.column_stack([phi, np.ones(phi.shape[0])])
            lb = np.zeros(A.shape[1])
            ub = np.full(A.shape[1], np.inf)
            if st["offset"]:
                lb[-1] = -np.inf
            sol = lsq_linear(A, y[::stride], bounds=(lb, ub), method="bvls")
            cost = float(np.sum((A @ sol.x - y[::stride]) ** 2))
            if best is None or cost < best[2]:
                best = (r, sol.x, cost)
        return best

    def _exp_start(self, v: np.ndarray, data: HysteresisData, st: dict) -> tuple[float, float, float, float, float]:
        """Start of the exponential law (eq. 8) on a grid of ``r`` and ``β``: ``(cost, r, β, ω, offset)``.

        For given ``r`` and ``β`` the output is linear in ``ω`` (and the offset), so ``ω``
        comes from one regression; the best pair with ``ω > 0`` is kept.
        """
        n = st["n_operators"]
        half_span = 0.5 * float(np.ptp(v))
        if half_span <= 0:
            raise ModelError("the command reaching the PI model is constant: nothing to fit")
        stride = max(1, v.size // 5000)
        y = data.meas_deg[::stride]
        vv = np.ascontiguousarray(v, dtype=float)
        best = None
        for frac in _STEP_FRACTIONS:
            r = frac * half_span / n
            ri = pi_thresholds(r, n)
            phi = play_bank_states(vv, ri, data.run_starts)[::stride]
            for f in (-0.5, 0.0, 0.3, 1.0, 3.0, 10.0):
                beta = 3.0 / (n * r) * f
                col = phi @ np.exp(-beta * ri)
                A = col[:, None] if not st["offset"] else np.column_stack([col, np.ones(col.size)])
                coef, *_ = np.linalg.lstsq(A, y, rcond=None)
                if not coef[0] > 0:
                    continue
                cost = float(np.sum((A @ coef - y) ** 2))
                if best is None or cost < best[0]:
                    best = (cost, float(r), float(beta), float(coef[0]), float(coef[1]) if st["offset"] else 0.0)
        if best is not None:
            best = self._refine_exp(vv, y, stride, data.run_starts, st, best)
        if best is None:
            r = 0.3 * half_span / n
            beta = 1.0 / (n * r)
            scale = float(np.ptp(data.meas_deg)) / max(2.0 * half_span, 1e-300)
            best = (np.inf, r, beta, scale / np.exp(-beta * pi_thresholds(r, n)).sum(),
                    float(np.mean(data.meas_deg)) if st["offset"] else 0.0)
        return best

    @staticmethod
    def _refine_exp(v: np.ndarray, y_dec: np.ndarray, stride: int, run_starts: np.ndarray, st: dict, best: tuple):
        """Polish a grid start of eq. 8 by a few Gauss-Newton steps on the decimated data (input fixed)."""
        n = st["n_operators"]
        # decimate the input after the plays would lose reversals: run the plays on the
        # full input, compare on the decimated samples
        G = np.zeros((v.size, 0))
        off = st["offset"]
        last: dict = {}  # the kernel's Jacobian at the point fun saw last: the solver asks for it there next

        def fun(x):
            yy, J = pi_exp_forward_jac(v, x[0], x[1], x[2], n, G, run_starts)
            last.update(x=np.array(x[:3]), J=J)
            return (yy[::stride] + (x[3] if off else 0.0)) - y_dec

        def jac(x):
            J = last["J"] if "x" in last and np.array_equal(last["x"], x[:3]) else \
                pi_exp_forward_jac(v, x[0], x[1], x[2], n, G, run_starts)[1]
            J = J[::stride]
            return np.column_stack([J, np.ones(J.shape[0])]) if off else J

        cost0, r0, b0, w0, o0 = best
        x0 = np.array([r0, w0, b0] + ([o0] if off else []))
        lo = np.array([1e-6 * r0, 1e-9 * w0, -np.inf] + ([-np.inf] if off else []))
        hi = np.full(x0.size, np.inf)
        try:
            with np.errstate(all="ignore"):
                res = least_squares(fun, x0, jac=jac, bounds=(lo, hi), method="trf", x_scale="jac", max_nfev=30)
        except (ValueError, FloatingPointError):
            return best
        cost = 2.0 * float(res.cost)
        if not (np.isfinite(cost) and cost < cost0):
            return best
        x = res.x
        return (cost, float(x[0]), float(x[2]), float(x[1]), float(x[3]) if off else 0.0)

    def _base_initial(self, structure: dict, v: np.ndarray, data: HysteresisData) -> list[Parameter]:
        n = structure["n_operators"]
        kind = structure["weights"]
        v_chosen, data_chosen, chosen = self.__dict__.pop("_start_memo", {}).get(kind, (None, None, None))
        same_step = kind != "free" or (chosen is not None and chosen[0] == structure["threshold_step"])
        if v_chosen is not v or data_chosen is not data or not same_step:
            chosen = None  # not found for this command: search again
        out: list[Parameter] = []
        if kind == "free":
            _, x, _ = chosen or self._choose_step(v, data, structure, [structure["threshold_step"]])
            w = x[: n + 1]
            scale = max(float(w.sum()), 1e-12)
            out += [Parameter(f"w{i}", float(w[i]), 1e-9 * scale if i == 0 else 0.0, np.inf) for i in range(n + 1)]
        else:
            _, r, beta, w0, off = chosen or self._exp_start(v, data, structure)
            out += [Parameter("r", r, 1e-12 * max(r, 1e-300), np.inf), Parameter("w", w0, 1e-12 * max(w0, 1e-300), np.inf),
                    Parameter("beta", beta)]
            if structure["offset"]:
                out.append(Parameter("offset_deg", off))
            return out
        if structure["offset"]:
            out.append(Parameter("offset_deg", float(x[-1])))
        return out

    # ------------------------------------------------------------------ forward / inverse
    def _base_forward(self, structure: dict, p: dict, v: np.ndarray, run_starts: np.ndarray) -> np.ndarray:
        r, w = self._thresholds_weights(structure, p)
        y = play_bank_forward(np.ascontiguousarray(v, dtype=float), r, w, run_starts)
        if structure["offset"]:
            y += p["offset_deg"]
        return y

    def _base_forward_jac(self, structure: dict, p: dict, v: np.ndarray, run_starts: np.ndarray, M: np.ndarray):
        """Output, its Jacobian w.r.t. the base parameters (n, n_base) and w.r.t. upstream ones (n, q).

        Analytic for both weight laws: eq. 8 via :func:`pi_exp_forward_jac`, free weights via
        :func:`pi_free_forward_jac`.
        """
        v = np.ascontiguousarray(v, dtype=float)
        if structure["weights"] != "exponential":
            r, w = self._thresholds_weights(structure, p)
            y, J = pi_free_forward_jac(v, r, w, np.ascontiguousarray(M), run_starts)
        else:
            y, J = pi_exp_forward_jac(v, p["r"], p["w"], p["beta"], structure["n_operators"], np.ascontiguousarray(M),
                                      run_starts)
        q = M.shape[1]
        Jb = J[:, q:]
        if structure["offset"]:
            y += p["offset_deg"]
            Jb = np.column_stack([Jb, np.ones(y.size)])
        return y, Jb, J[:, :q]

    def _base_inverse(self, structure: dict, p: dict, y: np.ndarray, run_starts: np.ndarray, v_range) -> np.ndarray:
        r, w = self._thresholds_weights(structure, p)
        r_inv, w_inv = pi_inverse_parameters(r, w)
        if structure["offset"]:
            y = y - p["offset_deg"]
        return play_bank_forward(np.ascontiguousarray(y, dtype=float), r_inv, w_inv, run_starts)

    def _base_stepper(self, structure: dict, p: dict, v_range):
        r, w = self._thresholds_weights(structure, p)
        r_inv, w_inv = pi_inverse_parameters(r, w)
        stepper = _PIStepper(r_inv, w_inv, p["offset_deg"] if structure["offset"] else 0.0)
        stepper.forward = (r, w)
        return stepper

    def thresholds_weights(self) -> tuple[np.ndarray, np.ndarray]:
        """Fitted thresholds ``r_i`` (input units of the plays) and weights ``ω_i``, each (n+1,)."""
        self._require_fitted()
        base_p, _ = self._grouped(self.params_)
        return self._thresholds_weights(self.structure_, base_p)

    # ------------------------------------------------------------------ printing
    def _base_describe(self, structure: dict, p: dict, se: dict, inner: str) -> str:
        n = structure["n_operators"]
        # the plays' thresholds r_i = r·i are in the drive's unit (deg, or mm for a linear drive)
        if structure["weights"] == "exponential":
            units = {"r": self.drive_unit_}
            parts = [f"{k}={fmt_value(p[k], se.get(k), units.get(k, ''))}" for k in ("r", "w", "beta")]
        else:
            parts = [f"r={fmt_value(structure['threshold_step'], unit=self.drive_unit_)} (fixed)"]
            parts += [f"w{i}={fmt_value(p[f'w{i}'], se.get(f'w{i}'))}" for i in range(n + 1) if p[f"w{i}"] != 0.0]
        out = f"PI{n}({inner}) [{', '.join(parts)}]"
        if structure["offset"] and p["offset_deg"] != 0.0:
            out += f" + {fmt_value(p['offset_deg'], se.get('offset_deg'), 'deg')}"
        return out

    def _gauge(self, effects: list[Effect]) -> dict[str, float]:
        # The play operator is homogeneous (Phi_{c r}[c x] = c Phi_r[x]): an effect's scale that
        # trades off exactly against r, ω and β is fixed by the effect's own gauge (the envelope's k1 = 1).
        for e in effects:
            if g := e.gauge("scale"):
                return g
        return {}


def _branch_lines_rmse(d: HysteresisData) -> float:
    """RMSE (deg) of a least-squares straight line per direction of motion (a still sample
    keeps the direction it had): the simplest loop, that any PI should beat."""
    du = np.diff(d.cmd_deg, prepend=d.cmd_deg[0])
    up = np.where(du > 0, 1.0, np.where(du < 0, 0.0, np.nan))
    idx = np.where(np.isnan(up), 0, np.arange(up.size))
    up = np.nan_to_num(up[np.maximum.accumulate(idx)], nan=1.0)  # carry the last direction forward
    A = np.column_stack([d.cmd_deg * up, up, d.cmd_deg * (1 - up), 1 - up])
    coef, *_ = np.linalg.lstsq(A, d.meas_deg, rcond=None)
    return float(np.sqrt(np.mean((A @ coef - d.meas_deg) ** 2)))
