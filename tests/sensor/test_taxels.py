"""Taxel layouts: generator geometry, YAML files in config/, surface projection."""

from pathlib import Path

import numpy as np
import pytest

from tactile_driver.taxels import (
    hemisphere_layout, layout_from_dict, load_layout, ring_layout,
)

CONFIG = Path(__file__).resolve().parents[2] / "src" / "tactile_driver" / "config"


@pytest.mark.parametrize("layout", [ring_layout(), hemisphere_layout()], ids=["ring", "hemisphere"])
def test_taxels_lie_on_the_finger_surface_with_outward_normals(layout):
    p, n = layout.positions_m, layout.normals
    r = layout.tip_radius_m
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-12)
    side = p[:, 2] >= 0 if layout.hemisphere else np.ones(len(p), bool)
    np.testing.assert_allclose(np.hypot(p[side, 0], p[side, 1]), r, atol=1e-12)
    np.testing.assert_allclose(n[side, 2], 0.0, atol=1e-12)
    if layout.hemisphere:
        cap = ~side
        assert cap.sum() > 50
        np.testing.assert_allclose(np.linalg.norm(p[cap], axis=1), r, atol=1e-12)
        np.testing.assert_allclose(n[cap], p[cap] / r, atol=1e-12)
    # the surface projection of a taxel is the taxel itself
    q, m = layout.project_to_surface(p)
    np.testing.assert_allclose(q, p, atol=1e-12)
    np.testing.assert_allclose(m, n, atol=1e-12)


@pytest.mark.parametrize("name,gen", [("ring", ring_layout), ("hemisphere", hemisphere_layout)])
def test_config_files_match_their_generator(name, gen):
    from_file = load_layout(CONFIG / f"taxels_{name}.yaml")
    fresh = gen(**from_file.params)
    np.testing.assert_allclose(from_file.positions_m, fresh.positions_m, atol=1e-8)
    np.testing.assert_allclose(from_file.normals, fresh.normals, atol=1e-8)
    assert from_file.hemisphere == fresh.hemisphere


def test_projection_of_interior_points():
    lay = hemisphere_layout()
    pts = np.array([[0.004, 0.0, -0.003], [0.0, 0.002, 0.004], [0.0, 0.0, -0.001]])
    q, n = lay.project_to_surface(pts)
    r = lay.tip_radius_m
    np.testing.assert_allclose(q[0], r * np.array([0.8, 0.0, -0.6]), atol=1e-12)  # sphere, radial
    np.testing.assert_allclose(q[1], [0.0, r, 0.004], atol=1e-12)  # cylinder, horizontal
    np.testing.assert_allclose(q[2], [0.0, 0.0, -r], atol=1e-12)  # pole
    np.testing.assert_allclose(n[1], [0.0, 1.0, 0.0], atol=1e-12)


def test_bad_layout_is_a_clear_error(tmp_path):
    with pytest.raises(ValueError, match="6 numbers"):
        layout_from_dict({"taxels": [[0, 0, 0]] * 4, "tip_radius_m": 0.01, "axis_z_range_m": [0, 0], "hemisphere": False})
    with pytest.raises(ValueError, match="cannot read"):
        load_layout(tmp_path / "missing.yaml")
