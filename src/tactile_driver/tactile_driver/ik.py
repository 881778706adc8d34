"""Damped least-squares IK on the fingertip position, finger kept near a target axis.

Task priority (all in the world frame), per iteration:

1. position: J_p dq = e_p, e_p = p* - p(q) (the tip centre), damped
   pseudo-inverse J# = Jᵀ (J Jᵀ + λ² I)⁻¹;
2. tilt, in the null space N_1 = I - J_p# J_p: (P J_w) dq = k_t z × a, where z
   is the fingertip z-axis (from the tip towards the flange), a the target
   axis (a unit vector; default world +z, the vertical finger), k_t the tilt
   gain and P = I - z zᵀ leaves the spin about the finger free;
3. posture, in the null space of both: a pull k (q_rest - q) that keeps the
   elbow where the warm start put it.

Success: |e_p| ≤ ``tol_m`` and angle(z, a) ≤ ``max_tilt_rad``. Joint limits:
every iterate is clamped to [lower + margin, upper - margin] (the step is
limited to ``max_step_rad``). Failures raise typed exceptions that carry the
data, as in pink.

Without an axis the iteration is the vertical one, float for float (a = the
module's ``_EZ``, the tilt measured by :func:`tilt_of`): plans made before
the axis existed are reproduced exactly.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np

from tactile_driver.kinematics import ArmModel

_EZ = np.array([0.0, 0.0, 1.0])
#: An axis shorter than this is "zero" (no direction).
MIN_AXIS_NORM = 1e-9


class IKError(ValueError):
    """Base class of IK failures."""


class NoSolutionFound(IKError):
    """The iteration ended without reaching the target.

    Attributes:
        target_xyz: the requested tip position (world, m).
        q_best: the best joint vector found.
        residual_m: its tip position error.
        tilt_rad: its finger axis error: the angle from the requested axis,
            or from vertical (world +z) when none was requested.
        iterations: iterations used.
        axis_xyz: the requested finger axis (world, unit), or None (vertical).
    """

    def __init__(self, target_xyz: np.ndarray, q_best: np.ndarray, residual_m: float,
                 tilt_rad: float, iterations: int, reason: str, axis_xyz: Optional[np.ndarray] = None) -> None:
        self.target_xyz = np.asarray(target_xyz, dtype=float)
        self.q_best = np.asarray(q_best, dtype=float)
        self.residual_m = float(residual_m)
        self.tilt_rad = float(tilt_rad)
        self.iterations = int(iterations)
        self.axis_xyz = None if axis_xyz is None else np.asarray(axis_xyz, dtype=float)
        if self.axis_xyz is None:
            angle = f"tilt {np.degrees(self.tilt_rad):.1f} deg"
        else:
            angle = (f"{np.degrees(self.tilt_rad):.1f} deg from the requested finger axis "
                     f"{np.round(self.axis_xyz, 4).tolist()}")
        super().__init__(
            f"IK found no solution for tip at {np.round(self.target_xyz, 4).tolist()}: {reason} "
            f"(residual {self.residual_m * 1e3:.2f} mm, {angle}, {self.iterations} iterations)"
        )


@dataclass(frozen=True)
class IKSettings:
    """Solver settings (tolerances in metres and radians)."""

    tol_m: float = 1e-4
    max_tilt_rad: float = 0.10
    max_iterations: int = 200
    damping: float = 1e-3
    gain: float = 1.0
    tilt_gain: float = 0.5
    posture_gain: float = 0.05
    max_step_rad: float = 0.2
    limit_margin_rad: float = 0.02


@dataclass(frozen=True)
class IKResult:
    q: np.ndarray
    residual_m: float
    tilt_rad: float
    iterations: int


def _dls(J: np.ndarray, damping: float) -> np.ndarray:
    """Damped pseudo-inverse Jᵀ (J Jᵀ + λ² I)⁻¹."""
    A = J @ J.T
    A[np.diag_indices_from(A)] += damping**2
    return J.T @ np.linalg.inv(A)


def tilt_of(rotation: np.ndarray) -> float:
    """Angle (rad) between the fingertip z-axis and world +z."""
    return float(np.arccos(np.clip(rotation[2, 2], -1.0, 1.0)))


def axis_error_rad(rotation: np.ndarray, axis_xyz: np.ndarray) -> float:
    """Angle (rad, in [0, π]) between the fingertip z-axis R[:, 2] and the unit ``axis_xyz`` (world).

    atan2(|z × a|, z · a): accurate at small angles too (arccos is not).
    """
    z = rotation[:, 2]
    return float(np.arctan2(np.linalg.norm(np.cross(z, axis_xyz)), np.dot(z, axis_xyz)))


def unit_axis(axis_xyz: object) -> Optional[np.ndarray]:
    """``axis_xyz`` as a (3,) unit vector (world), or None when it is not a finite vector of norm ≥
    ``MIN_AXIS_NORM`` (wrong size, NaN, inf, zero, not numbers)."""
    try:
        a = np.asarray(axis_xyz, dtype=float)
    except (TypeError, ValueError):
        return None
    if a.size != 3 or not np.all(np.isfinite(a)):
        return None
    a = a.reshape(3)
    n = float(np.linalg.norm(a))
    return a / n if n >= MIN_AXIS_NORM else None


def solve_ik(
    model: ArmModel,
    target_xyz: np.ndarray,
    q_init: np.ndarray,
    settings: IKSettings = IKSettings(),
    q_rest: Optional[np.ndarray] = None,
    axis_xyz: Optional[np.ndarray] = None,
) -> IKResult:
    """Joint vector putting the tip centre at ``target_xyz`` (world), finger near ``axis_xyz``.

    Args:
        model: the arm.
        target_xyz: (3,) tip centre target, world frame, m.
        q_init: warm start (the previous waypoint's solution for continuity).
        settings: tolerances and gains.
        q_rest: posture the null-space task pulls towards (default ``q_init``).
        axis_xyz: (3,) target of the fingertip z-axis (tip → flange), world frame; normalised
            here. None: world +z (the vertical finger), exactly the iteration without an axis.

    Returns:
        An :class:`IKResult` whose ``tilt_rad`` is the angle between the fingertip z-axis and
        the target axis (world +z when none was given).

    Raises:
        NoSolutionFound: position error > ``tol_m`` or axis error > ``max_tilt_rad``
            after ``max_iterations``; a target or axis that is not a finite (non-zero) vector.
    """
    s = settings
    target = np.asarray(target_xyz, dtype=float).reshape(3)
    if not np.all(np.isfinite(target)):
        raise NoSolutionFound(target, q_init, np.inf, np.nan, 0, "target is not finite")
    axis = None if axis_xyz is None else unit_axis(axis_xyz)
    if axis_xyz is not None and axis is None:
        raise NoSolutionFound(target, q_init, np.inf, np.nan, 0,
                              f"finger axis {_describe(axis_xyz)} is not a finite non-zero 3-vector")
    a = _EZ if axis is None else axis
    angle_of: Callable[[np.ndarray], float] = tilt_of if axis is None else (lambda R: axis_error_rad(R, a))
    lo = model.lower_rad + s.limit_margin_rad
    hi = model.upper_rad - s.limit_margin_rad
    q = np.clip(np.asarray(q_init, dtype=float), lo, hi)
    rest = q.copy() if q_rest is None else np.asarray(q_rest, dtype=float)
    eye = np.eye(model.nq)
    eye3 = np.eye(3)
    best = (np.inf, q.copy(), np.nan)
    for it in range(1, s.max_iterations + 1):
        p, R, J = model.fk_jacobian(q)
        e_p = target - p
        z = R[:, 2]
        err = float(np.linalg.norm(e_p))
        tilt = angle_of(R)
        if err < best[0]:
            best = (err, q.copy(), tilt)
        if err <= s.tol_m and tilt <= s.max_tilt_rad:
            return IKResult(q, err, tilt, it - 1)
        Jp = J[:3]
        Jp_pinv = _dls(Jp, s.damping)
        dq = Jp_pinv @ (s.gain * e_p)
        N1 = eye - Jp_pinv @ Jp
        Jt = (eye3 - np.outer(z, z)) @ J[3:]
        e_t = s.tilt_gain * np.cross(z, a)
        JtN = Jt @ N1
        JtN_pinv = _dls(JtN, s.damping)
        dq += JtN_pinv @ (e_t - Jt @ dq)
        Ja = np.vstack([Jp, Jt])
        N2 = eye - _dls(Ja, s.damping) @ Ja
        dq += N2 @ (s.posture_gain * (rest - q))
        step = float(np.max(np.abs(dq)))
        if step > s.max_step_rad:
            dq *= s.max_step_rad / step
        q = np.clip(q + dq, lo, hi)
    p, R = model.fk(q)
    err, tilt = float(np.linalg.norm(target - p)), angle_of(R)
    if err < best[0]:
        best = (err, q, tilt)
    if best[0] <= s.tol_m:
        reason = "tilt above limit" if axis is None else "finger axis error above limit"
    else:
        reason = "position not reached"
    raise NoSolutionFound(target, best[1], best[0], best[2], s.max_iterations, reason, axis)


def _describe(value: object) -> str:
    """A short printable form of a user value (for error messages)."""
    try:
        return str(np.asarray(value, dtype=float).round(4).tolist())
    except (TypeError, ValueError):
        return repr(value)[:60]
