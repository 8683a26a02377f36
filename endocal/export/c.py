"""A fitted model's streaming compensator as C99 source: a header and a source, one call per tick.

The generated code is the C twin of :class:`~endocal.models.compensator.StreamingCompensator`:
the same chain (output filters undone, then the base's inverse, then the input effects undone,
last applied first), the same arithmetic in the same order, so in ``double`` it gives the
Python compensator's commands to rounding (tests/test_export_c.py: within 1e-9 deg) and in
``float`` to about 1e-4 deg. It allocates nothing, calls nothing but ``<math.h>`` and keeps
its whole state in one struct the caller owns::

    PREFIX_state st;
    PREFIX_init(&st);
    cmd_deg = PREFIX_step(&st, desired_deg);   /* every tick */

What each part implements:

- ``pi`` base: the inverse PI, a weighted sum of play operators on the desired angle with the
  thresholds and weights of eq. 11 (duodenoscope paper, eqs. 9 and 11): one clamp per operator
  per tick;
- ``linear``/``bspline`` bases: the generalised play's numerical inverse (bisection on the
  monotone step map; the thesis's direction-dependent model), as :func:`gplay_inverse_step`;
- effects, each through its own exact causal inverse: ``creep`` (standard linear solid),
  ``envelope`` (eq. 10), ``deadzone`` and ``deadzone:tip`` (slack), ``tension`` and ``rate`` (friction plays).

Effects that cannot be undone one sample at a time (``delay`` needs future samples; ``load``,
``coupling``, ``drift`` logged columns or time) are refused by the compensator itself, with one
line naming the effect. A streamable effect that has no C emitter here (a user's own effect)
is refused the same way.

Two differences from Python a controller needs: ``step`` never fails. A command beyond the
fitted range is clamped to it and ``status`` says ``CLAMPED`` (the Python compensator of an
``out_of_range="error"`` model raises there); a NaN or infinite desired angle leaves the state
untouched, repeats the last command and sets ``NONFINITE``.
"""

from __future__ import annotations

import hashlib
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from endocal.errors import ModelError, OutputExistsError, OutputPathError

#: C scalar types the generator writes
REALS = ("double", "float")

#: relative tolerance of the two hold tests (deadzone candidate, generalised play hold) in float: 8 float
#: epsilons (32 held a reversal of 3e-4 deg at a damped sine's peak: 8 deg off at that tick); in double the
#: Python values (1e-12, 1e-9) are kept, so both give one answer
_FLOAT_TOL = "(8.0f * FLT_EPSILON)"

_C_KEYWORDS = frozenset(
    "auto break case char const continue default do double else enum extern float for goto if inline int long "
    "register restrict return short signed sizeof static struct switch typedef union unsigned void volatile while "
    "_Bool _Complex _Imaginary".split())


@dataclass
class _Part:
    """One link of the compensator chain as C: state fields, init lines, a static function, its call."""

    fields: list[str] = field(default_factory=list)  # lines inside the state struct (header)
    init: list[str] = field(default_factory=list)  # lines of PREFIX_init
    code: str = ""  # constants and the static function (source)
    call: str = ""  # one statement of PREFIX_step
    needs: set[str] = field(default_factory=set)  # helper functions it uses (rmin, rmax)


@dataclass
class CCompensator:
    """The generated C compensator of one model.

    Attributes
    ----------
    name : str
        The identifier prefix (``PREFIX_state``, ``PREFIX_init``, ``PREFIX_step``) and the file
        stem (``PREFIX.h``, ``PREFIX.c``).
    real : {"double", "float"}
        The arithmetic of the generated code.
    header, source : str
        The two files' text.
    chain : list of str
        The inverse chain in the order ``step`` runs it (e.g. ``["pi20 inverse (eqs. 9-11)",
        "envelope"]``).
    dt_s : float or None
        The loop period the time-based effects were discretised for (None: no such effect).
    cmd_range : (float, float)
        The fitted command range ``step`` clamps to, in ``drive_unit``.
    drive_unit : str
        ``deg`` (a knob) or ``mm`` (a linear drive).
    """

    name: str
    real: str
    header: str
    source: str
    chain: list[str]
    dt_s: float | None
    cmd_range: tuple[float, float]
    drive_unit: str
    #: ``(key, text)`` of what the user should know (``float-holds``), empty when nothing
    warnings: list[tuple[str, str]] = field(default_factory=list)
    #: the header and source written by :meth:`write` (None before)
    files: tuple[Path, Path] | None = None

    def __repr__(self) -> str:
        period = f", loop period {self.dt_s:g} s" if self.dt_s else ""
        return (f"CCompensator({self.name}.h/.c, {self.real}: {' -> '.join(self.chain)}{period}; "
                f"commands clamped to [{self.cmd_range[0]:g}, {self.cmd_range[1]:g}] {self.drive_unit})")

    def to_dict(self) -> dict:
        """Everything but the code: name, arithmetic, chain, loop period, range, warnings, files written."""
        return {"name": self.name, "real": self.real, "chain": list(self.chain), "dt_s": self.dt_s,
                "cmd_range": list(self.cmd_range), "drive_unit": self.drive_unit,
                "warnings": [{"key": k, "text": t} for k, t in self.warnings],
                "files": [str(p) for p in self.files] if self.files else None}

    def paths(self, out_dir) -> tuple[Path, Path]:
        """``(OUT_DIR/PREFIX.h, OUT_DIR/PREFIX.c)``."""
        out_dir = Path(out_dir)
        return out_dir / f"{self.name}.h", out_dir / f"{self.name}.c"

    def write(self, out_dir, *, force: bool = False) -> tuple[Path, Path]:
        """Write both files into ``out_dir`` (created if missing); both or neither.

        Raises
        ------
        OutputExistsError
            A file exists and ``force`` is False (nothing written).
        OutputPathError
            The folder cannot be created or written.
        """
        from endocal.files import atomic_write_bytes

        h_path, c_path = self.paths(out_dir)
        existing = [str(p) for p in (h_path, c_path) if p.exists()]
        if existing and not force:
            raise OutputExistsError(f"{', '.join(existing)} already exist(s): choose another --out or --name, "
                                    "or pass --force")
        try:
            Path(out_dir).mkdir(parents=True, exist_ok=True)
            atomic_write_bytes(h_path, self.header.encode())
            try:
                atomic_write_bytes(c_path, self.source.encode())
            except OSError:
                if not existing:
                    h_path.unlink(missing_ok=True)
                raise
        except OSError as exc:
            raise OutputPathError(f"cannot write the C compensator into {out_dir}: {exc.strerror or exc}") from None
        self.files = (h_path, c_path)
        return h_path, c_path


# ---------------------------------------------------------------------------------------------- literals
def _lit(x: float, real: str) -> str:
    """A C literal of ``x`` that reads back as the same double (shortest repr), ``f``-suffixed in float."""
    x = float(x)
    if math.isnan(x):
        raise ModelError("the model holds a NaN parameter: it cannot be exported")
    if real == "float":
        with np.errstate(over="ignore", under="ignore"):
            x = float(np.float32(x))  # the float it becomes (beyond float's range: INFINITY, not a compiler warning)
    if math.isinf(x):
        return f"({'-' if x < 0 else ''}(real_t)INFINITY)"
    s = repr(x)
    if "e" not in s and "." not in s:
        s += ".0"
    return s + ("f" if real == "float" else "")


def _array(name: str, values, real: str, comment: str) -> str:
    items = [_lit(v, real) for v in values]
    rows = [", ".join(items[i:i + 4]) for i in range(0, len(items), 4)]
    body = ",\n    ".join(rows)
    return f"/* {comment} */\nstatic const real_t {name}[{len(items)}] = {{\n    {body}\n}};\n"


def _const(name: str, value: float, real: str, comment: str) -> str:
    return f"static const real_t {name} = {_lit(value, real)};  /* {comment} */\n"


# ---------------------------------------------------------------------------------------------- bases
def _pi_base(stepper, real: str, n_macro: str) -> tuple[_Part, str]:
    n = stepper.r_inv.size
    consts = (_array("PI_R_INV", stepper.r_inv, real,
                     "thresholds r'_i of the inverse plays (duodenoscope paper, eq. 11)")
              + _array("PI_W_INV", stepper.w_inv, real, "weights w'_i of the inverse plays (eq. 11)")
              + _const("PI_OFFSET", stepper.offset, real, "constant output offset of the forward PI (deg)"))
    if real == "double":
        # the Python compensator's arithmetic, operation for operation: the same commands to the bit
        code = consts + f"""
/* inverse PI (eq. 9): a weighted sum of play operators on the desired angle, one clamp each (eq. 5) */
static real_t pi_inverse_step(STATE *s, real_t y)
{{
    const real_t x = y - PI_OFFSET;
    real_t acc = 0;
    int i;
    for (i = 0; i < {n_macro}; ++i) {{
        real_t z = s->play[i];
        if (z < x - PI_R_INV[i]) {{
            z = x - PI_R_INV[i];
        }} else if (z > x + PI_R_INV[i]) {{
            z = x + PI_R_INV[i];
        }}
        s->play[i] = z;
        acc += PI_W_INV[i] * z;
    }}
    return acc;
}}
"""
        fields = [f"real_t play[{n_macro}];  /* the inverse plays' outputs (eq. 9) */"]
        init = [f"for (i = 0; i < {n_macro}; ++i) {{ s->play[i] = 0; }}"]
    else:
        # In float each play keeps its deviation from the input, d_i = Phi'_i - x in [-r'_i, r'_i], and the output is
        # x sum_i w'_i + sum_i w'_i d_i (sum_i w'_i = 1 / sum_i w_i, eq. 11 telescoped). Stored as Phi'_i, a play of a
        # threshold below float's resolution at the input's size (a fitted pure backlash: w_0 ~ 1e-9, r'_1 ~ 1e-9 deg,
        # w'_0 = -w'_1 ~ 1e9) would lose its state, and w'_0 x + w'_1 Phi'_1 cancel catastrophically (54 deg off).
        _, w_fwd = stepper.forward
        code = consts + _const("PI_W_INV_SUM", 1.0 / float(np.sum(w_fwd)), real,
                               "sum_i w'_i = 1 / sum_i w_i (eq. 11)") + f"""
/* inverse PI (eq. 9), each play held as its deviation from the input: one clamp each (eq. 5) */
static real_t pi_inverse_step(STATE *s, real_t y)
{{
    const real_t x = y - PI_OFFSET;
    const real_t dx = s->x_prev - x;
    real_t acc = 0;
    int i;
    for (i = 0; i < {n_macro}; ++i) {{
        real_t d = s->dev[i] + dx;
        if (d < -PI_R_INV[i]) {{
            d = -PI_R_INV[i];
        }} else if (d > PI_R_INV[i]) {{
            d = PI_R_INV[i];
        }}
        s->dev[i] = d;
        acc += PI_W_INV[i] * d;
    }}
    s->x_prev = x;
    return x * PI_W_INV_SUM + acc;
}}
"""
        fields = [f"real_t dev[{n_macro}];  /* each inverse play's output minus the input (eq. 9) */",
                  "real_t x_prev;  /* the last input of the plays (deg) */"]
        init = [f"for (i = 0; i < {n_macro}; ++i) {{ s->dev[i] = 0; }}", "s->x_prev = 0;"]
    part = _Part(fields=fields, init=init, code=code, call="v = pi_inverse_step(s, y);")
    return part, f"#define {n_macro} {n}  /* inverse play operators (n + 1) */"


def _gplay_base(stepper, real: str) -> _Part:
    slope, t_up, c_up, t_dn, c_dn, deg = stepper.args
    hold = "1e-9" if real == "double" else _FLOAT_TOL
    code = (
        _array("GP_T_UP", t_up, real, "knots of the ascending branch (a B-spline, extended along its end tangents)")
        + _array("GP_C_UP", c_up, real, "its coefficients (deg)")
        + _array("GP_T_DN", t_dn, real, "knots of the descending branch")
        + _array("GP_C_DN", c_dn, real, "its coefficients (deg)")
        + f"#define GP_DEG {int(deg)}\n"
        + _const("GP_SLOPE", slope, real, "backlash transition slope after a reversal")
        + _const("GP_V_MIN", stepper.v_min, real, "search range of the base's input")
        + _const("GP_V_MAX", stepper.v_max, real, "")
        + f"#define GP_HOLD_TOL ({hold})  /* relative: a target this close to the output holds the command */\n"
        + """
/* de Boor's algorithm for t[deg] <= x <= t[nc] */
static real_t bspline_inside(const real_t *t, const real_t *c, int nc, real_t x)
{
    real_t d[GP_DEG + 1];
    int lo = GP_DEG, hi = nc - 1, ell, j, r;
    if (x >= t[hi]) {
        ell = hi;
    } else {
        int a = lo, b = hi;
        while (b - a > 1) {
            int mid = (a + b) / 2;
            if (t[mid] <= x) {
                a = mid;
            } else {
                b = mid;
            }
        }
        ell = a;
    }
    for (j = 0; j <= GP_DEG; ++j) {
        d[j] = c[ell - GP_DEG + j];
    }
    for (r = 1; r <= GP_DEG; ++r) {
        for (j = GP_DEG; j > r - 1; --j) {
            real_t left = t[ell - GP_DEG + j], right = t[ell + 1 + j - r];
            real_t den = right - left;
            real_t alpha = den == 0 ? 0 : (x - left) / den;
            d[j] = (1 - alpha) * d[j - 1] + alpha * d[j];
        }
    }
    return d[GP_DEG];
}

/* a branch: the clamped B-spline, continued linearly beyond its base interval */
static real_t bspline_eval(const real_t *t, const real_t *c, int nc, real_t x)
{
    real_t a = t[GP_DEG], b = t[nc];
    if (x < a) {
        real_t slope = GP_DEG * (c[1] - c[0]) / (t[GP_DEG + 1] - t[1]);
        return c[0] + slope * (x - a);
    }
    if (x > b) {
        real_t slope = GP_DEG * (c[nc - 1] - c[nc - 2]) / (t[nc + GP_DEG - 1] - t[nc - 1]);
        return c[nc - 1] + slope * (x - b);
    }
    return bspline_inside(t, c, nc, x);
}

#define GP_NC_UP ((int)(sizeof GP_C_UP / sizeof GP_C_UP[0]))
#define GP_NC_DN ((int)(sizeof GP_C_DN / sizeof GP_C_DN[0]))

/* one step of the generalised play: y = clip(y_prev + s (u - u_prev), branches at u) */
static real_t gplay_g(real_t u, real_t u_prev, real_t y_prev)
{
    real_t a = bspline_eval(GP_T_UP, GP_C_UP, GP_NC_UP, u);
    real_t b = bspline_eval(GP_T_DN, GP_C_DN, GP_NC_DN, u);
    real_t lo = rmin(a, b), hi = rmax(a, b);
    real_t y = y_prev + GP_SLOPE * (u - u_prev);
    if (y < lo) {
        return lo;
    }
    if (y > hi) {
        return hi;
    }
    return y;
}

/* the first command of a run: on the branches' mid-line, by bisection */
static void gplay_midline_inverse(STATE *s, real_t target)
{
    real_t lo_u = GP_V_MIN, hi_u = GP_V_MAX, uk;
    int it;
    for (it = 0; it < 200; ++it) {
        real_t mid = (real_t)0.5 * (lo_u + hi_u), m;
        if (mid == lo_u || mid == hi_u) {
            break;
        }
        m = (real_t)0.5 * (bspline_eval(GP_T_UP, GP_C_UP, GP_NC_UP, mid)
                           + bspline_eval(GP_T_DN, GP_C_DN, GP_NC_DN, mid));
        if (m < target) {
            lo_u = mid;
        } else {
            hi_u = mid;
        }
    }
    uk = (real_t)0.5 * (lo_u + hi_u);
    s->gp_u = uk;
    s->gp_y = (real_t)0.5 * (bspline_eval(GP_T_UP, GP_C_UP, GP_NC_UP, uk)
                             + bspline_eval(GP_T_DN, GP_C_DN, GP_NC_DN, uk));
}

/* the command whose generalised-play output from (u_prev, y_prev) is target: bisection on the monotone
   step map, the command closest to u_prev among equal outputs (endocal.models._kernels.gplay_inverse_step) */
static real_t gplay_inverse_step(STATE *s, real_t target)
{
    real_t u_prev = s->gp_u, y_prev = s->gp_y, a, b, u, g0;
    int it;
    if (!s->gp_started) {
        s->gp_started = 1;
        gplay_midline_inverse(s, target);
        return s->gp_u;
    }
    g0 = gplay_g(u_prev, u_prev, y_prev);
    if ((g0 > target ? g0 - target : target - g0) <= GP_HOLD_TOL * rmax(1, target < 0 ? -target : target)) {
        s->gp_y = g0;
        return u_prev;
    }
    if (target > g0) {
        real_t gb;
        a = u_prev;
        b = rmax(GP_V_MAX, u_prev);
        gb = gplay_g(b, u_prev, y_prev);
        if (gb <= target) {
            s->gp_u = b;
            s->gp_y = gb;
            return b;
        }
        for (it = 0; it < 80; ++it) {
            real_t mid = (real_t)0.5 * (a + b);
            if (mid == a || mid == b) {
                break;
            }
            if (gplay_g(mid, u_prev, y_prev) >= target) {
                b = mid;
            } else {
                a = mid;
            }
        }
        u = b;
    } else {
        real_t ga;
        a = rmin(GP_V_MIN, u_prev);
        b = u_prev;
        ga = gplay_g(a, u_prev, y_prev);
        if (ga >= target) {
            s->gp_u = a;
            s->gp_y = ga;
            return a;
        }
        for (it = 0; it < 80; ++it) {
            real_t mid = (real_t)0.5 * (a + b);
            if (mid == a || mid == b) {
                break;
            }
            if (gplay_g(mid, u_prev, y_prev) <= target) {
                a = mid;
            } else {
                b = mid;
            }
        }
        u = a;
    }
    s->gp_y = gplay_g(u, u_prev, y_prev);
    s->gp_u = u;
    return u;
}
""")
    return _Part(fields=["int gp_started;  /* the first sample starts on the branches' mid-line */",
                         "real_t gp_u;  /* the last command of the base (its input) */",
                         "real_t gp_y;  /* and its output (deg) */"],
                 init=["s->gp_started = 0;", "s->gp_u = 0;", "s->gp_y = 0;"],
                 code=code, call="v = gplay_inverse_step(s, y);", needs={"rmin", "rmax"})


# ---------------------------------------------------------------------------------------------- effects
def _creep(e, p: dict, state, real: str) -> _Part:
    P, f = e.prefix.upper(), e.prefix
    code = (_const(f"{P}_A", p["fraction"], real, "creep_fraction: the share of the bend that relaxes")
            + _const(f"{P}_ALPHA", state[2], real, "1 - exp(-dt / creep_tau_s)")
            + f"""
/* creep (standard linear solid) undone exactly: the quasi-static bend whose filtered bend is y */
static real_t {f}_invert_step(STATE *s, real_t y)
{{
    real_t yb;
    if (!s->{f}_started) {{
        s->{f}_started = 1;
        s->{f}_slow = y;
        return y;
    }}
    yb = (y - {P}_A * (1 - {P}_ALPHA) * s->{f}_slow) / (1 - {P}_A + {P}_A * {P}_ALPHA);
    s->{f}_slow = s->{f}_slow + {P}_ALPHA * (yb - s->{f}_slow);
    return yb;
}}
""")
    return _Part(fields=[f"int {f}_started;", f"real_t {f}_slow;  /* the relaxing share's state (deg) */"],
                 init=[f"s->{f}_started = 0;", f"s->{f}_slow = 0;"], code=code, call=f"y = {f}_invert_step(s, y);")


def _envelope(e, p: dict, state, real: str) -> _Part:
    P, f = e.prefix.upper(), e.prefix
    code = "".join(_const(f"{P}_{k.upper()}", p[k], real, f"envelope_{k}")
                   for k in ("theta0_deg", "theta1_deg", "theta2_deg", "k0", "k1", "k2"))
    code += f"""
/* the inverse envelope (duodenoscope paper, eq. 10) */
static real_t {f}_invert_step(real_t v)
{{
    const real_t x0 = {P}_K1 * ({P}_THETA0_DEG - {P}_THETA1_DEG);
    const real_t x2 = {P}_K1 * ({P}_THETA2_DEG - {P}_THETA1_DEG);
    if (v < x0) {{
        return (v - x0) / {P}_K0 + {P}_THETA0_DEG;
    }}
    if (v > x2) {{
        return (v - x2) / {P}_K2 + {P}_THETA2_DEG;
    }}
    return v / {P}_K1 + {P}_THETA1_DEG;
}}
"""
    return _Part(code=code, call=f"v = {f}_invert_step(v);")


def _deadzone(e, p: dict, state, real: str) -> _Part:
    from endocal.models.effects.base import InputEffect

    P, f = e.prefix.upper(), e.prefix
    x = "v" if isinstance(e, InputEffect) else "y"  # the command on the knob's side, the bend on the tip's
    tol = "1e-12" if real == "double" else _FLOAT_TOL
    code = (_const(f"{P}_H", p["slack_deg"], real, "deadzone_slack_deg: half play of the slack")
            + _const(f"{P}_C", p["band_deg"], real, "deadzone_band_deg: half width of the band")
            + _const(f"{P}_M", p["center_deg"], real, "deadzone_center_deg: its centre")
            + f"""
/* one step of the slack operator (endocal.models.effects.deadzone) */
static real_t {f}_forward(real_t s, real_t dx, real_t x)
{{
    real_t p;
    if (s > {P}_C) {{
        p = rmax(s + dx, {P}_C);
    }} else if (s < -{P}_C) {{
        p = rmin(s + dx, -{P}_C);
    }} else {{
        p = s;
    }}
    if (p < x - {P}_H) {{
        return x - {P}_H;
    }}
    if (p > x + {P}_H) {{
        return x + {P}_H;
    }}
    return p;
}}

/* the slack undone: keep the slack state if that reaches the target, else wind the slack in with one jump */
static real_t {f}_invert_step(STATE *s, real_t v)
{{
    const real_t target = v - {P}_M;
    real_t x_new, tol, cand, sv = s->{f}_s, xv = s->{f}_x;
    if (!s->{f}_started) {{
        xv = target > 0 ? target + {P}_H : (target < 0 ? target - {P}_H : 0);
        s->{f}_started = 1;
        s->{f}_s = target;
        s->{f}_x = xv;
        return xv + {P}_M;
    }}
    tol = {tol} * (1 + (target < 0 ? -target : target) + {P}_H + {P}_C);
    cand = xv + (target - sv);
    {{
        real_t miss = {f}_forward(sv, cand - xv, cand) - target;
        if ((miss < 0 ? -miss : miss) <= tol) {{
            x_new = cand;
        }} else if (target > sv) {{
            x_new = target + {P}_H;
        }} else if (target < sv) {{
            x_new = target - {P}_H;
        }} else {{
            x_new = rmin(rmax(xv, target - {P}_H), target + {P}_H);
        }}
    }}
    s->{f}_s = {f}_forward(sv, x_new - xv, x_new);
    s->{f}_x = x_new;
    return x_new + {P}_M;
}}
""")
    return _Part(fields=[f"int {f}_started;", f"real_t {f}_s;  /* the drive's position from the slack centre */",
                         f"real_t {f}_x;  /* the knob's */"],
                 init=[f"s->{f}_started = 0;", f"s->{f}_s = 0;", f"s->{f}_x = 0;"], code=code,
                 call=f"{x} = {f}_invert_step(s, {x});", needs={"rmin", "rmax"})


def _play_reference_code() -> str:
    return """
/* relative: a target this close to where the drive is holds the knob (rounding, not a reversal) */
#define PLAY_HOLD_TOL (1e-9)

/* where the drive is after an inverse step: at v, unless a hold within the tolerance left the knob still
   (endocal.models._kernels.play_reference) */
static real_t play_reference(real_t v, real_t v_prev, real_t u, real_t u_prev)
{
    const real_t d = v - v_prev;
    if (u == u_prev && (d < 0 ? -d : d) <= (real_t)PLAY_HOLD_TOL * rmax(1, v < 0 ? -v : v)) {
        return v_prev;
    }
    return v;
}
"""


def _play_inverse_step_code() -> str:
    return """
/* one sample of a play's inverse: the knob that moves the drive from v_prev to v with half width w
   (endocal.models._kernels.play_inverse_step) */
static real_t play_inverse_step(real_t v, real_t v_prev, real_t u_prev, real_t w)
{
    const real_t tol = (real_t)PLAY_HOLD_TOL * rmax(1, v < 0 ? -v : v);
    if (v - v_prev > tol) {
        return v + w;
    }
    if (v_prev - v > tol) {
        return v - w;
    }
    return rmin(rmax(u_prev, v - w), v + w);
}
"""


def _tension(e, p: dict, state, real: str) -> _Part:
    P, f = e.prefix.upper(), e.prefix
    code = (_const(f"{P}_FRICTION", p["friction"], real, "tension_friction: play width per deg of bend")
            + f"""
/* the tension play undone: x_k = v_k +- c |x_(k-1)| while the drive moves */
static real_t {f}_invert_step(STATE *s, real_t v)
{{
    real_t x;
    if (!s->{f}_started) {{
        s->{f}_started = 1;
        s->{f}_v_prev = v;
        s->{f}_x_prev = v;
        return v;
    }}
    x = play_inverse_step(v, s->{f}_v_prev, s->{f}_x_prev,
                          {P}_FRICTION * (s->{f}_x_prev < 0 ? -s->{f}_x_prev : s->{f}_x_prev));
    s->{f}_v_prev = play_reference(v, s->{f}_v_prev, x, s->{f}_x_prev);
    s->{f}_x_prev = x;
    return x;
}}
""")
    return _Part(fields=[f"int {f}_started;", f"real_t {f}_v_prev;", f"real_t {f}_x_prev;"],
                 init=[f"s->{f}_started = 0;", f"s->{f}_v_prev = 0;", f"s->{f}_x_prev = 0;"], code=code,
                 call=f"v = {f}_invert_step(s, v);", needs={"rmin", "rmax", "play", "play_hold"})


def _rate(e, p: dict, state, real: str) -> _Part:
    P, f = e.prefix.upper(), e.prefix
    sfx = "f" if real == "float" else ""
    exp_, expm1_, log_ = f"exp{sfx}", f"expm1{sfx}", f"log{sfx}"
    code = (_const(f"{P}_G", p["gain_s"], real, "rate_gain_s")
            + _const(f"{P}_H", p["amp_s_per_deg"], real, "rate_amp_s_per_deg")
            + _const(f"{P}_KAPPA", p["capstan_s_per_deg"], real, "rate_capstan_s_per_deg")
            + _const(f"{P}_ALPHA", state[4], real, "1 - exp(-dt / speed_filter_s): the knob speed's smoothing")
            + _const(f"{P}_DT", state[5], real, "the loop period (s)")
            + f"""
/* (e^(kappa s) - 1) / kappa (deg/s), the speed term of the play width (its series below kappa s = 1e-4) */
static real_t {f}_capstan_speed(real_t sp)
{{
    const real_t ks = {P}_KAPPA * sp;
    if (ks < (real_t)1e-4) {{
        return sp * (1 + ks / 2 + ks * ks / 6);
    }}
    return {expm1_}(ks) / {P}_KAPPA;
}}

/* root of x - y - G F(s_rest + c |x - x_prev|) in [lo, hi] (negative at lo, >= 0 at hi) */
static real_t {f}_bisect_root(real_t y, real_t x_prev, real_t s_rest, real_t c, real_t G, real_t lo, real_t hi)
{{
    int it;
    for (it = 0; it < 200; ++it) {{
        real_t mid = (real_t)0.5 * (lo + hi), d = mid - x_prev;
        if (mid == lo || mid == hi) {{
            break;
        }}
        if (mid - y - G * {f}_capstan_speed(s_rest + c * (d < 0 ? -d : d)) < 0) {{
            lo = mid;
        }} else {{
            hi = mid;
        }}
    }}
    return hi;
}}

/* the knob u that moves the drive from v_prev to v, given the friction its own speed adds
   (endocal.models.effects.rate.knob_for_drive) */
static real_t {f}_knob_for_drive(real_t v, real_t v_prev, real_t u_prev, real_t s_prev, real_t G)
{{
    const real_t c = {P}_ALPHA / {P}_DT;
    const real_t s_rest = (1 - {P}_ALPHA) * s_prev;
    const real_t w_rest = G * {f}_capstan_speed(s_rest);
    real_t sig, x_prev, y, lo, hi, slope, d = v - v_prev;
    if ((d < 0 ? -d : d) <= (real_t)PLAY_HOLD_TOL * rmax(1, v < 0 ? -v : v)) {{  /* rounding, not a reversal */
        d = u_prev - v;
        if ((d < 0 ? -d : d) <= w_rest) {{
            return u_prev;
        }}
        sig = u_prev > v ? 1 : -1;
        x_prev = sig * u_prev;
        y = sig * v;
        return sig * {f}_bisect_root(y, x_prev, s_rest, c, G, y, x_prev);
    }}
    sig = v > v_prev ? 1 : -1;
    x_prev = sig * u_prev;
    y = sig * v;
    lo = y;
    if (x_prev > y && x_prev - y - w_rest >= 0) {{
        return sig * {f}_bisect_root(y, x_prev, s_rest, c, G, lo, x_prev);
    }}
    lo = rmax(y, x_prev);
    slope = 1 - G * c * {exp_}({P}_KAPPA * (s_rest + c * (lo - x_prev)));
    if (slope <= 0) {{
        return sig * lo;
    }}
    if ({P}_KAPPA > 0) {{
        const real_t s_star = {log_}(1 / (G * c)) / {P}_KAPPA;
        hi = x_prev + (s_star - s_rest) / c;
    }} else {{
        hi = lo + 2 * (G * {f}_capstan_speed(s_rest + c * (lo - x_prev)) + 1) / slope;
    }}
    d = hi - x_prev;
    if (hi - y - G * {f}_capstan_speed(s_rest + c * (d < 0 ? -d : d)) < 0) {{
        return sig * hi;
    }}
    return sig * {f}_bisect_root(y, x_prev, s_rest, c, G, lo, hi);
}}

/* the speed-dependent friction play undone, one sample */
static real_t {f}_invert_step(STATE *s, real_t v)
{{
    real_t u, du, u_prev = s->{f}_u_prev;
    if (!s->{f}_started) {{
        s->{f}_started = 1;
        s->{f}_v_prev = v;
        s->{f}_u_prev = v;
        return v;
    }}
    u = {f}_knob_for_drive(v, s->{f}_v_prev, u_prev, s->{f}_speed,
                           {P}_G + {P}_H * (u_prev < 0 ? -u_prev : u_prev));
    du = u - u_prev;
    s->{f}_speed += {P}_ALPHA * ((du < 0 ? -du : du) / {P}_DT - s->{f}_speed);
    s->{f}_v_prev = play_reference(v, s->{f}_v_prev, u, u_prev);
    s->{f}_u_prev = u;
    return u;
}}
""")
    return _Part(fields=[f"int {f}_started;", f"real_t {f}_v_prev;", f"real_t {f}_u_prev;",
                         f"real_t {f}_speed;  /* the smoothed knob speed (deg/s) */"],
                 init=[f"s->{f}_started = 0;", f"s->{f}_v_prev = 0;", f"s->{f}_u_prev = 0;", f"s->{f}_speed = 0;"],
                 code=code, call=f"v = {f}_invert_step(s, v);", needs={"rmax", "math", "play_hold"})


def _emitters() -> dict:
    """Effect class -> its C emitter (a streamable effect missing here is refused by name)."""
    from endocal.models.effects import Creep, Deadzone, Envelope, Rate, Tension
    from endocal.models.effects.deadzone import TipDeadzone

    # the slack's step and inverse are one operator on either side of the friction (on the output: a filter)
    return {Creep: _creep, Envelope: _envelope, Deadzone: _deadzone, TipDeadzone: _deadzone, Tension: _tension,
            Rate: _rate}


_HELPERS = {
    "rmin": "static real_t rmin(real_t a, real_t b) { return b < a ? b : a; }\n",
    "rmax": "static real_t rmax(real_t a, real_t b) { return b > a ? b : a; }\n",
}


# ---------------------------------------------------------------------------------------------- generator
def default_name(model) -> str:
    """``endocal_<axis>`` (``endocal_comp`` for a model without an axis)."""
    axis = getattr(model, "axis", None)
    stem = re.sub(r"[^A-Za-z0-9_]", "_", str(axis)) if axis else "comp"
    return f"endocal_{stem}"


def _check_name(name: str) -> str:
    if not isinstance(name, str) or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]{0,47}", name) or name in _C_KEYWORDS:
        raise ModelError(f"--name {name!r} is not a C identifier: letters, digits and _, not starting with a digit, "
                         "at most 48 characters (e.g. endocal_ap)")
    return name


def generate_c(model, *, name: str | None = None, real: str = "double", dt_s: float | None = None,
               source: str = "") -> CCompensator:
    """The C99 compensator of a fitted model: a header and a source for one ``step`` per tick.

    Parameters
    ----------
    model : HysteresisModel
        A fitted model whose effects all stream (see the module docstring).
    name : str, optional
        C identifier prefix and file stem; default ``endocal_<axis>``.
    real : {"double", "float"}
        The generated arithmetic.
    dt_s : float, optional
        The loop's fixed period (s): required by the time-based effects (``rate``, ``creep``),
        which are discretised for it.
    source : str, optional
        Where the model came from (a path), written into the header's comment with its hash.

    Returns
    -------
    CCompensator

    Raises
    ------
    ModelError
        An unfitted model, an effect that cannot be compensated one sample at a time (named),
        a time-based effect without ``dt_s``, a bad name or ``real``.
    """
    from endocal._version import __version__
    from endocal.models._directional import _GPlayStepper
    from endocal.models.compensator import StreamingCompensator
    from endocal.models.pi import _PIStepper

    if real not in REALS:
        raise ModelError(f"real must be one of {REALS}, got {real!r}")
    name = _check_name(name if name is not None else default_name(model))
    model._require_fitted()
    for e in model.effects_:
        if not e.streamable:
            raise ModelError(f"effect '{e.label}' cannot be compensated one sample at a time (it needs future samples "
                             "or logged columns), so it has no C compensator: refit the model without it to export one")
    try:
        comp = StreamingCompensator(model, dt_s=dt_s)
    except ModelError as exc:
        if "give dt_s" in str(exc):
            raise ModelError(str(exc).replace("give dt_s (s) to the compensator",
                                              "give the loop's rate (--loop-hz, dt_s in Python)")) from None
        raise
    # the compensator holds the chain exactly as Python steps it: filters, base, input effects (last applied first)
    emitters = _emitters()
    parts: list[_Part] = []
    chain: list[str] = []
    base_name = getattr(model, "base_name", type(model).__name__)
    if not isinstance(comp._base, (_PIStepper, _GPlayStepper)):  # the base first: without it no effect helps
        raise ModelError(f"the '{base_name}' base has no C code generator: the C export covers pi, linear and bspline")
    for (e, p), state in zip(comp._filters, comp._filter_states):
        parts.append(_emit(emitters, e, p, state, real))
        chain.append(e.label)
    NAME = name.upper()
    defines = []
    if isinstance(comp._base, _PIStepper):
        part, define = _pi_base(comp._base, real, f"{NAME}_N_PLAYS")
        defines.append(define)
        chain.append(f"{base_name}{comp._base.r_inv.size - 1} inverse (eqs. 9-11)")
    else:  # a _GPlayStepper (checked above)
        part = _gplay_base(comp._base, real)
        chain.append(f"{base_name} inverse (bisection)")
    parts.append(part)
    for (e, p), state in zip(comp._inputs, comp._states):
        parts.append(_emit(emitters, e, p, state, real))
        chain.append(e.label)
    lo, hi = comp._lo, comp._hi
    timed = any(getattr(e, "needs_period", False) for e in model.effects_)
    dt_used = float(dt_s) if (timed and dt_s is not None) else None
    equation = str(model).replace("*/", "* /")
    provenance = source
    if source and Path(source).is_file():
        provenance = f"{source} (sha256 {hashlib.sha256(Path(source).read_bytes()).hexdigest()[:16]}...)"
    header = _header(name, real, parts, defines, chain, equation, provenance, __version__, lo, hi,
                     model.drive_unit_, dt_used, model.out_of_range)
    src = _source(name, real, parts, __version__)
    return CCompensator(name=name, real=real, header=header, source=src, chain=chain, dt_s=dt_used,
                        cmd_range=(lo, hi), drive_unit=model.drive_unit_, warnings=_float_warnings(model, real))


def _float_warnings(model, real: str) -> list[tuple[str, str]]:
    """Where float cannot follow double: an inverse that jumps (a play's: deadzone, tension, rate; the backlash
    band of a linear or B-spline base) decides on the sign of the desired angle's step, and float cannot see a
    step below its resolution.

    Measured (tests/test_export_c.py, bench/bench_export_c.py): at a turning point whose first step back is
    ~5e-7 deg the float deadzone winds its slack in one tick after double (8 deg at that tick); after holds, where
    a decaying effect (rate, creep) settles in ever smaller steps, two plays can stay apart (tension + creep
    6.8 deg, rate + creep 12.6 deg); elsewhere float is within 3e-4 deg.
    """
    if real != "float":
        return []
    from endocal.models.effects.base import InputEffect
    from endocal.models.effects.deadzone import TipDeadzone

    jumps = [e.label for e in model.effects_
             if isinstance(e, (InputEffect, TipDeadzone)) and getattr(e, "stateful", False)]
    if getattr(model, "base_name", "") in ("linear", "bspline"):
        jumps.append(f"the {model.base_name} base's backlash")
    if not jumps:
        return []
    return [("float-holds", f"in float, {', '.join(jumps)} can turn the knob by a play's width a tick later than "
                            "double where the desired angle turns back by less than float's resolution (~1e-5 deg), "
                            "and stay apart after holds; generate double unless the target has no double-precision "
                            "FPU")]


def _emit(emitters: dict, e, p: dict, state, real: str) -> _Part:
    emit = emitters.get(type(e))
    if emit is None:
        raise ModelError(f"effect '{e.label}' streams in Python but has no C code generator: the C export covers "
                         f"{', '.join(sorted(c.name for c in emitters))}; leave it out of the model to export it")
    return emit(e, p, state, real)


def _c_comment(text: str, width: int = 96) -> list[str]:
    import textwrap

    return [f" * {line}" for line in textwrap.wrap(text, width)] or [" *"]


def _header(name, real, parts, defines, chain, equation, provenance, version, lo, hi, unit, dt_s, mode) -> str:
    NAME = name.upper()
    fields = "\n".join(f"    {f}" for part in parts for f in part.fields)
    fields = fields.replace("real_t", f"{name}_real")
    lines = ["/*", f" * {name}.h: feedforward compensator of a fitted endocal model, one call per control tick.",
             " *", f" * Generated by endocal {version} (`endocal export c`); do not edit, regenerate.", " *"]
    if provenance:
        lines += _c_comment(f"Model file: {provenance}")
    lines += _c_comment(f"Model: {equation}")
    lines += _c_comment(f"Inverse, in the order step() runs it: {' -> '.join(chain)}.")
    lines += _c_comment(f"Arithmetic: {real}. C99; no allocation, no library but <math.h>; the whole state is "
                        f"the struct {name}_state, owned by the caller.")
    if dt_s is not None:
        lines += _c_comment(f"Loop period: {dt_s:g} s ({1 / dt_s:g} Hz). The time-based effects were discretised "
                            "for it: call step() exactly once per period.")
    else:
        lines += _c_comment("Loop period: any (no time-based effect); call step() once per sample of the desired "
                            "trajectory.")
    lines += _c_comment(
        f"Commands are clamped to the fitted range [{lo:g}, {hi:g}] {unit} and the state's status says CLAMPED"
        + (" (the Python compensator of this model refuses such a desired angle: out_of_range='error')."
           if mode == "error" else "."))
    lines += [" *", " * Use:", f" *     {name}_state st;", f" *     {name}_init(&st);                    (at rest)",
              f" *     cmd = {name}_step(&st, desired_deg);   (every tick; st.status: {NAME}_OK, _CLAMPED, "
              "_NONFINITE)", " */"]
    lo_s = f"({'-' if lo < 0 else ''}INFINITY)" if math.isinf(lo) else _lit(lo, "double")
    hi_s = "(INFINITY)" if math.isinf(hi) else _lit(hi, "double")
    body = f"""
#ifndef {NAME}_H
#define {NAME}_H

#ifdef __cplusplus
extern "C" {{
#endif

typedef {real} {name}_real;

{chr(10).join(defines)}
#define {NAME}_CMD_MIN ({lo_s})  /* the fitted command range ({unit}); INFINITY is <math.h>'s */
#define {NAME}_CMD_MAX ({hi_s})
#define {NAME}_DRIVE_UNIT "{unit}"
{f"#define {NAME}_DT_S {_lit(dt_s, 'double')}  /* the loop period the code was generated for (s) */" if dt_s else ""}
#define {NAME}_OK 0         /* the command is the model's inverse */
#define {NAME}_CLAMPED 1    /* the command lay beyond the fitted range and was clamped to it */
#define {NAME}_NONFINITE 2  /* the desired angle was NaN or infinite: the last command repeated, state unchanged */

typedef struct {{
{fields}
    {name}_real cmd_last;  /* the last command returned ({unit}) */
    int status;  /* of the last step: {NAME}_OK, {NAME}_CLAMPED or {NAME}_NONFINITE */
}} {name}_state;

/* Start from rest (every operator unloaded, as the model's runs start). */
void {name}_init({name}_state *s);

/* The knob command ({unit}) for the next desired bending angle (deg). */
{name}_real {name}_step({name}_state *s, {name}_real desired_deg);

#ifdef __cplusplus
}}
#endif

#endif /* {NAME}_H */
"""
    return "\n".join(lines) + "\n" + re.sub(r"\n{3,}", "\n\n", body)


def _source(name, real, parts, version) -> str:
    NAME = name.upper()
    needs = set().union(*(p.needs for p in parts))
    helpers = "".join(_HELPERS[k] for k in ("rmin", "rmax") if k in needs)
    if "play_hold" in needs:
        helpers += _play_reference_code()
    if "play" in needs:
        helpers += _play_inverse_step_code()
    init_lines = [line for part in parts for line in part.init]
    uses_i = any("for (i" in line for line in init_lines)
    init = "\n".join(f"    {line}" for line in init_lines)
    calls = "\n".join(f"    {part.call}" for part in parts)
    code = "\n".join(part.code for part in parts)
    return f"""/* {name}.c: generated by endocal {version} (`endocal export c`); do not edit, regenerate.
   See {name}.h. */
#include "{name}.h"

#include <float.h>
#include <math.h>

/* one rounding per operation, as numpy and numba do: no fused multiply-add, whatever the flags
   (-march=native, ARM64). A fitted pure backlash has inverse weights near 1e9 (eq. 11), whose sums
   a fused multiply-add rounds 4e-6 deg away from the Python compensator's. */
#if defined(__clang__)
#pragma STDC FP_CONTRACT OFF
#elif defined(__GNUC__)
#pragma GCC optimize("fp-contract=off")
#elif defined(_MSC_VER)
#pragma fp_contract(off)
#endif

typedef {name}_real real_t;
typedef {name}_state STATE;

{helpers}
{code}
void {name}_init({name}_state *s)
{{
{"    int i;" + chr(10) if uses_i else ""}{init}
    s->cmd_last = 0;
    if (s->cmd_last < {NAME}_CMD_MIN) {{
        s->cmd_last = ({name}_real){NAME}_CMD_MIN;
    }} else if (s->cmd_last > {NAME}_CMD_MAX) {{
        s->cmd_last = ({name}_real){NAME}_CMD_MAX;
    }}
    s->status = {NAME}_OK;
}}

{name}_real {name}_step({name}_state *s, {name}_real desired_deg)
{{
    real_t y = desired_deg, v;
    if (!isfinite(desired_deg)) {{
        s->status = {NAME}_NONFINITE;
        return s->cmd_last;
    }}
{calls}
    s->status = {NAME}_OK;
    if (v < {NAME}_CMD_MIN) {{
        v = (real_t){NAME}_CMD_MIN;
        s->status = {NAME}_CLAMPED;
    }} else if (v > {NAME}_CMD_MAX) {{
        v = (real_t){NAME}_CMD_MAX;
        s->status = {NAME}_CLAMPED;
    }}
    s->cmd_last = v;
    return v;
}}
"""


def export_c(model_path, out_dir, *, real: str = "double", loop_hz: float | None = None, name: str | None = None,
             force: bool = False) -> CCompensator:
    """Read a model file and write its C99 compensator into ``out_dir`` (``endocal export c``).

    Parameters
    ----------
    model_path : path
        A model file (``endocal fit hysteresis --out``).
    out_dir : path
        Folder for ``NAME.h`` and ``NAME.c`` (created if missing).
    real : {"double", "float"}
    loop_hz : float, optional
        The control loop's rate (Hz); required when the model has a time-based effect (``rate``, ``creep``).
    name : str, optional
        C identifier prefix and file stem (default ``endocal_<axis>``).
    force : bool
        Overwrite existing files.

    Returns
    -------
    CCompensator
        With ``files`` set to the two paths written.

    Raises
    ------
    ModelError
        Unreadable model, an effect that cannot stream (named), a missing or bad ``loop_hz``; nothing is written.
    OutputExistsError, OutputPathError
    """
    from endocal.models import load_model

    dt_s = None
    if loop_hz is not None:
        if not (isinstance(loop_hz, (int, float)) and math.isfinite(loop_hz) and loop_hz > 0):
            raise ModelError(f"--loop-hz must be a positive rate in Hz, got {loop_hz!r}")
        dt_s = 1.0 / float(loop_hz)
    model = load_model(model_path)
    comp = generate_c(model, name=name, real=real, dt_s=dt_s, source=str(model_path))
    comp.write(out_dir, force=force)
    return comp


# ---------------------------------------------------------------------------------------------- compile and run
_DRIVER = """/* driver: the whole trajectory through {name}_step in one call (tests, bench) */
#include <stddef.h>
#include "{name}.h"

size_t {name}_run(const double *desired_deg, double *cmd, int *status, size_t n)
{{
    {name}_state st;
    size_t k;
    {name}_init(&st);
    for (k = 0; k < n; ++k) {{
        cmd[k] = (double){name}_step(&st, ({name}_real)desired_deg[k]);
        status[k] = st.status;
    }}
    return sizeof st;
}}
"""

#: flags of :func:`compile_c`: strict C99, every warning an error (the source itself turns fused
#: multiply-adds off, so the double code rounds as numpy and numba do, whatever the flags)
CFLAGS = ("-std=c99", "-O2", "-Wall", "-Wextra", "-pedantic", "-Werror", "-fPIC", "-shared")


def find_c_compiler() -> str | None:
    """The system C compiler: ``$CC``, else ``cc``, ``gcc`` or ``clang`` on the PATH (None if none)."""
    import os
    import shutil

    for cand in (os.environ.get("CC"), "cc", "gcc", "clang"):
        if cand and shutil.which(cand):
            return shutil.which(cand)
    return None


class CompiledCompensator:
    """A :class:`CCompensator` compiled into a shared library and loaded with ctypes.

    ``run(desired_deg)`` plays a whole trajectory through ``init`` and ``step`` in C (one
    ctypes call) and returns the commands and each tick's status; ``state_bytes`` is
    ``sizeof(PREFIX_state)``.
    """

    def __init__(self, library: Path, name: str):
        import ctypes

        import numpy as np

        self.library = Path(library)
        self._lib = ctypes.CDLL(str(self.library))
        fn = getattr(self._lib, f"{name}_run")
        dbl = np.ctypeslib.ndpointer(dtype=np.float64, flags="C_CONTIGUOUS")
        fn.argtypes = [dbl, dbl, np.ctypeslib.ndpointer(dtype=np.intc, flags="C_CONTIGUOUS"), ctypes.c_size_t]
        fn.restype = ctypes.c_size_t
        self._run = fn
        self.state_bytes = int(fn(np.zeros(0), np.zeros(0), np.zeros(0, dtype=np.intc), 0))

    def run(self, desired_deg):
        """Commands (n,) and statuses (n,) for a desired trajectory (deg), from rest."""
        import numpy as np

        x = np.ascontiguousarray(desired_deg, dtype=np.float64)
        cmd = np.empty_like(x)
        status = np.empty(x.size, dtype=np.intc)
        self._run(x, cmd, status, x.size)
        return cmd, status


def compile_c(comp: CCompensator, build_dir, *, cc: str | None = None, flags=()) -> CompiledCompensator:
    """Write ``comp`` and a driver into ``build_dir``, compile them with the system C compiler, load them.

    ``flags`` are added to :data:`CFLAGS` (e.g. ``("-march=native",)``).

    Raises
    ------
    ModelError
        No C compiler, or the compiler refused the code (its first lines in the message).
    """
    import subprocess

    cc = cc or find_c_compiler()
    if cc is None:
        raise ModelError("no C compiler found ($CC, cc, gcc, clang): install one (e.g. apt-get install gcc)")
    build = Path(build_dir)
    h_path, c_path = comp.write(build, force=True)
    driver = build / f"{comp.name}_driver.c"
    driver.write_text(_DRIVER.format(name=comp.name))
    lib = build / f"lib{comp.name}.so"
    proc = subprocess.run([cc, *CFLAGS, *flags, "-o", str(lib), str(c_path), str(driver), "-lm"], capture_output=True,
                          text=True)
    if proc.returncode != 0:
        first = " | ".join(proc.stderr.strip().splitlines()[:4])
        raise ModelError(f"{cc} refused {c_path}: {first}")
    return CompiledCompensator(lib, comp.name)
