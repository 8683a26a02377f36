"""``coupling``: the other bending axis moving this one.

Both bending axes bend one section, so the tip sits where the *sum* of their bends puts
it, and the tracker reads each axis's angle from that one tip position (thesis eq. 1).
In eq.-1 coordinates a constant-curvature arc of bending vector ``b`` (rad) has its tip at
``p ∝ ((1 - cos α)/α² b, sin α/α)``, ``α = |b|``; with the half-bend ``h = b/2`` (one
axis alone reads exactly half its bend) this axis reads::

    θ = atan2(h_y · sin|h| / |h|,  cos|h|)            (thesis eq. 1 on a constant-curvature arc)

so the other axis's bend ``h_x`` both enters through the magnitude ``|h|`` (the angle
reads larger when the other axis bends: ``θ ≈ h_y (1 + |h|²/3)``) and, where the bending
planes deviate from their nominal directions (duodenoscope paper, sec. 3.2: 2-20 deg,
different on each half-plane), is projected onto this axis's plane and this axis's own
bend onto the other's. The two half-bends, from this axis's output ``y`` (the base
model's, deg) and the other axis's position ``x`` (deg)::

    B   = g · x + κ · y              the other half-bend. g: per deg of x; κ (``mutual``): per
                                     deg of this one, whose bend shifts the other's tendon
                                     anchors (tendon-hole offsets), so the other bend moves with
                                     this one even with its knob still
    h_y = y + a · B + b · |B|        a, b: the other bend projected through its deviated
                                     half-planes (odd and even part), and the shift of this
                                     axis's tendon anchors by the other bend
    h_x = B + c± · y                 c±: this axis's own deviation on its + / - half-plane
                                     (c = -tan(deviation))

Model files written before the mutual shift (``"mutual": false``, or no ``mutual`` in their settings) shift this
axis's anchors by the other knob's drive (``a · x + b · |x|``) and have no ``κ``; they load so, as fitted. On the
Bouc-Wen closed loop's `coupling` case (each bend shifts the other's anchors) the last record is a speed ladder
of this knob with the other still, on which the plant's other half-bend spans 16 deg at -0.18 deg per deg of this
one. Fitted on the loop's records (two-knob and ladder), scored on the ladder against its noise (0.362 deg): the
drive of the files before, 0.702 deg (1.94x); with the mutual shift, 0.419 deg (1.16x, ``κ`` fitted at -0.163);
the plant's true other half-bend in place of ``B``, 0.401 deg (2026-12-07, a scratch fit of the loop's records).
The shift is on by default on a base without return-point memory (``dahl``, ``bouc-wen``) and off on a bank of
plays (``linear``, ``bspline``, ``pi``), as measured, not as derived: the capstan plant shifts its anchors by the
other bend too (endocal/sim/tendon.py), and there the shift predicts records its fit never saw 2-4 % better, but on
validate's rolling-origin folds of its circle record (tests/test_validation_hidden.py, `bspline`) it loses the
last block, where the record spirals back to rest through the circle's interior, a region no fold was fitted on:
1.08 against 0.81 deg there, so 0.620 against 0.541 deg over the five blocks, while it wins each block on the
circle (tests/test_models_coupling_lag.py, 2026-12-07). So a shift fitted on one region of the two knobs' travel
can extrapolate worse than the drive does; the bank-of-plays bases keep the drive their closed loops were validated
with, and on the Bouc-Wen plant the shift's gain (1.94x to 1.16x) outweighs that risk.

The other bend lags its knob as this one does: its tendons slide through their own sheath
against friction. ``x`` is therefore the other knob's position through a play of half-width
``λ`` (``lag_deg``, deg of the other knob; the other bend's dead band and backlash, the
first-order share of its hysteresis)::

    x_k = min(max(x_{k-1}, X_k - λ), X_k + λ),   x_0 = X_0   (per run; X: the column)

On the Lissajous records of the closed loops (the simulator, both knobs at 60 deg) the lag
took the validation error from 0.80 to 0.51 deg with Bouc-Wen friction and from 0.65 to
0.44 deg with capstan friction, the noise being 0.33 deg (2026-11-28): without it the two
bends' loops are fitted with one bend's.

The other bend's tendons slide against the friction this axis's base models, so the lag follows
the base's memory rule. On a base with return-point memory (``linear``, ``bspline``, ``pi``: a bank
of plays) it is the play above. On a base without (``dahl``, ``bouc-wen``) it is the play's smooth
counterpart, the stretch ``s = X - x = λ w`` of a Bouc-Wen element (n = 1, saturation ``λ``, shape
``σ`` >= 1/2, ``lag_sigma``; :func:`~endocal.models._smooth_friction.smooth_lag`): right after a reversal
the stretch unwinds one to one (the bend holds), then winds up the other way along an exponential of
length ``2 σ λ``. The model file names the rule (``lag``: ``play``, ``smooth``, or ``none`` for files
written before the lag).

Those tendons also run through the same sheath, so what scales the base's friction scales theirs: with
``rate:friction`` or ``load:friction:COLUMN`` in the model the smooth lag's bound is ``λ f``, ``f`` their factor
at the other knob (its speed, the shared condition; :attr:`OutputFilter.other_friction`), held as
:func:`~endocal.models._smooth_friction.scaled_friction_states` holds a changing bound. On the two-knob records
at two sheath wraps of the Bouc-Wen closed loop (dahl, delay, envelope:tip, coupling, load:friction), in-sample,
the bound held constant → scaled: 0.448 → 0.409 deg in the control, 0.526 → 0.401 with friction growing with
speed (and rate:friction), the noise 0.37-0.38 deg; the other bend read from the plant's truth instead, 0.394 and
0.396 (2026-12-07).

Those tendons also have the slack this axis's have: where the model carries a dead band (``deadzone`` in any
form) the other bend's drive has one too, of half-width ``w`` (``band_deg``, deg of the other knob past the lag;
the model file says ``"band": true``)::

    x_b = x - clip(x, -w, w)       (flat inside the band: both of the other bend's tendons slack)

On the same records with the plant's slack (`deadzone` hidden), in-sample: 0.412 → 0.374 deg, the noise 0.359,
the plant's true other bend 0.368 (2026-12-07).

A base sensor that slips turns the whole frame eq. 1 reads. This axis's share of the turn adds to its angle
(``drift``); the other axis's turns the tip about this axis's direction, which moves this angle in proportion to
the other bend. Where the model carries ``drift``, eq. 1's tip is turned by ``d = s · t`` (``slip_dps``, deg/s,
``t`` from the run's start as ``drift`` counts it; the model file says ``"slip": true``)::

    θ = atan2(h_y sinc|h|,  cos|h| cos d - h_x sinc|h| sin d)

On the Bouc-Wen closed loop's `drift` case (the simulator's sensor slips by 3 and -1 deg/min about the two axes)
the loop ended at 1.21x its last record's noise without the turn; with the other axis's slip set to 0 in the
plant, at 1.13x (2026-12-07).

Parameters ``coupling_linear`` (``a``), ``coupling_abs`` (``b``), ``coupling_gain``
(``g``), ``coupling_tilt_pos`` / ``coupling_tilt_neg`` (``c+`` / ``c-``), ``coupling_lag_deg``
(``λ``), for the smooth lag ``coupling_lag_sigma`` (``σ``), with a dead band ``coupling_band_deg`` (``w``),
with the frame's slip ``coupling_slip_dps`` (``s``), and ``coupling_mutual`` (``κ``). All zero is no coupling
(``θ = y``). ``X`` is the extra column ``other_cmd_deg``
(the other knob's command, deg) unless another is named: ``coupling:ml_meas_deg`` uses the
other axis's measured angle (then ``g ≈ 1`` and ``λ ≈ 0``). A model file written before the
lag (its ``coupling`` settings without ``lag`` or ``other_lag``) loads without it, as it was fitted.

The term acts on the base's output (an :class:`OutputFilter`): the magnification
multiplies it. The anchor shift is, physically, an input of this axis's tendons (it
passes through their friction); ``a · B`` is its first-order share on the output.
``θ`` rises monotonically with ``y`` (with the mutual shift, for values as fitted: a, b and κ are
tenths, so ``1 + (a ± b) κ`` stays near 1), so the inverse solves one scalar equation per sample
exactly (safeguarded Newton, bisection where a step leaves its bracket); it needs the other
axis's logged (or planned) trajectory and therefore does not stream.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from endocal.errors import ModelError
from endocal.models._kernels import varplay_forward_jac
from endocal.models._smooth_friction import smooth_lag
from endocal.models.data import OTHER_CMD, HysteresisData
from endocal.models.effects.base import OutputFilter
from endocal.models.effects.requirements import other_knob_moving
from endocal.models.params import Parameter

_D2R = math.pi / 180.0


@njit(cache=True)
def _eq1(u, z, cd, sd):
    """Thesis eq. 1 on a constant-curvature arc: ``atan2(u sinc r, cos r cos d - z sinc r sin d)``, ``r = hypot(u,
    z)``, with the tip turned by ``d`` about this axis's direction (the other axis's frame slip; ``cd, sd = cos d,
    sin d``, 1 and 0 without).

    ``u``, ``z``: half-bend in and across this axis's plane (rad). Returns the angle (rad) and its derivatives by
    ``u``, ``z`` and ``d``; smooth at ``r = 0`` (series of ``sinc``).
    """
    r2 = u * u + z * z
    r = math.sqrt(r2)
    if r < 1e-4:
        s = 1.0 - r2 / 6.0
        ds_r = -1.0 / 3.0 + r2 / 30.0  # (d sinc / dr) / r
    else:
        s = math.sin(r) / r
        ds_r = (r * math.cos(r) - math.sin(r)) / (r2 * r)
    a = u * s
    cr = math.cos(r)
    c = cr * cd - z * s * sd
    den = a * a + c * c
    # d(cos r)/du = -sinc(r) u, d(cos r)/dz = -sinc(r) z; d(sinc r)/du = ds_r u, d(sinc r)/dz = ds_r z
    a_u = s + u * u * ds_r
    a_z = u * z * ds_r
    c_u = -s * u * cd - z * u * ds_r * sd
    c_z = -s * z * cd - (s + z * z * ds_r) * sd
    c_d = -cr * sd - z * s * cd
    return math.atan2(a, c), (c * a_u - a * c_u) / den, (c * a_z - a * c_z) / den, -a * c_d / den


@njit(cache=True)
def coupling_forward(y_deg, x_deg, a, b, g, c_pos, c_neg, kappa, mutual, dx_lag, slip_deg, t_run_s):
    """Measured angle (deg) from the base output ``y`` and the other axis's drive ``x`` (deg).

    ``kappa``: the other half-bend per deg of this one (the shift of its anchors by this bend); with ``mutual``
    the other half-bend ``B = g x + kappa y``, not ``x``, shifts this axis's anchors (module docstring).
    ``dx_lag`` (n, m): the derivatives of ``x`` by the lag's and the band's m parameters (:meth:`Coupling._x`).
    ``slip_deg`` (n,): the other axis's frame slip at each sample (deg; zeros without), ``t_run_s`` (n,) its time
    (its derivative by the slip rate). Returns ``theta`` (n,), ``d theta / d y`` (n,) and the derivatives (n, 7 + m)
    by ``(a, b, g, c_pos, c_neg)``, the drive's m parameters, the slip rate and ``kappa``.
    """
    n = y_deg.shape[0]
    m = dx_lag.shape[1]
    out = np.empty(n)
    dy = np.empty(n)
    own = np.zeros((n, 7 + m))
    for k in range(n):
        y = y_deg[k] * _D2R
        x = x_deg[k] * _D2R
        other = g * x + kappa * y  # the other half-bend
        # what shifts this axis's anchors: the other half-bend, or (files before the mutual shift) its drive
        s_deg = (g * x_deg[k] + kappa * y_deg[k]) if mutual else x_deg[k]
        s = s_deg * _D2R
        c = c_pos if y >= 0.0 else c_neg
        d = slip_deg[k] * _D2R
        f, f_u, f_z, f_d = _eq1(y + a * s + b * abs(s), other + c * y, math.cos(d), math.sin(d))
        out[k] = f / _D2R
        sgn = 1.0 if s_deg > 0.0 else (-1.0 if s_deg < 0.0 else 0.0)
        ab = a + b * sgn  # d(a s + b |s|) / ds
        ds_dy = kappa if mutual else 0.0
        ds_dx = g if mutual else 1.0
        dy[k] = f_u * (1.0 + ab * ds_dy) + f_z * (kappa + c)
        own[k, 0] = f_u * s_deg
        own[k, 1] = f_u * abs(s_deg)
        own[k, 2] = (f_u * ab if mutual else 0.0) * x_deg[k] + f_z * x_deg[k]
        own[k, 3 if y >= 0.0 else 4] = f_z * y_deg[k]
        dth_dx = f_u * ab * ds_dx + f_z * g
        for j in range(m):
            own[k, 5 + j] = dth_dx * dx_lag[k, j]
        own[k, 5 + m] = f_d * t_run_s[k]
        own[k, 6 + m] = ((f_u * ab) if mutual else 0.0) * y_deg[k] + f_z * y_deg[k]
    return out, dy, own


@njit(cache=True)
def coupling_inverse(theta_deg, x_deg, a, b, g, c_pos, c_neg, kappa, mutual, slip_deg):
    """Base output ``y`` (deg) whose coupled angle is ``theta`` (deg): safeguarded Newton per sample."""
    n = theta_deg.shape[0]
    out = np.empty(n)
    ds_dy = kappa if mutual else 0.0
    for k in range(n):
        th = theta_deg[k] * _D2R
        x = x_deg[k] * _D2R
        s0 = g * x if mutual else x  # the anchors' shift at y = 0; it grows by ds_dy per rad of y
        d = slip_deg[k] * _D2R
        cd = math.cos(d)
        sd = math.sin(d)
        lo = -0.5 * math.pi
        hi = 0.5 * math.pi
        y = min(max(th - a * s0 - b * abs(s0), lo), hi)
        for _ in range(200):
            c = c_pos if y >= 0.0 else c_neg
            s = s0 + ds_dy * y
            f, f_u, f_z, _f_d = _eq1(y + a * s + b * abs(s), g * x + kappa * y + c * y, cd, sd)
            r = f - th
            if r > 0.0:
                hi = y
            else:
                lo = y
            if r == 0.0 or hi - lo <= 1e-15:
                break
            sgn = 1.0 if s > 0.0 else (-1.0 if s < 0.0 else 0.0)
            dd = f_u * (1.0 + (a + b * sgn) * ds_dy) + f_z * (kappa + c)
            yn = y - r / dd if dd > 0.0 else 0.5 * (lo + hi)
            if not lo < yn < hi:
                yn = 0.5 * (lo + hi)
            if abs(yn - y) <= 1e-15:
                y = yn
                break
            y = yn
        out[k] = y / _D2R
    return out


#: Fade in and out of the both-knob figure of ``--next`` (s).
FADE_S = 5.0
#: The other bend's lag behind its knob: a play, its smooth counterpart, or none (files written before the lag).
LAG_RULES = ("play", "smooth", "none")
#: Bounds and start of the smooth lag's shape ``σ`` (Bouc-Wen's, >= 1/2): from one-to-one unwinding until slack
#: (1/2) to an exponential ten times the saturation long (5); the fit starts at 1, an exponential twice the
#: saturation long
LAG_SIGMA = (0.5, 1.0, 5.0)
#: Start of the other bend's lag (deg of its knob), inside a tendon drive's play (on the closed loops'
#: Lissajous records of the simulator it was fitted at 4.3 deg with capstan friction, 9.6 with Bouc-Wen).
LAG_START_DEG = 2.0
#: Start of the other bend's dead band (half-width, deg of its knob past the lag): the simulator's default slack
#: (1.5 mm on a 10 mm pulley) is a band of 4.3 deg each side.
BAND_START_DEG = 2.0


class Coupling(OutputFilter):
    """Cross-coupling from the other axis through the shared tip position (module docstring).

    Parameters
    ----------
    column : str
        Extra column holding the other axis's position (deg); default ``other_cmd_deg``.

    Fitted parameters (prefix ``coupling_``): ``linear``, ``abs`` (deg of this axis's
    half-bend per deg of the other's half-bend; per deg of its position without ``mutual``), ``gain`` (the
    other axis's half-bend per deg of its position), ``tilt_pos``, ``tilt_neg`` (out-of-plane share of this axis's
    own bend on its + / - half-plane), ``lag_deg`` (the other bend's play, or its smooth
    lag's saturation, deg of the other knob; not with ``lag="none"``), ``lag_sigma`` (the smooth
    lag's shape), ``band_deg`` (the other bend's dead band, with ``band``), ``slip_dps`` (the
    other axis's frame slip, with ``slip``), ``mutual`` (the other half-bend per deg of this one, with ``mutual``).
    lag : {"play", "smooth", "none"}, optional
        The other bend's lag behind its knob: a play, its smooth counterpart, or none (the form of
        model files written before the lag: five parameters, ``x`` the column itself). By default it
        follows the base's memory rule (module docstring): ``play`` on a base with return-point
        memory, ``smooth`` on one without.
    band : bool, optional
        Whether the other bend's drive has a dead band (``band_deg``). By default it does where the model
        carries ``deadzone`` in any form.
    slip : bool, optional
        Whether eq. 1's tip is turned by the other axis's frame slip (``slip_dps``). By default it is where
        the model carries ``drift``.
    mutual : bool, optional
        Whether this bend shifts the other's anchors (``mutual``) and the other bend, not its knob's drive, shifts
        this axis's. By default it does on a base without return-point memory (module docstring); model files
        written before it load without.
    """

    name = "coupling"
    order = 20  # eq. 1 reads the tip where the (relaxed) bends put it: after creep
    cause = ("cross-coupling: both axes bend one section, and eq. 1 reads each angle from the one tip position "
             "(magnified by the other bend, projected through deviated bending planes); the other bend also "
             "shifts this axis's tendon anchors (tendon-hole offsets)")
    signature = ("residual that follows the other axis's position (odd or even in it) and grows with this "
                 "axis's angle, not this axis's command alone")
    protocol = "move the other knob alone, or both knobs at different frequencies (circle, lissajous)"
    units = {"linear": "deg/deg", "abs": "deg/deg", "gain": "deg/deg", "tilt_pos": "", "tilt_neg": "", "lag_deg": "deg",
             "lag_sigma": "", "band_deg": "deg", "slip_dps": "deg/s", "mutual": "deg/deg"}
    usage = "coupling[:COLUMN]"
    needs = ("other_cmd_deg (or the named column)",)
    requires = (other_knob_moving(),)
    residual = ("other command", "regime:other axis")
    lookalikes = {}
    sim_section = "coupling"

    def segment(self, design, n_half_cycles: int):
        """Both knobs at once (a Lissajous figure): the other bend moves this one only when it moves."""
        if design.other is None:
            return design.cannot(f"probe '{design.probe}' has one knob, so nothing can couple")
        c = design.centre
        # one figure centre on both knobs: inside this axis's range and the other knob's limits
        amp = min(design.amplitude, design.other_hi - c, c - design.other_lo)
        if amp < design.min_amplitude_deg:
            return design.cannot(f"the other knob's limits leave no room about this axis's centre {c:.3g} deg")
        f1 = min(design.f_typ_hz, design.cap_hz(amp, start=False) / 1.5)
        duration = math.ceil(n_half_cycles / (2.0 * f1)) + 2.0 * FADE_S
        k = design.add("lissajous", axes=[design.axis, design.other], amplitude_deg=amp, offset_deg=c,
                       frequencies_hz=[round(f1, 6), round(1.5 * f1, 6)], duration_s=float(duration), fade_s=FADE_S)
        return design.planned(k, int(2 * f1 * (duration - 2 * FADE_S)))

    def __init__(self, column: str = OTHER_CMD, lag: str | None = None, band: bool | None = None,
                 slip: bool | None = None, mutual: bool | None = None):
        if not isinstance(column, str) or not column:
            raise ModelError(f"coupling: column must be a column name, got {column!r}")
        if lag is not None and lag not in LAG_RULES:
            raise ModelError(f"coupling: lag must be one of {', '.join(LAG_RULES)}, got {lag!r}")
        for name, value in (("band", band), ("slip", slip), ("mutual", mutual)):
            if value is not None and not isinstance(value, bool):
                raise ModelError(f"coupling: {name} must be true or false, got {value!r}")
        self.column = column
        self.lag = lag
        self.band = band
        self.slip = slip
        self.mutual = mutual

    @classmethod
    def from_settings(cls, settings: dict) -> Coupling:
        """A model file's entry. Files written before the smooth lag say ``other_lag`` (true: the play); files
        written before the lag say neither and keep their five parameters; files written before the other bend's
        dead band, the frame's slip or the mutual shift do not say ``band``, ``slip`` or ``mutual`` and load without
        them."""
        settings = {"band": False, "slip": False, "mutual": False, **settings}
        if "lag" not in settings:
            old = settings.pop("other_lag", False)
            if not isinstance(old, bool):
                raise ModelError(f"coupling: other_lag must be true or false, got {old!r}")
            settings["lag"] = "play" if old else "none"
        return cls(**settings)

    def for_model(self, model, effects) -> Coupling:
        """The other bend's drive as the model has this axis's (module docstring), where the effect does not name
        it: the lag rule the base's (a play on a base with return-point memory, else smooth), a dead band where
        ``effects`` carry one (``deadzone`` in any form), the other axis's frame slip where they carry a drift, and the
        mutual shift on a base without return-point memory (module docstring)."""
        lag = self.lag if self.lag is not None else ("play" if model.return_point_memory else "smooth")
        band = self.band if self.band is not None else any(e.name == "deadzone" for e in effects)
        slip = self.slip if self.slip is not None else any(e.name == "drift" for e in effects)
        mutual = self.mutual if self.mutual is not None else not model.return_point_memory
        if (lag, band, slip, mutual) == (self.lag, self.band, self.slip, self.mutual):
            return self
        return type(self)(self.column, lag, band, slip, mutual)

    @property
    def other_lag(self) -> bool:
        """Whether the other bend's lag is fitted (``lag_deg``)."""
        return self.lag != "none"

    @classmethod
    def from_argument(cls, arg: str) -> Coupling:
        """``coupling:COLUMN`` names the column with the other axis's position."""
        return cls(column=arg.strip())

    @property
    def label(self) -> str:
        return self.name if self.column == OTHER_CMD else f"{self.name}:{self.column}"

    def settings(self) -> dict:
        return {"column": self.column, "lag": self.lag or "play", "band": bool(self.band), "slip": bool(self.slip),
                "mutual": bool(self.mutual)}

    def param_names(self) -> list[str]:
        lag = {"none": (), "smooth": ("lag_deg", "lag_sigma")}.get(self.lag or "play", ("lag_deg",))
        return [k for k in self.units if (not k.startswith("lag_") or k in lag) and (k != "band_deg" or self.band)
                and (k != "slip_dps" or self.slip) and (k != "mutual" or self.mutual)]

    def check(self, data: HysteresisData) -> None:
        try:
            data.column(self.column)
        except ModelError as exc:
            raise ModelError(f"effect '{self.label}' needs the other axis's position: {exc}") from None
        if self.slip:
            data.require_time(f"effect '{self.label}' (the other axis's frame slip)")

    def initial(self, data: HysteresisData, u: np.ndarray) -> list[Parameter]:
        # Bounds: projections and deviations below 45 deg (|a|, |b|, |c| < 1); the other
        # half-bend up to 3 deg per deg of x; its lag below a quarter of the column's span
        # (a play wider than that leaves the other bend still for most of a sweep).
        own = [Parameter(f"{self.prefix}_linear", 0.0, -1.0, 1.0), Parameter(f"{self.prefix}_abs", 0.0, -1.0, 1.0),
               Parameter(f"{self.prefix}_gain", 0.5, 0.0, 3.0),
               Parameter(f"{self.prefix}_tilt_pos", 0.0, -1.0, 1.0), Parameter(f"{self.prefix}_tilt_neg", 0.0, -1.0, 1.0)]
        if self.other_lag:
            x = self._column(data)
            span = float(np.ptp(x)) if x.size else 0.0
            hi = max(0.25 * span, 1e-6)
            own.append(Parameter(f"{self.prefix}_lag_deg", min(LAG_START_DEG, 0.5 * hi), 0.0, hi))
        if self.lag == "smooth":
            lo, start, top = LAG_SIGMA
            own.append(Parameter(f"{self.prefix}_lag_sigma", start, lo, top))
        if self.band:  # below a quarter of the column's span, as the lag
            span = float(np.ptp(self._column(data))) if data.n_samples else 0.0
            hi = max(0.25 * span, 1e-6)
            own.append(Parameter(f"{self.prefix}_band_deg", min(BAND_START_DEG, 0.5 * hi), 0.0, hi))
        if self.slip:  # either sign, as drift's rate; 60 deg/min is beyond any sensor's slip
            own.append(Parameter(f"{self.prefix}_slip_dps", 0.0, -1.0, 1.0))
        if self.mutual:  # the other half-bend per deg of this one: a tendon-hole offset below the bend's radius
            own.append(Parameter(f"{self.prefix}_mutual", 0.0, -1.0, 1.0))
        return own

    def start_candidates(self, data: HysteresisData, u: np.ndarray) -> list[dict]:
        """Start values tried before the fit (the best is kept).

        From the planes' nominal directions a fit on a full circle run can stall where the
        base has bent its branches to mimic the coupling (seen on a 7000-sample run: 3.6 deg
        in-sample, 0.49 deg from these starts). Besides that start: the other half-bend
        twice as large, and both half-planes deviated by 17 deg (the paper's 2-20 deg).
        """
        return [{"gain": 0.5}, {"gain": 1.0}, {"tilt_pos": -0.3, "tilt_neg": -0.3}]

    def _column(self, data: HysteresisData) -> np.ndarray:
        return np.ascontiguousarray(data.column(self.column), dtype=float)

    @property
    def other_friction(self) -> str | None:
        """The column of the knob whose friction the smooth lag models: the conditions that scale the base's
        friction scale that lag's bound too (:meth:`~endocal.models.base.HysteresisModel._filter_inputs`); None
        for a play or no lag."""
        return self.column if self.lag == "smooth" else None

    def _x(self, p: dict, data: HysteresisData, friction: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The other bend's drive (n,): its knob's position through the lag and the dead band, and its derivatives
        by their parameters (n, m; m = 0 without either). ``friction`` (n,): the smooth lag's bound per sample, times
        its own (the base's friction conditions at the other knob; ones without)."""
        x, d = self._lagged(p, data, friction)
        if not self.band:
            return x, d
        # the dead band: x_b = x - clip(x, -w, w), flat inside (both tendons slack), x shifted by w outside
        w = float(p["band_deg"])
        outside = np.abs(x) > w
        sign = np.sign(x)
        xb = np.where(outside, x - sign * w, 0.0)
        return xb, np.column_stack([d * outside[:, None], np.where(outside, -sign, 0.0)])

    def _lagged(self, p: dict, data: HysteresisData, friction: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """The other knob's position through the lag (n,) and its derivatives by the lag's parameters (n, m)."""
        x = self._column(data)
        if not self.other_lag:
            return x, np.zeros((x.size, 0))
        starts = np.ascontiguousarray(data.run_starts, dtype=np.int64)
        lam = float(p["lag_deg"])
        if self.lag == "smooth":
            sigma = float(p["lag_sigma"])
            f = np.ones(x.size) if friction is None else np.ascontiguousarray(friction, dtype=float)
            out = smooth_lag(x, lam, sigma, starts, f)
            # central differences (one-sided at the lower bounds): the lag is O(n), each pass a fraction of a fit's step
            d = np.empty((x.size, 2))
            for j, (value, lo) in enumerate(((lam, 0.0), (sigma, LAG_SIGMA[0]))):
                h = 1e-6 * max(abs(value), 1e-3)
                args = [lam, sigma]
                args[j] = value + h
                up = smooth_lag(x, *args, starts, f)
                if value - h >= lo:
                    args[j] = value - h
                    d[:, j] = (up - smooth_lag(x, *args, starts, f)) / (2.0 * h)
                else:
                    d[:, j] = (up - out) / h
            return out, d
        # the play of the rate and load effects, its width constant: d width / d lag = 1, no upstream parameters
        width = np.full(x.size, lam)
        played, d_lag = varplay_forward_jac(x, width, np.ones((x.size, 1)), np.zeros((x.size, 0)), starts)
        return played, np.ascontiguousarray(d_lag[:, :1])

    def _args(self, p: dict) -> tuple:
        """``(a, b, g, c_pos, c_neg, kappa, mutual)`` for the kernels (``kappa`` 0 without the mutual shift)."""
        own = tuple(float(p[k]) for k in ("linear", "abs", "gain", "tilt_pos", "tilt_neg"))
        return (*own, float(p["mutual"]) if self.mutual else 0.0, bool(self.mutual))

    def _slip(self, p: dict, data: HysteresisData) -> tuple[np.ndarray, np.ndarray]:
        """The other axis's frame slip (deg, n) and the time it has grown over (s, n): zeros without ``slip``."""
        if not self.slip:
            zeros = np.zeros(data.n_samples)
            return zeros, zeros
        elapsed = data.elapsed_s(f"effect '{self.label}' (the other axis's frame slip)")
        return float(p["slip_dps"]) * elapsed, elapsed

    def _forward(self, p: dict, y: np.ndarray, data: HysteresisData, friction: np.ndarray | None = None):
        x, dx_lag = self._x(p, data, friction)
        slip, elapsed = self._slip(p, data)
        out, dy, own = coupling_forward(np.ascontiguousarray(y, dtype=float), x, *self._args(p), dx_lag, slip, elapsed)
        n_drive = own.shape[1] - 2  # (a, b, g, c+, c-) and the drive's; then the slip rate and kappa, where fitted
        cols = [*range(n_drive), *([n_drive] if self.slip else []), *([n_drive + 1] if self.mutual else [])]
        return out, dy, own[:, cols]

    def apply(self, p: dict, y: np.ndarray, data: HysteresisData, friction: np.ndarray | None = None) -> np.ndarray:
        return self._forward(p, y, data, friction)[0]

    def apply_jac(self, p: dict, y: np.ndarray, data: HysteresisData, J: np.ndarray):
        """Coupled output, the upstream Jacobian through it (n, m) and the own columns (n, 5 to 10). A model whose
        effects scale the base's friction is differentiated numerically, so no ``friction`` comes here."""
        out, dy, own = self._forward(p, y, data)
        return out, dy[:, None] * J, own

    def invert(self, p: dict, y: np.ndarray, data: HysteresisData, friction: np.ndarray | None = None) -> np.ndarray:
        return coupling_inverse(np.ascontiguousarray(y, dtype=float), self._x(p, data, friction)[0], *self._args(p),
                                self._slip(p, data)[0])

    def describe(self, p: dict, se: dict) -> str:
        return "coupling" + self._bracket(p, se)

    def wrap(self, inner: str) -> str:
        return f"coupling({inner}; {self.column})"
