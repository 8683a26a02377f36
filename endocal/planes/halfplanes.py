"""Plane of one half-plane sweep by SVD, and its deviation from the standard plane.

Duodenoscope paper, section 2.2. While a single knob pulls one wire, the distal end stays
in one plane through the probe axis. Stacking the in-plane vectors ``v_i`` (tip directions,
or tip positions, both in the base frame) as rows of ``V`` and decomposing

    V = U S W^T                                                       (duodenoscope paper, eq. 1)

the right-singular vector of the smallest singular value is the plane's normal ``n`` (the
direction of least variance). No centring: the motion plane contains the base origin
(directions all start there; a constant-curvature arc starts there too). The deviation of the
half-plane from its standard plane is the angle between the normals

    alpha_h = arccos(|n_h . n_std|)                                   (duodenoscope paper, eq. 2)

with ``n_std = x`` for the first-axis half-planes ``y+``/``y-`` (standard plane y-z) and
``n_std = y`` for ``x+``/``x-`` (standard plane x-z). The paper's text swaps the labels of
``n_X`` and ``n_Y`` in one sentence; what matters, and what is coded, is that each half-plane
is compared with the standard plane its knob is meant to bend in.

The paper's plane must contain the probe axis, which only holds while the other knob's bend is
exactly zero; a backlash-held residual bend tilts it. :func:`fit_half_plane` therefore also
offers (and defaults to) the same SVD on centred bending vectors, see its ``model``.

Besides the paper's unsigned angle we keep a *signed* deviation: the azimuth of the
half-plane's trace on the base ``x-y`` plane minus its nominal azimuth (``y+`` 90, ``y-`` -90,
``x+`` 0, ``x-`` 180 deg), counter-clockwise about ``+z`` positive. The compensator needs the
sign; for a plane that contains the probe axis ``|signed| == unsigned``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from endocal.errors import EndocalError

HALF_PLANES: tuple[str, ...] = ("y+", "y-", "x+", "x-")
NOMINAL_AZIMUTH_DEG: dict[str, float] = {"y+": 90.0, "y-": -90.0, "x+": 0.0, "x-": 180.0}
#: Index of the knob that moves in each half-plane (0: first axis ap/ud, 1: second axis ml/lr) and its sign.
KNOB_OF: dict[str, tuple[int, int]] = {"y+": (0, 1), "y-": (0, -1), "x+": (1, 1), "x-": (1, -1)}
_STANDARD_NORMAL = {"y+": np.array([1.0, 0.0, 0.0]), "y-": np.array([1.0, 0.0, 0.0]),
                    "x+": np.array([0.0, 1.0, 0.0]), "x-": np.array([0.0, 1.0, 0.0])}


class CalibrationError(EndocalError, ValueError):
    """Data cannot support a calibration (too little excursion, a half-plane missing, ...)."""


def check_half_plane(name: str) -> str:
    """Return ``name`` if it is one of ``y+ y- x+ x-``, else raise :class:`CalibrationError`."""
    if name not in HALF_PLANES:
        raise CalibrationError(f"unknown half-plane '{name}': use one of {', '.join(HALF_PLANES)}")
    return name


def wrap_deg(angle_deg):
    """Wrap an angle (or array) to (-180, 180] degrees."""
    return 180.0 - np.mod(180.0 - np.asarray(angle_deg, float), 360.0)


def knob_half_plane(knob: int, sign: float) -> str:
    """Half-plane a knob (0 first, 1 second) moving with the given sign sweeps."""
    return ("y" if knob == 0 else "x") + ("+" if sign > 0 else "-")


@dataclass(frozen=True)
class HalfPlaneFit:
    """Fitted motion plane of one half-plane.

    Attributes
    ----------
    half_plane : str
        ``y+``, ``y-``, ``x+`` or ``x-``.
    normal : (3,) array
        Unit normal in the base frame (duodenoscope eq. 1), oriented as ``z x trace``.
    azimuth_deg : float
        Direction of the half-plane's trace on the base x-y plane, degrees.
    deviation_deg : float
        Unsigned angle between the fitted and the standard plane (duodenoscope eq. 2), deg.
    deviation_signed_deg : float
        ``azimuth_deg`` minus the nominal azimuth, wrapped, counter-clockwise about +z, deg.
    tilt_deg : float
        ``"plane"`` model: angle between the probe axis and the fitted plane (0 when the plane
        contains it, as the paper assumes), deg.
    offset_deg : float
        ``"bend_line"`` model: distance of the sweep's line from zero bend (the other knob's
        residual bend), deg.
    excursion_deg : float
        Largest angle of the vectors from the probe axis, deg.
    rms_out_of_plane : float
        Scatter about the fit: RMS of ``n . v`` (vector units) for ``"plane"``, RMS distance
        from the line (deg of bend) for ``"bend_line"``.
    n_samples : int
    model : str
        ``"bend_line"`` or ``"plane"``.
    """

    half_plane: str
    normal: np.ndarray
    azimuth_deg: float
    deviation_deg: float
    deviation_signed_deg: float
    tilt_deg: float
    offset_deg: float
    excursion_deg: float
    rms_out_of_plane: float
    n_samples: int
    model: str


def excursion_deg(vectors: np.ndarray) -> float:
    """Largest angle between the given vectors and the probe axis ``+z``, degrees."""
    v = np.asarray(vectors, float)
    if len(v) == 0:
        return 0.0
    return float(np.degrees(np.max(np.arctan2(np.hypot(v[:, 0], v[:, 1]), v[:, 2]))))


MODELS = ("bend_line", "plane")


def bend_deg_from_vectors(vectors: np.ndarray, angle_scale=1.0) -> np.ndarray:
    """Bending vectors (deg) that point each vector away from the probe axis (constant curvature).

    A vector at angle ``theta`` from ``+z`` towards azimuth ``phi`` maps to
    ``angle_scale * theta * (cos phi, sin phi)``: for tip directions (``angle_scale=1``) that is
    the constant-curvature bending vector ``b``; a tip position's chord leaves the base at half
    the bend, so positions take ``angle_scale=2``.

    Parameters
    ----------
    vectors : (n, 3) array
    angle_scale : float or (n,) array

    Returns
    -------
    (n, 2) array
        ``(b_x, b_y)`` in degrees.
    """
    v = np.asarray(vectors, float)
    rho = np.hypot(v[:, 0], v[:, 1])
    theta = np.degrees(np.arctan2(rho, v[:, 2])) * np.asarray(angle_scale, float)
    safe = np.where(rho > 0, rho, 1.0)
    return np.where(rho[:, None] > 0, theta[:, None] * v[:, :2] / safe[:, None], 0.0)


def fit_half_plane(
    vectors_in_base: np.ndarray,
    half_plane: str,
    *,
    model: str = "bend_line",
    weights: np.ndarray | None = None,
    angle_scale=1.0,
    min_excursion_deg: float = 5.0,
    what: str = "vectors",
) -> HalfPlaneFit:
    """Fit the motion plane of one half-plane sweep (duodenoscope paper, eqs. 1-2).

    Two models:

    ``"plane"``
        The paper's eq. 1 as printed: SVD of the stacked vectors, no centring, so the plane
        passes through the base and contains the probe axis exactly when the other knob's
        bend is zero.
    ``"bend_line"`` (default)
        The same SVD on the *centred* bending vectors (:func:`bend_deg_from_vectors`): the
        sweep is a straight line ``b = beta u(psi) + b0`` in bend space and ``u(psi)`` its
        principal direction. With ``b0 = 0`` this is the paper's plane (a plane through
        ``z`` maps to a line through 0), but it also holds when the other knob keeps a
        residual bend ``b0`` (backlash: the knob is back at 0, the bend is not), which tilts
        the paper's plane and biases its deviation by degrees. ``offset_deg`` reports
        ``|b0|`` across the line.

    Parameters
    ----------
    vectors_in_base : (n, 3) array
        In-plane vectors in the base frame: tip directions (unit) or tip positions (mm).
    half_plane : str
        Which half-plane the vectors sweep (``y+``, ``y-``, ``x+``, ``x-``).
    model : {"bend_line", "plane"}
    weights : (n,) array, optional
        Non-negative row weights (e.g. inverse noise variance) for the SVD.
    angle_scale : float or (n,) array
        ``"bend_line"`` only: 1 for tip directions, 2 for tip positions (chords).
    min_excursion_deg : float
        Smallest largest-angle-from-the-axis that still defines a plane, degrees.
    what : str
        Words naming the vectors in error messages (``tip directions``, ``tip positions``).

    Returns
    -------
    HalfPlaneFit

    Raises
    ------
    CalibrationError
        Fewer than 3 vectors, or an excursion below ``min_excursion_deg`` (the message names
        the half-plane and the excursion seen).
    """
    check_half_plane(half_plane)
    if model not in MODELS:
        raise CalibrationError(f"unknown half-plane model '{model}': use one of {', '.join(MODELS)}")
    v = np.asarray(vectors_in_base, float)
    if v.ndim != 2 or v.shape[1] != 3:
        raise CalibrationError(f"half-plane '{half_plane}': {what} must have shape (n, 3), got {v.shape}")
    if len(v) < 3:
        raise CalibrationError(f"half-plane '{half_plane}': only {len(v)} {what} left to fit a plane (need at least 3)")
    seen = excursion_deg(v)
    if seen < min_excursion_deg:
        raise CalibrationError(
            f"half-plane '{half_plane}': the {what} move only {seen:.2f} deg from the probe axis, too little to fit "
            f"its plane (need at least {min_excursion_deg:g} deg); sweep that knob further"
        )
    sqrt_w = np.ones(len(v)) if weights is None else np.sqrt(np.asarray(weights, float))
    nominal = np.radians(NOMINAL_AZIMUTH_DEG[half_plane])
    if model == "plane":
        _, _, wt = np.linalg.svd(v * sqrt_w[:, None], full_matrices=False)  # duodenoscope eq. 1
        n = wt[-1]
        trace = np.array([-n[1], n[0]])  # the plane's trace on the base x-y plane
        if not np.linalg.norm(trace) > 1e-9:
            raise CalibrationError(f"half-plane '{half_plane}': the fitted plane is perpendicular to the probe axis")
        trace /= np.linalg.norm(trace)
        if trace @ v[:, :2].sum(axis=0) < 0:  # point it to the side the sweep went
            trace, n = -trace, -n
        deviation = float(np.degrees(np.arccos(min(1.0, abs(float(n @ _STANDARD_NORMAL[half_plane]))))))  # eq. 2
        tilt, offset = float(np.degrees(np.arcsin(min(1.0, abs(n[2]))))), 0.0
        rms = float(np.sqrt(np.mean((v @ n) ** 2)))
    else:
        b = bend_deg_from_vectors(v, angle_scale)
        w = sqrt_w**2
        centre = (w[:, None] * b).sum(axis=0) / w.sum()
        _, _, wt = np.linalg.svd((b - centre) * sqrt_w[:, None], full_matrices=False)  # eq. 1, centred, in bend space
        trace = wt[0]
        if trace @ [np.cos(nominal), np.sin(nominal)] < 0:  # deviations are within +-90 deg of nominal
            trace = -trace
        n = np.array([trace[1], -trace[0], 0.0])  # normal of the plane through z along the trace
        deviation = float(np.degrees(np.arccos(min(1.0, abs(float(n @ _STANDARD_NORMAL[half_plane]))))))  # eq. 2
        tilt = 0.0
        offset = float(abs(centre[0] * trace[1] - centre[1] * trace[0]))
        rms = float(np.sqrt(np.mean(((b - centre) @ wt[1]) ** 2)))
    azimuth = float(np.degrees(np.arctan2(trace[1], trace[0])))
    return HalfPlaneFit(
        half_plane=half_plane,
        normal=n,
        azimuth_deg=azimuth,
        deviation_deg=deviation,
        deviation_signed_deg=float(wrap_deg(azimuth - NOMINAL_AZIMUTH_DEG[half_plane])),
        tilt_deg=tilt,
        offset_deg=offset,
        excursion_deg=seen,
        rms_out_of_plane=rms,
        n_samples=len(v),
        model=model,
    )
