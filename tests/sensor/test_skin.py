"""The skin's indentation under a force: closed-form contact laws, the simulated skin, and
contacts that land on the object's surface instead of inside it."""

import numpy as np
import pytest
from sensor_shapes import Plane, Sphere

from tactile_driver.contact import ContactConfig, ContactDetector
from tactile_driver.skin import SkinIndentation
from tactile_driver.taxels import hemisphere_layout, ring_layout
from tactile_sim.sensor_model import SensorModel, SensorModelConfig
from tactile_sim.touch import simulate_approach

K = 2.0e7  # Pa/m, the simulated skin
MARGIN = 2.5 * SensorModelConfig().spread_m  # the simulated skin's reach beyond the band
TIP0 = np.array([0.50, 0.0, 0.06])


@pytest.mark.parametrize("force_n", [0.05, 0.15, 0.5])
def test_the_cap_pressed_straight_down_follows_the_sphere_law(force_n):
    """A sphere of radius r pressed δ into a plane by a spring skin: F = π k r δ² (the cap)."""
    skin = SkinIndentation(hemisphere_layout(), K, MARGIN, spacing_m=0.0002)
    r = hemisphere_layout().tip_radius_m
    assert skin.depth_m(force_n, np.array([0.0, 0.0, -1.0])) == pytest.approx(np.sqrt(force_n / (np.pi * K * r)),
                                                                              rel=0.03)


@pytest.mark.parametrize("force_n", [0.05, 0.15, 0.5])
def test_the_ring_finger_against_a_wall_follows_the_cylinder_law(force_n):
    """A cylinder of radius r and length H pressed δ into a plane: F = (4/3) k H √(2r) δ^(3/2)."""
    layout = ring_layout()
    skin = SkinIndentation(layout, K, MARGIN, spacing_m=0.0002)
    z0, z1 = layout.axis_z_range_m
    length = (z1 - z0) + 2 * MARGIN
    expected = (3 * force_n / (4 * K * length * np.sqrt(2 * layout.tip_radius_m))) ** (2 / 3)
    assert skin.depth_m(force_n, np.array([np.cos(0.3), np.sin(0.3), 0.0])) == pytest.approx(expected, rel=0.03)


@pytest.mark.parametrize("layout_fn, normal", [
    (hemisphere_layout, [0.0, 0.0, -1.0]), (hemisphere_layout, [0.6, 0.0, -0.8]),
    (hemisphere_layout, [1.0, 0.0, 0.0]), (ring_layout, [0.0, 1.0, 0.0])])
def test_the_depth_inverts_the_simulated_skins_force(layout_fn, normal):
    """The simulator's spring skin (its own SDF penetration sum) pushed δ into a plane gives F; the
    driver reads δ back from F."""
    layout = layout_fn()
    model = SensorModel(layout, seed=0)
    skin = SkinIndentation(layout, K, MARGIN)
    n = np.asarray(normal, dtype=float) / np.linalg.norm(normal)
    h_max = float((model._samples_m @ n).max())  # where the finger reaches furthest along n
    for depth in (0.0001, 0.0003, 0.0008):
        plane = Plane(TIP0 + (h_max - depth) * n, -n, dim=3 if layout.hemisphere else 2)
        force = model.force_n(plane, TIP0)
        assert skin.depth_m(force, n) == pytest.approx(depth, rel=0.02, abs=2e-6)


def _signed_errors(skin_stiffness: float) -> np.ndarray:
    """Signed distance (m) of each contact to the true surface, 12 approaches from 25° below the
    horizontal to straight down against planes and balls (negative: inside the object)."""
    layout = hemisphere_layout()
    model = SensorModel(layout, seed=2)
    rng = np.random.default_rng(5)
    out = []
    for k in range(12):
        az, el = rng.uniform(0, 2 * np.pi), rng.uniform(-np.pi / 2, -np.radians(25))
        d = np.array([np.cos(az) * np.cos(el), np.sin(az) * np.cos(el), np.sin(el)])
        obj = Plane(TIP0 + 0.015 * d, -d) if k % 2 == 0 else Sphere(TIP0 + 0.045 * d, 0.03)
        det = ContactDetector(layout, ContactConfig(skin_stiffness_pa_per_m=skin_stiffness))
        res = simulate_approach(obj, layout, model, det, TIP0, d, 0.02, 0.0001, np.eye(3),
                                np.random.default_rng(k))
        assert res.contact
        out.append(obj.sdf(res.point_xyz[None])[0])
    return np.array(out)


def test_contacts_land_on_the_surface_not_inside_it():
    raw, corrected = _signed_errors(0.0), _signed_errors(K)
    assert np.mean(raw) < -0.0002  # the undeformed skin point: ~0.3 mm inside the object
    assert abs(np.mean(corrected)) < 0.00005 and np.max(np.abs(corrected)) < np.max(np.abs(raw))


def test_bad_skin_parameters_are_clear_errors():
    with pytest.raises(ValueError, match="stiffness"):
        SkinIndentation(ring_layout(), 0.0, MARGIN)
    with pytest.raises(ValueError, match="skin_stiffness_pa_per_m"):
        ContactConfig(skin_stiffness_pa_per_m=-1.0).validate()
