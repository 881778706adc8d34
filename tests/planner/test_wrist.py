"""The wrist behind the flange: its cylinders hold the Panda's links, and the check agrees with exact geometry.

Oracles: the Panda's collision meshes placed by Pinocchio's forward kinematics (for the band radii), and
dense samples of each cylinder against an exact signed distance (box, mushroom) and the table plane.
"""

import os
import re

import numpy as np
import pytest

from tactile_planner.graph import build_free_graph
from tactile_planner.maps import MapLattice
from tactile_planner.synthetic import WORKSPACE_3D
from tactile_planner.tilt import TiltSettings, tilted_entries
from tactile_planner.wrist import PANDA_WRIST_BANDS_M, WristCheck, bands_from_flat

from test_shaft import box_sdf, mushroom_lattice, mushroom_sdf
from test_tilt import CASES, LENGTH, MARGIN, PATH_NEED, R_TIP, STANDOFF, TOUCH_NEED

TOWER = ((0.47, -0.03, 0.0), (0.53, 0.03, 0.20))  # taller than the rod


def _stl_surface_points(path: str) -> np.ndarray:
    """Points on every triangle of an STL mesh (ASCII or binary): its corners, edge midpoints and a 6 × 6
    barycentric grid, so that a face spanning two bands is sampled inside both."""
    data = open(path, "rb").read()
    if data[:5] == b"solid" and b"facet" in data[:400]:
        tri = np.array(re.findall(rb"vertex\s+(\S+)\s+(\S+)\s+(\S+)", data), dtype=float).reshape(-1, 3, 3)
    else:
        n = int(np.frombuffer(data[80:84], np.uint32)[0])
        rec = np.frombuffer(data[84:84 + 50 * n],
                            dtype=np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")]))
        tri = rec["v"].astype(float)
    i, j = np.meshgrid(np.arange(7), np.arange(7), indexing="ij")
    keep = i + j <= 6
    w = np.column_stack([i[keep], j[keep], 6 - i[keep] - j[keep]]) / 6.0  # barycentric weights
    return np.einsum("kw,twc->tkc", w, tri).reshape(-1, 3)


def test_the_panda_bands_hold_link_6_and_link_7_however_the_arm_stands():
    pin = pytest.importorskip("pinocchio")
    from tactile_driver.kinematics import default_urdf_path

    urdf = default_urdf_path()
    meshes = os.path.join(os.path.dirname(urdf), "..", "meshes", "collision")
    model = pin.buildModelFromUrdf(urdf)
    data = model.createData()
    verts = {k: _stl_surface_points(os.path.join(meshes, f"{k}.stl")) for k in ("link6", "link7")}
    rng = np.random.default_rng(0)
    lo, hi = model.lowerPositionLimit[:7], model.upperPositionLimit[:7]
    for _ in range(10):
        q = pin.neutral(model)
        q[:7] = lo + rng.random(7) * (hi - lo)
        pin.framesForwardKinematics(model, data, q)
        flange = data.oMf[model.getFrameId("panda_link8")]
        for link, v in verts.items():
            T = data.oMf[model.getFrameId(f"panda_{link}")]
            rel = (flange.rotation.T @ ((T.rotation @ v.T).T + T.translation - flange.translation).T).T
            t, r = -rel[:, 2], np.hypot(rel[:, 0], rel[:, 1])  # behind the flange (the tip is at +z), off the axis
            lo_t, hi_t = PANDA_WRIST_BANDS_M[0][0], PANDA_WRIST_BANDS_M[-1][1]
            assert t.min() >= lo_t - 1e-6 and t.max() <= hi_t + 1e-6, f"{link}: outside the bands' length"
            # a point on a boundary between two bands may be in either
            radius = np.zeros(len(t))
            for t0, t1, rho in PANDA_WRIST_BANDS_M:
                radius = np.where((t >= t0 - 1e-9) & (t <= t1 + 1e-9), np.maximum(radius, rho), radius)
            assert (r <= radius + 1e-6).all(), f"{link}: {np.max(r - radius):.4f} m outside its band"


def _cylinder_samples(x, a, t0, t1, rho, L=LENGTH, n_t=12, n_r=4, n_phi=24):
    """Points filling the band's cylinder (axis, rings, rim) for pose (x, a)."""
    a = np.asarray(a, float) / np.linalg.norm(a)
    u = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(a, u)
    t = L + np.linspace(t0, t1, n_t)
    r = np.linspace(0.0, rho, n_r + 1)
    phi = np.linspace(0.0, 2 * np.pi, n_phi, endpoint=False)
    T, Rr, P = np.meshgrid(t, r, phi, indexing="ij")
    return (np.asarray(x, float)[None] + T.reshape(-1, 1) * a + (Rr * np.cos(P)).reshape(-1, 1) * u
            + (Rr * np.sin(P)).reshape(-1, 1) * v)


def _box_lattice(n=48) -> MapLattice:
    axes = tuple(np.linspace(lo, hi, n) for lo, hi in WORKSPACE_3D)
    pts = np.stack([m.ravel() for m in np.meshgrid(*axes, indexing="ij")], axis=1)
    return MapLattice(axes, box_sdf(pts, *TOWER).reshape((n,) * 3), np.full((n,) * 3, 1e-4), None)


def test_the_estimate_check_agrees_with_the_exact_tower():
    lattice = _box_lattice()
    gap = 0.01
    wrist = WristCheck.on_lattice(lattice, PANDA_WRIST_BANDS_M, LENGTH, -1.0, gap)  # the table far below
    cell = float(np.max(lattice.spacing_m))
    rng = np.random.default_rng(1)
    n = 400
    tips = np.column_stack([rng.uniform(0.36, 0.64, n), rng.uniform(-0.14, 0.14, n), rng.uniform(0.0, 0.10, n)])
    tilt, az = rng.uniform(0.0, np.pi / 2, n), rng.uniform(-np.pi, np.pi, n)
    axes = np.column_stack([np.sin(tilt) * np.cos(az), np.sin(tilt) * np.sin(az), np.cos(tilt)])
    got = wrist.clear(tips, axes)
    exact = np.array([min(box_sdf(_cylinder_samples(x, a, *b), *TOWER).min() for b in PANDA_WRIST_BANDS_M)
                      for x, a in zip(tips, axes)])
    # into the tower: never clear; clear of it by the gap and a cell's diagonal more: always clear
    assert not got[exact < 0].any()
    assert got[exact >= gap + wrist.slack_m + np.sqrt(3) * cell].all()
    assert (exact < 0).sum() > 20 and (exact > 0.05).sum() > 20  # both kinds were drawn


@pytest.mark.parametrize("tilt_deg", [0, 30, 60, 80, 90])
def test_the_table_check_is_the_cylinders_lowest_point(tilt_deg):
    wrist = WristCheck(PANDA_WRIST_BANDS_M, LENGTH, 0.005, 0.01, 0.0, None)
    t = np.radians(tilt_deg)
    a = np.array([np.sin(t), 0.0, np.cos(t)])
    lowest = min(_cylinder_samples([0.5, 0.0, 0.0], a, *b, n_phi=720)[:, 2].min() for b in PANDA_WRIST_BANDS_M)
    # the tip at the height that puts the wrist's lowest point exactly on the floor, then 1 mm either side
    z0 = 0.005 - lowest
    assert wrist.clear([[0.5, 0.0, z0 + 1e-3]], a)[0]
    assert not wrist.clear([[0.5, 0.0, z0 - 1e-3]], a)[0]


def test_a_level_finger_under_the_deck_is_refused_for_its_wrist_not_its_rod():
    graph = build_free_graph(mushroom_lattice(), MARGIN, shell_m=0.03, min_z_m=0.015,
                             shaft_length_m=LENGTH, shaft_clearance_m=PATH_NEED)
    wrist = WristCheck.on_lattice(graph.lattice, PANDA_WRIST_BANDS_M, LENGTH, 0.005, 0.01)

    def entries(case, w):
        target, normal = (np.atleast_2d(v).astype(float) for v in CASES[case])
        pre, contact = target + (R_TIP + STANDOFF) * normal, target + R_TIP * normal
        return pre, contact, tilted_entries(graph, pre, contact, normal, R_TIP, TOUCH_NEED, PATH_NEED, np.pi / 2,
                                            TiltSettings(min_flange_z_m=0.0), -0.2, w)

    # the deck's underside: only a level finger senses it, and level at 9 cm link 6 is in the table
    assert entries("deck underside", None)[2].ok[0]
    assert not entries("deck underside", wrist)[2].ok[0]
    for case in ("pillar side under the deck", "pillar front under the deck"):
        pre, contact, e = entries(case, wrist)
        assert e.ok[0], case
        a, s = e.axis_xyz[0], float(e.insert_m[0])
        # every pose of the touch keeps the wrist out of the exact mushroom and off the table
        poses = [pre[0] + f * s * a for f in np.linspace(0, 1, 7)] + [contact[0]]
        for x in poses:
            for b in PANDA_WRIST_BANDS_M:
                pts = _cylinder_samples(x, a, *b)
                assert mushroom_sdf(pts).min() > 0.0 and pts[:, 2].min() >= 0.005 - 1e-9, case


def test_the_bands_parameter_is_checked():
    assert bands_from_flat([0.0, 0.1, 0.05]) == ((0.0, 0.1, 0.05),)
    for bad in ([], [0.0, 0.1], [0.1, 0.05, 0.02], [-0.01, 0.1, 0.02], [0.0, 0.1, -0.02]):
        with pytest.raises(ValueError, match="wrist_bands_m"):
            bands_from_flat(bad, "wrist_bands_m")
    from tactile_planner.planner import TouchPlanner
    with pytest.raises(ValueError, match="wrist_bands_m"):
        TouchPlanner.from_params({"mode": "3d", "wrist_bands_m": [0.0, 0.1]}, seed=0)
