"""Objects of the simulated world as signed distance functions (world frame, metres).

Every object, analytic or loaded from a file, is an :class:`SDFObject`:
``sdf(p)`` (N, dim) → (N,) signed distance (< 0 inside), ``gradient(p)``
(N, dim) unit outward normals, ``bounds`` (2, dim), ``name``, ``dim``.

Placement (docs/architecture.md): the object-local origin goes to
``center_xy_m`` on the table top, rotated by ``yaw_rad`` about z, sizes
multiplied by ``scale``. 3D solids stand on the table: their lowest point is
at z = 0 and the solid is intersected with the half-space z ≥ 0. In 2D the
object is the cross-section of a right prism of height ``prism_height_m``; a
2D shape asked for in 3D mode is that prism.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Callable

import numpy as np

from tactile_sim import sdf2d, sdf3d

LocalSdf = Callable[[np.ndarray], np.ndarray]

#: Central-difference step for numerical gradients [m].
FD_STEP_M = 1e-6
#: Plausible object size range for user files [m] (largest bounding-box side).
MIN_SIZE_M, MAX_SIZE_M = 0.01, 0.50


class SDFObject:
    """A solid in the world frame given by its signed distance function.

    Subclasses implement :meth:`sdf`; :meth:`gradient` defaults to central
    differences of the SDF, normalised.
    """

    name: str
    dim: int
    bounds: np.ndarray

    def sdf(self, p: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def gradient(self, p: np.ndarray) -> np.ndarray:
        """Unit outward normal field ∇d/‖∇d‖ by central differences (step FD_STEP_M)."""
        p = self._check(p)
        n = len(p)
        offsets = np.eye(self.dim) * FD_STEP_M
        stacked = np.concatenate([p + o for o in offsets] + [p - o for o in offsets])
        d = self.sdf(stacked).reshape(2, self.dim, n)
        g = ((d[0] - d[1]) / (2.0 * FD_STEP_M)).T
        return _normalise(g)

    def inside(self, p: np.ndarray) -> np.ndarray:
        """Boolean (N,): sdf(p) < 0."""
        return self.sdf(p) < 0.0

    def surface_samples(self, spacing_m: float = 0.002) -> np.ndarray:
        """Points of the zero level set, about one per ``spacing_m`` lattice cell (cached).

        Lattice nodes within one cell of the surface (found coarse-to-fine,
        using |∇d| ≤ 1) are projected onto it with p ← p − d(p)·∇d(p).
        Points that do not converge to |d| < 1e-7 m are dropped.
        """
        key = round(float(spacing_m), 12)
        cache = self.__dict__.setdefault("_surface_cache", {})
        if key not in cache:
            cache[key] = _project_to_surface(self, float(spacing_m))
        return cache[key]

    def _check(self, p: np.ndarray) -> np.ndarray:
        a = np.asarray(p, dtype=float)
        if a.ndim == 1 and a.shape[0] == self.dim:
            a = a[None, :]
        if a.ndim != 2 or a.shape[1] != self.dim:
            raise ValueError(f"object '{self.name}' is {self.dim}D: expected points of shape (N, {self.dim}), got {np.shape(p)}")
        return a

    def __repr__(self) -> str:
        return f"{type(self).__name__}(name={self.name!r}, dim={self.dim}, bounds={self.bounds.tolist()})"


def _normalise(g: np.ndarray) -> np.ndarray:
    norm = np.linalg.norm(g, axis=1, keepdims=True)
    return g / np.where(norm > 0.0, norm, 1.0)


@dataclass(frozen=True)
class Pose:
    """Object pose on the table: local origin at (x, y, 0), yaw about z, uniform scale."""

    center_xy_m: tuple[float, float] = (0.50, 0.0)
    yaw_rad: float = 0.0
    scale: float = 1.0

    def to_local(self, p: np.ndarray) -> np.ndarray:
        """World → object-local (unscaled): q = R(−yaw)(p − c) / s; z is kept (table at 0)."""
        c, s = np.cos(self.yaw_rad), np.sin(self.yaw_rad)
        x = p[:, 0] - self.center_xy_m[0]
        y = p[:, 1] - self.center_xy_m[1]
        q = np.empty_like(p)
        q[:, 0] = c * x + s * y
        q[:, 1] = -s * x + c * y
        if p.shape[1] == 3:
            q[:, 2] = p[:, 2]
        return q / self.scale

    def vector_to_world(self, v: np.ndarray) -> np.ndarray:
        """Rotate local direction vectors to the world frame (yaw only)."""
        c, s = np.cos(self.yaw_rad), np.sin(self.yaw_rad)
        out = v.copy()
        out[:, 0] = c * v[:, 0] - s * v[:, 1]
        out[:, 1] = s * v[:, 0] + c * v[:, 1]
        return out

    def bounds_to_world(self, local_bounds: np.ndarray) -> np.ndarray:
        """Axis-aligned world box of a local box (corners rotated, scaled, shifted)."""
        lo, hi = np.asarray(local_bounds, float)
        corners = np.array([[x, y] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])]) * self.scale
        c, s = np.cos(self.yaw_rad), np.sin(self.yaw_rad)
        xy = corners @ np.array([[c, s], [-s, c]]) + np.asarray(self.center_xy_m)
        out = np.vstack([xy.min(axis=0), xy.max(axis=0)])
        if len(lo) == 3:
            out = np.column_stack([out, [lo[2] * self.scale, hi[2] * self.scale]])
        return out


class PlacedShape(SDFObject):
    """An object-local SDF placed on the table (see module docstring).

    sdf(p) = s · d_local(q) with q = pose.to_local(p); in 3D additionally
    max(·, −z) (nothing below the table top).
    """

    def __init__(self, name: str, dim: int, local_sdf: LocalSdf, local_bounds: np.ndarray,
                 pose: Pose = Pose(), local_gradient: LocalSdf | None = None) -> None:
        self.name = name
        self.dim = dim
        self.pose = pose
        self._local_sdf = local_sdf
        self._local_gradient = local_gradient
        self.local_bounds = np.asarray(local_bounds, float)
        self.bounds = pose.bounds_to_world(self.local_bounds)
        if dim == 3:
            self.bounds[0, 2] = max(self.bounds[0, 2], 0.0)

    def sdf(self, p: np.ndarray) -> np.ndarray:
        p = self._check(p)
        d = self.pose.scale * self._local_sdf(self.pose.to_local(p))
        if self.dim == 3:
            d = np.maximum(d, -p[:, 2])
        return d

    def gradient(self, p: np.ndarray) -> np.ndarray:
        if self._local_gradient is None:
            return super().gradient(p)
        p = self._check(p)
        q = self.pose.to_local(p)
        g = self.pose.vector_to_world(self._local_gradient(q))
        if self.dim == 3:
            # The table face can only be the closest one below z = 0 (the solid lies in z >= 0).
            below = np.nonzero(p[:, 2] < 0.0)[0]
            if len(below):
                table = -p[below, 2] > self.pose.scale * self._local_sdf(q[below])
                g[below[table]] = (0.0, 0.0, -1.0)
        return _normalise(g)


class Prism(SDFObject):
    """The right prism 0 ≤ z ≤ h over a 2D object (exact extrusion SDF)."""

    def __init__(self, section: SDFObject, height_m: float) -> None:
        if section.dim != 2:
            raise ValueError(f"a prism needs a 2D cross-section, '{section.name}' is {section.dim}D")
        self.section = section
        self.height_m = float(height_m)
        self.name = section.name
        self.dim = 3
        self.bounds = np.column_stack([section.bounds, [0.0, self.height_m]])

    def sdf(self, p: np.ndarray) -> np.ndarray:
        p = self._check(p)
        half = 0.5 * self.height_m
        return sdf3d._cap(self.section.sdf(p[:, :2]), np.abs(p[:, 2] - half) - half)


# --------------------------------------------------------------------------
# Catalogue (object-local shapes; 3D solids have their lowest point at z = 0)
# --------------------------------------------------------------------------

def _centered(vertices: list[tuple[float, float]]) -> np.ndarray:
    """Vertices shifted so that their bounding box is centred on the origin."""
    v = np.asarray(vertices, dtype=float)
    return v - 0.5 * (v.min(axis=0) + v.max(axis=0))


def _star(n_points: int, outer_m: float, inner_m: float) -> np.ndarray:
    ang = np.pi / 2 + np.arange(2 * n_points) * np.pi / n_points
    r = np.where(np.arange(2 * n_points) % 2 == 0, outer_m, inner_m)
    return np.column_stack([r * np.cos(ang), r * np.sin(ang)])


def _triangle(circumradius_m: float) -> np.ndarray:
    ang = np.pi / 2 + np.arange(3) * 2 * np.pi / 3
    return circumradius_m * np.column_stack([np.cos(ang), np.sin(ang)])


_L_SHAPE = _centered([(0, 0), (0.10, 0), (0.10, 0.04), (0.04, 0.04), (0.04, 0.10), (0, 0.10)])
_C_SHAPE = _centered([(0, 0), (0.10, 0), (0.10, 0.035), (0.035, 0.035), (0.035, 0.065),
                      (0.10, 0.065), (0.10, 0.10), (0, 0.10)])
_STAR = _star(5, 0.060, 0.027)
_TRIANGLE = _triangle(0.050)
# Kidney: points within 2.2 cm of a circular arc of radius 4.5 cm spanning ±63°.
_KIDNEY = dict(half_aperture_rad=1.1, arc_radius_m=0.045, thickness_m=0.022)
_KIDNEY_Y0 = 0.5 * (0.045 * np.cos(1.1) - 0.022 + 0.045 + 0.022)
_KIDNEY_HALF = (0.045 * np.sin(1.1) + 0.022, 0.5 * (0.045 + 0.022 - (0.045 * np.cos(1.1) - 0.022)))


def _poly_bounds(v: np.ndarray) -> np.ndarray:
    return np.vstack([v.min(axis=0), v.max(axis=0)])


def _box_bounds(half: tuple[float, ...], center: tuple[float, ...] | None = None) -> np.ndarray:
    h = np.asarray(half, float)
    c = np.zeros_like(h) if center is None else np.asarray(center, float)
    return np.vstack([c - h, c + h])


def _shift(fn: LocalSdf, offset: tuple[float, ...]) -> LocalSdf:
    o = np.asarray(offset, float)
    return lambda q: fn(q - o)


def _kidney(q: np.ndarray) -> np.ndarray:
    return sdf2d.arc(q + np.array([0.0, _KIDNEY_Y0]), **_KIDNEY)


#: name -> (local sdf, local bounds, description with size)
SHAPES_2D: dict[str, tuple[LocalSdf, np.ndarray, str]] = {
    "circle": (partial(sdf2d.circle, radius_m=0.04), _box_bounds((0.04, 0.04)), "circle, diameter 8 cm"),
    "ellipse": (partial(sdf2d.ellipse, a_m=0.06, b_m=0.035), _box_bounds((0.06, 0.035)), "ellipse 12 x 7 cm"),
    "rounded_square": (partial(sdf2d.round_box, half_m=(0.04, 0.04), corner_radius_m=0.01),
                       _box_bounds((0.04, 0.04)), "square 8 x 8 cm, corner radius 1 cm"),
    "triangle": (partial(sdf2d.polygon, vertices=_TRIANGLE), _poly_bounds(_TRIANGLE),
                 "equilateral triangle, side 8.7 cm (centroid at the origin)"),
    "star": (partial(sdf2d.polygon, vertices=_STAR), _poly_bounds(_STAR), "5-pointed star, tip radius 6 cm, inner radius 2.7 cm"),
    "kidney": (_kidney, _box_bounds(_KIDNEY_HALF), "bean: 2.2 cm around an arc of radius 4.5 cm over ±63 deg, 12.4 x 6.9 cm (non-convex)"),
    "l_shape": (partial(sdf2d.polygon, vertices=_L_SHAPE), _poly_bounds(_L_SHAPE), "L, 10 x 10 cm, arms 4 cm wide (non-convex)"),
    "c_shape": (partial(sdf2d.polygon, vertices=_C_SHAPE), _poly_bounds(_C_SHAPE),
                "C, 10 x 10 cm, slot 3 cm wide and 6.5 cm deep opening to +x (non-convex)"),
}

_L_BLOCK_XZ = [(0, 0), (0.12, 0), (0.12, 0.04), (0.04, 0.04), (0.04, 0.12), (0, 0.12)]
_L_BLOCK_XZ_C = np.asarray(_L_BLOCK_XZ, float) - np.array([0.06, 0.0])
_CONE_RZ = np.array([(-0.05, 0.0), (0.05, 0.0), (0.0, 0.10)])
_CUP_RZ = np.array([(-0.04, 0.0), (0.04, 0.0), (0.04, 0.10), (0.034, 0.10), (0.034, 0.01),
                    (-0.034, 0.01), (-0.034, 0.10), (-0.04, 0.10)])


def _sphere_grad(q: np.ndarray) -> np.ndarray:
    return q - np.array([0.0, 0.0, 0.05])


SHAPES_3D: dict[str, tuple[LocalSdf, np.ndarray, str, LocalSdf | None]] = {
    "sphere": (_shift(partial(sdf3d.sphere, radius_m=0.05), (0, 0, 0.05)), _box_bounds((0.05,) * 3, (0, 0, 0.05)),
               "sphere, diameter 10 cm", _sphere_grad),
    "box": (_shift(partial(sdf3d.box, half_m=(0.04, 0.03, 0.05)), (0, 0, 0.05)),
            _box_bounds((0.04, 0.03, 0.05), (0, 0, 0.05)), "box 8 x 6 x 10 cm (x, y, z)", None),
    "cylinder": (_shift(partial(sdf3d.capped_cylinder, radius_m=0.035, half_height_m=0.06), (0, 0, 0.06)),
                 _box_bounds((0.035, 0.035, 0.06), (0, 0, 0.06)), "upright cylinder, diameter 7 cm, height 12 cm", None),
    "capsule": (partial(sdf3d.capsule, a=(-0.04, 0, 0.03), b=(0.04, 0, 0.03), radius_m=0.03),
                _box_bounds((0.07, 0.03, 0.03), (0, 0, 0.03)), "capsule lying along x: length 14 cm, diameter 6 cm", None),
    "torus": (_shift(partial(sdf3d.torus, major_radius_m=0.045, minor_radius_m=0.018), (0, 0, 0.018)),
              _box_bounds((0.063, 0.063, 0.018), (0, 0, 0.018)),
              "torus lying flat: outer diameter 12.6 cm, tube diameter 3.6 cm, hole diameter 5.4 cm (non-convex)", None),
    "l_block": (lambda q: sdf3d.extrude(q, partial(sdf2d.polygon, vertices=_L_BLOCK_XZ_C), (0, 2, 1), 0.03),
                np.array([[-0.06, -0.03, 0.0], [0.06, 0.03, 0.12]]),
                "L-block: L profile in x-z (12 cm long, 12 cm tall, 4 cm thick) extruded 6 cm in y (non-convex)", None),
    "cone": (lambda q: sdf3d.revolve(q, partial(sdf2d.polygon, vertices=_CONE_RZ)),
             np.array([[-0.05, -0.05, 0.0], [0.05, 0.05, 0.10]]), "upright cone, base diameter 10 cm, height 10 cm", None),
    "cup": (lambda q: sdf3d.revolve(q, partial(sdf2d.polygon, vertices=_CUP_RZ)),
            np.array([[-0.04, -0.04, 0.0], [0.04, 0.04, 0.10]]),
            "open cup (mug without handle): diameter 8 cm, height 10 cm, wall 6 mm, base 1 cm (non-convex)", None),
}


def list_objects(mode: str = "2d") -> list[str]:
    """Names of the built-in objects of a mode ("2d" or "3d")."""
    _check_mode(mode)
    return list(SHAPES_2D) if mode == "2d" else list(SHAPES_3D)


def describe_objects() -> dict[str, dict[str, str]]:
    """{"2d": {name: description}, "3d": {...}} (sizes in the descriptions)."""
    return {"2d": {k: v[2] for k, v in SHAPES_2D.items()}, "3d": {k: v[2] for k, v in SHAPES_3D.items()}}


def _check_mode(mode: str) -> None:
    if mode not in ("2d", "3d"):
        raise ValueError(f"mode must be '2d' or '3d', got {mode!r}")


def make_object(name_or_path: str | Path, mode: str = "2d", center_xy_m: tuple[float, float] = (0.50, 0.0),
                yaw_rad: float = 0.0, scale: float = 1.0, prism_height_m: float = 0.12) -> SDFObject:
    """Build a placed object by built-in name or from a file.

    Args:
        name_or_path: a name of :func:`list_objects` or a path to a ``.csv``
            2D polygon or a ``.stl`` / ``.obj`` 3D triangle mesh.
        mode: "2d" (cross-section, dim 2) or "3d" (dim 3). A 2D shape or
            polygon in 3D mode becomes the prism of height ``prism_height_m``.
        center_xy_m, yaw_rad, scale: object pose on the table (world frame).
        prism_height_m: height of the 2D prism (stored as ``.prism_height_m``).

    Raises:
        ValueError: unknown name, bad mode/pose, or a bad file (message names
            the file and the problem).
    """
    _check_mode(mode)
    center = tuple(float(c) for c in np.asarray(center_xy_m, dtype=float).reshape(-1))
    if len(center) != 2 or not np.all(np.isfinite(center)):
        raise ValueError(f"center_xy_m must be two finite numbers, got {center_xy_m!r}")
    if not (np.isfinite(scale) and scale > 0.0):
        raise ValueError(f"scale must be a positive number, got {scale!r}")
    if not (np.isfinite(prism_height_m) and prism_height_m > 0.0):
        raise ValueError(f"prism_height_m must be positive, got {prism_height_m!r}")
    if not np.isfinite(yaw_rad):
        raise ValueError(f"yaw_rad must be finite, got {yaw_rad!r}")
    pose = Pose(center, float(yaw_rad), float(scale))
    text = str(name_or_path)
    suffix = Path(text).suffix.lower()

    if suffix:
        obj = _from_file(Path(text), suffix, mode, pose)
    elif text in SHAPES_2D:
        fn, bounds, _ = SHAPES_2D[text]
        obj = PlacedShape(text, 2, fn, bounds, pose)
    elif text in SHAPES_3D:
        if mode == "2d":
            raise ValueError(f"'{text}' is a 3D object; 2D objects are: {', '.join(SHAPES_2D)}")
        fn, bounds, _, grad = SHAPES_3D[text]
        obj = PlacedShape(text, 3, fn, bounds, pose, grad)
    else:
        raise ValueError(f"unknown object {text!r}: use a path (.csv, .stl, .obj) or one of "
                         f"2D: {', '.join(SHAPES_2D)}; 3D: {', '.join(SHAPES_3D)}")
    if mode == "3d" and obj.dim == 2:
        obj = Prism(obj, prism_height_m)
    obj.prism_height_m = float(prism_height_m)
    return obj


def _from_file(path: Path, suffix: str, mode: str, pose: Pose) -> SDFObject:
    if suffix not in (".csv", ".stl", ".obj"):
        raise ValueError(f"{path}: unsupported object file extension '{suffix}' (use .csv for a 2D polygon, .stl or .obj for a 3D mesh)")
    if not path.is_file():
        raise ValueError(f"{path}: object file not found")
    if suffix == ".csv":
        vertices = load_polygon_csv(path)
        return PlacedShape(path.stem, 2, partial(sdf2d.polygon, vertices=vertices), _poly_bounds(vertices), pose)
    if mode == "2d":
        raise ValueError(f"{path}: a 3D mesh needs mode '3d' (2D mode takes a .csv polygon)")
    from tactile_sim import mesh  # noqa: PLC0415 - only needed for mesh files

    tri = mesh.load_mesh(path)
    corners = tri.reshape(-1, 3)
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    _check_size(path, hi - lo)
    # Stand on the table at the object pose: bounding-box centre in x-y, lowest point at z = 0.
    offset = np.array([0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), lo[2]])
    m = mesh.MeshSDF(tri - offset, name=str(path))
    obj = PlacedShape(path.stem, 3, m.sdf, np.vstack([lo - offset, hi - offset]), pose, m.gradient)
    obj.mesh = m
    return obj


def _check_size(path: Path, extent_m: np.ndarray) -> None:
    size = float(np.max(extent_m))
    if size < MIN_SIZE_M or size > MAX_SIZE_M:
        hint = ""
        if size > MAX_SIZE_M and MIN_SIZE_M <= size / 1000 <= MAX_SIZE_M:
            hint = " (looks like millimetres: coordinates must be in metres)"
        elif size < MIN_SIZE_M and MIN_SIZE_M <= size * 100 <= MAX_SIZE_M:
            hint = " (wrong units? coordinates must be in metres)"
        raise ValueError(f"{path}: object size {size:.4g} m is outside the plausible range "
                         f"{MIN_SIZE_M}-{MAX_SIZE_M} m{hint or ' (wrong units? coordinates must be in metres)'}")


def load_polygon_csv(path: str | Path) -> np.ndarray:
    """Read a 2D polygon: one ``x,y`` vertex per line (metres, object-local), optional header.

    The polygon is closed implicitly (a repeated first vertex is dropped) and
    shifted so that its bounding box is centred on the local origin.

    Raises:
        ValueError: missing/empty file, a bad line, fewer than 3 vertices,
            NaN/inf, zero area, self-intersection, implausible size.
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: polygon file not found")
    rows: list[tuple[float, float]] = []
    lines = path.read_text(errors="replace").splitlines()
    for number, line in enumerate(lines, start=1):
        text = line.split("#", 1)[0].strip()
        if not text:
            continue
        fields = [f.strip() for f in text.replace(";", ",").split(",")] if ("," in text or ";" in text) else text.split()
        try:
            if len(fields) != 2:
                raise ValueError
            x, y = float(fields[0]), float(fields[1])
        except ValueError:
            if not rows and number == next(i for i, ln in enumerate(lines, 1) if ln.split("#", 1)[0].strip()):
                continue  # header line
            raise ValueError(f"{path}: line {number}: expected 'x,y' (two numbers in metres), got {line.strip()!r}") from None
        rows.append((x, y))
    if not rows:
        raise ValueError(f"{path}: polygon file is empty (expected one 'x,y' vertex per line)")
    v = np.asarray(rows, dtype=float)
    if not np.all(np.isfinite(v)):
        bad = int(np.nonzero(~np.all(np.isfinite(v), axis=1))[0][0])
        raise ValueError(f"{path}: vertex {bad + 1} is not finite (NaN or inf): {v[bad].tolist()}")
    if len(v) > 1 and np.allclose(v[0], v[-1]):
        v = v[:-1]
    keep = np.ones(len(v), bool)
    keep[1:] = np.any(np.diff(v, axis=0) != 0.0, axis=1)
    v = v[keep]
    if len(v) < 3:
        raise ValueError(f"{path}: a polygon needs at least 3 distinct vertices, got {len(v)}")
    _check_size(path, np.ptp(v, axis=0))
    crossings = sdf2d.polygon_self_intersections(v)
    if crossings:
        i, j = crossings[0]
        raise ValueError(f"{path}: polygon is self-intersecting: edge {i + 1} (vertices {i + 1}-{(i + 1) % len(v) + 1}) "
                         f"crosses edge {j + 1} (vertices {j + 1}-{(j + 1) % len(v) + 1}); {len(crossings)} crossing(s)")
    if abs(sdf2d.polygon_area_m2(v)) < 1e-12:
        raise ValueError(f"{path}: polygon has zero area (all vertices on a line)")
    return v - 0.5 * (v.min(axis=0) + v.max(axis=0))


# --------------------------------------------------------------------------
# Surface sampling (generic, used by metrics)
# --------------------------------------------------------------------------

def _lattice(lo: np.ndarray, hi: np.ndarray, h: float) -> np.ndarray:
    axes = [np.arange(a, b + 0.5 * h, h) for a, b in zip(lo, hi)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(lo))


def _project_to_surface(obj: SDFObject, h: float, iterations: int = 6, tol_m: float = 1e-7) -> np.ndarray:
    dim = obj.dim
    lo, hi = obj.bounds[0] - 2 * h, obj.bounds[1] + 2 * h
    # Coarse pass: cells of size H whose centre is within the half diagonal of the surface.
    coarse = max(h, min(8 * h, float(np.min(hi - lo)) / 8))
    factor = max(1, int(round(coarse / h)))
    coarse = factor * h
    centres = _lattice(lo, hi, coarse)
    near = centres[np.abs(obj.sdf(centres)) <= 0.5 * coarse * np.sqrt(dim) + 1e-12]
    # Fine pass: the sub-lattice of spacing h inside the kept coarse cells.
    sub = (np.arange(factor) - 0.5 * (factor - 1)) * h
    offsets = np.stack(np.meshgrid(*([sub] * dim), indexing="ij"), axis=-1).reshape(-1, dim)
    p = (near[:, None, :] + offsets[None]).reshape(-1, dim)
    d = obj.sdf(p)
    keep = np.abs(d) <= 0.5 * h * np.sqrt(dim)
    p, d = p[keep], d[keep]
    done: list[np.ndarray] = []
    for _ in range(iterations):  # one step is exact for an exact SDF; iterate only the rest
        p = p - d[:, None] * obj.gradient(p)
        d = obj.sdf(p)
        ok = np.abs(d) < tol_m
        done.append(p[ok])
        p, d = p[~ok], d[~ok]
        if len(p) == 0:
            break
    return np.concatenate(done)
