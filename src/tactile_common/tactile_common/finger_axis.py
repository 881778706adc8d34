"""How the finger axis travels with a goal's path (ROS-free), for a tilted touch (tactile_planner.tilt).

World frame, metres. The finger axis is the unit vector from the tip centre towards the flange
(vertical: +z). Each pose of ``/planner/path`` carries the finger's frame at that point: its
**z-axis is the finger axis**, its x-axis the approach direction made orthogonal to it
(:func:`finger_frame`). An identity orientation (or none: an all-zero quaternion, as hand-made paths
often have) is the vertical finger; so is any axis within the commander's ``max_tilt_rad`` of +z.

A tilted touch's path ends with its *tail* (:func:`tilted_tail`): the entry point E twice, first with
the vertical finger, then with the tilted axis ``a`` (the finger turns there about the tip centre),
then the pre-touch point with ``a`` (the finger goes in along its own axis). The arm commander follows
the path with those axes, approaches along the goal's x-axis keeping ``a``, and at the end of the touch
goes back to E along ``a`` and turns the finger vertical again, so that between touches the finger is
always vertical.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

from tactile_common.rotations import quaternion_to_matrix

EZ = np.array([0.0, 0.0, 1.0])
#: Axes closer than this (rad) are the same axis.
SAME_AXIS_RAD = 1e-6


def finger_frame(approach_xyz: np.ndarray, axis_xyz: np.ndarray) -> np.ndarray:
    """Rotation (columns = x, y, z in world): z = the finger axis, x = the approach direction made
    orthogonal to it (world x, then y, when the approach is along the axis), y = z × x.

    Raises:
        ValueError: a zero or non-finite axis.
    """
    z = np.asarray(axis_xyz, dtype=float).reshape(3)
    nz = float(np.linalg.norm(z))
    if not (np.isfinite(nz) and nz > 1e-9):
        raise ValueError(f"finger axis {z.tolist()} must be a finite non-zero vector")
    z = z / nz
    d = np.asarray(approach_xyz, dtype=float).reshape(3)
    for x in (d, np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])):
        x = x - float(x @ z) * z
        nx = float(np.linalg.norm(x))
        if np.isfinite(nx) and nx > 1e-6:
            break
    x = x / nx
    return np.stack([x, np.cross(z, x), z], axis=1)


def axis_angles(a0: np.ndarray, a1: np.ndarray) -> np.ndarray:
    """(M,) angle (rad, in [0, π]) between unit rows of ``a0`` and ``a1`` (M, 3): atan2(|a0 × a1|, a0 · a1)."""
    return np.arctan2(np.linalg.norm(np.cross(a0, a1), axis=-1), np.einsum("...i,...i->...", a0, a1))


def slerp_axes(a0: np.ndarray, a1: np.ndarray, frac: np.ndarray) -> np.ndarray:
    """Great-circle interpolation of unit vectors (M, 3), row-wise, at fractions ``frac`` (M,) in [0, 1].

    a(t) = cos(tθ) a0 + sin(tθ) u, θ = angle(a0, a1), u the unit component of a1 orthogonal to
    a0: a(0) = a0, a(1) = a1, and the angle from a0 grows as tθ. Identical axes (θ below
    ``SAME_AXIS_RAD``) give a0. Opposite axes have no unique great circle: u is then a0 × e
    normalised, e the world axis least aligned with a0 (the same choice every time).
    """
    a0 = np.atleast_2d(np.asarray(a0, dtype=float))
    a1 = np.atleast_2d(np.asarray(a1, dtype=float))
    t = np.asarray(frac, dtype=float).reshape(-1)
    theta = axis_angles(a0, a1)
    ortho = a1 - np.einsum("ij,ij->i", a0, a1)[:, None] * a0
    n_ortho = np.linalg.norm(ortho, axis=1)
    # Nearly opposite (sin θ tiny, cos θ < 0): the orthogonal part is noise; pick a fixed perpendicular.
    opposite = (n_ortho < 1e-9) & (theta > np.pi / 2)
    e = np.eye(3)[np.argmin(np.abs(a0), axis=1)]
    perp = np.cross(a0, e)
    perp /= np.linalg.norm(perp, axis=1)[:, None]
    u = np.where(opposite[:, None], perp, ortho / np.maximum(n_ortho, 1e-300)[:, None])
    ang = t * theta
    out = np.cos(ang)[:, None] * a0 + np.sin(ang)[:, None] * u
    same = theta <= SAME_AXIS_RAD
    out = np.where(same[:, None], a0, out)
    return out / np.linalg.norm(out, axis=1)[:, None]


def axes_from_quaternions(xyzw: np.ndarray) -> np.ndarray:
    """(K, 3) finger axes (the z-axes) of (K, 4) quaternions (x, y, z, w; normalised here); an all-zero
    or non-finite quaternion is the vertical finger."""
    q = np.asarray(xyzw, dtype=float).reshape(-1, 4)
    n = np.linalg.norm(q, axis=1)
    q = np.where((np.isfinite(n) & (n > 1e-6))[:, None], q, [0.0, 0.0, 0.0, 1.0])
    return quaternion_to_matrix(q)[:, :, 2]


@dataclass(frozen=True)
class TiltedTail:
    """The end of a tilted touch's path: where the finger turns, and its axis from there on."""

    entry_xyz: np.ndarray  # (3,) world, m
    axis_xyz: np.ndarray  # (3,) unit, world


def tilted_tail(path_xyz: np.ndarray, axes_xyz: np.ndarray, vertical_tol_rad: float) -> Optional[TiltedTail]:
    """The tail of a path whose last axis is more than ``vertical_tol_rad`` from +z (None: a vertical
    finger's path): the entry is the last path point whose axis is within it (the finger is still
    vertical there), and the axis the last one.

    Raises:
        ValueError: the tail is not the module's form (the tilted poses do not all share one axis, the
            entry is not the first tilted pose's point, or no pose is vertical).
    """
    P = np.asarray(path_xyz, dtype=float).reshape(-1, 3)
    A = np.asarray(axes_xyz, dtype=float).reshape(-1, 3)
    if len(A) != len(P):
        raise ValueError(f"{len(A)} finger axes for {len(P)} path points")
    off = np.arccos(np.clip(A[:, 2], -1.0, 1.0)) > vertical_tol_rad
    if not len(P) or not off[-1]:
        if off.any():
            raise ValueError("a tilted finger inside the path: only its tail may be tilted")
        return None
    k = int(np.flatnonzero(~off)[-1]) + 1 if (~off).any() else 0
    if k == 0:
        raise ValueError("the path has no pose with the vertical finger: no place to turn it")
    if off[:k].any():
        raise ValueError("a tilted finger inside the path: only its tail may be tilted")
    if np.abs(A[k:] - A[-1]).max() > 1e-6:
        raise ValueError("the tilted poses of the path do not share one finger axis")
    if float(np.linalg.norm(P[k] - P[k - 1])) > 1e-6:
        raise ValueError("the finger turns where it is: the first tilted pose must repeat the last vertical one")
    return TiltedTail(P[k - 1].copy(), A[-1] / np.linalg.norm(A[-1]))
