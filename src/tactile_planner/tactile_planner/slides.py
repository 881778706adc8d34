"""Slide candidates and their value: where to start a slide, which way, how far (ROS-free).

World frame, metres, seconds. A candidate slide starts at a touch candidate
``c_i`` (a point of the estimated surface μ = 0 with outward normal n_i) and
runs along the estimated surface in one of ``directions`` start directions
(2D: ±t_i, t_i = z × n_i, the contour tangent; 3D: d_ik = cos a_k e1 + sin a_k e2,
a_k = 2πk/D, in the tangent plane of e1 = the horizontal tangent z × n_i (x × n_i
where n_i is within 6° of vertical) and e2 = n_i × e1, up the surface: D = 2 is
±e1, a horizontal band; D = 4 adds the slides up and down the surface). Its path is traced on the estimator's lattice: from x_0 = c_i,
step ``trace_step_m`` along the tangent, then two Newton steps back onto
μ = 0 (x ← x − μ ∇μ/|∇μ|², μ and ∇μ bilinear/trilinear on the lattice), and
carry the tangent over: t ← normalize(t − (t·n̂)n̂) with n̂ = ∇μ/|∇μ|. A
trace ends where it leaves the lattice, loses the gradient, fails to
return to μ = 0 within one step, or (3D) goes below ``min_z_m`` (the lowest
tip-centre height: the commander's box would stop the slide there) or where
the finger's rod above the tip would enter the estimate (``surface_ok``).
One exception to the last: a 3D path heading down (t_z < −``DROP_MIN_DOWN``)
along a wall (|n_xy| > ``WALL_MIN_NXY``) where the estimate turns under the rod goes on
straight down from the last point the rod cleared, while the rod (checked
with that wall's horizontal normal) clears and the tip is above ``min_z_m``.
Below the lowest contact the estimate of an object standing on the table
bends back towards the prior, so a wall's lower band faces down on the
estimate and no slide down it could be planned past the bend (measured on
the generated prism: 15–18 mm, against 60 mm to the lowest tip height); a
finger sliding down a wall follows the wall, and where it does not go
straight down the servo's own contact stops or steers it.

Value of the first s = k·h metres (k steps of length h): the uncertainty it
would remove, G_k = Σ_{j ≤ k} max(σ²(x_j) − ``known_var_m2``, 0)·h (the
variance integrated along the path, m³; ``value: variance``) or, the default,
the length of surface along it that may be wrong by more than τ, G_k =
Σ_{j ≤ k} 2Φ(−τ/σ(x_j))·h (m; ``value: wrong_surface``, τ =
``known_tolerance_m``, as the ``info_travel`` pokes weigh a candidate: σ²
spans orders of magnitude and lets one very uncertain spot outweigh a long
stretch of surface known only to a few millimetres), per second of robot time

    T_k = travel_i / tip_speed + (approach + retract) / approach_speed + dwell + s / slide_speed

(the travel to the start is the LMDP path length of the same solve as the
pokes; approach and retract are a standoff each). The chosen slide is the
(candidate, direction, length) with the highest G_k / T_k over
``slide_min_length_m`` ≤ s ≤ ``slide_max_length_m``: a long slide is chosen
where the variance stays high along the way, a short one where the path
runs into known surface. Cost O(M·D·K) lattice interpolations for M
candidates and K = max length / step.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Mapping, Optional

import numpy as np
from scipy.interpolate import RegularGridInterpolator

from tactile_common.touch_geometry import MotionModel

from .maps import MapLattice
from .strategies import wrong_probability


#: A 3D path heading down at least this steeply (−t_z) goes on straight down where the estimate turns
#: under the finger's rod (sin 30°) ...
DROP_MIN_DOWN = 0.5
#: ... when it left a wall: a surface whose unit normal's horizontal part is longer than this.
WALL_MIN_NXY = 0.5

#: What a metre of planned slide is worth (``SlideParams.value``, the planner's ``slide_value``).
SLIDE_VALUES = ("variance", "wrong_surface")


@dataclass(frozen=True)
class SlideParams:
    max_length_m: float = 0.6
    min_length_m: float = 0.02
    trace_step_m: float = 0.003
    known_var_m2: float = 0.0
    directions: int = 4  # start directions per candidate (3D; 2D always ±t)
    value: str = "wrong_surface"  # what a metre of slide is worth: "wrong_surface" (2Φ(−τ/σ)) or "variance" (σ²)
    known_tolerance_m: float = 0.002  # τ of "wrong_surface"

    @classmethod
    def from_params(cls, p: Mapping[str, Any]) -> "SlideParams":
        """From the planner's parameters (``slide_max_length_m``, ``slide_min_length_m``,
        ``slide_trace_step_m``, ``known_var_m2``, ``slide_directions_3d``)."""
        out = cls(float(p.get("slide_max_length_m", cls.max_length_m)),
                  float(p.get("slide_min_length_m", cls.min_length_m)),
                  float(p.get("slide_trace_step_m", cls.trace_step_m)),
                  float(p.get("known_var_m2", cls.known_var_m2)),
                  int(p.get("slide_directions_3d", cls.directions)),
                  str(p.get("slide_value", cls.value)),
                  float(p.get("known_tolerance_m", cls.known_tolerance_m)))
        if not 0 < out.min_length_m <= out.max_length_m:
            raise ValueError(f"need 0 < slide_min_length_m ({out.min_length_m}) ≤ slide_max_length_m "
                             f"({out.max_length_m})")
        if not out.trace_step_m > 0:
            raise ValueError(f"slide_trace_step_m = {out.trace_step_m}: must be > 0")
        if out.directions not in (2, 4, 8):
            raise ValueError(f"slide_directions_3d = {out.directions}: must be 2, 4 or 8")
        if out.value not in SLIDE_VALUES:
            raise ValueError(f"slide_value = '{out.value}': must be one of {SLIDE_VALUES}")
        return out


@dataclass
class SlideChoice:
    """The chosen slide (index −1 when no candidate is reachable) and every score.

    ``scores`` (M, D): the best G/T of each candidate in each start direction
    (:func:`start_directions`; −inf unreachable); ``direction_xyz``: the unit start tangent; ``path_xyz``
    (K+1, 3): the traced path of the chosen length on the estimate.
    """

    index: int
    direction_xyz: np.ndarray
    length_m: float
    score: float
    gain_m3: float
    time_s: float
    scores: np.ndarray
    path_xyz: np.ndarray


def start_tangents(normal_xyz: np.ndarray) -> np.ndarray:
    """(M, 3) unit tangents z × n (horizontal; 2D: the contour tangent, counter-clockwise)."""
    n = np.asarray(normal_xyz, dtype=float)
    t = np.column_stack([-n[:, 1], n[:, 0], np.zeros(len(n))])
    nrm = np.linalg.norm(t, axis=1, keepdims=True)
    return np.where(nrm > 1e-9, t / np.maximum(nrm, 1e-12), 0.0)


def start_directions(normal_xyz: np.ndarray, count: int) -> np.ndarray:
    """(M, D) x 3 unit start directions in each tangent plane (module docstring), direction k
    at angle 2πk/D from e1 = z × n towards e2 = n × e1; D = 2 gives ±(z × n).

    Where n is within ~6° of vertical (|z × n| < 0.1), e1 = x × n normalised: the horizontal
    tangent is ill-defined there.
    """
    n = np.asarray(normal_xyz, dtype=float)
    e1 = start_tangents(n)
    steep = np.hypot(n[:, 0], n[:, 1]) < 0.1  # |z × n|
    x_n = np.cross([1.0, 0.0, 0.0], n[steep])
    nrm = np.linalg.norm(x_n, axis=1, keepdims=True)
    e1[steep] = np.where(nrm > 1e-9, x_n / np.maximum(nrm, 1e-12), 0.0)
    e2 = np.cross(n, e1)
    a = 2.0 * np.pi * np.arange(count) / count
    c, s = np.round(np.cos(a), 15), np.round(np.sin(a), 15)  # exact ±1, 0 at the quarter turns
    return c[None, :, None] * e1[:, None, :] + s[None, :, None] * e2[:, None, :]


class _Field:
    """μ, ∇μ and σ² of the lattice, interpolated (points in the lattice's own dim).

    In 3D μ and the three components of ∇μ are one interpolator over a (..., 4) stack: the cell
    and its weights are found once for the four, and each channel is summed as alone (the same
    numbers). In 2D each keeps its own (scipy's compiled bilinear path takes one channel only).
    """

    def __init__(self, lattice: MapLattice) -> None:
        axes = tuple(np.asarray(a, dtype=float) for a in lattice.axes)
        mean = np.asarray(lattice.mean_m, dtype=float)
        grads = np.gradient(mean, *axes)
        grads = grads if lattice.dim > 1 else [grads]
        kw = dict(bounds_error=False, fill_value=np.nan)
        self.var = RegularGridInterpolator(axes, lattice.variance_m2, **kw)
        self.dim = lattice.dim
        if self.dim == 3:
            self._stack = RegularGridInterpolator(axes, np.stack([mean, *grads], axis=-1), **kw)
        else:
            self._mean = RegularGridInterpolator(axes, mean, **kw)
            self._grad = [RegularGridInterpolator(axes, g, **kw) for g in grads]

    def mean_grad_at(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """μ (N,) and ∇μ (N, dim) at (N, dim) points (NaN off the lattice)."""
        if self.dim == 3:
            v = self._stack(x)
            return v[:, 0], v[:, 1:]
        return self._mean(x), np.column_stack([g(x) for g in self._grad])


def _wall_normal(unit_normal_xyz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(M, 3) unit horizontal parts of (M, 3) unit normals (zero where there is none) and (M,) whether each
    is a wall's (|n_xy| > ``WALL_MIN_NXY``; NaN normals are not)."""
    h = np.nan_to_num(np.column_stack([unit_normal_xyz[:, :2], np.zeros(len(unit_normal_xyz))]))
    length = np.linalg.norm(h, axis=1)
    return h / np.maximum(length, 1e-12)[:, None], length > WALL_MIN_NXY


def trace(lattice: MapLattice, start_xyz: np.ndarray, tangent_xyz: np.ndarray, step_m: float,
          n_steps: int, min_z_m: float = -np.inf,
          surface_ok: Optional[Callable[[np.ndarray, np.ndarray], np.ndarray]] = None,
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Trace paths along μ = 0 (module docstring) from (M, 3) starts along (M, 3) tangents.

    Returns (points (M, K+1, 3), variance (M, K+1), valid (M, K+1) bool); a
    path is valid up to its first invalid step (3D: a point below ``min_z_m``
    is invalid, and with ``surface_ok`` one where ``surface_ok(points, unit
    normals)`` ((M, 3) each) is False: the planner's check of the finger's
    shaft above the tip). In 2D the z column is the start's.
    """
    field = _Field(lattice)
    d = field.dim
    x = np.asarray(start_xyz, dtype=float)[:, :d].copy()
    t = np.asarray(tangent_xyz, dtype=float)[:, :d].copy()
    M = len(x)
    pts = np.zeros((M, n_steps + 1, d))
    ok = np.zeros((M, n_steps + 1), bool)
    pts[:, 0] = x
    ok[:, 0] = np.isfinite(x).all(axis=1) & (np.linalg.norm(t, axis=1) > 0.5)
    alive = ok[:, 0].copy()
    may_drop = d == 3 and surface_ok is not None  # a drop needs the rod check it replaces
    dropping = np.zeros(M, bool)  # 3D: going straight down (the estimate turned under the rod)
    last_n = np.zeros((M, 3))  # 3D: the unit horizontal part of the last normal passed
    wall_n = np.zeros(M, bool)  # ... and whether that normal was a wall's
    if may_drop and alive.any():
        _, g0 = field.mean_grad_at(x[alive])
        last_n[alive], wall_n[alive] = _wall_normal(g0 / np.maximum(np.linalg.norm(g0, axis=1), 1e-12)[:, None])
    for k in range(1, n_steps + 1):
        # only the paths still going: a path is valid up to its first failure, so the later points
        # of an ended one are never read (they stay where it ended)
        a = np.flatnonzero(alive)
        if not len(a):
            pts[:, k:] = x[:, None, :]
            break
        xa, ta, go = x[a] + step_m * t[a], t[a], np.ones(len(a), bool)
        for _ in range(2):
            mu, g = field.mean_grad_at(xa)
            g2 = np.sum(g * g, axis=1)
            good = np.isfinite(mu) & np.isfinite(g2) & (g2 > 1e-8)
            xa = np.where(good[:, None], xa - (np.where(good, mu, 0.0) / np.where(good, g2, 1.0))[:, None] * g, xa)
            go &= good
        mu, g = field.mean_grad_at(xa)
        go &= np.isfinite(mu) & (np.abs(np.nan_to_num(mu, nan=np.inf)) < 0.25 * step_m)
        go &= np.linalg.norm(xa - x[a], axis=1) < 2.0 * step_m
        gn = np.linalg.norm(g, axis=1, keepdims=True)
        nh = np.where(gn > 1e-9, g / np.maximum(gn, 1e-12), 0.0)
        tt = ta - np.sum(ta * nh, axis=1, keepdims=True) * nh
        tn = np.linalg.norm(tt, axis=1, keepdims=True)
        go &= tn[:, 0] > 1e-6
        t[a] = np.where(tn > 1e-6, tt / np.maximum(tn, 1e-12), ta)
        if d == 3:
            go &= xa[:, 2] >= min_z_m
            if surface_ok is not None and go.any():  # only the paths still going
                shaft = go.copy()
                shaft[go] = surface_ok(xa[go], nh[go])
                # heading down where the estimate turns under the finger's rod: the finger goes on straight
                # down (module docstring), from the last point it could reach
                turn = go & ~shaft & ~dropping[a] & (ta[:, 2] < -DROP_MIN_DOWN) & wall_n[a]
                dropping[a[turn]] = True
                go = shaft
            drop = dropping[a]
            if drop.any():  # straight down from the last point, its rod checked with the wall's normal
                xd = x[a[drop]] - np.array([0.0, 0.0, step_m])
                nd = last_n[a[drop]]
                ok_d = xd[:, 2] >= min_z_m
                if ok_d.any():  # (a path drops only where surface_ok refused it)
                    ok_d[ok_d] = surface_ok(xd[ok_d], nd[ok_d])
                xa[drop], go[drop] = xd, ok_d
                t[a[drop]] = [0.0, 0.0, -1.0]
            keep = go & ~drop
            if may_drop and keep.any():  # the last normal passed, for a drop that may follow
                last_n[a[keep]], wall_n[a[keep]] = _wall_normal(nh[keep])
        x[a] = xa
        alive[a] = go
        pts[:, k] = x
        ok[:, k] = alive
    var = field.var(pts.reshape(-1, d)).reshape(M, n_steps + 1)
    if d == 2:
        z = np.broadcast_to(np.asarray(start_xyz, dtype=float)[:, 2:3, None], (M, n_steps + 1, 1))
        pts = np.concatenate([pts, z], axis=2)
    return pts, np.nan_to_num(var, nan=0.0), ok


def choose_slide(lattice: MapLattice, target_xyz: np.ndarray, normal_xyz: np.ndarray, reachable: np.ndarray,
                 travel_m: np.ndarray, motion: MotionModel, approach_m: float, params: SlideParams,
                 min_z_m: float = -np.inf,
                 surface_ok: Optional[Callable[[np.ndarray, np.ndarray], np.ndarray]] = None) -> SlideChoice:
    """The slide with the most uncertainty removed per second (module docstring).

    ``travel_m`` (M,): LMDP path length from the tip to each candidate's
    pre-touch point; ``approach_m``: the expected approach (and retract) length;
    ``min_z_m``: 3D, the lowest tip-centre height (a path below it is cut there);
    ``surface_ok``: 3D, where a path may go (:func:`trace`; it is cut at the first point that fails).
    """
    M = len(target_xyz)
    h = float(params.trace_step_m)
    K = max(1, int(np.floor(params.max_length_m / h + 1e-9)))  # K·h ≤ the longest slide
    k_min = max(1, int(np.ceil(params.min_length_m / h - 1e-9)))
    D = params.directions if lattice.dim == 3 else 2
    dirs = start_directions(normal_xyz, D)  # (M, D, 3)
    ok_start = np.asarray(reachable, bool) & np.isfinite(np.asarray(travel_m, dtype=float))
    idx = np.nonzero(ok_start)[0]
    scores = np.full((M, D), -np.inf)
    empty = SlideChoice(-1, np.full(3, np.nan), float("nan"), -np.inf, 0.0, float("nan"), scores, np.zeros((0, 3)))
    if len(idx) == 0:
        return empty
    # rows direction-major: row j = direction j // m of candidate idx[j % m]
    starts = np.tile(np.asarray(target_xyz, dtype=float)[idx], (D, 1))
    tangents = dirs[idx].transpose(1, 0, 2).reshape(-1, 3)
    pts, var, ok = trace(lattice, starts, tangents, h, K, min_z_m, surface_ok)
    valid = np.cumprod(ok, axis=1).astype(bool)  # valid up to the first failure
    if params.value == "wrong_surface":  # the chance the surface there is off by more than τ
        per_m = wrong_probability(var, params.known_tolerance_m)
    else:
        per_m = np.maximum(var - params.known_var_m2, 0.0)
    w = np.where(valid, per_m, 0.0) * h
    gain = np.cumsum(w, axis=1)  # (D·m, K+1): G_k
    s = np.arange(K + 1) * h
    fixed = np.tile(motion.slide_time_s(travel_m[idx], approach_m, 0.0, approach_m), D)
    T = fixed[:, None] + s[None, :] / motion.slide_speed_mps
    ratio = np.where(valid, gain / T, -np.inf)
    ratio[:, :k_min] = -np.inf
    best_k = np.argmax(ratio, axis=1)
    best = ratio[np.arange(len(ratio)), best_k]
    m = len(idx)
    scores[idx] = best.reshape(D, m).T
    if not np.isfinite(best).any():
        return empty
    j = int(np.argmax(best))
    k = int(best_k[j])
    return SlideChoice(int(idx[j % m]), tangents[j].copy(), float(k * h), float(best[j]), float(gain[j, k]),
                       float(T[j, k]), scores, pts[j, : k + 1].copy())
