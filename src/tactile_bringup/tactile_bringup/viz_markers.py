"""What the viewer markers show, as arrays (numpy only; the ``viz`` node makes messages).

- Colours: a viridis-like ramp (five anchors, linear in between) of log10 σ.
- σ at any point: log10 σ of the posterior on the estimator's lattice (the
  ``kind == 0`` points of ``/gpis/variance_map``, C order), interpolated
  linearly; in 2D the lattice is the plane z = const and z is ignored.
- Robot description: the URDF text with ``package://NAME/...`` mesh URIs
  resolved to ``file://`` paths when NAME is a folder above the URDF (viewers
  without that ROS package still find the meshes).
- The arm as a polyline through the link origins up to the fingertip (no TF
  on the PyPI wheels: viewers draw this instead of the robot model).

World frame, metres.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Optional, Sequence

import numpy as np

from tactile_common.fields import KIND_LATTICE

#: viridis at 0, 0.25, 0.5, 0.75, 1 (RGB)
_RAMP = np.array([[0.267, 0.005, 0.329], [0.229, 0.322, 0.546], [0.128, 0.567, 0.551],
                  [0.369, 0.789, 0.383], [0.993, 0.906, 0.144]])


def ramp_rgba(values: np.ndarray, lo: float, hi: float, alpha: float = 1.0) -> np.ndarray:
    """(N, 4) RGBA in [0, 1]: ``values`` mapped linearly from [lo, hi] onto the ramp (clipped)."""
    v = np.asarray(values, dtype=float)
    t = np.clip((v - lo) / (hi - lo), 0.0, 1.0) if hi > lo else np.zeros_like(v)
    t = np.nan_to_num(t, nan=0.0)
    x = np.linspace(0.0, 1.0, len(_RAMP))
    rgb = np.stack([np.interp(t, x, _RAMP[:, c]) for c in range(3)], axis=-1)
    return np.concatenate([rgb, np.full(rgb.shape[:-1] + (1,), float(alpha))], axis=-1)


class SigmaField:
    """log10 σ of the posterior on the lattice of a variance map, interpolated anywhere."""

    def __init__(self, map_array: np.ndarray) -> None:
        from scipy.interpolate import RegularGridInterpolator

        lat = map_array[map_array["kind"] == KIND_LATTICE]
        if len(lat) == 0:
            raise ValueError("the variance map has no lattice points (kind 0)")
        xyz = np.stack([lat["x"], lat["y"], lat["z"]], axis=-1)
        self.dim = 2 if np.ptp(xyz[:, 2]) == 0.0 else 3
        axes = [np.unique(xyz[:, i]) for i in range(self.dim)]
        shape = tuple(len(a) for a in axes)
        if int(np.prod(shape)) != len(lat):
            raise ValueError(f"lattice of {len(lat)} points is not a full grid {shape}")
        log_sd = 0.5 * np.log10(np.maximum(np.asarray(lat["variance"], dtype=float), 1e-30))
        self.log_sd = log_sd
        self._interp = RegularGridInterpolator(axes, log_sd.reshape(shape), bounds_error=False, fill_value=None)

    def __call__(self, points_xyz: np.ndarray) -> np.ndarray:
        P = np.asarray(points_xyz, dtype=float).reshape(-1, 3)
        return self._interp(P[:, : self.dim])

    def range(self) -> tuple[float, float]:
        """(1st, 99th) percentile of log10 σ over the lattice: the colour scale."""
        lo, hi = np.percentile(self.log_sd, [1, 99])
        return float(lo), float(max(hi, lo + 1e-6))


def resolve_package_uris(urdf_text: str, urdf_path: str) -> str:
    """``package://NAME/rest`` -> ``file:///<folder NAME above urdf_path>/rest`` where such a
    folder exists; other URIs are left as they are."""
    parents = {p.name: p for p in Path(urdf_path).resolve().parents}

    def sub(m: re.Match) -> str:
        root = parents.get(m.group(1))
        return m.group(0) if root is None else (root / m.group(2)).as_uri()

    return re.sub(r"package://([^/\"']+)/([^\"'\s]+)", sub, urdf_text)


def arm_polyline(model, q: np.ndarray, link_frames: Optional[Sequence[str]] = None) -> np.ndarray:
    """(K, 3) world positions of the link frames (default: the model's joints' child links
    present as frames) then the fingertip, for the joint vector ``q`` (command order)."""
    if link_frames is None:
        link_frames = arm_link_frames(model)
    pts = [model.frame_position(q, f) for f in link_frames]
    pts.append(model.fk(q)[0])
    return np.asarray(pts, dtype=float)


def arm_link_frames(model) -> list[str]:
    """Frames of the reduced model that are bodies (links), in tree order."""
    import pinocchio as pin

    return [f.name for f in model.model.frames if f.type == pin.FrameType.BODY]


def joint_vector(names: Sequence[str], positions: Sequence[float], joint_names: Sequence[str]) -> Optional[np.ndarray]:
    """The positions of ``joint_names`` (in that order) from a JointState's names/positions;
    None when one is missing."""
    index = {n: i for i, n in enumerate(names)}
    if any(j not in index for j in joint_names) or len(positions) < len(names):
        return None
    return np.array([positions[index[j]] for j in joint_names], dtype=float)
