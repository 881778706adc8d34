"""Write an estimated shape and observations (world frame, metres).

Shape: CSV contour (2D), PLY with per-vertex variance (2D polyline, 3D mesh), OBJ
(2D polyline, 3D mesh), binary STL (3D). Observations: PLY point cloud with normals
and labels. Formats: docs/recording.md, "Exports".
"""

from __future__ import annotations

from pathlib import Path
from typing import Optional

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


def _ply_header(comment: str, n_vertex: int, vertex_props: list[str], element: str = "",
                n_element: int = 0, element_props: tuple[str, ...] = ()) -> str:
    lines = ["ply", "format ascii 1.0", f"comment {comment}", f"element vertex {n_vertex}"]
    lines += [f"property {p}" for p in vertex_props]
    if element:
        lines.append(f"element {element} {n_element}")
        lines += [f"property {p}" for p in element_props]
    return "\n".join(lines + ["end_header"]) + "\n"


def _xyz(level_set: LevelSet, plane_z_m: float) -> np.ndarray:
    """(V, 3) vertices in metres: a 2D contour's at height ``plane_z_m``."""
    v = level_set.vertices
    return v if v.shape[1] == 3 else np.column_stack([v, np.full(len(v), plane_z_m)])


def write_ply(path: Path, level_set: LevelSet, variance: Optional[np.ndarray] = None,
              plane_z_m: float = 0.0) -> None:
    """ASCII PLY, world frame, metres: a 3D mesh (``element face``, counter-clockwise seen
    from outside) or a 2D contour (``element edge``, vertices at z = ``plane_z_m``).

    ``variance`` (V,): the GP posterior variance of f at each vertex (m^2), written as
    ``property float variance`` (omitted when None).
    """
    v, e = _xyz(level_set, plane_z_m), np.asarray(level_set.elements)
    props = ["double x", "double y", "double z"]
    cols, fmt = [v], ["%.9g"] * 3
    if variance is not None:
        variance = np.asarray(variance, float).reshape(-1)
        if variance.shape != (len(v),):
            raise ValueError(f"variance must have one value per vertex ({len(v)}), got {variance.shape[0]}")
        props.append("float variance")
        cols.append(variance[:, None])
        fmt.append("%.7g")
    if e.shape[1] == 3:
        head = _ply_header("tactile_gpis estimated surface; world frame, metres; variance: GP posterior "
                           "variance of f (m^2)", len(v), props, "face", len(e), ("list uchar int vertex_indices",))
        rows, efmt = np.column_stack([np.full(len(e), 3), e]), "%d"
    else:
        head = _ply_header("tactile_gpis estimated contour; world frame, metres; variance: GP posterior "
                           "variance of f (m^2)", len(v), props, "edge", len(e), ("int vertex1", "int vertex2"))
        rows, efmt = e, "%d"
    with open(path, "w") as fh:
        fh.write(head)
        np.savetxt(fh, np.hstack(cols), fmt=fmt)
        np.savetxt(fh, rows, fmt=efmt)


def write_obj(path: Path, level_set: LevelSet, plane_z_m: float = 0.0) -> None:
    """Wavefront OBJ, world frame, metres: ``v x y z`` then 1-based ``f a b c`` triangles
    (3D, counter-clockwise seen from outside) or ``l a b`` segments (2D contour at z =
    ``plane_z_m``)."""
    v, e = _xyz(level_set, plane_z_m), np.asarray(level_set.elements)
    tag = "f" if e.shape[1] == 3 else "l"
    with open(path, "w") as fh:
        fh.write("# tactile_gpis estimated shape; world frame, metres\n")
        np.savetxt(fh, v, fmt="v %.9g %.9g %.9g")
        np.savetxt(fh, e + 1, fmt=f"{tag}" + " %d" * e.shape[1])


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


def write_observations_ply(path: Path, points_xyz: np.ndarray, normals_xyz: np.ndarray,
                           labels: np.ndarray) -> None:
    """ASCII PLY point cloud of observations, world frame, metres: ``x y z`` (double),
    ``nx ny nz`` (float, the unit outward normal; 0 0 0 where none: free space, or a
    contact without a usable normal), ``label`` (uchar: 1 contact, 0 free space)."""
    P = np.asarray(points_xyz, float).reshape(-1, 3)
    N = np.nan_to_num(np.asarray(normals_xyz, float).reshape(-1, 3), nan=0.0)
    L = np.asarray(labels).reshape(-1)
    if not len(P) == len(N) == len(L):
        raise ValueError(f"points, normals and labels differ in length: {len(P)}, {len(N)}, {len(L)}")
    head = _ply_header("tactile observations; world frame, metres; label 1 contact, 0 free space", len(P),
                       ["double x", "double y", "double z", "float nx", "float ny", "float nz", "uchar label"])
    with open(path, "w") as fh:
        fh.write(head)
        np.savetxt(fh, np.column_stack([P, N, L]), fmt=["%.9g"] * 3 + ["%.7g"] * 3 + ["%d"])


#: extensions each dimension exports
FORMATS = {2: (".csv", ".ply", ".obj"), 3: (".ply", ".stl", ".obj")}


def export_level_set(path: str | Path, level_set: LevelSet, dim: int, variance: Optional[np.ndarray] = None,
                     plane_z_m: float = 0.0) -> Path:
    """Write by extension: .csv (2D contour), .ply (with ``variance`` per vertex if
    given), .obj, .stl (3D only: a 2D contour has no triangles)."""
    path = Path(path)
    ext = path.suffix.lower()
    if ext not in FORMATS.get(dim, ()):
        raise ValueError(f"cannot export a {dim}D shape as '{ext}': use .csv, .ply or .obj in 2D "
                         "(an STL holds triangles, a contour has none), .ply, .stl or .obj in 3D")
    if ext == ".csv":
        write_contour_csv(path, level_set)
    elif ext == ".ply":
        write_ply(path, level_set, variance, plane_z_m)
    elif ext == ".obj":
        write_obj(path, level_set, plane_z_m)
    else:
        write_stl(path, level_set)
    return path
