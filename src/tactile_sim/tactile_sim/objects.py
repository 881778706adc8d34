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

from functools import partial
from pathlib import Path

import numpy as np

from tactile_sim import generated, sdf2d
from tactile_sim.catalogue import SHAPES_2D, SHAPES_3D
from tactile_sim.polygon_file import MAX_SIZE_M, MIN_SIZE_M, check_size, load_polygon_csv
from tactile_sim.sdf_object import FD_STEP_M, PlacedShape, Pose, Prism, SDFObject

__all__ = ["SDFObject", "PlacedShape", "Pose", "Prism", "SHAPES_2D", "SHAPES_3D", "FD_STEP_M", "MIN_SIZE_M",
           "MAX_SIZE_M", "list_objects", "describe_objects", "make_object", "load_polygon_csv"]


def _poly_bounds(v: np.ndarray) -> np.ndarray:
    return np.vstack([v.min(axis=0), v.max(axis=0)])


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
        name_or_path: a name of :func:`list_objects`, a generated name
            (``gen2d-017-letter_T``, ``gen3d-s2-004-boxes``: see
            :mod:`tactile_sim.generated`) or a path to a ``.csv`` 2D polygon
            or a ``.stl`` / ``.obj`` 3D triangle mesh.
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
    elif generated.is_generated_name(text):
        shape = generated.make_generated(text)
        if shape.dim == 3 and mode == "2d":
            raise ValueError(f"'{text}' is a generated 3D object; use mode '3d' or a gen2d-... name")
        obj = PlacedShape(text, shape.dim, shape.sdf, shape.bounds, pose)
        obj.family = shape.family
        obj.description = shape.description
    else:
        raise ValueError(f"unknown object {text!r}: use a path (.csv, .stl, .obj), a generated name "
                         f"(gen2d-000-blob ..., see tactile_sim.generated.suite_names) or one of "
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
    check_size(path, hi - lo)
    # Stand on the table at the object pose: bounding-box centre in x-y, lowest point at z = 0.
    offset = np.array([0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), lo[2]])
    m = mesh.MeshSDF(tri - offset, name=str(path))
    obj = PlacedShape(path.stem, 3, m.sdf, np.vstack([lo - offset, hi - offset]), pose, m.gradient)
    obj.mesh = m
    return obj
