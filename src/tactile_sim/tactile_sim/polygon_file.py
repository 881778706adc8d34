"""User 2D polygons from CSV files, validated with clear messages; size plausibility check."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tactile_sim import sdf2d

#: Plausible object size range for user files [m] (largest bounding-box side).
MIN_SIZE_M, MAX_SIZE_M = 0.01, 0.50


def check_size(path: Path, extent_m: np.ndarray) -> None:
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
    check_size(path, np.ptp(v, axis=0))
    crossings = sdf2d.polygon_self_intersections(v)
    if crossings:
        i, j = crossings[0]
        raise ValueError(f"{path}: polygon is self-intersecting: edge {i + 1} (vertices {i + 1}-{(i + 1) % len(v) + 1}) "
                         f"crosses edge {j + 1} (vertices {j + 1}-{(j + 1) % len(v) + 1}); {len(crossings)} crossing(s)")
    if abs(sdf2d.polygon_area_m2(v)) < 1e-12:
        raise ValueError(f"{path}: polygon has zero area (all vertices on a line)")
    return v - 0.5 * (v.min(axis=0) + v.max(axis=0))
