"""Forward and inverse kinematics of the whole probe: 4 DoF <-> tip pose in the tracker frame.

The thesis's Task Space Control (thesis section 2.2, figure 5) drives the tip through four
joints: translation ``l`` along the probe axis, rotation ``phi`` about it, and the two
projected bending angles ``theta_first`` (AP / UD) and ``theta_second`` (ML / LR) of eq. 1.

Frames
------
``base_home``
    The base sensor's frame at translation 0 and rotation 0 (``z`` along the probe,
    distal), placed in the tracker frame by ``base_home2tracker`` and
    ``base_home_in_tracker_mm``.
``base``
    The base frame after the probe has moved: ``base2tracker = base_home2tracker @ Rz(phi)``
    with origin ``base_home_in_tracker_mm + base_home2tracker @ (0, 0, l)``.
``tip``
    The constant-curvature tip frame in ``base`` (:mod:`endocal.kinematics.constant_curvature`),
    reached by the bending vector ``b`` that :func:`endocal.kinematics.inverse.bend_from_angles_rad`
    derives from the eq. 1 angles.

Redundancy
----------
Tip position and direction depend on ``phi`` and the bending azimuth only through their
sum, so they fix three combinations of the four joints. :meth:`ProbeKinematics.inverse`
therefore takes either a target position with the rotation held at a given value, or a
full tip pose (position and orientation, which also fixes the roll and so ``phi``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from endocal.errors import ConfigError, LimitError
from endocal.kinematics.constant_curvature import tip_pose_in_base
from endocal.kinematics.inverse import (
    MAX_UNIQUE_BEND_RAD,
    angles_from_bend_deg,
    bend_from_angles_rad,
    bend_from_lateral_offset_rad,
    lateral_offset_mm,
)
from endocal.probe import ProbeConfig

_Z = np.array([0.0, 0.0, 1.0])


class UnreachableError(LimitError):
    """A target tip pose lies outside the probe's workspace.

    Attributes
    ----------
    index : int
        First target (row) that is out of reach.
    nearest_tip_in_tracker_mm : (n, 3) array
        For every target, the nearest reachable tip position (equal to the target where it
        is reachable), mm.
    nearest : ProbeJoints
        Joint values that reach ``nearest_tip_in_tracker_mm``.
    """

    def __init__(self, message: str, index: int, nearest_tip_in_tracker_mm: np.ndarray, nearest: ProbeJoints):
        super().__init__(message)
        self.index = index
        self.nearest_tip_in_tracker_mm = nearest_tip_in_tracker_mm
        self.nearest = nearest


@dataclass(frozen=True)
class ProbeJoints:
    """Joint values of the probe, each an ``(n,)`` array.

    ``translation_mm`` along the probe axis, ``rotation_deg`` about it, and the signed eq. 1
    bending angles ``theta_first_deg`` (y-z plane) and ``theta_second_deg`` (x-z plane).
    """

    translation_mm: np.ndarray
    rotation_deg: np.ndarray
    theta_first_deg: np.ndarray
    theta_second_deg: np.ndarray


@dataclass(frozen=True)
class ProbePose:
    """Tip pose in the tracker frame: ``tip_in_tracker_mm`` (n, 3), unit ``tip_dir_in_tracker``
    (n, 3) (the tip's ``z`` axis) and ``tip2tracker`` (scipy Rotation of length n)."""

    tip_in_tracker_mm: np.ndarray
    tip_dir_in_tracker: np.ndarray
    tip2tracker: Rotation


def _wrap_deg(angle_deg: np.ndarray) -> np.ndarray:
    """Wrap to (-180, 180]."""
    return 180.0 - np.mod(180.0 - np.asarray(angle_deg, float), 360.0)


class ProbeKinematics:
    """Constant-curvature kinematics of a 4-DoF probe (thesis section 2.3).

    Parameters
    ----------
    length_mm : float
        Arc length of the bending section, mm.
    base_home_in_tracker_mm : (3,) array_like
        Base sensor position at translation 0 / rotation 0, in the tracker frame, mm.
    base_home2tracker_quat_wxyz : (4,) array_like
        Base sensor orientation at translation 0 / rotation 0 (scalar first).
    max_bend_deg : float, optional
        Largest total bend the section reaches, degrees, at most 180. Default: 133.56 deg,
        the largest bend for which a tip position gives a unique bend.
    translation_limits_mm, rotation_limits_deg : (min, max), optional
        Joint ranges; ``None`` leaves the joint unlimited.
    """

    def __init__(
        self,
        length_mm: float,
        base_home_in_tracker_mm=(0.0, 0.0, 0.0),
        base_home2tracker_quat_wxyz=(1.0, 0.0, 0.0, 0.0),
        max_bend_deg: float | None = None,
        translation_limits_mm: tuple[float, float] | None = None,
        rotation_limits_deg: tuple[float, float] | None = None,
    ):
        if not length_mm > 0:
            raise ConfigError(f"length_mm must be positive, got {length_mm}")
        if max_bend_deg is not None and not 0 < max_bend_deg <= 180:
            raise ConfigError(f"max_bend_deg must lie in (0, 180] deg, got {max_bend_deg}")
        origin = np.asarray(base_home_in_tracker_mm, float)
        quat = np.asarray(base_home2tracker_quat_wxyz, float)
        if origin.shape != (3,) or quat.shape != (4,) or not np.linalg.norm(quat) > 0:
            raise ConfigError("base_home_in_tracker_mm must be 3 numbers and base_home2tracker_quat_wxyz 4 (non-zero)")
        for name, lim in (("translation_limits_mm", translation_limits_mm), ("rotation_limits_deg", rotation_limits_deg)):
            if lim is not None and not lim[0] < lim[1]:
                raise ConfigError(f"{name} must be (min, max) with min < max, got {lim}")
        self.length_mm = float(length_mm)
        self.base_home_in_tracker_mm = origin
        self.base_home2tracker = Rotation.from_quat(quat, scalar_first=True)
        self.max_bend_deg = float(np.degrees(MAX_UNIQUE_BEND_RAD)) if max_bend_deg is None else float(max_bend_deg)
        self.translation_limits_mm = translation_limits_mm
        self.rotation_limits_deg = rotation_limits_deg

    @classmethod
    def from_probe(cls, probe: ProbeConfig, **kwargs) -> ProbeKinematics:
        """Kinematics of a configured probe: its bending length and translation/rotation limits.

        ``kwargs`` go to the constructor (``base_home_in_tracker_mm``, ``base_home2tracker_quat_wxyz``,
        ``max_bend_deg``).
        """
        return cls(
            probe.bending_length_mm,
            translation_limits_mm=tuple(probe.translation_limits_mm),
            rotation_limits_deg=tuple(probe.rotation_limits_deg),
            **kwargs,
        )

    # -- helpers ---------------------------------------------------------------------------
    def _check_joint(self, values: np.ndarray, limits, name: str, unit: str) -> None:
        if limits is None:
            return
        bad = (values < limits[0] - 1e-9) | (values > limits[1] + 1e-9)
        if np.any(bad):
            v = values[np.flatnonzero(bad)[0]]
            raise LimitError(f"{name} {v:.4g} {unit} is outside the probe's range [{limits[0]:g}, {limits[1]:g}] {unit}")

    def _base2tracker(self, translation_mm: np.ndarray, rotation_deg: np.ndarray) -> tuple[np.ndarray, Rotation]:
        offset = np.zeros((translation_mm.size, 3))
        offset[:, 2] = translation_mm
        base_in_tracker = self.base_home_in_tracker_mm + self.base_home2tracker.apply(offset)
        base2tracker = self.base_home2tracker * Rotation.from_euler("z", np.asarray(rotation_deg, float)[:, None], degrees=True)
        return base_in_tracker, base2tracker

    # -- forward ---------------------------------------------------------------------------
    def forward(self, translation_mm, rotation_deg, theta_first_deg, theta_second_deg) -> ProbePose:
        """Tip pose in the tracker frame for given joint values.

        Parameters
        ----------
        translation_mm, rotation_deg, theta_first_deg, theta_second_deg : (n,) arrays or scalars
            Joint values (broadcast together); bending angles are the signed eq. 1 angles
            (thesis eq. 1), degrees.

        Returns
        -------
        ProbePose

        Raises
        ------
        LimitError
            A joint is outside its range, or the bend exceeds ``max_bend_deg``.
        """
        l, phi, t1, t2 = (np.atleast_1d(np.asarray(v, float)) for v in (translation_mm, rotation_deg, theta_first_deg, theta_second_deg))
        l, phi, t1, t2 = (np.ascontiguousarray(v) for v in np.broadcast_arrays(l, phi, t1, t2))
        self._check_joint(l, self.translation_limits_mm, "translation", "mm")
        self._check_joint(phi, self.rotation_limits_deg, "rotation", "deg")
        bx, by = bend_from_angles_rad(t1, t2)
        alpha_deg = np.degrees(np.hypot(bx, by))
        if np.any(alpha_deg > self.max_bend_deg * (1 + 1e-12)):
            i = int(np.argmax(alpha_deg))
            raise LimitError(
                f"bending angles ({t1[i]:.3f}, {t2[i]:.3f}) deg mean a {alpha_deg[i]:.2f} deg bend, "
                f"beyond max_bend_deg={self.max_bend_deg:.2f}"
            )
        tip_in_base, tip2base = tip_pose_in_base(bx, by, self.length_mm)
        base_in_tracker, base2tracker = self._base2tracker(l, phi)
        tip2tracker = base2tracker * tip2base
        return ProbePose(
            tip_in_tracker_mm=base_in_tracker + base2tracker.apply(tip_in_base),
            tip_dir_in_tracker=tip2tracker.apply(_Z),
            tip2tracker=tip2tracker,
        )

    # -- inverse ---------------------------------------------------------------------------
    def inverse(self, tip_in_tracker_mm, *, rotation_deg=None, tip2tracker: Rotation | None = None, tol_mm: float = 1e-6) -> ProbeJoints:
        """Joint values that put the tip at a target position (and orientation).

        Give either ``rotation_deg`` (the rotation is held there and translation plus the two
        bending angles reach the position; default 0 deg) or ``tip2tracker`` (the full tip
        orientation, which fixes all four joints; the position must then agree with it).

        Parameters
        ----------
        tip_in_tracker_mm : (n, 3) or (3,) array
            Target tip positions in the tracker frame, mm.
        rotation_deg : (n,) array or scalar, optional
            Probe rotation to hold, degrees.
        tip2tracker : scipy Rotation, optional
            Target tip orientations (length 1 or n).
        tol_mm : float
            With ``tip2tracker``: largest distance between the target position and the one
            the orientation implies that still counts as reachable, mm.

        Returns
        -------
        ProbeJoints
            Arrays of shape (n,); ``forward`` of them reproduces the target.

        Raises
        ------
        UnreachableError
            A target is out of the workspace (too far off the axis for the bending section,
            beyond the translation range, or inconsistent with the given orientation). The
            error carries the nearest reachable tip positions and their joints.
        LimitError, ConfigError
            ``rotation_deg`` outside its range; both or neither mode arguments misused.
        """
        p = np.atleast_2d(np.asarray(tip_in_tracker_mm, float))
        if p.ndim != 2 or p.shape[1] != 3:
            raise ConfigError(f"tip_in_tracker_mm must have shape (n, 3), got {np.shape(tip_in_tracker_mm)}")
        n = p.shape[0]
        if tip2tracker is not None and rotation_deg is not None:
            raise ConfigError("give either rotation_deg or tip2tracker to inverse kinematics, not both")
        p_home = self.base_home2tracker.inv().apply(p - self.base_home_in_tracker_mm)
        L = self.length_mm
        if tip2tracker is None:
            phi = np.broadcast_to(np.atleast_1d(np.asarray(0.0 if rotation_deg is None else rotation_deg, float)), (n,)).copy()
            self._check_joint(phi, self.rotation_limits_deg, "rotation", "deg")
            q = Rotation.from_euler("z", phi[:, None], degrees=True).inv().apply(p_home)
            rho = np.hypot(q[:, 0], q[:, 1])
            alpha_lim = min(np.radians(self.max_bend_deg), MAX_UNIQUE_BEND_RAD)
            rho_max = float(lateral_offset_mm(alpha_lim, L))
            too_far = rho > rho_max * (1 + 1e-12)
            alpha = bend_from_lateral_offset_rad(np.minimum(rho, rho_max), L)
            azimuth = np.arctan2(q[:, 1], q[:, 0])
            reasons = np.where(too_far, f"is more than {rho_max:.3f} mm off the probe axis (bend limit "
                               f"{np.degrees(alpha_lim):.2f} deg)", "")
        else:
            quat = np.atleast_2d(tip2tracker.as_quat())
            if quat.shape[0] == 1 and n > 1:
                quat = np.repeat(quat, n, axis=0)
            if quat.shape[0] != n:
                raise ConfigError(f"tip2tracker has {quat.shape[0]} orientations for {n} target positions")
            tip2home = self.base_home2tracker.inv() * Rotation.from_quat(quat)
            if len(tip2home) != n:
                raise ConfigError(f"tip2tracker has {len(tip2home)} orientations for {n} target positions")
            d = tip2home.apply(_Z)
            alpha = np.arctan2(np.hypot(d[:, 0], d[:, 1]), d[:, 2])
            a = np.arctan2(d[:, 1], d[:, 0])  # phi + bending azimuth (ZYZ: Rz(a) Ry(alpha) Rz(c))
            m = (Rotation.from_rotvec(np.outer(-alpha, [0.0, 1.0, 0.0])) * Rotation.from_euler("z", -a[:, None]) * tip2home).as_matrix()
            c = np.arctan2(m[:, 1, 0], m[:, 0, 0])  # c = -bending azimuth
            phi = _wrap_deg(np.degrees(a + c))
            azimuth = -c
            q = Rotation.from_euler("z", phi[:, None], degrees=True).inv().apply(p_home)
            too_far = alpha > np.radians(self.max_bend_deg) * (1 + 1e-12)
            alpha = np.minimum(alpha, np.radians(self.max_bend_deg))
            reasons = np.where(too_far, f"needs a bend beyond max_bend_deg={self.max_bend_deg:.2f}", "")
        sin_over_a = np.where(alpha > 1e-8, np.sin(alpha) / np.where(alpha > 1e-8, alpha, 1.0), 1.0 - alpha**2 / 6.0)
        l = q[:, 2] - L * sin_over_a
        l_clipped = l if self.translation_limits_mm is None else np.clip(l, *self.translation_limits_mm)
        out_of_range = np.abs(l_clipped - l) > 1e-9
        reasons = np.where(out_of_range & (reasons == ""), f"needs a translation outside {self.translation_limits_mm} mm", reasons)
        t1, t2 = angles_from_bend_deg(alpha * np.cos(azimuth), alpha * np.sin(azimuth))
        joints = ProbeJoints(translation_mm=l_clipped, rotation_deg=phi, theta_first_deg=t1, theta_second_deg=t2)
        bad = too_far | out_of_range
        if tip2tracker is not None or np.any(bad):
            reached = self.forward(joints.translation_mm, joints.rotation_deg, t1, t2).tip_in_tracker_mm
            if tip2tracker is not None:
                miss = np.linalg.norm(reached - p, axis=1) > tol_mm
                reasons = np.where(miss & (reasons == ""), "is not where the given orientation puts the tip", reasons)
                bad = bad | miss
            if np.any(bad):
                i = int(np.flatnonzero(bad)[0])
                gap = float(np.linalg.norm(reached[i] - p[i]))
                raise UnreachableError(
                    f"target tip {np.array2string(p[i], precision=3)} mm (row {i}) {reasons[i]}; nearest reachable "
                    f"point {np.array2string(reached[i], precision=3)} mm ({gap:.3f} mm away)",
                    index=i,
                    nearest_tip_in_tracker_mm=np.where(bad[:, None], reached, p),
                    nearest=joints,
                )
        return joints
