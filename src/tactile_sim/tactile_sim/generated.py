"""A seeded, generated benchmark suite of 2D sections and 3D solids (object-local, metres).

Object ``i`` of the suite with seed ``S`` in a mode is drawn from its own
generator, ``numpy.random.default_rng([S, i, dim])``, and its family is
``FAMILIES_<mode>[i % len(FAMILIES_<mode>)]`` (round robin): the first N
objects are the same whatever the count, every family is present from
N = len(families) on, and the name alone rebuilds the object:

    gen2d-017-letter_T        (seed 0)
    gen3d-s3-004-superquadric (seed 3)

Sizes: largest side 5–15 cm, so that a placed object at (0.50, 0.00) leaves
at least 7.5 cm to the estimator's workspace edges (x ∈ [0.35, 0.65],
y ∈ [−0.15, 0.15]). 3D solids stand on the table (lowest point z = 0) and
are at most 15 cm tall (workspace z ∈ [0, 0.22]).

SDFs: polygons, round boxes, discs, arcs, spheres, cylinders and prisms are
exact; unions are ``min`` (exact outside the solid, where the finger
senses; a bound inside); a 2D section with holes is ``max(d_outer,
−d_hole)`` with holes strictly inside the outline (exact); superquadrics
use the first-order distance (F − 1)/‖∇F‖ of the inside–outside function
F (homogeneous of degree one): exact on the surface and, F being convex
for exponents ≤ 2, a lower bound of the distance outside (what the sensor
model's 1-Lipschitz skipping needs), within ~12 % at 1–2 cm. "Rounded" polygon variants are the Minkowski sum with a
disc of radius ρ (d_polygon − ρ: convex corners round, concave ones stay
sharp).

Promises, tested in tests/sim/test_generated.py: ``concave_corners_rad``
lists the free-space angle of every sharp concave corner of a 2D shape
whose concavities are all wider than the finger (``None``: no such promise,
e.g. spiky stars); ``reachable_points`` are object-local points a finger of
radius :data:`TIP_RADIUS_M` can reach (inside slots, holes, under overhangs).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from functools import partial
from typing import Callable, Optional

import numpy as np
from scipy.spatial import ConvexHull

from tactile_sim import sdf2d, sdf3d

LocalSdf = Callable[[np.ndarray], np.ndarray]

#: The finger the promises are made for (explore_*.yaml tip_radius_m).
TIP_RADIUS_M = 0.01
#: Narrowest promised concavity: the finger's diameter plus 5 mm.
MIN_GAP_M = 2 * TIP_RADIUS_M + 0.005
MIN_SIZE_M, MAX_SIZE_M = 0.05, 0.15
MAX_HEIGHT_M = 0.15

FAMILIES_2D = ("blob", "spiky", "convex", "notched", "letter_T", "letter_L", "letter_H", "letter_U",
               "letter_E", "letter_X", "thin")
FAMILIES_3D = ("prism", "letter_prism", "superquadric", "boxes", "compound", "holed", "flat", "overhang",
               "thin_wall", "revolved")

_NAME = re.compile(r"^gen(2d|3d)-(?:s(\d+)-)?(\d{3,})-([A-Za-z_]+)$")


@dataclass
class GeneratedShape:
    """One generated object in its local frame (2D: centred on the bounding box;
    3D: bounding box centred in x–y, lowest point at z = 0)."""

    name: str
    family: str
    dim: int
    sdf: LocalSdf
    bounds: np.ndarray                        #: (2, dim) local axis-aligned box
    description: str
    concave_corners_rad: Optional[list] = None  #: see module docstring
    reachable_points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))


# -- names ---------------------------------------------------------------------
def object_name(mode: str, index: int, seed: int = 0) -> str:
    """The stable name of object ``index`` of the suite (mode "2d"/"3d", seed ≥ 0)."""
    fams = _families(mode)
    s = "" if seed == 0 else f"s{int(seed)}-"
    return f"gen{mode}-{s}{int(index):03d}-{fams[int(index) % len(fams)]}"


def suite_names(mode: str, count: int, seed: int = 0) -> list[str]:
    """Names of the first ``count`` objects of the suite."""
    _families(mode)
    if not (isinstance(count, (int, np.integer)) and count >= 1):
        raise ValueError(f"count must be a positive integer, got {count!r}")
    _check_seed(seed)
    return [object_name(mode, i, seed) for i in range(int(count))]


def is_generated_name(name: str) -> bool:
    """True when ``name`` has the form of a generated object's name (``gen2d-…``/``gen3d-…``)."""
    return bool(_NAME.match(str(name)))


def parse_name(name: str) -> tuple[str, int, int, str]:
    """``(mode, seed, index, family)`` of a generated name; ValueError if it is none."""
    m = _NAME.match(str(name))
    if not m:
        raise ValueError(f"{name!r} is not a generated object name (e.g. gen2d-017-letter_T, gen3d-s2-004-superquadric)")
    mode, seed, index, family = m.group(1), int(m.group(2) or 0), int(m.group(3)), m.group(4)
    expected = object_name(mode, index, seed)
    if expected != name:
        raise ValueError(f"generated object {name!r} does not exist: object {index} of the {mode} suite "
                         f"with seed {seed} is {expected!r}")
    return mode, seed, index, family


def make_generated(name: str) -> GeneratedShape:
    """Rebuild a generated object from its name (deterministic)."""
    mode, seed, index, family = parse_name(name)
    rng = np.random.default_rng([seed, index, 2 if mode == "2d" else 3])
    builder = _BUILDERS_2D[family] if mode == "2d" else _BUILDERS_3D[family]
    shape = builder(rng)
    shape.name = name
    shape.family = family
    shape.dim = 2 if mode == "2d" else 3
    return shape


def generate_suite(mode: str, count: int, seed: int = 0) -> list[GeneratedShape]:
    """The first ``count`` objects of the ``mode`` suite with ``seed``."""
    return [make_generated(n) for n in suite_names(mode, count, seed)]


def _families(mode: str) -> tuple[str, ...]:
    if mode not in ("2d", "3d"):
        raise ValueError(f"mode must be '2d' or '3d', got {mode!r}")
    return FAMILIES_2D if mode == "2d" else FAMILIES_3D


def _check_seed(seed) -> None:
    if not (isinstance(seed, (int, np.integer)) and seed >= 0):
        raise ValueError(f"suite seed must be a non-negative integer, got {seed!r}")


# -- 2D helpers ----------------------------------------------------------------
def _rot(theta: float) -> np.ndarray:
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s], [s, c]])


def _rotated(fn: LocalSdf, theta: float) -> LocalSdf:
    """fn rotated by +theta about the origin: d(q) = fn(R(−θ) q)."""
    R = _rot(theta)
    return lambda q: fn(q @ R)  # (R^T q^T)^T = q R


@dataclass
class _Shape2D:
    """A 2D construction before rotation and centring."""

    sdf: LocalSdf
    bounds: np.ndarray
    description: str
    concave_corners_rad: Optional[list] = None
    reachable: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    #: exact bounds of the shape rotated by theta (None: the rotated corners of ``bounds``)
    tight_bounds: Optional[Callable[[float], np.ndarray]] = None


def _polygon_shape(v: np.ndarray, rho_m: float, description: str, corners=None, reachable=()) -> _Shape2D:
    """Polygon (optionally Minkowski-rounded by rho) with tight bounds under rotation."""
    v = np.asarray(v, float)
    fn = partial(sdf2d.polygon, vertices=v)
    if rho_m > 0:
        poly = fn
        fn = lambda q: poly(q) - rho_m  # noqa: E731
    s = _Shape2D(fn, np.vstack([v.min(axis=0) - rho_m, v.max(axis=0) + rho_m]), description, corners,
                 np.asarray(reachable, float).reshape(-1, 2))
    s.tight_bounds = lambda th: _vertex_bounds(v @ _rot(th).T, rho_m)
    return s


def _vertex_bounds(v: np.ndarray, pad: float = 0.0) -> np.ndarray:
    return np.vstack([v.min(axis=0) - pad, v.max(axis=0) + pad])


def _scale_to(v: np.ndarray, size_m: float) -> np.ndarray:
    """Scale vertices so that the largest side of their box is ``size_m``."""
    return v * (size_m / float(np.ptp(v, axis=0).max()))


def _variant(rng: np.random.Generator) -> tuple[float, str]:
    """Sharp (ρ = 0) or rounded (ρ ∈ [3, 8] mm), half each."""
    if rng.random() < 0.5:
        return 0.0, "sharp"
    rho = float(rng.uniform(0.003, 0.008))
    return rho, f"rounded (r {rho * 1e3:.0f} mm)"


# -- 2D families -----------------------------------------------------------------
def _blob2d(rng: np.random.Generator) -> _Shape2D:
    """Star-convex smooth blob r(θ) = 1 + Σ a_k cos(kθ + φ_k), k = 2..5, 256 vertices."""
    ks = np.arange(2, 6)
    a = rng.uniform(0.0, 1.0, len(ks)) / ks
    a *= rng.uniform(0.15, 0.4) / a.sum()
    phase = rng.uniform(0, 2 * np.pi, len(ks))
    t = np.linspace(0, 2 * np.pi, 256, endpoint=False)
    r = 1.0 + (a[:, None] * np.cos(ks[:, None] * t[None] + phase[:, None])).sum(axis=0)
    aspect = rng.uniform(1.0, 1.8)
    v = np.column_stack([aspect * r * np.cos(t), r * np.sin(t)])
    size = float(rng.uniform(0.06, MAX_SIZE_M))
    v = _scale_to(v, size)
    return _polygon_shape(v, 0.0, f"smooth star-convex blob, {size * 100:.1f} cm")


def _spiky2d(rng: np.random.Generator) -> _Shape2D:
    """Star polygon with random vertex radii: sharp spikes and possibly narrow notches."""
    n = int(rng.integers(5, 10))
    t = np.sort((np.arange(2 * n) + rng.uniform(-0.25, 0.25, 2 * n)) * np.pi / n)
    r = np.where(np.arange(2 * n) % 2 == 0, rng.uniform(0.75, 1.0, 2 * n), rng.uniform(0.35, 0.7, 2 * n))
    v = np.column_stack([r * np.cos(t), r * np.sin(t)])
    size = float(rng.uniform(0.07, MAX_SIZE_M))
    rho, var = _variant(rng)
    v = _scale_to(v, size - 2 * rho)
    return _polygon_shape(v, rho, f"{n}-point star polygon, {size * 100:.1f} cm, {var} (notches may be narrower than the finger)")


def _convex2d(rng: np.random.Generator) -> _Shape2D:
    """Convex hull of 6–12 random points in an ellipse of aspect 1–2.5."""
    k = int(rng.integers(6, 13))
    t = rng.uniform(0, 2 * np.pi, k)
    rr = np.sqrt(rng.uniform(0.5, 1.0, k))
    pts = np.column_stack([rng.uniform(1.0, 2.5) * rr * np.cos(t), rr * np.sin(t)])
    v = pts[ConvexHull(pts).vertices]
    size = float(rng.uniform(MIN_SIZE_M + 0.01, MAX_SIZE_M))
    rho, var = _variant(rng)
    v = _scale_to(v, size - 2 * rho)
    return _polygon_shape(v, rho, f"convex polygon, {len(v)} vertices, {size * 100:.1f} cm, {var}", corners=[])


def _notched2d(rng: np.random.Generator) -> _Shape2D:
    """Rectangle with 1–2 slots from the top edge and 0–1 from the bottom, each wider than the finger."""
    rho, var = _variant(rng)
    W = float(rng.uniform(0.09, 0.14)) - 2 * rho
    H = float(rng.uniform(0.06, 0.11)) - 2 * rho
    wall = 0.015
    reach = []

    def slots(k: int) -> list[tuple[float, float]]:
        """k slot x-ranges along [0, W] with walls ≥ 1.5 cm between them."""
        for _ in range(100):
            widths = rng.uniform(MIN_GAP_M, MIN_GAP_M + 0.02, k) + 2 * rho
            free = W - widths.sum() - (k + 1) * wall
            if free > 0:
                gaps = wall + free * rng.dirichlet(np.ones(k + 1))
                x0 = np.cumsum(gaps[:-1]) + np.concatenate([[0.0], np.cumsum(widths)[:-1]])
                return [(float(a), float(a + w)) for a, w in zip(x0, widths)]
        return []

    top = slots(int(rng.integers(1, 3)))
    bottom = slots(int(rng.integers(0, 2)))
    depth_top = float(rng.uniform(0.02, 0.55 * H))
    depth_bot = float(rng.uniform(0.015, max(0.016, H - depth_top - wall))) if bottom else 0.0
    # Trace counter-clockwise: bottom edge (left to right) with its slots, then the top edge back.
    v = [(0.0, 0.0)]
    for a, b in bottom:
        v += [(a, 0.0), (a, depth_bot), (b, depth_bot), (b, 0.0)]
        reach.append(((a + b) / 2, max(depth_bot - TIP_RADIUS_M - rho, 0.5 * depth_bot)))
    v += [(W, 0.0), (W, H)]
    for a, b in reversed(top):
        v += [(b, H), (b, H - depth_top), (a, H - depth_top), (a, H)]
        reach.append(((a + b) / 2, H - depth_top + min(TIP_RADIUS_M + rho, 0.5 * depth_top)))
    v += [(0.0, H)]
    corners = [np.pi / 2] * (2 * (len(top) + len(bottom)))
    return _polygon_shape(np.array(v), rho, f"{W * 100 + 2 * rho * 100:.1f} x {H * 100 + 2 * rho * 100:.1f} cm block, "
                          f"{len(top) + len(bottom)} slots wider than 2.5 cm, {var}", corners, reach)


def _bars_shape(boxes: list[tuple[float, float, float, float, float]], rho: float, description: str,
                corners: list, reachable=()) -> _Shape2D:
    """Union of (rounded) bars (cx, cy, hx, hy, angle): exact outside (min of exact SDFs)."""
    def fn(q: np.ndarray) -> np.ndarray:
        out = np.full(len(q), np.inf)
        for cx, cy, hx, hy, ang in boxes:
            local = (q - (cx, cy)) @ _rot(ang)
            out = np.minimum(out, sdf2d.round_box(local, (hx, hy), rho))
        return out

    def corner_pts(th: float) -> np.ndarray:
        """Centres of the corner arcs (box corners moved in by rho), rotated by th."""
        pts = []
        for cx, cy, hx, hy, ang in boxes:
            c = np.array([[sx * (hx - rho), sy * (hy - rho)] for sx in (-1, 1) for sy in (-1, 1)])
            pts.append(c @ _rot(ang).T + (cx, cy))
        return np.vstack(pts) @ _rot(th).T

    # A round box is its arc centres' hull grown by rho: exact bounds at any rotation.
    s = _Shape2D(fn, _vertex_bounds(corner_pts(0.0), rho), description, corners,
                 np.asarray(reachable, float).reshape(-1, 2))
    s.tight_bounds = lambda th: _vertex_bounds(corner_pts(th), rho)
    return s


def _letter_dims(rng: np.random.Generator) -> tuple[float, float, float, str]:
    w = float(rng.uniform(0.015, 0.03))
    g = float(rng.uniform(MIN_GAP_M, MIN_GAP_M + 0.025))
    rho, var = _variant(rng)
    rho = min(rho, 0.45 * w)
    return w, g, rho, var


def _letter_T(rng):
    w, _, rho, var = _letter_dims(rng)
    W, H = rng.uniform(0.07, MAX_SIZE_M), rng.uniform(0.06, MAX_SIZE_M)
    boxes = [(0, H - w / 2, W / 2, w / 2, 0.0), (0, H / 2 - w / 4, w / 2, H / 2 - w / 4, 0.0)]
    return _bars_shape(boxes, rho, f"T, {W * 100:.1f} x {H * 100:.1f} cm, bars {w * 1e3:.0f} mm, {var}",
                       [np.pi / 2] * 2, [(W / 4 + w / 4, H - w - TIP_RADIUS_M - 0.002)])


def _letter_L(rng):
    w, _, rho, var = _letter_dims(rng)
    W, H = rng.uniform(0.06, MAX_SIZE_M), rng.uniform(0.06, MAX_SIZE_M)
    boxes = [(w / 2, H / 2, w / 2, H / 2, 0.0), (W / 2, w / 2, W / 2, w / 2, 0.0)]
    return _bars_shape(boxes, rho, f"L, {W * 100:.1f} x {H * 100:.1f} cm, bars {w * 1e3:.0f} mm, {var}",
                       [np.pi / 2], [(w + TIP_RADIUS_M + 0.002, w + TIP_RADIUS_M + 0.002)])


def _letter_H(rng):
    w, g, rho, var = _letter_dims(rng)
    W = 2 * w + g
    H = float(rng.uniform(max(0.06, 2 * (MIN_GAP_M + 0.01) + w), MAX_SIZE_M))
    yc = float(rng.uniform(MIN_GAP_M + 0.005 + w / 2, H - MIN_GAP_M - 0.005 - w / 2))
    boxes = [(w / 2, H / 2, w / 2, H / 2, 0.0), (W - w / 2, H / 2, w / 2, H / 2, 0.0), (W / 2, yc, W / 2 - w / 2, w / 2, 0.0)]
    return _bars_shape(boxes, rho, f"H, {W * 100:.1f} x {H * 100:.1f} cm, bars {w * 1e3:.0f} mm, gap {g * 1e3:.0f} mm, {var}",
                       [np.pi / 2] * 4, [(W / 2, yc + w / 2 + TIP_RADIUS_M + 0.002), (W / 2, yc - w / 2 - TIP_RADIUS_M - 0.002)])


def _letter_U(rng):
    w, g, rho, var = _letter_dims(rng)
    W = 2 * w + g + float(rng.uniform(0.0, 0.03))
    H = float(rng.uniform(max(0.06, w + 0.03), MAX_SIZE_M))
    boxes = [(w / 2, H / 2, w / 2, H / 2, 0.0), (W - w / 2, H / 2, w / 2, H / 2, 0.0), (W / 2, w / 2, W / 2, w / 2, 0.0)]
    return _bars_shape(boxes, rho, f"U, {W * 100:.1f} x {H * 100:.1f} cm, bars {w * 1e3:.0f} mm, slot {(W - 2 * w) * 1e3:.0f} mm, {var}",
                       [np.pi / 2] * 2, [(W / 2, w + TIP_RADIUS_M + 0.002)])


def _letter_E(rng):
    w, g, rho, var = _letter_dims(rng)
    g = min(g, (MAX_SIZE_M - 3 * w) / 2)
    H = 3 * w + 2 * g
    W = float(rng.uniform(max(0.05, w + 0.03), MAX_SIZE_M))
    boxes = [(w / 2, H / 2, w / 2, H / 2, 0.0)]
    boxes += [(W / 2, y, W / 2, w / 2, 0.0) for y in (w / 2, H / 2, H - w / 2)]
    reach = [(w + TIP_RADIUS_M + 0.002, w + g / 2), (w + TIP_RADIUS_M + 0.002, H - w - g / 2)]
    return _bars_shape(boxes, rho, f"E, {W * 100:.1f} x {H * 100:.1f} cm, bars {w * 1e3:.0f} mm, gaps {g * 1e3:.0f} mm, {var}",
                       [np.pi / 2] * 4, reach)


def _letter_X(rng):
    w, _, rho, var = _letter_dims(rng)
    alpha = float(rng.uniform(np.radians(55), np.radians(90)))
    L = float(rng.uniform(0.08, MAX_SIZE_M))
    boxes = [(0.0, 0.0, L / 2, w / 2, alpha / 2), (0.0, 0.0, L / 2, w / 2, -alpha / 2)]
    # The crossing's four concave corners: free-space angles alpha (x2) and pi - alpha (x2).
    reach = [((w / 2) / np.sin(alpha / 2) + TIP_RADIUS_M / np.sin(alpha / 2) + 0.004, 0.0)]
    return _bars_shape(boxes, rho, f"X, arms {L * 100:.1f} cm crossing at {np.degrees(alpha):.0f} deg, bars {w * 1e3:.0f} mm, {var}",
                       [alpha, alpha, np.pi - alpha, np.pi - alpha], reach)


def _thin2d(rng: np.random.Generator) -> _Shape2D:
    """Thin and elongated: a bar, an ellipse, an arc or a V of thin bars (8–16 mm thick)."""
    kind = ["bar", "ellipse", "arc", "vee"][int(rng.integers(4))]
    t = float(rng.uniform(0.008, 0.016))
    if kind == "bar":
        L = float(rng.uniform(0.07, MAX_SIZE_M))
        rho = float(rng.uniform(0.0, t / 2))
        return _bars_shape([(0, 0, L / 2, t / 2, 0.0)], rho, f"thin bar {L * 100:.1f} cm x {t * 1e3:.0f} mm", [])
    if kind == "ellipse":
        a = float(rng.uniform(0.04, MAX_SIZE_M / 2))
        b = max(t, a / rng.uniform(3.0, 7.0)) / 1.0
        b = min(b, a / 3)
        s = _Shape2D(partial(sdf2d.ellipse, a_m=a, b_m=b), np.array([[-a, -b], [a, b]]),
                     f"thin ellipse {2 * a * 100:.1f} x {2 * b * 100:.1f} cm", [])
        s.tight_bounds = lambda th: _ellipse_bounds(a, b, th)
        return s
    if kind == "arc":
        R = float(rng.uniform(0.04, 0.065))
        half = float(rng.uniform(0.8, 1.5))  # chord ≥ 5.7 cm
        fn = partial(sdf2d.arc, half_aperture_rad=half, arc_radius_m=R, thickness_m=t / 2)
        s = _Shape2D(fn, _arc_bounds(R, half, t / 2, 0.0), f"thin arc, radius {R * 100:.1f} cm, "
                     f"{np.degrees(2 * half):.0f} deg, {t * 1e3:.0f} mm thick", [])
        s.tight_bounds = lambda th: _arc_bounds(R, half, t / 2, th)
        return s
    L = float(rng.uniform(0.06, 0.12))
    ang = float(rng.uniform(np.radians(30), np.radians(70)))
    ends = [(L / 2 * np.cos(a), L / 2 * np.sin(a), L / 2, t / 2, a) for a in (ang / 2, -ang / 2)]
    return _bars_shape(ends, 0.0, f"thin V, arms {L * 100:.1f} cm, {np.degrees(ang):.0f} deg, {t * 1e3:.0f} mm thick", None)


def _ellipse_bounds(a: float, b: float, th: float) -> np.ndarray:
    hx = np.hypot(a * np.cos(th), b * np.sin(th))
    hy = np.hypot(a * np.sin(th), b * np.cos(th))
    return np.array([[-hx, -hy], [hx, hy]])


def _arc_bounds(R: float, half: float, t: float, th: float) -> np.ndarray:
    a = np.linspace(np.pi / 2 - half, np.pi / 2 + half, 721)
    pts = np.column_stack([R * np.cos(a), R * np.sin(a)]) @ _rot(th).T
    return _vertex_bounds(pts, t)


_BUILDERS_2D_RAW = {"blob": _blob2d, "spiky": _spiky2d, "convex": _convex2d, "notched": _notched2d,
                    "letter_T": _letter_T, "letter_L": _letter_L, "letter_H": _letter_H, "letter_U": _letter_U,
                    "letter_E": _letter_E, "letter_X": _letter_X, "thin": _thin2d}


def _section(family: str, rng: np.random.Generator) -> GeneratedShape:
    """A rotated, centred 2D section of a family."""
    raw = _BUILDERS_2D_RAW[family](rng)
    return _finish2d_full(raw, rng)


def _finish2d_full(s: _Shape2D, rng: np.random.Generator) -> GeneratedShape:
    """Rotate by a random angle whose bounding box still fits MAX_SIZE_M (else the
    unrotated shape), centre the box, wrap as a GeneratedShape."""
    tight = s.tight_bounds

    def rotated_bounds(theta: float) -> np.ndarray:
        if tight is not None:
            return tight(theta)
        lo, hi = s.bounds
        return _vertex_bounds(np.array([[x, y] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])]) @ _rot(theta).T)

    thetas = np.append(rng.uniform(0, 2 * np.pi, 32), 0.0)  # unrotated: every builder fits it
    sizes = [float(np.ptp(rotated_bounds(t), axis=0).max()) for t in thetas]
    fits = [i for i, z in enumerate(sizes) if z <= MAX_SIZE_M]
    theta = float(thetas[fits[0]] if fits else thetas[int(np.argmin(sizes))])
    R = _rot(theta)
    fn = _rotated(s.sdf, theta)
    bounds = rotated_bounds(theta)
    c = 0.5 * (bounds[0] + bounds[1])
    pts = np.asarray(s.reachable, float).reshape(-1, 2) @ R.T - c
    return GeneratedShape("", "", 2, (lambda q: fn(q + c)), bounds - c, s.description, s.concave_corners_rad, pts)


_BUILDERS_2D = {k: partial(_section, k) for k in _BUILDERS_2D_RAW}


# -- 3D families -----------------------------------------------------------------
def _solid(fn: LocalSdf, bounds: np.ndarray, description: str, reachable=()) -> GeneratedShape:
    """Centre the bounding box in x–y (the lowest point is already at z = 0)."""
    b = np.asarray(bounds, float)
    c = np.array([0.5 * (b[0, 0] + b[1, 0]), 0.5 * (b[0, 1] + b[1, 1]), 0.0])
    pts = np.asarray(reachable, float).reshape(-1, 3) - c
    return GeneratedShape("", "", 3, (lambda q: fn(q + c)), b - c, description, None, pts)


def _extruded(sec: GeneratedShape, height_m: float, description: str, reach_z=()) -> GeneratedShape:
    h = float(height_m)
    fn2 = sec.sdf

    def fn(q: np.ndarray) -> np.ndarray:
        return sdf3d.cap(fn2(q[:, :2]), np.abs(q[:, 2] - h / 2) - h / 2)

    b = np.column_stack([sec.bounds, [0.0, h]])
    reach = [np.append(p, z) for p in sec.reachable_points for z in reach_z]
    return _solid(fn, b, description, reach)


def _height(rng, lo=0.04, hi=0.14) -> float:
    return float(rng.uniform(lo, hi))


def _prism3d(rng):
    fam = ["blob", "spiky", "convex", "notched"][int(rng.integers(4))]
    sec = _section(fam, rng)
    h = _height(rng)
    return _extruded(sec, h, f"prism {h * 100:.1f} cm tall over a {fam} section: {sec.description}", [h / 2])


def _letter_prism3d(rng):
    fam = ["letter_T", "letter_L", "letter_H", "letter_U", "letter_E", "letter_X"][int(rng.integers(6))]
    sec = _section(fam, rng)
    h = _height(rng, 0.03, 0.10)
    return _extruded(sec, h, f"upright {fam[-1]} prism {h * 100:.1f} cm tall: {sec.description}", [h / 2])


def _superquadric3d(rng):
    """Superellipsoid F = ((|x/a|^(2/e2) + |y/b|^(2/e2))^(e2/e1) + |z/c|^(2/e1))^(e1/2), d ≈ (F − 1)/‖∇F‖."""
    a, b = rng.uniform(0.025, 0.053, 2)  # any yaw keeps the footprint within 15 cm
    c = float(rng.uniform(0.025, 0.07))
    e1, e2 = rng.uniform(0.3, 1.5, 2)
    yaw = float(rng.uniform(0, np.pi))
    R = _rot(yaw)
    half = np.array([a, b, c])

    def F(q: np.ndarray) -> np.ndarray:
        x, y, z = np.abs(q[:, 0]) / a, np.abs(q[:, 1]) / b, np.abs(q[:, 2]) / c
        xy = (x ** (2 / e2) + y ** (2 / e2)) ** (e2 / e1)
        return (xy + z ** (2 / e1)) ** (e1 / 2)

    def fn(p: np.ndarray) -> np.ndarray:
        q = np.column_stack([p[:, :2] @ R, p[:, 2] - c])
        h = 1e-6
        f = F(q)
        g = np.stack([(F(q + h * e) - F(q - h * e)) / (2 * h) for e in np.eye(3)], axis=1)
        gn = np.maximum(np.linalg.norm(g, axis=1), 1.0 / half.max())
        return (f - 1.0) / gn

    # xy extent: the rotated superellipse outline (the widest section, z = 0 of the local frame).
    t = np.linspace(0, 2 * np.pi, 2000)
    ct, st = np.cos(t), np.sin(t)
    ex = np.column_stack([a * np.sign(ct) * np.abs(ct) ** e2, b * np.sign(st) * np.abs(st) ** e2]) @ R.T
    lo, hi = ex.min(axis=0), ex.max(axis=0)
    b3 = np.array([[lo[0], lo[1], 0.0], [hi[0], hi[1], 2 * c]])
    return _solid(fn, b3, f"superquadric, semi-axes {a * 100:.1f} x {b * 100:.1f} x {c * 100:.1f} cm, "
                  f"exponents {e1:.2f}/{e2:.2f} (first-order SDF)")


def _round_box3(q: np.ndarray, centre, half, rho: float) -> np.ndarray:
    """Exact rounded box: box(q − c, h − ρ) − ρ."""
    return sdf3d.box(q - np.asarray(centre), tuple(np.asarray(half) - rho)) - rho


def _union(parts: list[LocalSdf]) -> LocalSdf:
    def fn(q: np.ndarray) -> np.ndarray:
        out = parts[0](q)
        for p in parts[1:]:
            out = np.minimum(out, p(q))
        return out
    return fn


def _boxes3d(rng):
    """A base box with 1–3 boxes stacked on it (steps, towers), sharp or rounded."""
    rho = 0.0 if rng.random() < 0.5 else float(rng.uniform(0.002, 0.006))
    hx, hy = rng.uniform(0.03, 0.07, 2)
    hz = float(rng.uniform(0.01, 0.03))
    boxes = [((0.0, 0.0, hz), (hx, hy, hz))]
    z = 2 * hz
    for _ in range(int(rng.integers(1, 4))):
        phx, phy = boxes[-1][1][0], boxes[-1][1][1]
        cx0, cy0 = boxes[-1][0][0], boxes[-1][0][1]
        nhx, nhy = rng.uniform(0.4, 0.9) * phx, rng.uniform(0.4, 0.9) * phy
        nhx, nhy = max(nhx, 0.012), max(nhy, 0.012)
        nhz = float(rng.uniform(0.01, 0.03))
        if z + 2 * nhz > MAX_HEIGHT_M:
            break
        cx = cx0 + rng.uniform(-1, 1) * (phx - nhx)
        cy = cy0 + rng.uniform(-1, 1) * (phy - nhy)
        boxes.append(((cx, cy, z + nhz), (nhx, nhy, nhz)))
        z += 2 * nhz
    rho = min(rho, 0.45 * min(min(h) for _, h in boxes))
    fn = _union([partial(_round_box3, centre=c, half=h, rho=rho) for c, h in boxes])
    lo = np.min([np.subtract(c, h) for c, h in boxes], axis=0)
    hi = np.max([np.add(c, h) for c, h in boxes], axis=0)
    return _solid(fn, np.vstack([lo, hi]), f"{len(boxes)} stacked boxes, {z * 100:.1f} cm tall, "
                  + ("sharp" if rho == 0 else f"rounded (r {rho * 1e3:.0f} mm)"))


def _cyl(q, centre, r, hh):
    return sdf3d.capped_cylinder(q - np.asarray(centre), r, hh)


def _sph(q, centre, r):
    return sdf3d.sphere(q - np.asarray(centre), r)


def _compound3d(rng):
    """Unions of cylinders, spheres and capsules: snowman, bollard (cylinder + dome), dumbbell."""
    kind = ["snowman", "bollard", "dumbbell"][int(rng.integers(3))]
    if kind == "snowman":
        r1 = float(rng.uniform(0.03, 0.045))
        r2 = float(rng.uniform(0.5, 0.8) * r1)
        z2 = 2 * r1 + 0.8 * r2
        parts = [partial(_sph, centre=(0, 0, r1), r=r1), partial(_sph, centre=(0, 0, z2), r=r2)]
        b = np.array([[-r1, -r1, 0.0], [r1, r1, z2 + r2]])
        desc = f"snowman: spheres of radius {r1 * 100:.1f} and {r2 * 100:.1f} cm"
    elif kind == "bollard":
        r = float(rng.uniform(0.02, 0.045))
        h = float(rng.uniform(0.04, 0.10))
        parts = [partial(_cyl, centre=(0, 0, h / 2), r=r, hh=h / 2), partial(_sph, centre=(0, 0, h), r=r)]
        b = np.array([[-r, -r, 0.0], [r, r, h + r]])
        desc = f"cylinder radius {r * 100:.1f} cm, {h * 100:.1f} cm tall, with a dome"
    else:
        rb = float(rng.uniform(0.02, 0.035))
        L = float(rng.uniform(0.05, MAX_SIZE_M - 2 * rb))
        rbar = float(rng.uniform(0.008, 0.6 * rb))
        parts = [partial(_sph, centre=(-L / 2, 0, rb), r=rb), partial(_sph, centre=(L / 2, 0, rb), r=rb),
                 partial(sdf3d.capsule, a=(-L / 2, 0, rb), b=(L / 2, 0, rb), radius_m=rbar)]
        yaw = float(rng.uniform(0, np.pi))
        base = _union(parts)
        R = _rot(yaw)
        fn = (lambda q: base(np.column_stack([q[:, :2] @ R, q[:, 2]])))
        ends = np.array([[-L / 2, 0], [L / 2, 0]]) @ R.T
        lo, hi = ends.min(axis=0) - rb, ends.max(axis=0) + rb
        return _solid(fn, np.array([[lo[0], lo[1], 0.0], [hi[0], hi[1], 2 * rb]]),
                      f"dumbbell lying: balls radius {rb * 100:.1f} cm, {L * 100:.1f} cm apart, bar radius {rbar * 1e3:.0f} mm",
                      [(0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), 2 * rb + TIP_RADIUS_M + 0.002)])
    return _solid(_union(parts), b, desc)


def _outline_with_holes(rng, height_lo: float, height_hi: float) -> tuple[GeneratedShape, float, str]:
    """A rounded rectangle or disc with 1–3 vertical through holes (radius ≥ 1.4 cm, ≥ 8 mm of material around)."""
    disc = rng.random() < 0.4
    if disc:
        R = float(rng.uniform(0.045, 0.075))
        outer = partial(sdf2d.circle, radius_m=R)
        bounds = np.array([[-R, -R], [R, R]])
        inside_ok = lambda c, r: np.hypot(*c) + r + 0.008 <= R  # noqa: E731
        span = (R, R)
    else:
        hx, hy = float(rng.uniform(0.04, 0.075)), float(rng.uniform(0.03, 0.06))
        cr = float(rng.uniform(0.0, 0.015))
        outer = partial(sdf2d.round_box, half_m=(hx, hy), corner_radius_m=cr)
        bounds = np.array([[-hx, -hy], [hx, hy]])
        inside_ok = lambda c, r: abs(c[0]) + r + 0.008 <= hx and abs(c[1]) + r + 0.008 <= hy  # noqa: E731
        span = (hx, hy)
    holes: list[tuple[tuple[float, float], float]] = []
    for _ in range(200):
        if len(holes) >= int(rng.integers(1, 4)) and holes:
            break
        r = float(rng.uniform(0.014, 0.025))
        c = (float(rng.uniform(-span[0], span[0])), float(rng.uniform(-span[1], span[1])))
        if inside_ok(c, r) and all(np.hypot(c[0] - d[0], c[1] - d[1]) >= r + rr + 0.008 for d, rr in holes):
            holes.append((c, r))
    if not holes:  # always room for one central hole of the smallest radius
        holes = [((0.0, 0.0), 0.014)]

    def fn2(q: np.ndarray) -> np.ndarray:
        d = outer(q)
        for c, r in holes:
            d = np.maximum(d, -sdf2d.circle(q - np.asarray(c), r))
        return d

    sec = GeneratedShape("", "", 2, fn2, bounds, "", None, np.array([c for c, _ in holes]))
    h = float(rng.uniform(height_lo, height_hi))
    desc = (f"{'disc' if disc else 'plate'} {np.ptp(bounds[:, 0]) * 100:.1f} x {np.ptp(bounds[:, 1]) * 100:.1f} cm, "
            f"{h * 100:.1f} cm tall, {len(holes)} through holes of radius "
            + ", ".join(f"{r * 100:.1f}" for _, r in holes) + " cm")
    return sec, h, desc


def _holed3d(rng):
    sec, h, desc = _outline_with_holes(rng, 0.03, 0.08)
    return _extruded(sec, h, desc, [h / 2])


def _flat3d(rng):
    """Low objects (2–4 cm): a flat blob/convex/rounded plate, or a holed flat plate."""
    if rng.random() < 0.35:
        sec, h, desc = _outline_with_holes(rng, 0.02, 0.035)
        return _extruded(sec, h, "flat " + desc, [])
    fam = ["blob", "convex", "notched"][int(rng.integers(3))]
    sec = _section(fam, rng)
    h = _height(rng, 0.02, 0.04)
    return _extruded(sec, h, f"flat {fam} slab {h * 100:.1f} cm tall: {sec.description}", [])


def _overhang3d(rng):
    """Mushroom (stem + cap), bridge (two pillars + slab), shelf (pillar + cantilever), table (slab on legs)."""
    kind = ["mushroom", "bridge", "shelf", "table"][int(rng.integers(4))]
    clear = float(rng.uniform(0.035, 0.08))      # free height under the overhang
    top_t = float(rng.uniform(0.012, 0.03))      # thickness of the overhanging part
    if kind == "mushroom":
        rs = float(rng.uniform(0.012, 0.02))
        rc = float(rng.uniform(0.04, 0.07))
        parts = [partial(_cyl, centre=(0, 0, clear / 2), r=rs, hh=clear / 2),
                 partial(_cyl, centre=(0, 0, clear + top_t / 2), r=rc, hh=top_t / 2)]
        b = np.array([[-rc, -rc, 0.0], [rc, rc, clear + top_t]])
        reach = [((rs + rc) / 2, 0.0, clear - TIP_RADIUS_M - 0.002)]
        desc = f"mushroom: stem radius {rs * 100:.1f} cm, cap radius {rc * 100:.1f} cm at {clear * 100:.1f} cm"
        return _solid(_union(parts), b, desc, reach)
    hx, hy = float(rng.uniform(0.04, 0.06)), float(rng.uniform(0.025, 0.045))  # diagonal ≤ 15 cm
    slab = ((0.0, 0.0, clear + top_t / 2), (hx, hy, top_t / 2))
    if kind == "bridge":
        pw = float(rng.uniform(0.01, 0.02))
        gap = 2 * hx - 4 * pw
        if gap < MIN_GAP_M + 0.005:
            pw = (2 * hx - MIN_GAP_M - 0.005) / 4
        pillars = [((sx * (hx - pw), 0.0, clear / 2), (pw, hy, clear / 2)) for sx in (-1, 1)]
        boxes, reach = [slab] + pillars, [(0.0, 0.0, clear / 2)]
        desc = f"bridge {2 * hx * 100:.1f} cm long, {clear * 100:.1f} cm clearance"
    elif kind == "shelf":
        pw = float(rng.uniform(0.012, 0.025))
        boxes = [slab, ((-hx + pw, 0.0, clear / 2), (pw, hy, clear / 2))]
        reach = [(hx - TIP_RADIUS_M - 0.004, 0.0, clear - TIP_RADIUS_M - 0.002)]
        desc = f"shelf: {2 * hx * 100:.1f} cm cantilever at {clear * 100:.1f} cm on a pillar"
    else:
        lw = float(rng.uniform(0.008, 0.012))
        legs = [((sx * (hx - lw), sy * (hy - lw), clear / 2), (lw, lw, clear / 2)) for sx in (-1, 1) for sy in (-1, 1)]
        boxes, reach = [slab] + legs, [(0.0, 0.0, clear / 2)]
        desc = f"table {2 * hx * 100:.1f} x {2 * hy * 100:.1f} cm top at {clear * 100:.1f} cm on four legs"
    fn = _union([partial(_round_box3, centre=c, half=h, rho=0.0) for c, h in boxes])
    lo = np.min([np.subtract(c, h) for c, h in boxes], axis=0)
    hi = np.max([np.add(c, h) for c, h in boxes], axis=0)
    yaw = float(rng.uniform(0, np.pi))
    R = _rot(yaw)
    rot_fn = (lambda q: fn(np.column_stack([q[:, :2] @ R, q[:, 2]])))
    corners = np.array([[x, y] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])]) @ R.T
    b = np.array([[*corners.min(axis=0), 0.0], [*corners.max(axis=0), hi[2]]])
    reach = [np.append(np.asarray(p[:2]) @ R.T, p[2]) for p in reach]
    return _solid(rot_fn, b, desc, reach)


def _thin_wall3d(rng):
    """A standing thin plate or a thin pole (8–16 mm)."""
    t = float(rng.uniform(0.008, 0.016))
    if rng.random() < 0.6:
        L = float(rng.uniform(0.06, MAX_SIZE_M - 0.01))
        h = _height(rng, 0.05, 0.14)
        yaw = float(rng.uniform(0, np.pi))
        R = _rot(yaw)
        fn = lambda q: sdf3d.box(np.column_stack([q[:, :2] @ R, q[:, 2] - h / 2]), (L / 2, t / 2, h / 2))  # noqa: E731
        corners = np.array([[sx * L / 2, sy * t / 2] for sx in (-1, 1) for sy in (-1, 1)]) @ R.T
        b = np.array([[*corners.min(axis=0), 0.0], [*corners.max(axis=0), h]])
        return _solid(fn, b, f"standing thin plate {L * 100:.1f} x {t * 1e3:.0f} mm, {h * 100:.1f} cm tall")
    h = _height(rng, 0.06, 0.14)
    r = t / 2 + 0.002
    base_r = float(rng.uniform(0.025, 0.05))
    base_h = float(rng.uniform(0.008, 0.015))
    parts = [partial(_cyl, centre=(0, 0, h / 2), r=r, hh=h / 2), partial(_cyl, centre=(0, 0, base_h / 2), r=base_r, hh=base_h / 2)]
    return _solid(_union(parts), np.array([[-base_r, -base_r, 0.0], [base_r, base_r, h]]),
                  f"thin pole radius {r * 1e3:.0f} mm, {h * 100:.1f} cm tall, on a disc of radius {base_r * 100:.1f} cm")


def _revolved3d(rng):
    """Vase/bottle: a profile r(z) (body, optional neck, lip), mirrored about r = 0 and revolved (exact)."""
    H = _height(rng, 0.06, 0.14)
    rb = float(rng.uniform(0.025, 0.06))       # base radius
    rm = float(rng.uniform(0.6, 1.25)) * rb    # belly radius
    rn = float(rng.uniform(0.35, 0.9)) * min(rb, rm)  # neck radius
    rl = float(rng.uniform(1.0, 1.5)) * rn     # lip radius
    rm = min(rm, MAX_SIZE_M / 2)
    zs = np.array([0.0, rng.uniform(0.3, 0.55) * H, rng.uniform(0.7, 0.85) * H, H])
    rs = np.array([rb, rm, rn, rl])
    # The (r, z) profile mirrored about r = 0 (revolve is exact for a symmetric section).
    verts = np.vstack([np.column_stack([-rs[::-1], zs[::-1]]), np.column_stack([rs, zs])])
    fn2 = partial(sdf2d.polygon, vertices=verts)
    fn = lambda q: sdf3d.revolve(q, fn2)  # noqa: E731
    R = float(rs.max())
    return _solid(fn, np.array([[-R, -R, 0.0], [R, R, H]]),
                  f"vase {H * 100:.1f} cm tall: radii base {rb * 100:.1f}, belly {rm * 100:.1f}, neck {rn * 100:.1f}, lip {rl * 100:.1f} cm")


_BUILDERS_3D = {"prism": _prism3d, "letter_prism": _letter_prism3d, "superquadric": _superquadric3d,
                "boxes": _boxes3d, "compound": _compound3d, "holed": _holed3d, "flat": _flat3d,
                "overhang": _overhang3d, "thin_wall": _thin_wall3d, "revolved": _revolved3d}
