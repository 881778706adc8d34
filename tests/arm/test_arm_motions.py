"""The commander's plans without ROS (tactile_driver.arm_motions), against the forward kinematics.

The back-off waypoint is judged from the plan's own tip polyline measured here
(cumulative lengths); the joint move's end against the exact goal joints. A tilted finger
(reorientation in place, an approach that holds the axis) against the full model's FK and
scipy's spline of the trajectory.
"""

import warnings

import numpy as np
import pinocchio as pin
import pytest
from scipy.interpolate import CubicHermiteSpline

from tactile_common.touch_geometry import APPROACH_BOX_INSET_M
from tactile_driver.arm_motions import ArmMotions, path_point_before, timed_start_ns
from tactile_driver.commander_api import CommanderConfig
from tactile_driver.safety import OutsideWorkspace
from tactile_driver.trajectory import TrajectoryError, plan_tip_path

from finger_axis_helpers import OFFSET_M, full_model, full_tip as _full_tip, axis as _axis, angle as _angle


@pytest.fixture(scope="module")
def motions():
    return ArmMotions(CommanderConfig())


@pytest.fixture(scope="module")
def straight_path(motions):
    """A 6 cm straight tip path along +x at 6 cm height, from the IK of its start."""
    q0 = motions.tip_path(np.array([[0.40, 0.0, 0.06]]), motions.home).positions_rad[-1]
    return motions.tip_path(np.array([[0.40, 0.0, 0.06], [0.46, 0.0, 0.06]]), q0)


def _travelled(traj):
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(traj.tip_xyz, axis=0), axis=1))])


def test_the_back_off_waypoint_is_the_last_one_a_clearance_before_the_contact(motions, straight_path):
    traj, start_s = straight_path, 3.0
    s = _travelled(traj)
    t_contact = float(np.interp(0.045, s, traj.times_s))  # the tip had gone 4.5 cm along the path
    q = path_point_before(traj, start_s, start_s + t_contact, 0.01)
    k = int(np.flatnonzero(s <= 0.035 + 1e-12)[-1])
    assert np.array_equal(q, traj.positions_rad[k])
    tip = motions.model.fk(q)[0]
    assert 0.01 <= 0.45 - tip[0] + 1e-9 and 0.45 - tip[0] < 0.01 + 0.011  # within a waypoint step (1 cm)


def test_a_contact_sooner_than_the_clearance_backs_off_to_the_paths_start(motions, straight_path):
    """Never a point that depends on where the arm stopped (the straight-away back-off did)."""
    traj, start_s = straight_path, 3.0
    t_contact = float(np.interp(0.004, _travelled(traj), traj.times_s))
    q = path_point_before(traj, start_s, start_s + t_contact, 0.01)
    assert np.array_equal(q, traj.positions_rad[0])


def test_a_joint_move_ends_exactly_on_its_goal_in_steps_of_about_the_tip_step(motions, straight_path):
    q0, q1 = straight_path.positions_rad[-1], straight_path.positions_rad[0]
    traj = motions.joint_move(q0, q1, 0.02, 0.005)
    assert np.array_equal(traj.positions_rad[-1], q1) and np.array_equal(traj.positions_rad[0], q0)
    steps = np.linalg.norm(np.diff([motions.model.fk(q)[0] for q in traj.positions_rad], axis=0), axis=1)
    assert len(steps) == int(np.ceil(0.06 / 0.005))  # from the tip's 6 cm straight-line span
    assert 0.95 * 0.005 < steps.min() and steps.max() < 1.05 * 0.005  # a curved joint-space path


@pytest.mark.parametrize("now_ns, lead_s, grid_s, expected_ns", [
    (1_234_567_891, 0.5, 0.01, 1_740_000_000),  # 0.5 s later, up to the next 10 ms tick
    (1_230_000_000, 0.5, 0.01, 1_730_000_000),  # already on the grid: stays there
    (1_234_567_891, 0.0, 0.01, 0),  # no lead: start on receipt
    (1_234_567_891, 0.5, 0.0, 1_734_567_891),  # no grid
])
def test_timed_starts_fall_on_the_tick_grid(now_ns, lead_s, grid_s, expected_ns):
    assert timed_start_ns(now_ns, lead_s, grid_s) == expected_ns


def test_an_approach_is_shortened_to_end_inside_the_box_and_refused_when_it_cannot_reach_the_surface(motions):
    """A guarded approach's depth is a bound: it ends inside the box (the floor above the table)."""
    floor = motions.box.lower_xyz[2]
    assert floor == pytest.approx(0.0 + 0.005 + 0.010)  # table + table margin + tip radius (CommanderConfig)
    start = np.array([0.45, 0.0, floor + 0.025])
    down = np.array([0.0, 0.0, -1.0])
    depth = motions.approach_depth_m(start, down, 0.04, 0.01)
    assert depth == pytest.approx(0.025 - APPROACH_BOX_INSET_M)
    q0 = motions.tip_path(start[None], motions.home).positions_rad[-1]
    approach = motions.tip_path((start + depth * down)[None], q0, 0.02, 0.005)  # in the box: no OutsideWorkspace
    assert approach.tip_xyz[:, 2].min() >= floor
    tilted = np.array([0.6, 0.0, -0.8])  # along the ray: the floor is 25 mm / 0.8 away
    assert motions.approach_depth_m(start, tilted, 0.04) == pytest.approx(0.025 / 0.8 - APPROACH_BOX_INSET_M)
    assert motions.approach_depth_m(start, [1.0, 0.0, 0.0], 0.04) == 0.04  # far from every face: unchanged
    with pytest.raises(OutsideWorkspace, match="outside the safety box"):  # 5 mm left: the standoff is 10
        motions.approach_depth_m(np.array([0.45, 0.0, floor + 0.005]), down, 0.04, 0.01)


def test_a_path_may_leave_a_tip_a_hair_outside_the_box_but_not_go_there(motions):
    """A motion can end a few µm past a face (the IK's residual, up to ``ik_tol_m``, at a point planned on
    it: 13 µm below the floor, seen at a pre-touch point there). A path that starts at that tip is a way
    back, not a target there; a path whose first point is a target outside is still refused."""
    from tactile_driver.ik import IKSettings, solve_ik

    floor = motions.box.lower_xyz[2]
    below = np.array([0.45, 0.0, floor - 13e-6])
    q_near = motions.tip_path(np.array([[0.45, 0.0, floor + 0.01]]), motions.home).positions_rad[-1]
    q_below = solve_ik(motions.model, below, q_near, IKSettings(tol_m=1e-7)).q
    tip = motions.model.fk(q_below)[0]
    assert tip[2] < floor  # the arm is there, outside the box
    up = motions.tip_path(np.array([tip, tip + [0.0, 0.0, 0.02]]), q_below)
    assert up.tip_xyz[-1] == pytest.approx(tip + [0.0, 0.0, 0.02], abs=1e-4)
    assert up.tip_xyz[1:, 2].min() >= floor
    with pytest.raises(OutsideWorkspace, match="tip point 0 outside the safety box: z=0.0149"):
        motions.tip_path(np.array([below, tip + [0.0, 0.0, 0.02]]), q_near)  # going there: refused


def test_an_approach_from_a_pretouch_point_the_ik_put_a_hair_below_the_floor(motions):
    """A pre-touch point planned on the floor (the planner's lowest tip height is the box floor) is
    reached within the IK's accuracy, possibly below it: the approach along the floor still gets its
    depth and a target inside the box; a start farther outside still gets none."""
    floor = motions.box.lower_xyz[2]
    side = np.array([1.0, 0.0, 0.0])
    start = np.array([0.45, 0.0, floor - 13e-6])
    assert motions.approach_depth_m(start, side, 0.04) == 0.04
    assert motions.into_box(start)[2] == floor and np.all(motions.into_box(start)[:2] == start[:2])
    far = np.array([0.45, 0.0, floor - 1e-3])  # 1 mm below: not rounding
    assert np.all(motions.into_box(far) == far)
    with pytest.raises(OutsideWorkspace):
        motions.approach_depth_m(far, side, 0.04, 0.01)


# -- a tilted finger ---------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def full():
    return full_model()


@pytest.fixture(scope="module")
def q_low(motions):
    """Joints with the tip at (0.5, 0, 0.1), finger vertical."""
    return motions.tip_path(np.array([[0.5, 0.0, 0.1]]), motions.home).positions_rad[-1]


def test_a_path_from_a_vertical_finger_is_planned_as_before(motions):
    """tip_path without axes from a vertical start: plan_tip_path without axes, bit for bit."""
    path = np.array([[0.45, -0.05, 0.25], [0.40, -0.10, 0.06], [0.52, 0.03, 0.06]])
    traj = motions.tip_path(path, motions.home)
    ref = plan_tip_path(motions.model, path, motions.home, motions.limits, motions.cfg.waypoint_step_m,
                        motions.ik, motions.cfg.max_joint_step_rad)
    assert np.array_equal(traj.positions_rad, ref.positions_rad) and np.array_equal(traj.times_s, ref.times_s)
    assert "axes_xyz" not in traj.meta


@pytest.mark.parametrize("tilt_deg, azimuth_deg", [(60, 90), (45, 225), (75, 315)])
def test_a_rotation_in_place_keeps_the_tip_and_respects_the_joint_limits(motions, full, q_low, tilt_deg,
                                                                           azimuth_deg):
    axis = _axis(tilt_deg, azimuth_deg)
    tip0 = _full_tip(full, q_low)[0]
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no division by zero on a path without tip travel
        traj = motions.reorient(q_low, axis)
    fk = [_full_tip(full, q) for q in traj.positions_rad]
    assert max(np.linalg.norm(t - tip0) for t, _ in fk) <= motions.ik.tol_m
    assert _angle(fk[-1][1], axis) <= motions.ik.max_tilt_rad
    assert _angle(fk[0][1], [0, 0, 1]) < 1e-3 and len(traj.times_s) >= np.radians(tilt_deg) / 0.05
    # The executed spline (scipy): within the joint velocity and acceleration limits, the tip stays put.
    lim = motions.limits
    spline = CubicHermiteSpline(traj.times_s, traj.positions_rad, traj.velocities_rad_s)
    t = np.linspace(0.0, traj.duration_s, 4000)
    assert np.all(np.abs(spline(t, 1)) <= lim.velocity_rad_s * (1 + 1e-6))
    assert np.all(np.abs(spline(t, 2)) <= lim.acceleration_rad_s2 * (1 + 1e-6))
    assert max(np.linalg.norm(_full_tip(full, q)[0] - tip0) for q in spline(t[::40])) < 1e-3
    # The joints set the time: no faster than the largest joint travel at its velocity limit.
    travel = np.abs(np.diff(traj.positions_rad, axis=0)).sum(axis=0)
    assert traj.duration_s >= np.max(travel / lim.velocity_rad_s)
    assert np.all(np.diff(traj.times_s) > 0) and np.all(np.isfinite(traj.times_s))
    # The flange (link8, full model) moves at most at the tip speed (the turn's path parameter is its arc).
    # A sideways turn (the wrist's easy direction) takes no more than 3x the longer of the flange's arc at
    # that speed and the joints' travel at their limit, + 2 s: 60 deg took 7.7 s when an in-place turn was
    # timed by a 1 µm floor (over this bound), 4.5 s now. (Towards the robot the joints' back and forth set it.)
    model, data = full
    flange = []
    for q7 in spline(t):
        q = np.zeros(model.nq)
        q[:7] = q7
        pin.framesForwardKinematics(model, data, q)
        flange.append(data.oMf[model.getFrameId("panda_link8")].translation.copy())
    speed = np.linalg.norm(np.diff(flange, axis=0), axis=1) / np.diff(t)
    assert speed.max() <= lim.tip_speed_mps * 1.05
    arc_m = OFFSET_M * np.radians(tilt_deg)
    if azimuth_deg == 90:
        assert traj.duration_s <= 3.0 * max(arc_m / lim.tip_speed_mps, np.max(travel / lim.velocity_rad_s)) + 2.0


@pytest.mark.parametrize("bad", [[np.nan, 0.0, 1.0], [0.0, 0.0, 0.0], [1.0, 0.0], "up"])
def test_a_bad_reorientation_axis_is_a_clear_error(motions, q_low, bad):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(TrajectoryError, match="finger ax"):
            motions.reorient(q_low, bad)


def test_an_approach_from_a_tilted_finger_keeps_its_axis(motions, full, q_low):
    """tip_path without axes holds a tilted start's axis (a vertical start is planned vertical, as before)."""
    q_tilted = motions.reorient(q_low, _axis(50, 90)).positions_rad[-1]
    z0 = _full_tip(full, q_tilted)[1]
    assert _angle(z0, [0, 0, 1]) > np.radians(40)
    approach = motions.tip_path(np.array([[0.5, 0.0, 0.06]]), q_tilted, 0.02, 0.005)
    fk = [_full_tip(full, q) for q in approach.positions_rad]
    assert max(_angle(z, z0) for _, z in fk) <= motions.ik.max_tilt_rad
    assert np.linalg.norm(fk[-1][0] - [0.5, 0.0, 0.06]) <= motions.ik.tol_m
    np.testing.assert_allclose(approach.meta["axes_xyz"], np.repeat(z0[None], len(fk), axis=0), atol=1e-12)
    # A given axis wins: back to vertical along the same approach.
    up = motions.tip_path(np.array([[0.5, 0.0, 0.06]]), q_tilted, 0.02, 0.005, axes_xyz=[[0.0, 0.0, 1.0]])
    assert _angle(_full_tip(full, up.positions_rad[-1])[1], [0, 0, 1]) <= motions.ik.max_tilt_rad


def test_a_tilted_finger_goes_back_through_its_paths_own_joints_to_where_it_turned(motions, full, q_low):
    """The way back of a tilted touch (ArmMotions.retrace): the plan's waypoints in reverse, down to the last
    one planned vertical; the tip ends at the entry point, the finger vertical, and no joint jumps."""
    from tactile_driver.arm_motions import turn_start_index

    tip0 = _full_tip(full, q_low)[0]
    entry = tip0 + np.array([0.0, 0.04, 0.0])
    a = _axis(60, 90)
    path = np.array([entry, entry, entry - 0.03 * a])
    traj = motions.tip_path(path, q_low, axes_xyz=np.array([[0, 0, 1.0], a, a]))
    k0 = turn_start_index(traj, motions.ik.max_tilt_rad)
    assert k0 is not None and np.linalg.norm(traj.tip_xyz[k0] - entry) < 1e-9
    assert turn_start_index(motions.tip_path(path[:1], q_low), motions.ik.max_tilt_rad) is None
    back = motions.retrace(traj, traj.positions_rad[-1], k0)
    np.testing.assert_array_equal(back.positions_rad[1:], traj.positions_rad[k0:][::-1])
    tip, z = _full_tip(full, back.positions_rad[-1])
    assert np.linalg.norm(tip - entry) <= motions.ik.tol_m and _angle(z, [0, 0, 1]) <= motions.ik.max_tilt_rad
    assert np.abs(np.diff(back.positions_rad, axis=0)).max() <= motions.cfg.max_joint_step_rad
    # from a waypoint part way (a back-off on the path): it starts from the nearest one
    mid = (k0 + len(traj.positions_rad)) // 2
    part = motions.retrace(traj, traj.positions_rad[mid], k0)
    assert len(part.positions_rad) == mid - k0 + 2


def test_a_turn_that_would_put_the_wrist_on_the_table_is_refused(motions, full):
    """Level, link 6 reaches 14.1 cm from the finger axis (tactile_common.wrist): with the tip 10 cm up it
    would go 4 cm into the table; 17 cm up it clears the table + margin."""
    level = _axis(90, 90)
    q_low = motions.tip_path(np.array([[0.5, 0.0, 0.10]]), motions.home).positions_rad[-1]
    with pytest.raises(TrajectoryError, match="wrist would reach z = -0.04"):
        motions.reorient(q_low, level)
    q_high = motions.tip_path(np.array([[0.5, 0.0, 0.17]]), motions.home).positions_rad[-1]
    traj = motions.reorient(q_high, level)
    assert _angle(_full_tip(full, traj.positions_rad[-1])[1], level) <= motions.ik.max_tilt_rad
    # another arm: no bands wider than the rod, and the low turn is planned
    thin = ArmMotions(CommanderConfig(wrist_bands_m=(0.0, 0.01, 0.0)))
    assert thin.reorient(q_low, level).positions_rad.shape[0] > 1
    with pytest.raises(ValueError, match="wrist_bands_m"):
        ArmMotions(CommanderConfig(wrist_bands_m=(0.0, 0.1)))


def test_what_the_planner_sends_near_the_floor_the_commander_approaches(motions):
    """The planner's "touched below the lowest tip height" rule against the commander's own approach depth:
    every candidate near the table that the planner lets through gets an approach of at least the shortest
    useful length (no OutsideWorkspace), and those it refuses would have been refused. Before, a target whose
    shortest approach ended 0.15 mm short of the commander's inset was sent, refused as unreachable, and
    excluded with its neighbours: a flat object's run then revisited one target to the end."""
    from tactile_common.fields import KIND_CANDIDATE, KIND_LATTICE, VARIANCE_MAP_DTYPE
    from tactile_common.touch_geometry import TouchGeometry
    from tactile_planner.planner import TouchPlanner

    rng = np.random.default_rng(3)
    k = 400
    normal = rng.normal(size=(k, 3))
    normal[:, 2] = np.abs(normal[:, 2]) + 0.05
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    target = np.column_stack([rng.uniform(0.45, 0.55, k), rng.uniform(-0.05, 0.05, k), rng.uniform(0.0, 0.03, k)])
    ax = (np.linspace(0.35, 0.65, 16), np.linspace(-0.15, 0.15, 16), np.linspace(0.0, 0.22, 12))
    grid = np.stack([g.ravel() for g in np.meshgrid(*ax, indexing="ij")], axis=1)
    rows = np.zeros(len(grid) + k, VARIANCE_MAP_DTYPE)
    rows["x"], rows["y"], rows["z"] = np.vstack([grid, target]).T
    rows["mean"], rows["variance"] = 0.03, 1e-6  # free everywhere (within the planner's shell)
    rows["kind"] = np.r_[np.full(len(grid), KIND_LATTICE), np.full(k, KIND_CANDIDATE)]
    rows["normal_x"][len(grid):], rows["normal_y"][len(grid):], rows["normal_z"][len(grid):] = normal.T
    planner = TouchPlanner.from_params({"mode": "3d", "min_tip_z_m": float(motions.box.lower_xyz[2]),
                                        "search_quantile": 0.0, "clearance": "mean"}, seed=0)
    planner.plan(rows, np.array([0.5, 0.0, 0.15]))
    refused = planner.last_why["touched below the lowest tip height"]
    assert 50 < refused.sum() < k - 50  # both kinds, near the line
    geo = TouchGeometry()
    pretouch = geo.pretouch_xyz(target, normal)

    def commander_takes(i: int) -> bool:
        try:
            motions.approach_depth_m(pretouch[i], -normal[i], geo.approach_length_m, geo.min_approach_m)
            return True
        except OutsideWorkspace:
            return False

    takes = np.array([commander_takes(i) for i in range(k)])
    assert takes[~refused].all()  # sent: approached
    assert not takes[refused].any()  # refused: the commander would have too
