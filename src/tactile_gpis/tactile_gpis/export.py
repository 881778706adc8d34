"""Write an estimated shape: CSV contour (2D), PLY / STL triangle mesh (3D)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .levelset import LevelSet


def contour_loops(segments: np.ndarray) -> list[np.ndarray]:
    """Chain undirected segments (S, 2) of vertex ids into polylines (closed loops repeat
    their first id at the end)."""
    adj: dict[int, list[int]] = {}
    for a, b in segments.tolist():
        adj.setdefault(a, []).append(b)
        adj.setdefault(b, []).append(a)
    seen_edges: set = set()
    loops = []
    # start at open ends first (degree 1), then anywhere
    starts = [v for v, n in adj.items() if len(n) == 1] + list(adj)
    for s in starts:
        if all(tuple(sorted((s, n))) in seen_edges for n in adj[s]):
            continue
        path = [s]
        cur = s
        while True:
            nxt = next((n for n in adj[cur] if tuple(sorted((cur, n))) not in seen_edges), None)
            if nxt is None:
                break
            seen_edges.add(tuple(sorted((cur, nxt))))
            path.append(nxt)
            cur = nxt
        loops.append(np.array(path))
    return loops


def write_contour_csv(path: Path, level_set: LevelSet) -> None:
    """CSV with header ``x_m,y_m,loop``: the contour's polylines, one vertex per row
    (a closed loop repeats its first vertex)."""
    rows = []
    for i, loop in enumerate(contour_loops(level_set.elements)):
        xy = level_set.vertices[loop, :2]
        rows.append(np.column_stack([xy, np.full(len(loop), i)]))
    data = np.concatenate(rows) if rows else np.zeros((0, 3))
    with open(path, "w") as fh:
        fh.write("x_m,y_m,loop\n")
        for x, y, i in data:
            fh.write(f"{x:.9g},{y:.9g},{int(i)}\n")


def write_ply(path: Path, level_set: LevelSet) -> None:
    """ASCII PLY mesh (vertices in metres, faces counter-clockwise seen from outside)."""
    v, f = level_set.vertices, level_set.elements
    with open(path, "w") as fh:
        fh.write(f"ply\nformat ascii 1.0\nelement vertex {len(v)}\nproperty double x\nproperty double y\n"
                 f"property double z\nelement face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n")
        np.savetxt(fh, v, fmt="%.9g")
        np.savetxt(fh, np.column_stack([np.full(len(f), 3), f]), fmt="%d")


def write_stl(path: Path, level_set: LevelSet) -> None:
    """Binary STL mesh (float32, metres)."""
    v = level_set.vertices[level_set.elements]  # (T, 3, 3)
    n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    rec = np.zeros(len(v), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])
    rec["n"], rec["v"] = n, v
    with open(path, "wb") as fh:
        fh.write(b"tactile_gpis estimated shape".ljust(80, b" "))
        fh.write(np.uint32(len(v)).tobytes())
        fh.write(rec.tobytes())


def export_level_set(path: str | Path, level_set: LevelSet, dim: int) -> Path:
    """Write by extension: .csv (2D), .ply / .stl (3D)."""
    path = Path(path)
    ext = path.suffix.lower()
    if dim == 2 and ext == ".csv":
        write_contour_csv(path, level_set)
    elif dim == 3 and ext == ".ply":
        write_ply(path, level_set)
    elif dim == 3 and ext == ".stl":
        write_stl(path, level_set)
    else:
        raise ValueError(f"cannot export a {dim}D shape as '{ext}': use .csv in 2D, .ply or .stl in 3D")
    return path
