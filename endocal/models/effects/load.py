"""``load:COLUMN``: friction that scales with a logged covariate (e.g. sheath curvature).

Capstan friction of a tendon in its sheath grows with the wrap angle of the sheath
(``T_out = T_in e^{μΘ}``): when the insertion tube curves more, the hysteresis widens.
Any extra numeric column ``x`` of the data (``sheath_wrap_deg``, a shape sensor, a
force) can be named; the extra backlash is a play on the command whose half width
follows the covariate linearly. Capstan friction is proportional to the tendon tension,
which grows with the bend away from neutral, so the extra play also grows with the knob
angle ``|u|`` (taken at the previous sample, which keeps the inverse explicit)::

    a_k = |u_{k-1}|
    w_k = max((c_up + d_up · a_k) · (x_k - x_lo) + (c_down + d_down · a_k) · (x_hi - x_k), 0)
    p_k = clip(p_{k-1}, u_k - w_k, u_k + w_k)
    v_k = (1 + g · (x_k - (x_lo + x_hi) / 2)) · p_k

``c_up`` (``load_<COLUMN>_up``) and ``c_down`` (``load_<COLUMN>_down``), both >= 0 (deg of
play per unit of ``x``), are fitted: friction growing with the covariate, or falling
with it; ``d_up``, ``d_down`` (``load_<COLUMN>_up_amp``, ``_down_amp``, >= 0, deg of play per
unit of ``x`` and per knob degree) are their tension-proportional shares. The same friction
also costs transmission: while the tendon slips, the distal tension is the knob tension
times ``e^{-mu Theta}`` (capstan), so a given bend needs more tendon stretch, i.e. more knob
travel, the more the sheath wraps; the gain ``g`` (``load_<COLUMN>_gain``, per unit of ``x``,
signed, bounded so the factor stays within 0.75..1.25 over the fitted range) scales the
command that reaches the base. Without it the play alone would have to mimic a flatter loop
by widening, which fits the covariate values it was fitted on but extrapolates wrongly
beyond them. ``x_lo``, ``x_hi`` (``load_<COLUMN>_lo``, ``_hi``) are the covariate's range in the
fitted data, held fixed: the base model carries the width at the least-friction end and the
gain at mid-range (centring keeps ``g`` from trading off against the base's own scale, which
made the fit crawl), the term what the covariate adds. (Two one-signed play gains rather than one signed
gain keep the model smooth where the sign would change, so the fit does not stall at zero.)
The inverse is exact for a logged covariate (the batch inverse needs the column); the
future covariate is unknown to a control loop, so the effect does not stream.

``load:friction:COLUMN`` (:class:`FrictionLoad`) is the same physics where the base is one friction element
(``dahl``, ``bouc-wen``): the condition scales the element's holding force, as ``rate:friction`` scales it with
speed. A play in front of such a base adds a second friction, whose lag opens as a dead band after each
reversal; a sheath that wraps more holds more of the same exponential instead. Written on the base's
friction bound (:func:`endocal.models._smooth_friction.scaled_friction_states`)::

    f_k = 1 + g · (x_k - (x_lo + x_hi) / 2)

``g`` (``load_friction_<COLUMN>_gain``, per unit of ``x``, signed) is bounded so that ``f`` stays within
0.05..1.95 over the fitted range: a holding force proportional to the wrap (Coulomb friction of a sheath
whose normal force grows with its curvature) is ``g = 2 / (x_lo + x_hi)``, inside the bound when ``x_lo``
is positive. Unlike ``rate:friction`` it has an inverse: the condition is logged, so the bound at each sample is
known ahead and each sample's step map stays monotone in the command (the batch inverse needs the column; it
does not stream, as ``load:COLUMN`` does not).
"""

from __future__ import annotations

import numpy as np

from endocal.errors import ModelError
from endocal.models._kernels import causal_play_inverse, varplay_forward_jac
from endocal.models.data import HysteresisData
from endocal.models.effects.base import InputEffect, from_form
from endocal.models.effects.requirements import condition_varying
from endocal.models.params import Parameter, fmt_value


class Load(InputEffect):
    """Covariate-scaled friction play (module docstring).

    Parameters
    ----------
    column : str
        The extra column of the data holding the covariate.
    """

    name = "load"
    order = 25
    cause = ("friction that scales with a logged load: sheath curvature (capstan, e^{mu*wrap}), "
             "tube shape or contact, widening the hysteresis when it grows")
    signature = ("loop width (residual at reversals, with the sign of the motion) that changes with the "
                 "covariate; residual correlated with the covariate times the direction of motion")
    protocol = "the same motion repeated while the covariate changes (e.g. different sheath curvatures)"
    units = {"up": "deg/unit", "down": "deg/unit", "up_amp": "1/unit", "down_amp": "1/unit", "gain": "1/unit",
             "lo": "", "hi": ""}
    usage = "load:COLUMN"
    needs = ("the named column, not constant",)
    open_bounds = ("lo", "hi")  # the covariate's range, set from the data and held fixed
    requires = (condition_varying("log the condition as a column, and record the same motion at two of its values, "
                                  "or change it during a run", to="fit"),)
    residual = ("load",)
    lookalikes = {}
    sim_section = "load"
    segment_order = 95  # a condition for the whole run, after every motion is planned

    def segment(self, design, n_half_cycles: int):
        """The same motion at the earlier value of the condition and at a new one (a condition of the run)."""
        return design.condition(n_half_cycles)

    def __init__(self, column: str | None = None):
        if not isinstance(column, str) or not column.strip():
            raise ModelError("load needs a column name: write load:COLUMN (e.g. load:sheath_wrap_deg)")
        self.column = column.strip()

    #: the form for a friction base: the condition scales its holding force (``load:friction:COLUMN``)
    variants = ("load:friction:COLUMN",)

    @classmethod
    def from_argument(cls, arg: str) -> Load:
        """``load:COLUMN``, or ``load:friction:COLUMN`` (a friction base's holding force scales with the column)."""
        form, sep, column = arg.partition(":")
        if sep and form.strip() == "friction":
            return FrictionLoad(column=column)
        return cls(column=arg)

    @classmethod
    def from_settings(cls, settings: dict) -> Load:
        """A model file's entry: ``{"form": "friction", "column": ...}`` for :class:`FrictionLoad`; files without a
        form are the play's."""
        return from_form("load", settings, {"play": cls, "friction": FrictionLoad}, "play")

    @property
    def prefix(self) -> str:
        return f"load_{self.column}"

    @property
    def label(self) -> str:
        return f"load:{self.column}"

    def settings(self) -> dict:
        return {"column": self.column}

    def check(self, data: HysteresisData) -> None:
        try:
            data.column(self.column)
        except ModelError as exc:
            raise ModelError(f"effect '{self.label}': {exc}") from None

    def check_fit(self, data: HysteresisData) -> None:
        """A fit needs the covariate to vary (a record at one condition, e.g. one sheath curvature, cannot show
        how it acts); a fitted model predicts at any value, a constant one included."""
        x = data.column(self.column)
        if np.ptp(x) == 0.0:
            raise ModelError(f"effect '{self.label}': column '{self.column}' is constant ({x[0]:g}) in the data, "
                             "so friction scaling with it cannot be identified; log a covariate that varies")

    def constants(self, data: HysteresisData) -> dict[str, float]:
        """Parameters set from the data and held fixed: the covariate's range."""
        x = data.column(self.column)
        return {"lo": float(x.min()), "hi": float(x.max())}

    def initial(self, data: HysteresisData, u: np.ndarray) -> list[Parameter]:
        plays = [Parameter(f"{self.prefix}_{k}", 0.0, 0.0, np.inf) for k in ("up", "down", "up_amp", "down_amp")]
        return plays + self._condition_params(self.constants(data), 0.25)

    def _condition_params(self, c: dict, spread: float) -> list[Parameter]:
        """The gain ``g`` of a factor ``1 + g (x - (lo + hi) / 2)``, bounded so that the factor stays within
        ``1 +- spread`` over the fitted range, and the range (``lo``, ``hi``), held fixed."""
        g_max = spread / (0.5 * (c["hi"] - c["lo"]))
        return [Parameter(f"{self.prefix}_gain", 0.0, -g_max, g_max),
                Parameter(f"{self.prefix}_lo", c["lo"]), Parameter(f"{self.prefix}_hi", c["hi"])]

    def start_candidates(self, data: HysteresisData, u: np.ndarray) -> list[dict]:
        """Start values tried before the fit (the best is kept): extra play of 1 % of the command span on one side."""
        x = data.column(self.column)
        scale = float(np.ptp(u)) / float(np.ptp(x))
        amp = scale / max(float(np.max(np.abs(u))), 1e-9)
        zero = {"up": 0.0, "down": 0.0, "up_amp": 0.0, "down_amp": 0.0, "gain": 0.0}
        return [zero] + [{**zero, side: f * s} for side, s in (("up", scale), ("down", scale), ("up_amp", amp),
                                                                ("down_amp", amp)) for f in (0.01,)]

    def _parts(self, p: dict, data: HysteresisData) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Width at zero knob angle ``w0`` and its growth per knob degree ``w1`` (n,), and ``x - lo``, ``hi - x``."""
        x = data.column(self.column)
        above, below = x - p["lo"], p["hi"] - x
        w0 = p["up"] * above + p["down"] * below
        w1 = p.get("up_amp", 0.0) * above + p.get("down_amp", 0.0) * below
        return w0, w1, above, below

    def apply(self, p: dict, u: np.ndarray, data: HysteresisData) -> np.ndarray:
        v, _, _ = self.apply_jac(p, u, data, np.zeros((len(u), 0)))
        return v

    def apply_jac(self, p: dict, u: np.ndarray, data: HysteresisData, M: np.ndarray):
        w0, w1, above, below = self._parts(p, data)
        u = np.asarray(u, dtype=float)
        M = np.asarray(M, dtype=float)
        q = M.shape[1]
        prev = np.concatenate([u[:1], u[:-1]])
        Mprev = np.concatenate([M[:1], M[:-1]])
        a = np.abs(prev)
        raw = w0 + w1 * a
        w = np.maximum(raw, 0.0)
        on = (raw >= 0.0).astype(float)  # the width is clipped at zero only for covariates beyond the fitted range
        zeros = np.zeros((w.size, 3))  # gain: applied after the play; lo and hi are held fixed
        Wg = np.column_stack([(on * w1 * np.sign(prev))[:, None] * Mprev, on * above, on * below,
                              on * above * a, on * below * a, zeros])
        play, J = varplay_forward_jac(np.ascontiguousarray(u, dtype=float), w, Wg, np.ascontiguousarray(M, dtype=float),
                                      data.run_starts)
        centred = above - 0.5 * (p["hi"] - p["lo"])
        f = 1.0 + p.get("gain", 0.0) * centred
        J = J * f[:, None]
        J[:, q + 4] = play * centred
        return play * f, J[:, q:], J[:, :q]

    def invert(self, p: dict, v: np.ndarray, data: HysteresisData) -> np.ndarray:
        w0, w1, above, _ = self._parts(p, data)
        play = np.asarray(v, dtype=float) / (1.0 + p.get("gain", 0.0) * (above - 0.5 * (p["hi"] - p["lo"])))
        return causal_play_inverse(np.ascontiguousarray(play), w0, w1, data.run_starts)

    def wrap(self, inner: str) -> str:
        return f"loadplay({inner})"

    def describe(self, p: dict, se: dict) -> str:
        x = self.column
        def gain(side):
            c = fmt_value(p[side], se.get(side), "deg")
            d = p.get(f"{side}_amp", 0.0)
            return c if d == 0.0 else f"({c} + {fmt_value(d, se.get(f'{side}_amp'), '')}*|u|)"

        play = f"loadplay = load[up={gain('up')}*({x}-{p['lo']:.4g}), down={gain('down')}*({p['hi']:.4g}-{x})"
        if p.get("gain", 0.0) != 0.0:
            play += f", gain=1 + {fmt_value(p['gain'], se.get('gain'), '')}*({x}-{0.5 * (p['lo'] + p['hi']):.4g})"
        return play + "]"

    def is_zero(self, p: dict) -> bool:
        return all(p.get(k, 0.0) == 0.0 for k in ("up", "down", "up_amp", "down_amp", "gain"))


class FrictionLoad(Load):
    """``load:friction:COLUMN``: a friction base's holding force scales with a logged condition (module docstring).

    Fitted parameter (prefix ``load_friction_<COLUMN>_``): ``gain`` (per unit of the column), the relative change
    of the holding force per unit of the condition about the fitted range's middle; ``lo``, ``hi`` the range, held
    fixed. The command passes unchanged: the base scales its friction (:meth:`friction_factor`); a base without a
    friction state refuses it.
    """

    form = "friction"
    usage = "load:friction:COLUMN"
    needs_friction_state = "it scales that state's holding force"
    units = {"gain": "1/unit", "lo": "", "hi": ""}

    @property
    def prefix(self) -> str:
        return f"load_friction_{self.column}"

    @property
    def label(self) -> str:
        return f"load:friction:{self.column}"

    def settings(self) -> dict:
        return {"form": self.form, "column": self.column}

    def initial(self, data: HysteresisData, u: np.ndarray) -> list[Parameter]:
        return self._condition_params(self.constants(data), 0.95)  # the bound within 0.05..1.95 of its own

    def start_candidates(self, data: HysteresisData, u: np.ndarray) -> list[dict]:
        """Start values tried before the fit (the best is kept): the force constant, or growing or falling by a
        third over the fitted range."""
        c = self.constants(data)
        third = (1.0 / 3.0) / (c["hi"] - c["lo"])
        return [{"gain": 0.0}, {"gain": third}, {"gain": -third}]

    def friction_factor(self, p: dict, v: np.ndarray | None, data: HysteresisData) -> np.ndarray:
        """The base's friction bound, ``1 + g (x - (x_lo + x_hi) / 2)`` times its own, floored at 1e-3 for a
        condition beyond the fitted range."""
        x = data.column(self.column)
        return np.maximum(1.0 + p["gain"] * (x - 0.5 * (p["lo"] + p["hi"])), 1e-3)

    def apply(self, p: dict, u: np.ndarray, data: HysteresisData) -> np.ndarray:
        return np.asarray(u, dtype=float)

    apply_jac = None  # the base's friction carries the term: the fit differentiates numerically

    def invert(self, p: dict, v: np.ndarray, data: HysteresisData) -> np.ndarray:
        """The command passes unchanged: the base's inverse carries the scaled bound (``friction_factor``)."""
        return np.asarray(v, dtype=float)

    def wrap(self, inner: str) -> str:
        return inner

    def describe(self, p: dict, se: dict) -> str:
        mid = 0.5 * (p["lo"] + p["hi"])
        return (f"friction x (1 + g ({self.column} - {mid:.4g})): load:friction:{self.column}"
                f"[g={fmt_value(p['gain'], se.get('gain'), '')}]")

    def is_zero(self, p: dict) -> bool:
        return p["gain"] == 0.0
