"""Probes at the foot of a wall (tactile_planner.foot, ``foot_probe_gap_m``).

The estimates here are exact signed distances (independent of the planner): a box floating above
the table (its walls end at its bottom), the same box standing on the table (nothing to probe), a
sphere resting on the table (its wall ends where the sphere curves in, in closed form), and a
mushroom whose cap overhangs the wall below (the rod at the probe's end would be under the cap).
"""

import numpy as np

from tactile_common.fields import KIND_CANDIDATE, KIND_LATTICE, VARIANCE_MAP_DTYPE
from tactile_planner.foot import foot_probes
from tactile_planner.maps import Candidates, MapLattice
from tactile_planner.planner import SHAFT_REASON, TouchPlanner
from tactile_planner.synthetic import WORKSPACE_3D

from test_shaft import SHAFT, box_sdf

PROBE_Z = 0.017


def _lattice(sdf, n: int = 48) -> MapLattice:
    axes = tuple(np.linspace(lo, hi, n) for lo, hi in WORKSPACE_3D)
    pts = np.stack([m.ravel() for m in np.meshgrid(*axes, indexing="ij")], axis=1)
    mu = sdf(pts).reshape((n,) * 3)
    var = 1e-6 + 1e-4 * np.clip(0.1 - pts[:, 2], 0.0, None).reshape(mu.shape)  # rises towards the table
    return MapLattice(axes, mu, var, None)


def _walls(x0, x1, y0, y1, zs):
    """Candidates on the four walls of the box [x0, x1] × [y0, y1] at heights zs (outward normals)."""
    xyz, n = [], []
    for z in zs:
        for s in np.linspace(0.2, 0.8, 4):
            x, y = x0 + s * (x1 - x0), y0 + s * (y1 - y0)
            xyz += [[x1, y, z], [x0, y, z], [x, y1, z], [x, y0, z]]
            n += [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]]
    xyz, n = np.array(xyz, float), np.array(n, float)
    return Candidates(xyz, n, np.zeros(len(xyz)), np.full(len(xyz), 1e-6))


FLOATING = dict(lo=(0.46, -0.03, 0.04), hi=(0.54, 0.03, 0.09))


def test_a_wall_that_ends_above_the_table_gets_probes_at_its_foot():
    lat = _lattice(lambda p: box_sdf(p, FLOATING["lo"], FLOATING["hi"]))
    cands = _walls(0.46, 0.54, -0.03, 0.03, [0.05, 0.07])
    found = foot_probes(lat, cands, PROBE_Z, gap_m=0.01, end_offset_m=0.028)
    assert found is not None
    probes, wall, z_b = found
    dz = lat.axes[2][1] - lat.axes[2][0]
    # the wall's estimate ends at the box's bottom (the lowest lattice node inside, within one node)
    assert (np.abs(z_b - 0.04) <= dz + 1e-9).all()
    # one probe per wall point's column, at the probe height, end_offset_m out along the wall's normal
    src = cands.xyz[wall]
    np.testing.assert_allclose(probes.xyz[:, :2], src[:, :2] + 0.028 * cands.normal[wall, :2], atol=1e-12)
    np.testing.assert_allclose(probes.xyz[:, 2], PROBE_Z)
    np.testing.assert_array_equal(probes.normal, cands.normal[wall])
    assert len(probes) == 16  # the two heights' points share their columns
    # mean and variance: the estimate's at the wall's line at the probe height (exact SDF: the box is above)
    line = np.column_stack([src[:, :2], np.full(len(src), PROBE_Z)])
    np.testing.assert_allclose(probes.mean_m, box_sdf(line, FLOATING["lo"], FLOATING["hi"]), atol=2e-3)
    assert (probes.variance_m2 > 1e-6).all()


def test_no_probe_where_the_estimate_reaches_the_table_or_within_the_gap():
    standing = _lattice(lambda p: box_sdf(p, (0.46, -0.03, 0.0), (0.54, 0.03, 0.09)))
    assert foot_probes(standing, _walls(0.46, 0.54, -0.03, 0.03, [0.05]), PROBE_Z, 0.01, 0.028) is None
    floating = _lattice(lambda p: box_sdf(p, FLOATING["lo"], FLOATING["hi"]))
    assert foot_probes(floating, _walls(0.46, 0.54, -0.03, 0.03, [0.05]), PROBE_Z, 0.03, 0.028) is None
    # a candidate that is not on a wall (a top, facing up) gives none
    top = Candidates(np.array([[0.5, 0.0, 0.09]]), np.array([[0.0, 0.0, 1.0]]), np.zeros(1), np.full(1, 1e-6))
    assert foot_probes(floating, top, PROBE_Z, 0.01, 0.028) is None


def test_a_sphere_on_the_table_ends_its_wall_where_it_curves_in():
    R, inset = 0.05, 0.003
    lat = _lattice(lambda p: np.linalg.norm(p - [0.5, 0.0, R], axis=1) - R)
    ang = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    n = np.column_stack([np.cos(ang), np.sin(ang), np.zeros(12)])
    cands = Candidates(np.array([0.5, 0.0, R]) + R * n, n, np.zeros(12), np.full(12, 1e-6))
    probes, wall, z_b = foot_probes(lat, cands, PROBE_Z, 0.01, 0.028, inset_m=inset)
    # closed form: the column inset inside the equator leaves the sphere at R - sqrt(R² - (R - inset)²)
    want = R - np.sqrt(R ** 2 - (R - inset) ** 2)
    dz = lat.axes[2][1] - lat.axes[2][0]
    assert len(probes) == 12 and (np.abs(z_b - want) <= dz + 1e-9).all()


def _map(lat: MapLattice, cands: Candidates) -> np.ndarray:
    pts = lat.grid_xyz()
    rows = np.zeros(len(pts), VARIANCE_MAP_DTYPE)
    rows["x"], rows["y"], rows["z"] = pts.T
    rows["mean"], rows["variance"], rows["kind"] = lat.mean_m.ravel(), lat.variance_m2.ravel(), KIND_LATTICE
    c = np.zeros(len(cands), VARIANCE_MAP_DTYPE)
    c["x"], c["y"], c["z"] = cands.xyz.T
    c["normal_x"], c["normal_y"], c["normal_z"] = cands.normal.T
    c["mean"], c["variance"], c["kind"] = cands.mean_m, cands.variance_m2, KIND_CANDIDATE
    return np.concatenate([rows, c])


def _planner(gap: float) -> TouchPlanner:
    return TouchPlanner.from_params({"mode": "3d", "strategy": "uncertainty", "foot_probe_gap_m": gap,
                                     "clearance": "mean", **SHAFT}, seed=0)


def test_the_planner_goes_for_the_uncertain_foot_and_its_approach_keeps_the_rod_outside():
    lat = _lattice(lambda p: box_sdf(p, FLOATING["lo"], FLOATING["hi"]))
    cands = _walls(0.46, 0.54, -0.03, 0.03, [0.05, 0.07])
    tip = np.array([0.62, 0.0, 0.12])
    off = _planner(0.0).plan(_map(lat, cands), tip)
    assert off.ok and off.index < len(cands)  # off: the map's candidates only
    res = _planner(0.01).plan(_map(lat, cands), tip)
    assert res.ok and res.index >= len(cands), res.message
    assert "foot of the wall" in res.message
    assert abs(res.target_xyz[2] - PROBE_Z) < 1e-12 and abs(res.normal_xyz[2]) < 1e-12
    # the approach's end (tip centre at target + r n - depth n) keeps the rod its radius and gap out of the box
    end = res.target_xyz + (0.01 - 0.03) * res.normal_xyz
    rod = end + np.outer(np.linspace(0.01, 0.16, 76), [0, 0, 1])
    assert box_sdf(rod, FLOATING["lo"], FLOATING["hi"]).min() >= 0.005 + 0.002 - 1e-6
    # the path ends at the pre-touch point, at the probe height, outside the box's footprint
    assert abs(res.path_xyz[-1, 2] - PROBE_Z) < 1e-9
    assert box_sdf(res.path_xyz[-1:], (0.46, -0.03, 0.0), (0.54, 0.03, 0.09))[0] > 0.04


def test_under_an_overhanging_cap_the_rod_check_to_the_approach_end_refuses_the_probe():
    """A 6 × 6 cm column whose estimate ends 4 cm up under a cap 2 cm wider all round (z 0.08-0.10):
    at the end of a foot probe's approach the rod would be under the cap, though at the expected
    contact (2.8 cm out) it is clear."""
    def sdf(p):
        return np.minimum(box_sdf(p, (0.47, -0.03, 0.04), (0.53, 0.03, 0.08)),
                          box_sdf(p, (0.45, -0.05, 0.08), (0.55, 0.05, 0.10)))
    lat = _lattice(sdf)
    walls = _walls(0.47, 0.53, -0.03, 0.03, [0.06])
    # and one on the cap's top, so that the decision stays on the estimate (the walls' rods are under the cap)
    cands = Candidates(np.vstack([walls.xyz, [0.5, 0.0, 0.10]]), np.vstack([walls.normal, [0, 0, 1.0]]),
                       np.zeros(len(walls) + 1), np.full(len(walls) + 1, 1e-6))
    m = len(cands)
    pl = _planner(0.01)
    res = pl.plan(_map(lat, cands), np.array([0.62, 0.0, 0.14]))
    assert res.ok and res.index == m - 1, res.message  # the top
    blocked = pl.last_why[SHAFT_REASON]
    assert len(blocked) > m and blocked[m:].all()  # every foot probe: the rod would end under the cap
    # the same probes with the rod checked only down to the expected contact would pass: the check matters
    found = foot_probes(lat, walls, PROBE_Z, 0.01, 0.028)
    contact = found[0].xyz + 0.01 * found[0].normal
    rod = contact[:, None, :] + np.linspace(0.01, 0.16, 76)[None, :, None] * np.array([0, 0, 1.0])
    assert (sdf(rod.reshape(-1, 3)).reshape(len(contact), -1).min(axis=1) >= 0.007).all()


def test_the_probes_rod_is_measured_by_distance_not_by_a_mean_flatter_than_one():
    """A GP mean off its data is rarely a distance: |∇μ| < 1 reads the rod at the probe's end (its radius
    and gap, 7 mm, outside the wall's line) nearer than it is. With μ = 0.6 × the exact distance the
    probes are still taken (under a cap they are still refused: the test above, which runs the same check)."""
    lat = _lattice(lambda p: 0.6 * box_sdf(p, FLOATING["lo"], FLOATING["hi"]))
    cands = _walls(0.46, 0.54, -0.03, 0.03, [0.05, 0.07])
    res = _planner(0.01).plan(_map(lat, cands), np.array([0.62, 0.0, 0.12]))
    assert res.ok and res.index >= len(cands), res.message
    end = res.target_xyz + (0.01 - 0.03) * res.normal_xyz
    rod = end + np.outer(np.linspace(0.01, 0.16, 76), [0, 0, 1])
    assert box_sdf(rod, FLOATING["lo"], FLOATING["hi"]).min() >= 0.007 - 1e-6  # exact: clear by rod + gap
    assert 0.6 * box_sdf(rod, FLOATING["lo"], FLOATING["hi"]).min() < 0.007  # what μ would have said


def test_slides_get_no_foot_probes():
    """A slide starts on the estimated surface; a foot probe's target is off it."""
    lat = _lattice(lambda p: box_sdf(p, FLOATING["lo"], FLOATING["hi"]))
    cands = _walls(0.46, 0.54, -0.03, 0.03, [0.05, 0.07])
    pl = TouchPlanner.from_params({"mode": "3d", "strategy": "uncertainty", "foot_probe_gap_m": 0.01,
                                   "clearance": "mean", "touch": "slide", **SHAFT}, seed=0)
    res = pl.plan(_map(lat, cands), np.array([0.62, 0.0, 0.12]))
    assert res.ok and res.index < len(cands) and len(pl.last_why["invalid"]) == len(cands)
