"""Triangle meshes: STL/OBJ loading and an exact signed distance (object-local, metres).

Distance: exact point–triangle distance (Ericson, *Real-Time Collision
Detection* §5.1.5) to candidate triangles found with a k-d tree on triangle
centroids: the k nearest centroids give an upper bound u on the distance,
then every triangle whose centroid lies within u + R_max (R_max = largest
centroid-to-vertex radius) is tested, so the minimum is exact.
Sign: for a closed mesh, the angle-weighted pseudonormal of the closest
feature (face, edge or vertex; Bærentzen & Aanæs 2005), exact for a closed
mesh and O(1) per point; in a mesh with a few holes, points whose closest
feature is a boundary edge/vertex take the sign of the generalized winding
number instead (Jacobson et al. 2013; Van Oosterom–Strackee solid angles,
O(T) per point, so only for those few points).
"""

from __future__ import annotations

import itertools
import re
import struct
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

#: Reject meshes with more boundary (single-use) edges than this fraction.
MAX_BOUNDARY_EDGE_FRACTION = 0.01
#: Point x triangle pairs held in memory at once.
_PAIR_CHUNK = 1 << 20
_FACE, _VA, _VB, _VC, _EAB, _EAC, _EBC = range(7)


def load_mesh(path: str | Path) -> np.ndarray:
    """Triangles (T, 3, 3) from an ASCII/binary ``.stl`` or an ``.obj`` file.

    Raises:
        ValueError: unreadable/empty file, no triangles, NaN/inf coordinates
            (message names the file and the problem).
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: mesh file not found")
    data = path.read_bytes()
    if not data.strip():
        raise ValueError(f"{path}: mesh file is empty")
    suffix = path.suffix.lower()
    if suffix == ".stl":
        tri = _parse_stl(path, data)
    elif suffix == ".obj":
        tri = _parse_obj(path, data.decode("utf-8", errors="replace"))
    else:
        raise ValueError(f"{path}: unsupported mesh extension '{suffix}' (use .stl or .obj)")
    if len(tri) == 0:
        raise ValueError(f"{path}: mesh has no triangles")
    if not np.all(np.isfinite(tri)):
        raise ValueError(f"{path}: mesh has NaN or inf vertex coordinates")
    return tri


def _parse_stl(path: Path, data: bytes) -> np.ndarray:
    if len(data) >= 84:
        (count,) = struct.unpack_from("<I", data, 80)
        if len(data) == 84 + 50 * count:
            rec = np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])
            return np.frombuffer(data, dtype=rec, count=count, offset=84)["v"].astype(float)
    text = data.decode("ascii", errors="replace")
    if not text.lstrip().lower().startswith("solid"):
        raise ValueError(f"{path}: not an STL file (neither binary with a consistent triangle count nor ASCII 'solid ...')")
    numbers = re.findall(r"^\s*vertex\s+(\S+)\s+(\S+)\s+(\S+)", text, flags=re.MULTILINE | re.IGNORECASE)
    try:
        v = np.array(numbers, dtype=float)
    except ValueError as exc:
        raise ValueError(f"{path}: bad vertex line in ASCII STL ({exc})") from None
    if len(v) % 3:
        raise ValueError(f"{path}: ASCII STL has {len(v)} vertices, not a multiple of 3 (truncated file?)")
    return v.reshape(-1, 3, 3)


def _parse_obj(path: Path, text: str) -> np.ndarray:
    verts: list[tuple[float, float, float]] = []
    faces: list[list[int]] = []
    for number, line in enumerate(text.splitlines(), start=1):
        parts = line.split("#", 1)[0].split()
        if not parts:
            continue
        try:
            if parts[0] == "v":
                verts.append((float(parts[1]), float(parts[2]), float(parts[3])))
            elif parts[0] == "f":
                idx = [int(tok.split("/")[0]) for tok in parts[1:]]
                if len(idx) < 3:
                    raise ValueError("a face needs at least 3 vertices")
                faces.append([i - 1 if i > 0 else len(verts) + i for i in idx])
        except (ValueError, IndexError) as exc:
            raise ValueError(f"{path}: line {number}: cannot parse {line.strip()!r} ({exc})") from None
    if not faces:
        raise ValueError(f"{path}: OBJ has no faces ('f' lines)")
    v = np.asarray(verts, dtype=float).reshape(-1, 3)
    tris = [(f[0], f[k], f[k + 1]) for f in faces for k in range(1, len(f) - 1)]  # fan triangulation
    idx = np.asarray(tris, dtype=np.int64)
    if idx.min() < 0 or idx.max() >= len(v):
        raise ValueError(f"{path}: face refers to a vertex index outside 1..{len(v)}")
    return v[idx]


def weld(triangles: np.ndarray, tol_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Shared vertices (V, 3) and faces (F, 3) by merging corners closer than ~tol_m (grid snap)."""
    flat = triangles.reshape(-1, 3)
    keys = np.round(flat / tol_m).astype(np.int64)
    _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    return flat[first], inverse.reshape(-1, 3)


class MeshSDF:
    """Signed distance to a triangle mesh (see module docstring); points (N, 3) → (N,).

    Raises ValueError (naming ``name``) for degenerate or badly open meshes.
    """

    def __init__(self, triangles: np.ndarray, name: str = "mesh", k_nearest: int = 8) -> None:
        tri = np.asarray(triangles, dtype=float)
        extent = float(np.ptp(tri.reshape(-1, 3), axis=0).max())
        self.vertices, faces = weld(tri, 1e-9 * max(extent, 1e-12))
        v = self.vertices[faces]
        cross = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
        area2 = np.linalg.norm(cross, axis=1)
        keep = area2 > 1e-12 * extent * extent
        if not np.any(keep):
            raise ValueError(f"{name}: all triangles are degenerate (zero area)")
        self.faces = faces[keep]
        self.tri = v[keep]
        self.face_normals = cross[keep] / area2[keep, None]
        self._build_features(name)
        self._a = self.tri[:, 0]
        self._ab, self._ac = self.tri[:, 1] - self._a, self.tri[:, 2] - self._a
        self._gram = np.column_stack([np.einsum("ij,ij->i", self._ab, self._ab), np.einsum("ij,ij->i", self._ab, self._ac),
                                      np.einsum("ij,ij->i", self._ac, self._ac)])
        centres, self._index_owner, self._radius = _index_points(self.tri)
        self._tree = cKDTree(centres)
        self._k = min(k_nearest, len(centres))

    def _build_features(self, name: str) -> None:
        f = self.faces
        edges = np.sort(np.stack([f[:, [0, 1]], f[:, [0, 2]], f[:, [1, 2]]], axis=1), axis=2)  # AB, AC, BC
        uniq, self.face_edges, counts = np.unique(edges.reshape(-1, 2), axis=0, return_inverse=True, return_counts=True)
        self.face_edges = self.face_edges.reshape(-1, 3)
        self.boundary_edges = int(np.count_nonzero(counts == 1))
        nonmanifold = int(np.count_nonzero(counts > 2))
        if self.boundary_edges > MAX_BOUNDARY_EDGE_FRACTION * len(uniq):
            raise ValueError(f"{name}: mesh is badly open: {self.boundary_edges} of {len(uniq)} edges are boundary edges "
                             f"(more than {MAX_BOUNDARY_EDGE_FRACTION:.0%}); the inside is undefined — close the mesh")
        self.closed = self.boundary_edges == 0 and nonmanifold == 0
        self._open_edge = counts != 2
        self._open_vertex = np.zeros(len(self.vertices), bool)
        self._open_vertex[uniq[self._open_edge].reshape(-1)] = True
        # Angle-weighted pseudonormals (sum over incident faces).
        self.edge_normals = np.zeros((len(uniq), 3))
        np.add.at(self.edge_normals, self.face_edges.reshape(-1), np.repeat(self.face_normals, 3, axis=0))
        self.vertex_normals = np.zeros((len(self.vertices), 3))
        t = self.tri
        for corner in range(3):
            a = t[:, (corner + 1) % 3] - t[:, corner]
            b = t[:, (corner + 2) % 3] - t[:, corner]
            cosang = np.einsum("ij,ij->i", a, b) / (np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1))
            ang = np.arccos(np.clip(cosang, -1.0, 1.0))
            np.add.at(self.vertex_normals, f[:, corner], ang[:, None] * self.face_normals)

    # ---------------------------------------------------------------- query
    def _closest(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Exact closest point: (distance (N,), closest point (N,3), triangle (N,), region (N,))."""
        k = self._k
        _, near = self._tree.query(p, k=k)
        near = self._index_owner[near.reshape(-1)]
        d2, _, _ = self._pairs(np.repeat(p, k, axis=0), near)
        upper = np.sqrt(d2.reshape(-1, k).min(axis=1))
        cand = self._tree.query_ball_point(p, upper + self._radius + 1e-12, return_sorted=False)
        lengths = np.fromiter((len(c) for c in cand), dtype=np.int64, count=len(p))
        tri_idx = self._index_owner[np.fromiter(itertools.chain.from_iterable(cand), dtype=np.int64, count=int(lengths.sum()))]
        owner = np.repeat(np.arange(len(p)), lengths)
        best_d2 = np.full(len(p), np.inf)
        best_q = np.zeros_like(p)
        best_t = np.zeros(len(p), dtype=np.int64)
        best_r = np.zeros(len(p), dtype=np.int64)
        for s in range(0, len(owner), _PAIR_CHUNK):
            o, ti = owner[s:s + _PAIR_CHUNK], tri_idx[s:s + _PAIR_CHUNK]
            d2, q, region = self._pairs(p[o], ti)
            # owner is sorted: per-owner minimum by reduceat, then its first position.
            starts = np.r_[0, np.nonzero(np.diff(o))[0] + 1]
            mins = np.minimum.reduceat(d2, starts)
            hit = np.nonzero(d2 == np.repeat(mins, np.diff(np.r_[starts, len(o)])))[0]
            first = hit[np.r_[True, o[hit][1:] != o[hit][:-1]]]
            better = d2[first] < best_d2[o[first]]
            w = first[better]
            best_d2[o[w]], best_q[o[w]], best_t[o[w]], best_r[o[w]] = d2[w], q[w], ti[w], region[w]
        return np.sqrt(best_d2), best_q, best_t, best_r

    def _pairs(self, p: np.ndarray, tri: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return _point_triangle(p, self._a[tri], self._ab[tri], self._ac[tri], self._gram[tri])

    def _feature_normal(self, tri: np.ndarray, region: np.ndarray) -> np.ndarray:
        n = self.face_normals[tri].copy()
        for r, corner in ((_VA, 0), (_VB, 1), (_VC, 2)):
            m = region == r
            n[m] = self.vertex_normals[self.faces[tri[m], corner]]
        for r, slot in ((_EAB, 0), (_EAC, 1), (_EBC, 2)):
            m = region == r
            n[m] = self.edge_normals[self.face_edges[tri[m], slot]]
        return n

    def _on_open_feature(self, tri: np.ndarray, region: np.ndarray) -> np.ndarray:
        """True where the closest feature is a boundary/non-manifold edge or vertex (sign ambiguous)."""
        out = np.zeros(len(tri), bool)
        for r, corner in ((_VA, 0), (_VB, 1), (_VC, 2)):
            m = region == r
            out[m] = self._open_vertex[self.faces[tri[m], corner]]
        for r, slot in ((_EAB, 0), (_EAC, 1), (_EBC, 2)):
            m = region == r
            out[m] = self._open_edge[self.face_edges[tri[m], slot]]
        return out

    def _outside(self, p: np.ndarray, q: np.ndarray, tri: np.ndarray, region: np.ndarray) -> np.ndarray:
        """Sign test: pseudonormal of the closest feature; winding number where that feature is open."""
        outside = np.einsum("ij,ij->i", p - q, self._feature_normal(tri, region)) >= 0.0
        if not self.closed:
            amb = np.nonzero(self._on_open_feature(tri, region))[0]
            if len(amb):
                outside[amb] = self.winding_number(p[amb]) < 0.5
        return outside

    def winding_number(self, p: np.ndarray) -> np.ndarray:
        """Generalized winding number Σ Ω_t / 4π (≈ 1 inside, ≈ 0 outside), chunked over points."""
        out = np.empty(len(p))
        step = max(1, _PAIR_CHUNK // len(self.tri))
        t = self.tri
        for s in range(0, len(p), step):
            pc = p[s:s + step]
            # Components (n, T) of the corners relative to p: a = A − p, b = B − p, c = C − p.
            ax, ay, az = (t[None, :, 0, k] - pc[:, k, None] for k in range(3))
            bx, by, bz = (t[None, :, 1, k] - pc[:, k, None] for k in range(3))
            cx, cy, cz = (t[None, :, 2, k] - pc[:, k, None] for k in range(3))
            la = np.sqrt(ax * ax + ay * ay + az * az)
            lb = np.sqrt(bx * bx + by * by + bz * bz)
            lc = np.sqrt(cx * cx + cy * cy + cz * cz)
            det = ax * (by * cz - bz * cy) - ay * (bx * cz - bz * cx) + az * (bx * cy - by * cx)
            den = (la * lb * lc + (ax * bx + ay * by + az * bz) * lc + (ax * cx + ay * cy + az * cz) * lb
                   + (bx * cx + by * cy + bz * cz) * la)
            out[s:s + step] = np.arctan2(det, den).sum(axis=1) / (2.0 * np.pi)
        return out

    def sdf(self, p: np.ndarray) -> np.ndarray:
        """Signed distance: exact distance; sign by the closest feature's pseudonormal, or by the
        winding number where that feature is a boundary edge/vertex of an open mesh."""
        p = np.asarray(p, dtype=float)
        d, q, tri, region = self._closest(p)
        return np.where(self._outside(p, q, tri, region), d, -d)

    def gradient(self, p: np.ndarray) -> np.ndarray:
        """Unit outward normals: ±(p − q)/|p − q| off the surface, the feature pseudonormal on it."""
        p = np.asarray(p, dtype=float)
        d, q, tri, region = self._closest(p)
        n = self._feature_normal(tri, region)
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        diff = p - q
        away = d > 1e-9
        sign = np.where(self._outside(p[away], q[away], tri[away], region[away]), 1.0, -1.0)
        n[away] = sign[:, None] * diff[away] / d[away, None]
        return n


def _index_points(tri: np.ndarray, max_levels: int = 10) -> tuple[np.ndarray, np.ndarray, float]:
    """Search points for the k-d tree: centroids of the triangles, large ones split 1→4 until
    their radius is at most twice the median triangle radius (so that a few big CAD faces do
    not widen every candidate ball). Returns (points, owning triangle, max radius)."""
    def radius(t):
        return np.max(np.linalg.norm(t - t.mean(axis=1, keepdims=True), axis=2), axis=1)

    r = radius(tri)
    target = 2.0 * float(np.median(r))
    sub, owner = tri, np.arange(len(tri))
    pts, owners, radii = [], [], []
    for level in range(max_levels + 1):
        r = radius(sub)
        done = (r <= target) | (level == max_levels)
        pts.append(sub[done].mean(axis=1))
        owners.append(owner[done])
        radii.append(r[done])
        sub, owner = sub[~done], owner[~done]
        if len(sub) == 0:
            break
        a, b, c = sub[:, 0], sub[:, 1], sub[:, 2]
        ab, bc, ca = 0.5 * (a + b), 0.5 * (b + c), 0.5 * (c + a)
        sub = np.concatenate([np.stack(x, axis=1) for x in ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))])
        owner = np.tile(owner, 4)
    return np.concatenate(pts), np.concatenate(owners), float(np.concatenate(radii).max())


def _point_triangle(p: np.ndarray, a: np.ndarray, ab: np.ndarray, ac: np.ndarray, gram: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Squared distance, closest point and Voronoi region of p (N,3) to triangles (Ericson 5.1.5).

    Triangles are given per pair by corner a, edges ab = b − a, ac = c − a (N,3) and
    gram (N,3) = (ab·ab, ab·ac, ac·ac); with ap = p − a the six dot products are
    d1 = ab·ap, d2 = ac·ap, d3 = d1 − ab·ab, d4 = d2 − ab·ac, d5 = d1 − ab·ac, d6 = d2 − ac·ac.
    """
    ap = p - a
    d1 = ab[:, 0] * ap[:, 0] + ab[:, 1] * ap[:, 1] + ab[:, 2] * ap[:, 2]
    d2 = ac[:, 0] * ap[:, 0] + ac[:, 1] * ap[:, 1] + ac[:, 2] * ap[:, 2]
    d3, d4 = d1 - gram[:, 0], d2 - gram[:, 1]
    d5, d6 = d1 - gram[:, 1], d2 - gram[:, 2]
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        conditions = [
            (d1 <= 0) & (d2 <= 0),
            (d3 >= 0) & (d4 <= d3),
            (d6 >= 0) & (d5 <= d6),
            (vc <= 0) & (d1 >= 0) & (d3 <= 0),
            (vb <= 0) & (d2 >= 0) & (d6 <= 0),
            (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0),
        ]
        region = np.select(conditions, [_VA, _VB, _VC, _EAB, _EAC, _EBC], default=_FACE)
        denom = va + vb + vc
        t_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        v = np.select([region == _FACE, region == _VB, region == _EAB, region == _EBC],
                      [vb / denom, 1.0, d1 / (d1 - d3), 1.0 - t_bc], default=0.0)
        w = np.select([region == _FACE, region == _VC, region == _EAC, region == _EBC],
                      [vc / denom, 1.0, d2 / (d2 - d6), t_bc], default=0.0)
    q = a + v[:, None] * ab + w[:, None] * ac
    diff = p - q
    return diff[:, 0] ** 2 + diff[:, 1] ** 2 + diff[:, 2] ** 2, q, region
