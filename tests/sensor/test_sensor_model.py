"""Skin model: its fast paths (Lipschitz pre-test, 2D column sharing) equal the brute-force sum."""

import numpy as np
import pytest
from sensor_shapes import Cylinder, Plane, Sphere, rotation_about

from tactile_driver.taxels import hemisphere_layout, ring_layout
from tactile_sim.sensor_model import SensorModel


def brute_force_counts(model, obj, tip, R):
    """v = b + c * sum_s Kn(i, s) k delta_s A_s over every surface sample."""
    world = tip + model._samples_m @ R.T
    pts = world[:, :2] if obj.dim == 2 else world
    f = model.config.stiffness_pa_per_m * np.maximum(0.0, -obj.sdf(pts)) * model._area_m2
    return model.baseline_counts + model.config.counts_per_newton * (model._kernel_t.T @ f)


@pytest.mark.parametrize("case", ["ring-disc", "ring-wall-tilted", "hemi-sphere", "hemi-plane"])
def test_fast_paths_match_brute_force(case):
    rng = np.random.default_rng(0)
    if case.startswith("ring"):
        model = SensorModel(ring_layout(), seed=0)
        obj = Cylinder([0.55, 0.0], 0.04, dim=2) if case == "ring-disc" else Plane([0.51, 0, 0], [-1, 0, 0], dim=2)
        tip = np.array([0.5003, 0.0, 0.06])
        R = np.eye(3) if case == "ring-disc" else rotation_about([0, 1, 0], 0.1)
    else:
        model = SensorModel(hemisphere_layout(), seed=0)
        tip = np.array([0.501, 0.0, 0.0597])
        n = np.array([0.3, 0.0, 1.0]) / np.linalg.norm([0.3, 0.0, 1.0])
        obj = Sphere([0.5, 0.0, 0.0], 0.05) if case == "hemi-sphere" else Plane(tip - 0.0097 * n, n)
        R = rotation_about(rng.normal(size=3), 0.2)
    got = model.clean_counts(obj, tip, R)
    want = brute_force_counts(model, obj, tip, R)
    assert np.max(want - model.baseline_counts) > 50, "the case must be in contact"
    np.testing.assert_allclose(got, want, atol=1e-3)


def test_counts_sum_to_the_force_and_noise_is_seeded():
    # a contact on the sensorised cap: the counts carry the whole force
    model = SensorModel(hemisphere_layout(), seed=0)
    wall = Plane([0.0, 0.0, 0.05], [0.0, 0.0, 1.0])
    tip = np.array([0.5, 0.0, 0.0597])
    signal = model.clean_counts(wall, tip) - model.baseline_counts
    assert signal.sum() / model.config.counts_per_newton == pytest.approx(model.force_n(wall, tip), rel=0.05)
    a = model.frame(wall, tip, rng=np.random.default_rng(3))
    b = model.frame(wall, tip, rng=np.random.default_rng(3))
    np.testing.assert_array_equal(a, b)
    assert a.dtype == np.uint16
