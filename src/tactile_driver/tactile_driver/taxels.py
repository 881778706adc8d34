"""Taxel layouts of the omnidirectional fingertip, and its surface geometry (ROS-free).

Fingertip frame: origin at the tip centre, z along the finger from the tip
towards the flange. The finger surface is

- 2D rig (``ring_layout``): a vertical cylinder of radius r around the z-axis,
  covering the band ``axis_z_range_m`` = [z0, z1] of the taxel rings;
- 3D rig (``hemisphere_layout``): a capsule end: the lower hemisphere
  |p| = r, z <= 0, plus the cylinder of radius r for z in [0, z1].

Every surface point is ``a + r n`` with ``a`` on the axis segment and ``n``
the outward unit normal; :meth:`TaxelLayout.project_to_surface` maps any
point to the surface point with the same axis foot / direction.

The layout files in ``config/`` are written by ``python -m tactile_driver.taxels``
from the generator functions below; they list each taxel's position (m) and
outward normal in the fingertip frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np
import yaml

TIP_RADIUS_M = 0.010


@dataclass(frozen=True)
class TaxelLayout:
    """Taxel positions/normals (fingertip frame) and the surface they cover."""

    name: str
    tip_radius_m: float
    positions_m: np.ndarray  # (N, 3)
    normals: np.ndarray  # (N, 3) unit, outward
    axis_z_range_m: tuple[float, float]  # side cylinder band [z0, z1]
    hemisphere: bool  # lower hemispherical cap below z = 0 (3D rig)
    params: dict = field(default_factory=dict)  # generator parameters

    @property
    def n_taxels(self) -> int:
        return int(self.positions_m.shape[0])

    def axis_foot(self, points_m: np.ndarray) -> np.ndarray:
        """(N, 3) foot on the axis segment of each point: (0, 0, clip(z))."""
        p = np.atleast_2d(points_m)
        z0, z1 = self.axis_z_range_m
        lo = 0.0 if self.hemisphere else z0
        foot = np.zeros_like(p, dtype=float)
        foot[:, 2] = np.clip(p[:, 2], lo, z1)
        return foot

    def project_to_surface(self, points_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Surface points and outward unit normals for (N, 3) points (fingertip frame).

        n = (p - a) / |p - a| with a the axis foot (cylinder only: the xy part),
        surface point = a + r n. A point on the axis itself has no direction:
        its rows are NaN.
        """
        p = np.atleast_2d(np.asarray(points_m, dtype=float))
        a = self.axis_foot(p)
        d = p - a
        if not self.hemisphere:
            d[:, 2] = 0.0
        norm = np.linalg.norm(d, axis=1, keepdims=True)
        with np.errstate(invalid="ignore", divide="ignore"):
            n = np.where(norm > 1e-9, d / norm, np.nan)
        return a + self.tip_radius_m * n, n

    def surface_samples(self, spacing_m: float, margin_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """A near-uniform sampling of the finger surface: points, normals, areas (m²).

        Covers the side band extended by ``margin_m`` above (and below, without
        a cap), and the hemisphere when present.
        """
        r = self.tip_radius_m
        z0, z1 = self.axis_z_range_m
        lo = 0.0 if self.hemisphere else z0 - margin_m
        hi = z1 + margin_m
        n_theta = max(8, int(round(2 * math.pi * r / spacing_m)))
        n_z = max(1, int(round((hi - lo) / spacing_m)))
        theta = (np.arange(n_theta) + 0.5) * 2 * math.pi / n_theta
        zs = lo + (np.arange(n_z) + 0.5) * (hi - lo) / n_z
        tt, zz = np.meshgrid(theta, zs, indexing="ij")
        n_side = np.stack([np.cos(tt).ravel(), np.sin(tt).ravel(), np.zeros(tt.size)], axis=1)
        p_side = n_side * r
        p_side[:, 2] = zz.ravel()
        a_side = np.full(tt.size, (2 * math.pi * r / n_theta) * ((hi - lo) / n_z))
        if not self.hemisphere:
            return p_side, n_side, a_side
        n_cap = _fibonacci_lower_hemisphere(max(16, int(round(2 * math.pi * r * r / spacing_m**2))))
        a_cap = np.full(len(n_cap), 2 * math.pi * r * r / len(n_cap))
        return (
            np.vstack([p_side, r * n_cap]),
            np.vstack([n_side, n_cap]),
            np.concatenate([a_side, a_cap]),
        )


def _fibonacci_lower_hemisphere(n: int) -> np.ndarray:
    """(n, 3) near-uniform unit vectors with z < 0 (Fibonacci lattice)."""
    i = np.arange(n) + 0.5
    z = -i / n  # uniform in z on (-1, 0): equal-area bands
    phi = i * math.pi * (3.0 - math.sqrt(5.0))
    s = np.sqrt(1.0 - z**2)
    return np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=1)


def ring_layout(
    n_per_ring: int = 32,
    ring_z_m: Sequence[float] = (-0.003, 0.0, 0.003),
    tip_radius_m: float = TIP_RADIUS_M,
    stagger: bool = True,
) -> TaxelLayout:
    """2D rig: rings of ``n_per_ring`` taxels on the cylinder of radius r at heights ``ring_z_m``.

    Taxel j of ring k sits at angle theta = 2 pi (j + s_k) / n_per_ring with
    s_k = k/2 mod 1 when staggered; position (r cos theta, r sin theta, z_k),
    normal (cos theta, sin theta, 0).
    """
    if n_per_ring < 3 or not len(ring_z_m):
        raise ValueError("a ring layout needs >= 3 taxels per ring and >= 1 ring")
    pos, nrm = [], []
    for k, z in enumerate(ring_z_m):
        shift = (0.5 * k) % 1.0 if stagger else 0.0
        theta = 2 * math.pi * (np.arange(n_per_ring) + shift) / n_per_ring
        n = np.stack([np.cos(theta), np.sin(theta), np.zeros(n_per_ring)], axis=1)
        p = n * tip_radius_m
        p[:, 2] = z
        pos.append(p)
        nrm.append(n)
    zs = [float(z) for z in ring_z_m]
    return TaxelLayout(
        name="ring",
        tip_radius_m=float(tip_radius_m),
        positions_m=np.vstack(pos),
        normals=np.vstack(nrm),
        axis_z_range_m=(min(zs), max(zs)),
        hemisphere=False,
        params={"n_per_ring": int(n_per_ring), "ring_z_m": zs, "tip_radius_m": float(tip_radius_m), "stagger": bool(stagger)},
    )


def hemisphere_layout(
    spacing_m: float = 0.003,
    n_side_rings: int = 2,
    tip_radius_m: float = TIP_RADIUS_M,
) -> TaxelLayout:
    """3D rig: taxels on the lower hemisphere plus ``n_side_rings`` rings on the cylinder above it.

    Hemisphere: one taxel at the pole, then rings at polar angles
    phi_k = k (pi/2) / K from the -z axis (K = round((pi/2) r / spacing)), ring k
    with round(2 pi r sin(phi_k) / spacing) taxels: position r (sin phi cos theta,
    sin phi sin theta, -cos phi), normal the same unit vector. Side rings at
    z = j * spacing (j = 1..n_side_rings), normals horizontal. Rings are
    staggered by half a spacing.
    """
    r = float(tip_radius_m)
    if spacing_m <= 0 or spacing_m > r:
        raise ValueError(f"spacing_m must be in (0, tip_radius_m], got {spacing_m}")
    n_polar = max(1, int(round(0.5 * math.pi * r / spacing_m)))
    dirs = [np.array([[0.0, 0.0, -1.0]])]
    for k in range(1, n_polar + 1):
        phi = k * 0.5 * math.pi / n_polar
        m = max(3, int(round(2 * math.pi * r * math.sin(phi) / spacing_m)))
        theta = 2 * math.pi * (np.arange(m) + 0.5 * (k % 2)) / m
        dirs.append(np.stack([math.sin(phi) * np.cos(theta), math.sin(phi) * np.sin(theta),
                              np.full(m, -math.cos(phi))], axis=1))
    nrm = np.vstack(dirs)
    pos = nrm * r
    m_side = max(3, int(round(2 * math.pi * r / spacing_m)))
    side_z = [j * spacing_m for j in range(1, n_side_rings + 1)]
    for j, z in enumerate(side_z, start=n_polar + 1):
        theta = 2 * math.pi * (np.arange(m_side) + 0.5 * (j % 2)) / m_side
        n = np.stack([np.cos(theta), np.sin(theta), np.zeros(m_side)], axis=1)
        p = n * r
        p[:, 2] = z
        pos = np.vstack([pos, p])
        nrm = np.vstack([nrm, n])
    return TaxelLayout(
        name="hemisphere",
        tip_radius_m=r,
        positions_m=pos,
        normals=nrm,
        axis_z_range_m=(0.0, float(side_z[-1]) if side_z else 0.0),
        hemisphere=True,
        params={"spacing_m": float(spacing_m), "n_side_rings": int(n_side_rings), "tip_radius_m": r},
    )


GENERATORS = {"ring": ring_layout, "hemisphere": hemisphere_layout}


def layout_to_dict(layout: TaxelLayout) -> dict:
    """Plain-data form of a layout (what the YAML files hold)."""
    return {
        "name": layout.name,
        "generator": f"tactile_driver.taxels.{GENERATORS[layout.name].__name__}" if layout.name in GENERATORS else "",
        "params": dict(layout.params),
        "tip_radius_m": layout.tip_radius_m,
        "axis_z_range_m": [float(v) for v in layout.axis_z_range_m],
        "hemisphere": layout.hemisphere,
        "taxels_comment": "one row per taxel: x_m, y_m, z_m, normal_x, normal_y, normal_z (fingertip frame)",
        "taxels": [[round(float(v), 9) for v in row] for row in np.hstack([layout.positions_m, layout.normals])],
    }


def layout_from_dict(d: dict, source: str = "layout") -> TaxelLayout:
    """Validate and build a layout from its plain-data form.

    Raises:
        ValueError: a missing key, a bad shape, a normal that is not unit length.
    """
    try:
        rows = np.asarray(d["taxels"], dtype=float)
        r = float(d["tip_radius_m"])
        z0, z1 = (float(v) for v in d["axis_z_range_m"])
        hemi = bool(d["hemisphere"])
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"{source}: invalid taxel layout ({exc!r})") from None
    if rows.ndim != 2 or rows.shape[1] != 6 or rows.shape[0] < 3:
        raise ValueError(f"{source}: 'taxels' must be >= 3 rows of 6 numbers, got shape {rows.shape}")
    normals = rows[:, 3:]
    if not np.allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-6):
        raise ValueError(f"{source}: every taxel normal must be a unit vector")
    if r <= 0 or z1 < z0:
        raise ValueError(f"{source}: need tip_radius_m > 0 and axis_z_range_m ordered")
    return TaxelLayout(
        name=str(d.get("name", "custom")), tip_radius_m=r, positions_m=rows[:, :3].copy(),
        normals=normals.copy(), axis_z_range_m=(z0, z1), hemisphere=hemi, params=dict(d.get("params", {})),
    )


def load_layout(path: str | Path) -> TaxelLayout:
    """Read a layout YAML file (see ``config/taxels_*.yaml``).

    Raises:
        ValueError: the file is missing or invalid (the message names it).
    """
    path = Path(path)
    try:
        data = yaml.safe_load(path.read_text())
    except OSError as exc:
        raise ValueError(f"cannot read taxel layout {path}: {exc.strerror}") from None
    except yaml.YAMLError as exc:
        raise ValueError(f"taxel layout {path} is not valid YAML: {exc}") from None
    if not isinstance(data, dict):
        raise ValueError(f"taxel layout {path} must be a mapping")
    return layout_from_dict(data, str(path))


def save_layout(layout: TaxelLayout, path: str | Path) -> None:
    """Write a layout YAML file."""
    header = (
        "# Taxel layout of the omnidirectional fingertip (fingertip frame: origin at the tip\n"
        "# centre, z along the finger towards the flange). Generated by\n"
        "# `python -m tactile_driver.taxels`; do not edit by hand.\n"
    )
    Path(path).write_text(header + yaml.safe_dump(layout_to_dict(layout), sort_keys=False, default_flow_style=None))


#: The layout file of each mode's fingertip, unless a ``layout_file`` parameter names another.
DEFAULT_LAYOUT_FILES = {"2d": "taxels_ring.yaml", "3d": "taxels_hemisphere.yaml"}


def resolve_layout_file(name: str, mode: str | None = None) -> Path:
    """The layout file to load: ``name`` itself when it is absolute or exists, else a file
    in tactile_driver's config (``share/tactile_driver/config``, or the source tree);
    an empty ``name`` means the default of ``mode`` (``DEFAULT_LAYOUT_FILES``)."""
    if not name:
        if mode not in DEFAULT_LAYOUT_FILES:
            raise ValueError(f"layout file: give a file name, or mode one of {sorted(DEFAULT_LAYOUT_FILES)} "
                             f"for its default; got mode {mode!r}")
        name = DEFAULT_LAYOUT_FILES[mode]
    path = Path(name)
    if path.is_absolute() or path.exists():
        return path
    from tactile_common.params_file import package_config

    return package_config("tactile_driver", name)


def default_config_dir() -> Path:
    """``config/`` of this package in the source tree (editable install)."""
    return Path(__file__).resolve().parent.parent / "config"


if __name__ == "__main__":  # regenerate the layout files
    save_layout(ring_layout(), default_config_dir() / "taxels_ring.yaml")
    save_layout(hemisphere_layout(), default_config_dir() / "taxels_hemisphere.yaml")
