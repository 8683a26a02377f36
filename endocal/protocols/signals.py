"""Pure excitation signal generators.

Every function here maps sample times ``t_s`` (seconds, measured from the start of the
signal, any shape) to values in the unit of ``amplitude`` (knob degrees in endocal), with
no state, no probe and no I/O. :mod:`endocal.protocols.protocol` places these signals on
a timeline, per axis, and checks them against a probe.

Conventions
-----------
- Every oscillating signal starts at zero with a rising slope (a zero crossing), so a
  servo resting at the offset is never asked to jump.
- Smooth transitions use the raised cosine ``s(u) = (1 - cos(pi u)) / 2`` on ``u in [0, 1]``:
  zero slope at both ends and a peak slope of ``pi / 2`` times the mean slope.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import brentq, minimize_scalar

#: Raised-cosine peak speed over mean speed: a ramp of height h lasting d peaks at (pi/2) h / d.
RAISED_COSINE_PEAK_RATIO = np.pi / 2


def raised_cosine(u: np.ndarray) -> np.ndarray:
    """Smooth step from 0 to 1: ``(1 - cos(pi u)) / 2`` for ``u`` clipped to ``[0, 1]``.

    Parameters
    ----------
    u : array
        Normalised time, dimensionless.

    Returns
    -------
    array
        Same shape as ``u``; exactly 0 at ``u <= 0`` and exactly 1 at ``u >= 1``.
    """
    u = np.clip(np.asarray(u, float), 0.0, 1.0)
    return 0.5 * (1.0 - np.cos(np.pi * u))


def ramp(t_s: np.ndarray, start: float, stop: float, duration_s: float) -> np.ndarray:
    """Raised-cosine move from ``start`` to ``stop`` over ``duration_s``, then holding ``stop``.

    Parameters
    ----------
    t_s : array
        Time since the start of the move, s.
    start, stop : float
        Levels before and after, in the signal's unit.
    duration_s : float
        Length of the move, s (``0`` gives an immediate step).

    Returns
    -------
    array
        ``start`` at ``t_s <= 0``, ``stop`` exactly at ``t_s >= duration_s``.
    """
    t_s = np.asarray(t_s, float)
    if duration_s <= 0:
        return np.where(t_s < 0, start, stop).astype(float)
    s = raised_cosine(t_s / duration_s)
    return start * (1.0 - s) + stop * s


def ramp_duration_s(height: float, rate_per_s: float) -> float:
    """Duration of a raised-cosine ramp of ``height`` whose peak speed is ``rate_per_s``.

    Parameters
    ----------
    height : float
        Size of the move (sign ignored), e.g. deg.
    rate_per_s : float
        Peak speed allowed, e.g. deg/s (> 0).

    Returns
    -------
    float
        ``(pi / 2) * |height| / rate_per_s`` in s.
    """
    return RAISED_COSINE_PEAK_RATIO * abs(height) / rate_per_s


def sine(t_s: np.ndarray, amplitude: float, frequency_hz: float) -> np.ndarray:
    """``amplitude * sin(2 pi f t)``: starts at a zero crossing, rising.

    Parameters
    ----------
    t_s : array
        Time, s.
    amplitude : float
        Peak value.
    frequency_hz : float
        Frequency, Hz.
    """
    return amplitude * np.sin(2.0 * np.pi * frequency_hz * np.asarray(t_s, float))


def damped_sine(t_s: np.ndarray, amplitude: float, frequency_hz: float, period_s: float) -> np.ndarray:
    """The damped sine identification input of the duodenoscope paper.

    Cheng et al., Machines 2024, 12(8), 500, section 3.2 (the PI identification input)::

        theta_input = A sin(2 pi f t)                          for 0 <= t < 2T
        theta_input = A sin(2 pi f t) exp(-(t - 2T) / (5T))    for 2T <= t <= 7T

    with ``T = 20 s`` and ``f = 0.05 Hz`` in the paper. Outside ``[0, 7T]`` the signal is 0.

    Parameters
    ----------
    t_s : array
        Time, s.
    amplitude : float
        ``A``, the peak of the undamped part.
    frequency_hz : float
        ``f``, Hz.
    period_s : float
        ``T``, s: two of them undamped, then five of exponential decay with time constant ``5T``.

    Returns
    -------
    array
        Same shape as ``t_s``.
    """
    t_s = np.asarray(t_s, float)
    T = period_s
    base = amplitude * np.sin(2.0 * np.pi * frequency_hz * t_s)  # duodenoscope paper, sec. 3.2, 0 <= t < 2T
    decay = np.exp(-(t_s - 2.0 * T) / (5.0 * T))  # duodenoscope paper, sec. 3.2, 2T <= t <= 7T
    out = np.where(t_s < 2.0 * T, base, base * decay)
    return np.where((t_s >= 0.0) & (t_s <= 7.0 * T), out, 0.0)


def stepped_frequency_phase_rad(t_s: np.ndarray, frequencies_hz: list[float], cycles: int) -> np.ndarray:
    """Phase of a sine that plays ``cycles`` periods at each frequency in turn, phase-continuous.

    Parameters
    ----------
    t_s : array
        Time, s.
    frequencies_hz : list of float
        The frequencies, in playing order, Hz.
    cycles : int
        Whole periods played at each frequency.

    Returns
    -------
    array
        ``2 pi * integral of f(t) dt`` in rad; it is continuous (with a kink in slope) at
        each change of frequency, which falls on a zero crossing because every segment
        holds whole periods. Held at the final phase after the last segment.
    """
    t_s = np.asarray(t_s, float)
    f = np.asarray(frequencies_hz, float)
    seg_s = cycles / f
    starts_s = np.concatenate([[0.0], np.cumsum(seg_s)[:-1]])
    phase_cycles = np.zeros_like(t_s)
    for i in range(f.size):
        local = np.clip(t_s - starts_s[i], 0.0, seg_s[i])
        phase_cycles = phase_cycles + f[i] * local
    return 2.0 * np.pi * phase_cycles


def stepped_frequency_sine(t_s: np.ndarray, amplitude: float, frequencies_hz: list[float], cycles: int) -> np.ndarray:
    """Sine whose frequency changes every ``cycles`` periods (the thesis's validation input).

    Parameters
    ----------
    t_s : array
        Time, s.
    amplitude : float
        Peak value.
    frequencies_hz : list of float
        Frequencies in playing order, Hz.
    cycles : int
        Periods per frequency.

    Returns
    -------
    array
        ``amplitude * sin(phase(t))`` with the phase of :func:`stepped_frequency_phase_rad`;
        total length ``sum(cycles / f)`` s.
    """
    return amplitude * np.sin(stepped_frequency_phase_rad(t_s, frequencies_hz, cycles))


def triangle(t_s: np.ndarray, amplitude: float, period_s: float) -> np.ndarray:
    """Triangle wave 0 -> +A -> -A -> 0 per period, slopes ``+-4 A / period``.

    Parameters
    ----------
    t_s : array
        Time, s.
    amplitude : float
        Peak value.
    period_s : float
        Period, s.

    Returns
    -------
    array
        Exactly piecewise linear (evaluated per segment, not through ``arcsin(sin)``,
        which loses precision at the corners).
    """
    u = np.mod(np.asarray(t_s, float) / period_s, 1.0)
    return amplitude * np.where(u < 0.25, 4.0 * u, np.where(u < 0.75, 2.0 - 4.0 * u, 4.0 * u - 4.0))


def chirp_phase_rad(t_s: np.ndarray, f0_hz: float, f1_hz: float, duration_s: float, method: str) -> np.ndarray:
    """Phase of a frequency sweep from ``f0_hz`` at ``t = 0`` to ``f1_hz`` at ``t = duration_s``.

    ``linear``: ``f(t) = f0 + (f1 - f0) t / D``, phase ``2 pi (f0 t + (f1 - f0) t^2 / (2 D))``.
    ``log``: ``f(t) = f0 k^(t / D)`` with ``k = f1 / f0``, phase
    ``2 pi f0 D (k^(t / D) - 1) / ln k``.

    Parameters
    ----------
    t_s : array
        Time, s.
    f0_hz, f1_hz : float
        Start and end frequency, Hz (both > 0 for ``log``).
    duration_s : float
        ``D``, s.
    method : {"linear", "log"}
        How the instantaneous frequency moves.

    Returns
    -------
    array
        Phase in rad, 0 at ``t = 0``; its derivative over ``2 pi`` is the instantaneous frequency.
    """
    t_s = np.asarray(t_s, float)
    if method == "linear":
        return 2.0 * np.pi * (f0_hz * t_s + (f1_hz - f0_hz) * t_s**2 / (2.0 * duration_s))
    if method == "log":
        if f0_hz <= 0 or f1_hz <= 0:
            raise ValueError("a logarithmic chirp needs f0_hz > 0 and f1_hz > 0")
        if f1_hz == f0_hz:
            return 2.0 * np.pi * f0_hz * t_s
        log_k = np.log(f1_hz / f0_hz)
        return 2.0 * np.pi * f0_hz * duration_s * np.expm1(log_k * t_s / duration_s) / log_k
    raise ValueError(f"chirp method must be 'linear' or 'log', got {method!r}")


def chirp_frequency_hz(t_s: np.ndarray, f0_hz: float, f1_hz: float, duration_s: float, method: str) -> np.ndarray:
    """Instantaneous frequency of :func:`chirp_phase_rad`, Hz."""
    t_s = np.asarray(t_s, float)
    if method == "linear":
        return f0_hz + (f1_hz - f0_hz) * t_s / duration_s
    if method == "log":
        return f0_hz * (f1_hz / f0_hz) ** (t_s / duration_s)
    raise ValueError(f"chirp method must be 'linear' or 'log', got {method!r}")


def chirp(
    t_s: np.ndarray, amplitude: float, f0_hz: float, f1_hz: float, duration_s: float, method: str, fade_s: float
) -> np.ndarray:
    """Swept sine ``A sin(phase(t))``, faded out to zero over its last ``fade_s``.

    It starts at a zero crossing; its end phase is arbitrary, so a raised-cosine fade
    brings it back to zero. The fade scales the amplitude only: zero crossings, hence
    the instantaneous frequency, are untouched.

    Parameters
    ----------
    t_s : array
        Time, s (the signal is 0 outside ``[0, duration_s]``).
    amplitude : float
        Peak value.
    f0_hz, f1_hz, duration_s, method
        See :func:`chirp_phase_rad`.
    fade_s : float
        Length of the fade-out, s (``<= duration_s``).
    """
    t_s = np.asarray(t_s, float)
    envelope = 1.0 - raised_cosine((t_s - (duration_s - fade_s)) / fade_s) if fade_s > 0 else np.ones_like(t_s)
    out = amplitude * envelope * np.sin(chirp_phase_rad(t_s, f0_hz, f1_hz, duration_s, method))
    return np.where((t_s >= 0.0) & (t_s <= duration_s), out, 0.0)


class BandLimitedRandom:
    """Seeded, band-limited, non-periodic random signal that starts and ends at zero.

    A multisine: equal-amplitude cosines at every frequency ``k / D`` inside
    ``[f_lo_hz, f_hi_hz]`` (``D`` the duration) with uniformly random phases, which is
    the deterministic counterpart of band-pass filtered white noise (flat spectrum over
    the band, Gaussian-like amplitude distribution). The sum is periodic in ``D``, so it
    is circularly shifted to start at one of its own upward zero crossings: it then also
    ends at zero at ``t = D``, with no window to leak energy outside the band. It never
    repeats within the record, and is scaled so that its peak magnitude is ``amplitude``.

    Parameters
    ----------
    amplitude : float
        Peak magnitude of the signal.
    f_lo_hz, f_hi_hz : float
        Band edges, Hz; at least one multiple of ``1 / duration_s`` must lie in between.
    duration_s : float
        Record length ``D``, s.
    seed : int or sequence of int
        Seed of the phases (anything :func:`numpy.random.default_rng` takes); the same
        seed always gives the same signal.
    """

    #: Most cosine evaluations the construction may take (grid points x components, ~10 s here):
    #: an hour-long record over 0-2 Hz needs 1.7e9.
    MAX_WORK = 4e9

    def __init__(self, amplitude: float, f_lo_hz: float, f_hi_hz: float, duration_s: float, seed) -> None:
        work = 32.0 * f_hi_hz * duration_s * max(f_hi_hz - f_lo_hz, 0.0) * duration_s
        if not work <= self.MAX_WORK:
            raise ValueError(f"a random signal of {duration_s:g} s over [{f_lo_hz:g}, {f_hi_hz:g}] Hz has too many "
                             "components to build: shorten the record, narrow the band, or record it in parts")
        k = np.arange(int(np.ceil(f_lo_hz * duration_s - 1e-9)), int(np.floor(f_hi_hz * duration_s + 1e-9)) + 1)
        k = k[k > 0]
        if k.size == 0:
            raise ValueError(
                f"no frequency k/{duration_s:g} s lies in the band [{f_lo_hz:g}, {f_hi_hz:g}] Hz: widen the band or lengthen the signal"
            )
        self.duration_s = float(duration_s)
        self.frequencies_hz = k / self.duration_s
        self.phases_rad = np.random.default_rng(seed).uniform(0.0, 2.0 * np.pi, k.size)
        # Dense grid: 32 points per period of the highest frequency finds every zero crossing and the peak's basin.
        n_grid = int(np.ceil(32 * self.frequencies_hz[-1] * self.duration_s)) + 1
        grid = np.linspace(0.0, self.duration_s, n_grid)
        p = self._multisine(grid)
        up = np.flatnonzero((p[:-1] < 0.0) & (p[1:] >= 0.0))
        if up.size == 0:  # a zero-mean periodic signal always crosses zero upwards once per period
            up = np.array([int(np.argmin(np.abs(p)))])
            self.shift_s = float(grid[up[0]])
        else:
            i = int(up[0])
            self.shift_s = float(brentq(self._multisine, grid[i], grid[i + 1], xtol=1e-14, rtol=1e-15))
        j = int(np.argmax(np.abs(p)))
        lo, hi = grid[max(j - 1, 0)], grid[min(j + 1, n_grid - 1)]
        best = minimize_scalar(lambda t: -abs(self._multisine(t)), bounds=(lo, hi), method="bounded", options={"xatol": 1e-10})
        peak = max(abs(float(self._multisine(best.x))), float(np.abs(p).max()))
        self.scale = amplitude / peak

    def _multisine(self, t_s):
        t = np.asarray(t_s, float)
        if t.ndim == 0:
            return np.cos(2.0 * np.pi * t * self.frequencies_hz + self.phases_rad).sum()
        # in blocks of rows, so a long record never holds the whole (time x component) table
        rows = max(1, 4_000_000 // self.frequencies_hz.size)
        return np.concatenate([
            np.cos(2.0 * np.pi * np.multiply.outer(t[i:i + rows], self.frequencies_hz) + self.phases_rad).sum(axis=-1)
            for i in range(0, max(t.size, 1), rows)]) if t.size else np.zeros(0)

    def __call__(self, t_s: np.ndarray) -> np.ndarray:
        """Signal values at ``t_s`` (s); zero outside ``[0, duration_s]``."""
        t_s = np.asarray(t_s, float)
        out = self.scale * self._multisine(t_s + self.shift_s)
        return np.where((t_s >= 0.0) & (t_s <= self.duration_s), out, 0.0)


def band_limited_random(
    t_s: np.ndarray, amplitude: float, f_lo_hz: float, f_hi_hz: float, duration_s: float, seed: int
) -> np.ndarray:
    """Values of :class:`BandLimitedRandom` at ``t_s``; see there for the construction."""
    return BandLimitedRandom(amplitude, f_lo_hz, f_hi_hz, duration_s, seed)(t_s)


def staircase_levels(amplitude: float, steps: int) -> np.ndarray:
    """Levels of an up-and-down staircase: 0 up to ``+A``, down to ``-A``, back to 0.

    Parameters
    ----------
    amplitude : float
        Top level ``A``.
    steps : int
        Steps between 0 and ``A``.

    Returns
    -------
    (4 * steps,) array
        ``A/n, 2A/n, ..., A, ..., -A, ..., -A/n, 0`` (the starting 0 is not included).
    """
    h = amplitude / steps
    up = h * np.arange(1, steps + 1)
    down = h * np.arange(steps - 1, -steps - 1, -1)
    back = h * np.arange(-steps + 1, 1)
    return np.concatenate([up, down, back])


def circle(t_s: np.ndarray, radius: float, frequency_hz: float, cycles: int, spiral_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Circle in the plane of two axes, spiralling in from and out to the centre.

    The radius grows from 0 to ``radius`` over ``spiral_s`` (raised cosine) while the
    angle already turns, holds for ``cycles`` full turns, then shrinks back to 0 over
    ``spiral_s``. The angle turns at ``frequency_hz`` throughout.

    Parameters
    ----------
    t_s : array
        Time, s.
    radius : float
        Radius of the steady circle.
    frequency_hz : float
        Turns per second.
    cycles : int
        Full turns at the full radius.
    spiral_s : float
        Duration of the spiral in and of the spiral out, s.

    Returns
    -------
    first, second : arrays
        ``r(t) sin(2 pi f t)`` and ``r(t) cos(2 pi f t)``: both 0 at the start and the
        end (where ``r = 0``); total duration ``2 spiral_s + cycles / frequency_hz``.
    """
    t_s = np.asarray(t_s, float)
    steady_s = cycles / frequency_hz
    total_s = 2.0 * spiral_s + steady_s
    r = radius * circle_envelope(t_s, spiral_s, total_s)
    angle = 2.0 * np.pi * frequency_hz * t_s
    return r * np.sin(angle), r * np.cos(angle)


def circle_envelope(t_s: np.ndarray, fade_s: float, total_s: float) -> np.ndarray:
    """Envelope rising 0 -> 1 over ``fade_s``, 1 until ``total_s - fade_s``, then falling to 0.

    Raised-cosine edges; 0 outside ``[0, total_s]``. With ``fade_s = 0`` it is 1 on the record.
    """
    t_s = np.asarray(t_s, float)
    if fade_s <= 0:
        return np.where((t_s >= 0.0) & (t_s <= total_s), 1.0, 0.0)
    rise = raised_cosine(t_s / fade_s)
    fall = 1.0 - raised_cosine((t_s - (total_s - fade_s)) / fade_s)
    return np.where((t_s >= 0.0) & (t_s <= total_s), np.minimum(rise, fall), 0.0)


def lissajous(
    t_s: np.ndarray, amplitude: float, frequencies_hz: tuple[float, float], phase_deg: float, duration_s: float, fade_s: float
) -> tuple[np.ndarray, np.ndarray]:
    """Lissajous figure ``(A sin(2 pi f1 t), A sin(2 pi f2 t + phase))`` under a fade-in/out envelope.

    Parameters
    ----------
    t_s : array
        Time, s.
    amplitude : float
        Peak of each axis.
    frequencies_hz : (float, float)
        Frequency of the first and of the second axis, Hz.
    phase_deg : float
        Phase lead of the second axis, deg (90 with equal frequencies draws a circle).
    duration_s : float
        Length, s.
    fade_s : float
        Raised-cosine fade in and out, s, so both axes start and end at 0.
    """
    t_s = np.asarray(t_s, float)
    env = amplitude * circle_envelope(t_s, fade_s, duration_s)
    f1, f2 = frequencies_hz
    return env * np.sin(2.0 * np.pi * f1 * t_s), env * np.sin(2.0 * np.pi * f2 * t_s + np.radians(phase_deg))
