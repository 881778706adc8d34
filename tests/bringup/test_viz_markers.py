"""Viewer marker arrays: σ field against the map's own variances, the arm against FK, URIs."""

from pathlib import Path

import numpy as np
import pytest

from tactile_bringup.viz_markers import (
    SigmaField,
    arm_link_frames,
    arm_polyline,
    joint_vector,
    ramp_rgba,
    resolve_package_uris,
)
from tactile_common.fields import KIND_CANDIDATE
from tactile_gpis.estimator import ShapeEstimator


def _estimator(mode):
    est = ShapeEstimator({"mode": mode, "lattice.points_per_axis_2d": 24, "lattice.points_per_axis_3d": 10})
    est.add_observation(np.array([0.54, 0.0, 0.06]), np.array([1.0, 0.0, 0.0]), 1)
    est.add_observation(np.array([0.5, 0.05, 0.06]), np.array([0.0, 1.0, 0.0]), 1)
    return est


@pytest.mark.parametrize("mode", ["2d", "3d"])
def test_sigma_field_matches_the_lattice_and_interpolates_linearly(mode):
    est = _estimator(mode)
    arr = est.map_array()
    field = SigmaField(arr)
    lat = arr[arr["kind"] == 0]
    xyz = np.stack([lat["x"], lat["y"], lat["z"]], axis=-1)
    assert field.dim == (2 if mode == "2d" else 3)
    # at the nodes: log10 sqrt(variance), exactly
    assert np.allclose(field(xyz[::7]), 0.5 * np.log10(lat["variance"][::7]))
    # half-way along x between two neighbouring nodes: the mean of their values
    axes = est.lattice_axes
    i = len(axes[0]) // 3
    node = np.array([axes[0][i], axes[1][i], axes[2][i] if mode == "3d" else est.plane_z_m])
    nxt = node.copy()
    nxt[0] = axes[0][i + 1]
    v0, v1 = field(np.vstack([node, nxt]))
    assert field(0.5 * (node + nxt))[0] == pytest.approx(0.5 * (v0 + v1))
    lo, hi = field.range()
    assert lo < hi


def test_sigma_field_needs_a_lattice():
    est = _estimator("2d")
    arr = est.map_array()
    with pytest.raises(ValueError, match="no lattice points"):
        SigmaField(arr[arr["kind"] == KIND_CANDIDATE])


def test_ramp_ends_and_clipping():
    rgba = ramp_rgba(np.array([-5.0, 0.0, 1.0, 9.0]), 0.0, 1.0, alpha=0.5)
    assert rgba.shape == (4, 4) and np.all(rgba[:, 3] == 0.5)
    assert np.allclose(rgba[0], rgba[1]) and np.allclose(rgba[2], rgba[3])
    assert rgba[0, 2] > rgba[0, 0] and rgba[2, 0] > rgba[2, 2], "dark blue-violet to yellow"


def test_package_uris_resolve_to_files(tmp_path):
    urdf = tmp_path / "share" / "my_robot" / "urdf" / "r.urdf"
    urdf.parent.mkdir(parents=True)
    text = ('<mesh filename="package://my_robot/meshes/a.stl"/>'
            '<mesh filename="package://elsewhere/b.stl"/>')
    out = resolve_package_uris(text, str(urdf))
    assert f'filename="{(tmp_path / "share" / "my_robot" / "meshes" / "a.stl").as_uri()}"' in out
    assert 'package://elsewhere/b.stl' in out


def test_arm_polyline_ends_at_the_fingertip():
    from tactile_driver.kinematics import ArmModel, home_configuration

    arm = ArmModel()
    q = home_configuration(arm)
    P = arm_polyline(arm, q)
    assert np.allclose(P[0], 0.0), "the arm base is the world origin"
    assert np.allclose(P[-1], arm.fk(q)[0])
    frames = arm_link_frames(arm)
    assert frames[0] == "panda_link0" and len(P) == len(frames) + 1
    # segment lengths are the URDF's link offsets: link1 is 0.333 m above the base
    assert np.linalg.norm(P[1] - P[0]) == pytest.approx(0.333)
    urdf_text = Path(arm.urdf_path).read_text()
    assert "package://" in urdf_text and "package://" not in resolve_package_uris(urdf_text, arm.urdf_path)


def test_joint_vector_in_command_order():
    assert joint_vector(["b", "a", "c"], [2.0, 1.0, 3.0], ["a", "b"]).tolist() == [1.0, 2.0]
    assert joint_vector(["a"], [1.0], ["a", "b"]) is None
