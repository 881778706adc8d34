"""Analytic objects: SDF sign and zero set vs closed forms, exactness, gradients, placement, errors."""

from __future__ import annotations

import numpy as np
import pytest

from tactile_sim.objects import list_objects, make_object

RNG = np.random.default_rng(7)
ALL = [("2d", n) for n in list_objects("2d")] + [("3d", n) for n in list_objects("3d")]


def polygon_sdf_reference(p: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Brute force, one point at a time: min segment distance, sign from the winding angle sum."""
    out = np.empty(len(p))
    n = len(v)
    for k, x in enumerate(p):
        best = np.inf
        angle = 0.0
        for i in range(n):
            a, b = v[i], v[(i + 1) % n]
            ab = b - a
            t = min(1.0, max(0.0, float(np.dot(x - a, ab) / np.dot(ab, ab))))
            best = min(best, float(np.linalg.norm(x - (a + t * ab))))
            u, w = a - x, b - x
            angle += np.arctan2(u[0] * w[1] - u[1] * w[0], np.dot(u, w))
        out[k] = -best if abs(angle) > np.pi else best
    return out


def world_to_local(p, center, yaw, scale):
    c, s = np.cos(yaw), np.sin(yaw)
    d = p[:, :2] - np.asarray(center)
    return np.column_stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]]) / scale


def test_circle_closed_form_with_pose():
    center, yaw, scale = (0.48, 0.02), 0.7, 1.3
    obj = make_object("circle", center_xy_m=center, yaw_rad=yaw, scale=scale)
    p = RNG.uniform([0.35, -0.15], [0.65, 0.15], size=(2000, 2))
    expected = np.linalg.norm(p - center, axis=1) - 0.04 * scale
    np.testing.assert_allclose(obj.sdf(p), expected, atol=1e-12)
    ang = RNG.uniform(0, 2 * np.pi, 100)
    on = np.asarray(center) + 0.04 * scale * np.column_stack([np.cos(ang), np.sin(ang)])
    np.testing.assert_allclose(obj.sdf(on), 0.0, atol=1e-12)
    np.testing.assert_allclose(obj.gradient(on), (on - center) / (0.04 * scale), atol=1e-6)


def test_ellipse_is_exact_along_normals():
    obj = make_object("ellipse", center_xy_m=(0.0, 0.0))
    a, b = 0.06, 0.035
    t = np.linspace(0, 2 * np.pi, 97)
    on = np.column_stack([a * np.cos(t), b * np.sin(t)])
    n = np.column_stack([np.cos(t) / a, np.sin(t) / b])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    np.testing.assert_allclose(obj.sdf(on), 0.0, atol=1e-10)
    for delta in (0.02, 0.005, -0.005):  # inside offsets stay below the smallest radius of curvature b²/a
        np.testing.assert_allclose(obj.sdf(on + delta * n), delta, atol=1e-9)
    np.testing.assert_allclose(obj.gradient(on + 0.005 * n), n, atol=1e-6)


@pytest.mark.parametrize("name", ["triangle", "star", "l_shape", "c_shape"])
def test_polygon_shapes_match_brute_force(name):
    from tactile_sim.objects import SHAPES_2D

    vertices = SHAPES_2D[name][0].keywords["vertices"]
    center, yaw, scale = (0.5, -0.01), -0.4, 0.9
    obj = make_object(name, center_xy_m=center, yaw_rad=yaw, scale=scale)
    p = RNG.uniform([0.40, -0.10], [0.60, 0.10], size=(300, 2))
    expected = scale * polygon_sdf_reference(world_to_local(p, center, yaw, scale), vertices)
    np.testing.assert_allclose(obj.sdf(p), expected, atol=1e-12)


def test_kidney_and_rounded_square_closed_forms():
    sq = make_object("rounded_square", center_xy_m=(0.0, 0.0))
    # Flat faces at |x| = 0.04; corner arc centre (0.03, 0.03), radius 0.01.
    np.testing.assert_allclose(sq.sdf(np.array([[0.05, 0.0], [0.0, -0.045], [0.0, 0.0]])), [0.01, 0.005, -0.04], atol=1e-12)
    corner = np.array([[0.03, 0.03]]) + 0.02 * np.array([[np.sqrt(0.5), np.sqrt(0.5)]])
    np.testing.assert_allclose(sq.sdf(corner), 0.01, atol=1e-12)
    kid = make_object("kidney", center_xy_m=(0.0, 0.0))
    # Arc centre is at the local origin shifted down by y0; on the arc's middle, depth = -thickness.
    y0 = 0.5 * (0.045 * np.cos(1.1) - 0.022 + 0.045 + 0.022)
    np.testing.assert_allclose(kid.sdf(np.array([[0.0, 0.045 - y0], [0.0, 0.045 + 0.03 - y0]])), [-0.022, 0.008], atol=1e-12)
    # Non-convex: the arc's centre (concave side) is outside the bean.
    assert kid.sdf(np.array([[0.0, -y0]]))[0] > 0


def test_sphere_and_box_closed_forms():
    s = make_object("sphere", mode="3d", center_xy_m=(0.5, 0.0))
    p = RNG.uniform([0.35, -0.15, 0.0], [0.65, 0.15, 0.22], size=(2000, 3))
    c = np.array([0.5, 0.0, 0.05])
    np.testing.assert_allclose(s.sdf(p), np.linalg.norm(p - c, axis=1) - 0.05, atol=1e-12)
    np.testing.assert_allclose(s.gradient(p), (p - c) / np.linalg.norm(p - c, axis=1, keepdims=True), atol=1e-9)

    yaw = 0.3
    b = make_object("box", mode="3d", yaw_rad=yaw)
    half = np.array([0.04, 0.03, 0.05])
    q = np.column_stack([world_to_local(p, (0.5, 0.0), yaw, 1.0), p[:, 2] - 0.05])
    outside = np.linalg.norm(np.maximum(np.abs(q) - half, 0), axis=1)
    inside = np.minimum(np.max(np.abs(q) - half, axis=1), 0)
    np.testing.assert_allclose(b.sdf(p), outside + inside, atol=1e-12)
    # Face points: zero, with the face normal as gradient.
    u = RNG.uniform(-0.9, 0.9, size=(50, 2))
    face = np.column_stack([np.full(50, half[0]), u[:, 0] * half[1], 0.05 + u[:, 1] * half[2]])
    cw, sw = np.cos(yaw), np.sin(yaw)
    world = np.column_stack([0.5 + cw * face[:, 0] - sw * face[:, 1], sw * face[:, 0] + cw * face[:, 1], face[:, 2]])
    np.testing.assert_allclose(b.sdf(world), 0.0, atol=1e-12)
    np.testing.assert_allclose(b.gradient(world + 1e-4 * np.array([cw, sw, 0])), np.tile([cw, sw, 0], (50, 1)), atol=1e-6)


def test_torus_cylinder_capsule_closed_forms():
    t = make_object("torus", mode="3d", center_xy_m=(0.5, 0.0))
    # Tube centre circle at radius 0.045, height 0.018; the hole's centre is outside.
    np.testing.assert_allclose(t.sdf(np.array([[0.545, 0.0, 0.018], [0.5, 0.0, 0.018], [0.5, 0.07, 0.018]])),
                               [-0.018, 0.045 - 0.018, 0.025 - 0.018], atol=1e-12)
    cyl = make_object("cylinder", mode="3d")
    np.testing.assert_allclose(cyl.sdf(np.array([[0.5, 0.0, 0.13], [0.54, 0.0, 0.06], [0.5, 0.0, 0.06]])),
                               [0.01, 0.005, -0.035], atol=1e-12)
    cap = make_object("capsule", mode="3d", yaw_rad=np.pi / 2)  # axis along world y
    np.testing.assert_allclose(cap.sdf(np.array([[0.5, 0.08, 0.03], [0.5, 0.0, 0.07]])), [0.01, 0.01], atol=1e-12)


@pytest.mark.parametrize("mode,name", ALL)
def test_exact_distance_and_gradient_near_surface(mode, name):
    """Eikonal |∇d| = 1 near the surface, p − d∇d lands on the surface, gradients = finite differences."""
    obj = make_object(name, mode=mode, yaw_rad=0.2)
    s = obj.surface_samples(0.004)
    assert len(s) > 50
    assert np.all(s >= obj.bounds[0] - 1e-9) and np.all(s <= obj.bounds[1] + 1e-9)
    n = obj.gradient(s)
    p = s + RNG.uniform(-0.002, 0.002, size=(len(s), 1)) * n
    d = obj.sdf(p)
    h = 1e-5
    fd = np.column_stack([(obj.sdf(p + h * e) - obj.sdf(p - h * e)) / (2 * h) for e in np.eye(obj.dim)])
    norm = np.linalg.norm(fd, axis=1)
    good = np.abs(norm - 1.0) < 1e-4
    # Non-smooth points (medial axis at concave corners/edges) are rare near the surface.
    assert np.mean(good) > 0.9, f"{name}: |grad| != 1 at {np.mean(~good):.0%} of near-surface points"
    g = obj.gradient(p)
    np.testing.assert_allclose(g[good], fd[good] / norm[good, None], atol=1e-4)
    back = p - d[:, None] * g
    assert np.quantile(np.abs(obj.sdf(back[good])), 0.95) < 1e-6


@pytest.mark.parametrize("name", list_objects("3d"))
def test_3d_solids_stand_on_the_table(name):
    obj = make_object(name, mode="3d", center_xy_m=(0.45, 0.05), yaw_rad=1.0, scale=1.2)
    assert obj.bounds[0, 2] == 0.0
    below = RNG.uniform([0.3, -0.1, -0.05], [0.6, 0.2, -1e-6], size=(2000, 3))
    assert np.all(obj.sdf(below) > 0)
    # The lowest point touches the table: some surface points at z ~ 0.
    assert obj.surface_samples(0.004)[:, 2].min() < 2e-3
    # Nothing outside the bounds is inside.
    grid = RNG.uniform(obj.bounds[0] - 0.05, obj.bounds[1] + 0.05, size=(20000, 3))
    out = np.any((grid < obj.bounds[0]) | (grid > obj.bounds[1]), axis=1)
    assert np.all(obj.sdf(grid[out]) > -1e-12)


def test_prism_in_3d_mode():
    obj = make_object("star", mode="3d", prism_height_m=0.1)
    flat = make_object("star", mode="2d")
    assert obj.dim == 3 and obj.prism_height_m == 0.1
    p = np.array([[0.5, 0.0, 0.05], [0.5, 0.0, 0.13], [0.5, 0.0, -0.02], [0.62, 0.0, 0.05]])
    np.testing.assert_allclose(obj.sdf(p), [flat.sdf(p[:1, :2])[0], 0.03, 0.02, flat.sdf(p[3:, :2])[0]], atol=1e-12)


def test_errors_are_clear():
    with pytest.raises(ValueError, match="unknown object 'blob'.*circle"):
        make_object("blob")
    with pytest.raises(ValueError, match="'torus' is a 3D object"):
        make_object("torus", mode="2d")
    with pytest.raises(ValueError, match="mode must be"):
        make_object("circle", mode="4d")
    with pytest.raises(ValueError, match="scale must be"):
        make_object("circle", scale=-1)
    with pytest.raises(ValueError, match=r"expected points of shape \(N, 2\)"):
        make_object("circle").sdf(np.zeros((3, 3)))
