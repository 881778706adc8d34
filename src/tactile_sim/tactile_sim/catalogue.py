"""Built-in objects: object-local exact SDFs with sizes (5–15 cm).

2D shapes are centred on the local origin (bounding box; the triangle at its
centroid). 3D solids have their lowest point at z = 0.
"""

from __future__ import annotations

from functools import partial

import numpy as np

from tactile_sim import sdf2d, sdf3d
from tactile_sim.sdf_object import LocalSdf


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
