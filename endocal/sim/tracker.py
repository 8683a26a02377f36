"""Simulated EM tracker: tip and base sensor frames with noise, latency, slip and dropouts.

Frames ``k = 0, 1, 2, ...`` are stamped on the motor clock at ``t_k = k / rate_hz``; frame
``k`` shows the probe as it was at ``t_k - latency`` (interpolated between motor ticks).
Poses compose as

    base2tracker = mount2tracker * probe_motion(translation along z, rotation about z)
    tip2tracker  = base2tracker * tip2base(bend)            (constant curvature)

The base sensor reports ``base2tracker * slip`` where ``slip`` is the ``[drift]`` sensor slip
(a rotation growing linearly in time), so the measured eq.-1 angles drift by the configured
rates while the true bend does not.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from endocal.kinematics import tip_pose_in_base
from endocal.sim.config import TrackerConfig


def frame_indices(k_next: int, t_end_s: float, rate_hz: float) -> np.ndarray:
    """Frame numbers ``k >= k_next`` with ``k / rate_hz <= t_end_s`` (exact float comparison)."""
    k_max = int(np.floor(t_end_s * rate_hz))
    while (k_max + 1) / rate_hz <= t_end_s:
        k_max += 1
    while k_max >= k_next and k_max / rate_hz > t_end_s:
        k_max -= 1
    return np.arange(k_next, k_max + 1, dtype=np.int64)


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of scalar-first quaternions, broadcast over leading axes."""
    aw, ax, ay, az = np.moveaxis(np.asarray(a, float), -1, 0)
    bw, bx, by, bz = np.moveaxis(np.asarray(b, float), -1, 0)
    return np.stack([aw * bw - ax * bx - ay * by - az * bz,
                     aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw], axis=-1)


def quat_from_rotvec(rotvec: np.ndarray) -> np.ndarray:
    """Scalar-first unit quaternions of rotation vectors (n, 3) (rad), exact near zero."""
    v = np.asarray(rotvec, float)
    angle = np.linalg.norm(v, axis=-1)
    half = 0.5 * angle
    small = angle < 1e-6
    # sin(a/2)/a with its series where a -> 0.
    k = np.where(small, 0.5 - angle**2 / 48.0, np.sin(half) / np.where(small, 1.0, angle))
    return np.concatenate([np.cos(half)[..., None], v * k[..., None]], axis=-1)


def quat_apply(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors ``v`` (n, 3) by unit quaternions ``q`` (n, 4), scalar first."""
    w = q[..., :1]
    u = q[..., 1:]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def slip_quat(t_s: np.ndarray, drift_deg_per_min: tuple[float, float]) -> np.ndarray:
    """Base-sensor slip (scalar-first quaternions) at times ``t_s`` that shifts the measured
    eq.-1 angles by ``rate * t``.

    A rotation of the tip-in-base vector by ``-delta_1`` about ``x`` adds ``delta_1`` to the
    first axis' angle ``atan2(y, z)``; one by ``+delta_2`` about ``y`` adds ``delta_2`` to the
    second's ``atan2(x, z)``. The sensor reports ``base2tracker * slip``, so the measured
    tip-in-base is ``slip^-1 tip_in_base`` and ``slip^-1 = Rx(-delta_1) Ry(delta_2)``, i.e.
    ``slip = Ry(-delta_2) Rx(delta_1)``.

    The shift is exact for a straight tip and for a tip bent in the first axis' plane; a tip
    bent out of that plane by ``x`` also sees ``delta_2`` change its first angle by about
    ``delta_2 * x / z`` (the second rotation tilts the tip vector before the first).
    """
    minutes = np.asarray(t_s, float) / 60.0
    d1 = np.radians(drift_deg_per_min[0] * minutes)
    d2 = np.radians(drift_deg_per_min[1] * minutes)
    z = np.zeros_like(d1)
    return quat_mul(quat_from_rotvec(np.column_stack([z, -d2, z])), quat_from_rotvec(np.column_stack([d1, z, z])))


def sensor_frames(
    t_frame_s: np.ndarray,
    state: np.ndarray,
    length_mm: float,
    cfg: TrackerConfig,
    drift_deg_per_min: tuple[float, float] | None,
    rng_pos: np.random.Generator,
    rng_rot: np.random.Generator,
    rng_valid: np.random.Generator,
    t_source_s: np.ndarray,
) -> dict[str, np.ndarray]:
    """Tracker rows (long format, tip then base per frame) for frames at ``t_frame_s``.

    Parameters
    ----------
    t_frame_s : (m,) array
        Frame stamps on the motor clock (s).
    state : (m, 4) array
        ``bend_x_rad, bend_y_rad, translation_mm, rotation_rad`` at the frames' source times.
    length_mm : float
        Bending length.
    cfg : TrackerConfig
    drift_deg_per_min : pair of float or None
        Sensor slip rates (``[drift]``), None when off.
    rng_pos, rng_rot, rng_valid : numpy Generators
        Separate streams so that chunking never changes which draw goes where.
    t_source_s : (m,) array
        Times the frames show (``t_frame_s - latency``), for the slip.

    Returns
    -------
    dict of (2m,) arrays
        ``t_s, sensor, x_mm, y_mm, z_mm, qw, qx, qy, qz, valid``; invalid frames carry NaN.
    """
    m = t_frame_s.size
    if m == 0:
        return empty_frames()
    # Draw first, always the same amount per frame, so the streams stay aligned across chunks.
    pos_noise = rng_pos.standard_normal((m, 2, 3)) * (cfg.noise_mm / np.sqrt(3.0))
    rot_noise = rng_rot.standard_normal((m, 2, 3)) * (np.radians(cfg.orientation_noise_deg) / np.sqrt(3.0))
    valid = rng_valid.random((m, 2)) >= cfg.invalid_rate

    tip_in_base, tip2base = tip_pose_in_base(state[:, 0], state[:, 1], length_mm)  # constant curvature
    mount_q = Rotation.from_euler("xyz", cfg.mount_rpy_deg, degrees=True).as_quat(scalar_first=True)
    zeros = np.zeros(m)
    spin_q = np.column_stack([np.cos(0.5 * state[:, 3]), zeros, zeros, np.sin(0.5 * state[:, 3])])
    base2tracker = quat_mul(mount_q, spin_q)
    base_mm = np.asarray(cfg.mount_xyz_mm, float) + quat_apply(
        np.broadcast_to(mount_q, (m, 4)), np.column_stack([zeros, zeros, state[:, 2]]))
    tip_mm = base_mm + quat_apply(base2tracker, tip_in_base)
    tip2tracker = quat_mul(base2tracker, tip2base.as_quat(scalar_first=True))
    base_reported = base2tracker if drift_deg_per_min is None else quat_mul(base2tracker, slip_quat(t_source_s, drift_deg_per_min))

    pos = np.stack([tip_mm, base_mm], axis=1) + pos_noise  # (m, 2, 3)
    quat = np.stack([quat_mul(quat_from_rotvec(rot_noise[:, 0]), tip2tracker),
                     quat_mul(quat_from_rotvec(rot_noise[:, 1]), base_reported)], axis=1)
    pos[~valid] = np.nan
    quat[~valid] = np.nan
    pos = pos.reshape(2 * m, 3)
    quat = quat.reshape(2 * m, 4)
    return {
        "t_s": np.repeat(np.asarray(t_frame_s, float), 2),
        "sensor": np.tile(np.array(["tip", "base"], dtype=object), m),
        "x_mm": pos[:, 0],
        "y_mm": pos[:, 1],
        "z_mm": pos[:, 2],
        "qw": quat[:, 0],
        "qx": quat[:, 1],
        "qy": quat[:, 2],
        "qz": quat[:, 3],
        "valid": valid.reshape(2 * m),
    }


def empty_frames() -> dict[str, np.ndarray]:
    """A tracker chunk with no rows (a chunk shorter than one frame period)."""
    out = {k: np.empty(0) for k in ("t_s", "x_mm", "y_mm", "z_mm", "qw", "qx", "qy", "qz")}
    out["sensor"] = np.empty(0, dtype=object)
    out["valid"] = np.empty(0, dtype=bool)
    return {k: out[k] for k in ("t_s", "sensor", "x_mm", "y_mm", "z_mm", "qw", "qx", "qy", "qz", "valid")}
