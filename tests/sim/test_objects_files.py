"""User object files: CSV polygons and STL/OBJ meshes vs analytic shapes, and every bad-file message."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from tactile_sim.objects import make_object

RNG = np.random.default_rng(11)
HALF = 0.0625  # exactly representable in float32 (binary STL)

# Cube [-1, 1]^3: 6 outward quads (counter-clockwise seen from outside).
CUBE_V = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
CUBE_QUADS = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]


def cube_triangles(half: float) -> np.ndarray:
    tris = [(q[0], q[k], q[k + 1]) for q in CUBE_QUADS for k in (1, 2)]
    return half * CUBE_V[np.array(tris)]


def icosphere(radius: float, subdivisions: int) -> np.ndarray:
    t = (1 + 5**0.5) / 2
    v = np.array([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t], [0, -1, -t], [0, 1, -t],
                  [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]], float)
    f = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4], [11, 10, 2],
                  [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5],
                  [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]])
    tri = v[f] / np.linalg.norm(v[f], axis=2, keepdims=True)
    for _ in range(subdivisions):
        a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
        ab, bc, ca = ((x + y) / np.linalg.norm(x + y, axis=1, keepdims=True) for x, y in ((a, b), (b, c), (c, a)))
        tri = np.concatenate([np.stack(s, 1) for s in ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))])
    return radius * tri


def write_binary_stl(path, tri):
    with open(path, "wb") as f:
        f.write(b"binary test mesh".ljust(80, b" "))
        f.write(struct.pack("<I", len(tri)))
        for t in tri:
            f.write(struct.pack("<12fH", 0, 0, 0, *t.reshape(-1), 0))


def write_ascii_stl(path, tri):
    lines = ["solid test"]
    for t in tri:
        lines += ["  facet normal 0 0 0", "    outer loop"] + [f"      vertex {float(x)!r} {float(y)!r} {float(z)!r}" for x, y, z in t]
        lines += ["    endloop", "  endfacet"]
    path.write_text("\n".join(lines + ["endsolid test"]) + "\n")


def write_obj(path, vertices, faces):
    text = ["# test mesh"] + [f"v {float(x)!r} {float(y)!r} {float(z)!r}" for x, y, z in vertices]
    text += ["f " + " ".join(f"{i + 1}/{i + 1}" for i in face) for face in faces]
    path.write_text("\n".join(text) + "\n")


def box_sdf(p, center, half):
    q = np.abs(p - center) - half
    return np.linalg.norm(np.maximum(q, 0), axis=1) + np.minimum(q.max(axis=1), 0)


def sample_points(center, size, n=4000):
    p = center + RNG.uniform(-size, size, size=(n, 3))
    p[:, 2] = np.abs(p[:, 2])  # above the table (the table clip is tested elsewhere)
    return p


@pytest.mark.parametrize("fmt", ["binary_stl", "ascii_stl", "obj_quads"])
def test_cube_mesh_matches_the_analytic_box(tmp_path, fmt):
    path = tmp_path / ("cube.obj" if fmt == "obj_quads" else "cube.stl")
    # Offset in the file: placement must centre it in x-y and put its bottom on the table.
    shift = np.array([0.25, -0.125, 0.5])
    if fmt == "binary_stl":
        write_binary_stl(path, cube_triangles(HALF) + shift)
    elif fmt == "ascii_stl":
        write_ascii_stl(path, cube_triangles(HALF) + shift)
    else:
        write_obj(path, HALF * CUBE_V + shift, CUBE_QUADS)
    obj = make_object(path, mode="3d", center_xy_m=(0.5, 0.02))
    center = np.array([0.5, 0.02, HALF])
    np.testing.assert_allclose(obj.bounds, [center - HALF, center + HALF], atol=1e-12)
    p = sample_points(center, 2.5 * HALF)
    np.testing.assert_allclose(obj.sdf(p), box_sdf(p, center, HALF), atol=1e-9)
    h = 1e-6
    fd = np.column_stack([(box_sdf(p + h * e, center, HALF) - box_sdf(p - h * e, center, HALF)) / (2 * h) for e in np.eye(3)])
    smooth = np.abs(np.linalg.norm(fd, axis=1) - 1) < 1e-6
    np.testing.assert_allclose(obj.gradient(p)[smooth], fd[smooth], atol=1e-5)


def test_icosphere_obj_matches_the_sphere_and_yaw_is_applied(tmp_path):
    tri = icosphere(0.05, 3)
    path = tmp_path / "ball.obj"
    write_obj(path, tri.reshape(-1, 3), np.arange(len(tri) * 3).reshape(-1, 3))
    obj = make_object(path, mode="3d", center_xy_m=(0.45, -0.03), yaw_rad=0.8)
    c = np.array([0.45, -0.03, 0.05])
    p = sample_points(c, 0.1)
    sagitta = 0.05 * (1 - np.cos(0.55 * np.arctan(2) / 8))  # facet depth of subdivision level 3 (bound)
    assert np.max(np.abs(obj.sdf(p) - (np.linalg.norm(p - c, axis=1) - 0.05))) < 2 * sagitta
    on = obj.surface_samples(0.004)
    assert np.all(np.abs(np.linalg.norm(on - c, axis=1) - 0.05) < 2 * sagitta)


def l_block_triangles() -> np.ndarray:
    """The catalogue's l_block (L profile in x-z, extruded ±3 cm in y) as a closed mesh, outward faces."""
    prof = np.array([(0, 0), (0.12, 0), (0.12, 0.04), (0.04, 0.04), (0.04, 0.12), (0, 0.12)]) - [0.06, 0.0]
    n = len(prof)
    lift = lambda xz, y: np.array([xz[0], y, xz[1]])  # noqa: E731
    tris = []
    for i in range(n):  # side walls
        a, b = prof[i], prof[(i + 1) % n]
        tris += [(lift(a, -0.03), lift(b, -0.03), lift(b, 0.03)), (lift(a, -0.03), lift(b, 0.03), lift(a, 0.03))]
    for i, j in ((4, 5), (5, 0), (0, 1), (1, 2)):  # caps: fan from the reflex vertex 3
        for y in (-0.03, 0.03):
            tris.append((lift(prof[3], y), lift(prof[i], y), lift(prof[j], y)))
    tri = np.array(tris)
    # Orient outward with the analytic solid: a point just off the face must be outside.
    ref = make_object("l_block", mode="3d", center_xy_m=(0.0, 0.0))
    nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    probe = tri.mean(axis=1) + 1e-4 * nrm / np.linalg.norm(nrm, axis=1, keepdims=True)
    flip = ref.sdf(probe) < 0
    tri[flip] = tri[flip][:, ::-1]
    return tri


def test_non_convex_l_block_mesh_matches_the_analytic_l_block(tmp_path):
    path = tmp_path / "l.stl"
    write_ascii_stl(path, l_block_triangles())
    obj = make_object(path, mode="3d", yaw_rad=0.4)
    ref = make_object("l_block", mode="3d", yaw_rad=0.4)
    assert obj.mesh.closed
    np.testing.assert_allclose(obj.bounds, ref.bounds, atol=1e-12)
    p = sample_points(np.array([0.5, 0.0, 0.06]), 0.09, n=6000)
    # Include points around the concave (reflex) edge, where a face normal alone gets the sign wrong.
    corner = np.array([0.5 - 0.02 * np.cos(0.4), -0.02 * np.sin(0.4), 0.04])
    p = np.vstack([p, corner + RNG.uniform(-0.015, 0.015, size=(3000, 3))])
    np.testing.assert_allclose(obj.sdf(p), ref.sdf(p), atol=1e-12)


def test_sharp_wedge_mesh_matches_the_extruded_triangle(tmp_path):
    """A 28° apex edge: outside points there need the edge pseudonormal, not one face normal."""
    from tactile_sim import sdf2d, sdf3d

    prof = np.array([(-0.03, -0.06), (0.03, -0.06), (0.0, 0.06)])
    tris = []
    for i in range(3):
        a, b = np.r_[prof[i], 0.0], np.r_[prof[(i + 1) % 3], 0.0]
        up = np.array([0, 0, 0.06])
        tris += [(a, b, b + up), (a, b + up, a + up)]
    tris += [tuple(np.c_[prof, np.zeros(3)]), tuple(np.c_[prof, np.full(3, 0.06)])]
    tri = np.array(tris)

    def ref(p):
        q = p - [0.5, 0.0, 0.03]
        return sdf3d.extrude(q, lambda xy: sdf2d.polygon(xy, prof), (0, 1, 2), 0.03)

    nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    flip = ref(tri.mean(axis=1) + [0.5, 0, 0] + 1e-4 * nrm / np.linalg.norm(nrm, axis=1, keepdims=True)) < 0
    tri[flip] = tri[flip][:, ::-1]
    path = tmp_path / "wedge.stl"
    write_binary_stl(path, tri)
    obj = make_object(path, mode="3d")
    apex = np.array([0.5, 0.06, 0.03])
    p = np.vstack([sample_points(np.array([0.5, 0.0, 0.03]), 0.08, n=3000),
                   apex + RNG.uniform(-0.02, 0.02, size=(3000, 3))])
    np.testing.assert_allclose(obj.sdf(p), ref(p), atol=1e-8)  # float32 vertices


def test_winding_number_of_a_closed_mesh_is_the_indicator(tmp_path):
    from tactile_sim.mesh import MeshSDF

    m = MeshSDF(icosphere(0.05, 2))
    p = RNG.uniform(-0.08, 0.08, size=(500, 3))
    r = np.linalg.norm(p, axis=1)
    clear = np.abs(r - 0.05) > 0.003
    np.testing.assert_allclose(m.winding_number(p[clear]), (r[clear] < 0.05).astype(float), atol=1e-9)


def test_mesh_with_a_small_hole_uses_the_winding_number(tmp_path):
    tri = icosphere(0.05, 3)[1:]  # one triangle missing: 3 boundary edges of 1920
    path = tmp_path / "holey.stl"
    write_ascii_stl(path, tri)
    obj = make_object(path, mode="3d")
    assert not obj.mesh.closed
    c = np.array([0.5, 0.0, 0.05])
    p = sample_points(c, 0.08, n=1500)
    ref = np.linalg.norm(p - c, axis=1) - 0.05
    clear = np.abs(ref) > 0.002
    assert np.all(np.sign(obj.sdf(p)[clear]) == np.sign(ref[clear]))
    # Points on the axis through the hole: their closest feature is the hole's rim.
    hole = icosphere(0.05, 3)[0].mean(axis=0)
    hole /= np.linalg.norm(hole)
    s = np.r_[np.linspace(0.005, 0.045, 9), np.linspace(0.055, 0.1, 9)]
    axis_pts = c + s[:, None] * hole
    assert np.all((obj.sdf(axis_pts) < 0) == (s < 0.05))


def test_bad_mesh_files(tmp_path):
    def write(name, content):
        path = tmp_path / name
        path.write_bytes(content if isinstance(content, bytes) else content.encode())
        return path

    with pytest.raises(ValueError, match="nothere.stl: object file not found"):
        make_object(tmp_path / "nothere.stl", mode="3d")
    with pytest.raises(ValueError, match="empty.stl: mesh file is empty"):
        make_object(write("empty.stl", ""), mode="3d")
    with pytest.raises(ValueError, match="junk.stl: not an STL file"):
        make_object(write("junk.stl", b"\x01\x02garbage" * 20), mode="3d")
    with pytest.raises(ValueError, match="noface.obj: OBJ has no faces"):
        make_object(write("noface.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n"), mode="3d")
    with pytest.raises(ValueError, match="nan.obj: mesh has NaN or inf"):
        make_object(write("nan.obj", "v 0 0 0\nv 0.1 0 0\nv 0 nan 0\nf 1 2 3\n"), mode="3d")
    with pytest.raises(ValueError, match="badidx.obj: face refers to a vertex index outside 1..3"):
        make_object(write("badidx.obj", "v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nf 1 2 9\n"), mode="3d")
    with pytest.raises(ValueError, match="badline.obj: line 2: cannot parse"):
        make_object(write("badline.obj", "v 0 0 0\nv 0.1 zero 0\n"), mode="3d")
    with pytest.raises(ValueError, match="shape.ply: unsupported object file extension '.ply'"):
        make_object(write("shape.ply", "ply\n"), mode="3d")
    half = icosphere(0.05, 2)
    half = half[half[:, :, 2].mean(axis=1) > 0]  # a bowl: hundreds of boundary edges
    p = tmp_path / "bowl.stl"
    write_binary_stl(p, half)
    with pytest.raises(ValueError, match=r"bowl.stl: mesh is badly open: \d+ of \d+ edges are boundary edges"):
        make_object(p, mode="3d")
    mm = tmp_path / "mm.stl"
    write_binary_stl(mm, cube_triangles(50.0))
    with pytest.raises(ValueError, match="mm.stl: object size 100 m .*millimetres"):
        make_object(mm, mode="3d")
    tiny = tmp_path / "tiny.stl"
    write_binary_stl(tiny, cube_triangles(0.001))
    with pytest.raises(ValueError, match="tiny.stl: object size 0.002 m is outside the plausible range"):
        make_object(tiny, mode="3d")
    ok = tmp_path / "ok.stl"
    write_binary_stl(ok, cube_triangles(HALF))
    with pytest.raises(ValueError, match="ok.stl: a 3D mesh needs mode '3d'"):
        make_object(ok, mode="2d")


# ------------------------------------------------------------------ CSV polygons

def polygon_sdf_reference(p, v):
    """Per point: min distance to the edges; inside by the winding angle sum."""
    out = []
    for x in p:
        best, angle = np.inf, 0.0
        for i in range(len(v)):
            a, b = v[i], v[(i + 1) % len(v)]
            t = np.clip(np.dot(x - a, b - a) / np.dot(b - a, b - a), 0, 1)
            best = min(best, np.linalg.norm(x - a - t * (b - a)))
            u, w = a - x, b - x
            angle += np.arctan2(u[0] * w[1] - u[1] * w[0], np.dot(u, w))
        out.append(-best if abs(angle) > np.pi else best)
    return np.array(out)


def test_csv_polygon_with_header_and_closing_vertex(tmp_path):
    arrow = np.array([[0.0, 0.0], [0.08, 0.0], [0.08, -0.02], [0.12, 0.02], [0.08, 0.06], [0.08, 0.04], [0.0, 0.04]])
    path = tmp_path / "arrow.csv"
    path.write_text("x,y\n" + "\n".join(f"{x},{y}" for x, y in np.vstack([arrow, arrow[:1]])) + "\n")
    obj = make_object(path, center_xy_m=(0.5, 0.01), yaw_rad=np.pi / 2)
    assert obj.name == "arrow" and obj.dim == 2
    local = arrow - [0.06, 0.02]  # bounding box centred on the object origin
    p = np.array([0.5, 0.01]) + RNG.uniform(-0.1, 0.1, size=(300, 2))
    d = p - [0.5, 0.01]
    q = np.column_stack([d[:, 1], -d[:, 0]])  # rotate by -90 deg
    np.testing.assert_allclose(obj.sdf(p), polygon_sdf_reference(q, local), atol=1e-12)
    prism = make_object(path, mode="3d", prism_height_m=0.1)
    assert prism.dim == 3 and prism.bounds[1, 2] == 0.1


@pytest.mark.parametrize("content,message", [
    ("", "empty.csv: polygon file is empty"),
    ("x,y\n", "empty.csv: polygon file is empty"),
    ("0,0\n0.1,0\n", r"empty.csv: a polygon needs at least 3 distinct vertices, got 2"),
    ("0,0\n0.1,0\n0.1,0\n0,0\n", r"empty.csv: a polygon needs at least 3 distinct vertices, got 2"),
    ("0,0\n0.1,nan\n0,0.1\n", r"empty.csv: vertex 2 is not finite"),
    ("0,0\n0.1,0\ninf,0.1\n", r"empty.csv: vertex 3 is not finite"),
    ("0,0\n0.1,0.1\n0.1,0\n0,0.1\n", r"empty.csv: polygon is self-intersecting: edge 1 .* crosses edge 3"),
    ("0,0\n0.1,0\n0.2,0\n", "empty.csv: polygon has zero area"),
    ("0,0\n100,0\n100,100\n", r"empty.csv: object size 100 m .*millimetres"),
    ("0,0\n0.1,0\n0.1,0.1,0.3\n", r"empty.csv: line 3: expected 'x,y'"),
])
def test_bad_csv_files(tmp_path, content, message):
    path = tmp_path / "empty.csv"
    path.write_text(content)
    with pytest.raises(ValueError, match=message):
        make_object(path)


def test_missing_csv(tmp_path):
    with pytest.raises(ValueError, match="missing.csv: object file not found"):
        make_object(tmp_path / "missing.csv")
