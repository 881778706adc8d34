"""Goal orientation and free-space rules (P(inside), band) against direct computations."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from scipy.special import ndtr

from tactile_planner.graph import build_free_graph
from tactile_planner.maps import MapLattice
from tactile_planner.pose import approach_rotation, quaternion_xyzw


def rot_of_quat(q):
    """Independent oracle: scipy's quaternion (x, y, z, w) -> matrix."""
    return Rotation.from_quat(q).as_matrix()


@pytest.mark.parametrize("normal", [[1, 0, 0], [0, -1, 0], [0.3, 0.4, 0.5], [0, 0, 1], [0, 0, -1], [-1, 1e-9, 0]])
def test_goal_x_axis_is_the_approach_and_z_is_closest_to_up(normal):
    n = np.array(normal, float) / np.linalg.norm(normal)
    r = approach_rotation(n)
    np.testing.assert_allclose(r.T @ r, np.eye(3), atol=1e-12)
    assert np.linalg.det(r) == pytest.approx(1.0)
    np.testing.assert_allclose(r[:, 0], -n, atol=1e-12)
    np.testing.assert_allclose(rot_of_quat(quaternion_xyzw(r)), r, atol=1e-12)
    # z maximises z·up among unit vectors orthogonal to x (brute force over a circle)
    x = r[:, 0]
    a = np.cross(x, [0.3, 0.7, 0.1]); a /= np.linalg.norm(a)
    b = np.cross(x, a)
    t = np.linspace(0, 2 * np.pi, 3600)
    best_up = np.max(np.cos(t) * a[2] + np.sin(t) * b[2])
    assert r[2, 2] >= best_up - 1e-5


def test_p_inside_and_band_rules():
    ax = np.linspace(0.0, 0.3, 40)
    gx, gy = np.meshgrid(ax, ax, indexing="ij")
    mu = np.hypot(gx - 0.15, gy - 0.15) - 0.05
    var = np.where(gx > 0.15, 4e-4, 1e-8)  # very uncertain on one side
    lat = MapLattice((ax, ax), mu, var, 0.06)
    g = build_free_graph(lat, margin_m=0.01, shell_m=0.03, p_inside_max=0.05)
    want = (mu >= 0.01) & (mu <= 0.04) & (ndtr(-mu / np.sqrt(var)) <= 0.05)
    np.testing.assert_array_equal(g.free, want)
    assert want.sum() < ((mu >= 0.01) & (mu <= 0.04)).sum()  # P(inside) removed some nodes
