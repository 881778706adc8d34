"""Shape accuracy on analytic shapes: IoU of {mean < 0} against the true solid."""

import numpy as np

from tactile_gpis.estimator import ShapeEstimator

from shapes import (CENTRE_2D, CENTRE_3D, circle_sdf, fibonacci_sphere, iou, sphere_sdf,
                    star_inside, star_surface)


def eval_points_2d(n: int = 200) -> np.ndarray:
    g = np.stack(np.meshgrid(np.linspace(0.35, 0.65, n), np.linspace(-0.15, 0.15, n), indexing="ij"), -1)
    return g.reshape(-1, 2)


def test_circle_iou_with_few_contacts():
    est = ShapeEstimator.from_params({"mode": "2d", "lattice.points_per_axis_2d": 64})
    a = np.linspace(0, 2 * np.pi, 8, endpoint=False) + 0.3
    for ang in a:
        n = np.array([np.cos(ang), np.sin(ang), 0.0])
        assert est.add_observation(np.r_[CENTRE_2D + 0.05 * n[:2], 0.06], n, 1)[0]
    P = eval_points_2d()
    assert iou(est.inside(P), circle_sdf(P) < 0) >= 0.95


def test_sphere_iou_with_few_contacts():
    est = ShapeEstimator.from_params({"mode": "3d", "lattice.points_per_axis_3d": 24})
    d = fibonacci_sphere(20)
    for n in d:
        assert est.add_observation(CENTRE_3D + 0.05 * n, n, 1)[0]
    rng = np.random.default_rng(0)
    P = rng.uniform([0.35, -0.15, 0.0], [0.65, 0.15, 0.22], (60000, 3))
    assert iou(est.inside(P), sphere_sdf(P) < 0) >= 0.95


def star_iou(use_normals: bool, count: int) -> float:
    est = ShapeEstimator.from_params({"mode": "2d", "lattice.points_per_axis_2d": 64, "use_normals": use_normals})
    pts, nrm = star_surface(np.linspace(0, 2 * np.pi, count, endpoint=False) + 0.1)
    for p, n in zip(pts, nrm):
        assert est.add_observation(np.r_[p, 0.06], np.r_[n, 0.0], 1)[0]
    P = eval_points_2d()
    return iou(est.inside(P), star_inside(P))


def test_normals_improve_star_iou_at_equal_contact_count():
    without, with_normals = star_iou(False, 12), star_iou(True, 12)
    assert with_normals > without + 0.03, (without, with_normals)
    assert with_normals > 0.85
