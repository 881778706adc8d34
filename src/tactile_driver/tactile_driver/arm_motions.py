"""The arm commander's motion plans, ROS-free: what every verb sends, as a function of the joints.

:class:`ArmMotions` holds the arm model, the safety box, the joint and tip
limits and the IK settings of a :class:`~tactile_driver.commander_api.CommanderConfig`,
and plans (world frame, metres, radians, seconds):

- :meth:`tip_path`: a tip polyline from given joints (box-checked, IK per
  waypoint, time-parameterised rest to rest): the free-space path, the
  guarded approach, a back-off away from a contact; optionally with a target
  finger axis per point (the fingertip z-axis, tip → flange, world);
- :meth:`reorient`: the finger turned in place about the tip centre to a
  given axis (a tip path of the current tip point with that axis);
- :meth:`approach_depth_m`: how deep a guarded approach goes (its depth
  shortened to end inside the box);
- :meth:`joint_move`: a joint-space straight line to given joints (the
  retract, a back-off along a path), every tip waypoint box-checked;
- :func:`path_point_before`: the last waypoint of a followed path at least a
  clearance of tip travel before a contact (where a path back-off goes).

Finger axis of a path without axes (:meth:`ArmMotions.path_axes`): a finger
within ``max_tilt_rad + TILTED_START_MARGIN_RAD`` of vertical at the start is
planned vertical, exactly as before axes existed; a finger tilted farther
(after :meth:`reorient` or a path with axes) keeps its start axis along the
whole path, so a guarded approach or a back-off from a tilted finger does not
swing it back to vertical.

The arm commander sends these plans; the offline loop's simulated rig
(:mod:`tactile_bringup.rig_touch`) plans its touches with the same object, so
both run the same joint trajectories.
"""

from __future__ import annotations

from typing import Any, Optional

import numpy as np

from tactile_common.wrist import bands_from_flat, wrist_lowest_z_m
from tactile_driver.ik import IKSettings, tilt_of
from tactile_driver.kinematics import ArmModel, home_configuration
from tactile_driver.safety import OutsideWorkspace, WorkspaceBox
from tactile_driver.trajectory import (MAX_AXIS_STEP_RAD, MotionLimits, TimedTrajectory, TrajectoryError,
                                       plan_tip_path, time_parameterize, unit_axes)


#: A start finger counts as tilted (a path without axes then holds its axis) only beyond
#: ``max_tilt_rad`` + this (rad): a vertical-mode finger a hair past ``max_tilt_rad`` (a stop between two
#: waypoints of the spline, tracking error) must still be planned vertical, exactly as before.
TILTED_START_MARGIN_RAD = 0.05


class ArmMotions:
    """Model, box, limits and IK of one commander configuration, and the plans made with them."""

    def __init__(self, config: Any) -> None:
        c = self.cfg = config
        self.model = ArmModel(c.urdf_path, list(c.joint_names), c.flange_frame, c.tip_offset_m)
        self.box = WorkspaceBox.of_commander(c)
        self.limits = MotionLimits.for_model(self.model, list(c.max_joint_velocity_rad_s),
                                             list(c.max_joint_acceleration_rad_s2), c.tip_speed_mps)
        self.ik = IKSettings(tol_m=c.ik_tol_m, max_tilt_rad=c.max_tilt_rad)
        self.wrist_bands_m = bands_from_flat(c.wrist_bands_m, "wrist_bands_m")
        self.home = home_configuration(self.model, c.home_rad)

    def _limits(self, speed_mps: Optional[float]) -> MotionLimits:
        lim = self.limits
        return MotionLimits(lim.lower_rad, lim.upper_rad, lim.velocity_rad_s, lim.acceleration_rad_s2,
                            speed_mps or self.cfg.tip_speed_mps)

    def path_axes(self, n_points: int, q_start: np.ndarray,
                  axes_xyz: Optional[np.ndarray] = None) -> Optional[np.ndarray]:
        """The finger axes a tip path of ``n_points`` from ``q_start`` is planned with: ``axes_xyz`` when
        given; else None (vertical, today's plan) when the start finger's tilt from world +z is at most
        ``max_tilt_rad + TILTED_START_MARGIN_RAD``, and otherwise the start's fingertip z-axis (world)
        for every point (the finger held as it is)."""
        if axes_xyz is not None:
            return axes_xyz
        _, R = self.model.fk(np.asarray(q_start, dtype=float))
        if tilt_of(R) <= self.ik.max_tilt_rad + TILTED_START_MARGIN_RAD:
            return None
        return np.repeat(R[None, :, 2], n_points, axis=0)

    def tip_path(self, path_xyz: np.ndarray, q_start: np.ndarray, speed_mps: Optional[float] = None,
                 step_m: Optional[float] = None, axes_xyz: Optional[np.ndarray] = None,
                 step_rad: Optional[float] = None) -> TimedTrajectory:
        """The tip along ``path_xyz`` (K, 3) from joints ``q_start``, at up to ``speed_mps`` (default the
        tip speed), IK waypoints ≤ ``step_m`` apart (default ``waypoint_step_m``).

        ``axes_xyz`` (K, 3): the finger axis (fingertip z-axis, tip → flange, world) at each path point,
        turned along great circles in steps ≤ ``step_rad`` (default ``MAX_AXIS_STEP_RAD``) from the
        start's axis; None: see :meth:`path_axes` (vertical unless the start finger is tilted, then held).

        Raises:
            OutsideWorkspace: a path point or a planned tip waypoint is outside the box.
            TrajectoryError: IK failed, a joint limit would be broken, the axes are not finite
                non-zero (K, 3), or (a tilted finger) the wrist would reach below the table + margin.
        """
        path = np.asarray(path_xyz, dtype=float).reshape(-1, 3)
        # The targets must be inside the box; the IK waypoints towards them within the IK's accuracy: a
        # path along the floor (the planner's lowest tip height is the box floor) put one 13 µm below it,
        # and that refusal ended the run (3D poke, gen3d-003-boxes, seed 3). A path that starts where the tip
        # is (the FK of q_start: the planner's paths) does not check that point: it is not a target, and a
        # tip left within that accuracy outside must be able to move on.
        at_tip = bool(np.linalg.norm(path[0] - self.model.fk(np.asarray(q_start, dtype=float))[0]) < 1e-6)
        self.box.check(path, first=int(at_tip))
        axes = self.path_axes(len(path), q_start, axes_xyz)
        if axes is None:
            traj = plan_tip_path(self.model, path, np.asarray(q_start, dtype=float), self._limits(speed_mps),
                                 step_m or self.cfg.waypoint_step_m, self.ik, self.cfg.max_joint_step_rad)
        else:
            traj = plan_tip_path(self.model, path, np.asarray(q_start, dtype=float), self._limits(speed_mps),
                                 step_m or self.cfg.waypoint_step_m, self.ik, self.cfg.max_joint_step_rad,
                                 axes_xyz=axes, max_step_rad=step_rad or MAX_AXIS_STEP_RAD)
        self.box.check(traj.tip_xyz[1:], slack_m=self.ik.tol_m)
        if axes is not None:  # a vertical finger's wrist is ≥ tip_offset_m above its tip, over the table
            self._check_wrist(traj)
        return traj

    def _check_wrist(self, traj: TimedTrajectory) -> None:
        """Raise TrajectoryError where the wrist's cylinders (``wrist_bands_m``, tactile_common.wrist) of a
        waypoint reach below the table + ``table_margin_m``: a tilted finger turns the wrist low."""
        tips, axes = zip(*((p, R[:, 2]) for p, R in (self.model.fk(q) for q in traj.positions_rad)))
        low = wrist_lowest_z_m(np.array(tips), np.array(axes), self.wrist_bands_m, self.cfg.tip_offset_m)
        floor = self.cfg.table_z_m + self.cfg.table_margin_m
        k = int(np.argmin(low))
        if low[k] < floor - 1e-9:
            raise TrajectoryError(f"the wrist would reach z = {low[k]:.3f} m at waypoint {k + 1}/{len(low)}, "
                                  f"below the table + margin ({floor:.3f} m)")

    def reorient(self, q_start: np.ndarray, axis_xyz: np.ndarray, step_rad: Optional[float] = None) -> TimedTrajectory:
        """The finger turned in place about the tip centre, from its axis at ``q_start`` to ``axis_xyz``
        (world; normalised): a tip path of the current tip point with that axis, the axis along the great
        circle in steps ≤ ``step_rad`` (default ``MAX_AXIS_STEP_RAD``). Every waypoint's tip is within
        ``ik_tol_m`` of the start tip; the end axis within ``max_tilt_rad`` of ``axis_xyz`` (a quarter
        step where the IK gets there). The joint limits set the time (the tip does not travel).

        Raises:
            TrajectoryError: the axis is not a finite non-zero 3-vector, or IK failed on the way.
            OutsideWorkspace: the tip is outside the box by more than ``ik_tol_m``.
        """
        q0 = np.asarray(q_start, dtype=float)
        axis = unit_axes(axis_xyz, 1)  # (1, 3); TrajectoryError when not a finite non-zero 3-vector
        tip = self.model.fk(q0)[0]
        return self.tip_path(tip[None], q0, axes_xyz=axis, step_rad=step_rad)

    def approach_depth_m(self, start_xyz: np.ndarray, direction_xyz: np.ndarray, depth_m: float,
                         min_depth_m: float = 0.0) -> float:
        """The depth of a guarded approach from ``start_xyz`` along ``direction_xyz``: ``depth_m``, or
        less so that it ends ``APPROACH_BOX_INSET_M`` inside the safety box (the IK waypoints then
        stay in it too).

        Raises:
            OutsideWorkspace: the shortened approach is below ``min_depth_m`` (the touch's shortest
                useful approach, ``TouchGeometry.min_approach_m``); it names the point ``min_depth_m``
                along the approach, outside the box.
        """
        d = np.asarray(direction_xyz, dtype=float)
        d = d / np.linalg.norm(d)
        depth = self.box.approach_depth_m(self.into_box(start_xyz), d, depth_m)
        if depth < min_depth_m:
            raise OutsideWorkspace(0, np.asarray(start_xyz, dtype=float) + min_depth_m * d, self.box.lower_xyz,
                                   self.box.upper_xyz)
        return depth

    def into_box(self, xyz: np.ndarray) -> np.ndarray:
        """``xyz`` moved onto the box's nearest face when it lies outside by at most the IK's accuracy
        (``ik_tol_m``: where IK put a point planned on a face, e.g. a pre-touch point at the lowest tip
        height, which is the box floor); otherwise unchanged. An approach starts from here."""
        p = np.asarray(xyz, dtype=float)
        inside = np.clip(p, self.box.lower_xyz, self.box.upper_xyz)
        return inside if np.linalg.norm(p - inside) <= self.ik.tol_m else p

    def retrace(self, traj: TimedTrajectory, q_start: np.ndarray, to_index: int,
                speed_mps: Optional[float] = None) -> TimedTrajectory:
        """Back along the waypoints of a planned ``traj`` in joint space: from ``q_start`` to the waypoint
        of index ≥ ``to_index`` nearest it (joint distance), then through the waypoints in reverse down
        to ``to_index``, rest to rest at up to ``speed_mps`` (default the tip speed). The joints the plan
        went through, so the same IK branch, no new IK: a tilted finger's way back to where it turned
        (turning it back by IK near vertical, the wrist's singular pose, broke the joint-step limit).
        Every tip waypoint is box-checked. Raises OutsideWorkspace, TrajectoryError."""
        qs = np.asarray(traj.positions_rad, dtype=float)
        q0 = np.asarray(q_start, dtype=float)
        if not 0 <= to_index < len(qs):
            raise TrajectoryError(f"retrace to waypoint {to_index} of a plan of {len(qs)}")
        j = to_index + int(np.argmin(np.linalg.norm(qs[to_index:] - q0, axis=1)))
        back = np.vstack([q0[None], qs[to_index: j + 1][::-1]])
        fk = [self.model.fk(q) for q in back]
        tip = np.array([p for p, _ in fk])
        self.box.check(tip[1:], slack_m=self.ik.tol_m)
        axes = np.array([R[:, 2] for _, R in fk])  # timed as the way in: the turn by the flange's arc
        return time_parameterize(back, tip, self._limits(speed_mps), axes, self.model.tip_offset_m)

    def joint_move(self, q_start: np.ndarray, q_goal: np.ndarray, speed_mps: float, step_m: float) -> TimedTrajectory:
        """A joint-space straight line ``q_start`` → ``q_goal`` (exactly) in equal joint steps, as many as
        the tip's straight-line span needs at ``step_m`` (the tip's own steps then vary a few per cent
        around it on a curved joint-space path), rest to rest within the joint limits and ``speed_mps``
        at the tip. Every tip waypoint is box-checked. Raises OutsideWorkspace."""
        q0, q1 = np.asarray(q_start, dtype=float), np.asarray(q_goal, dtype=float)
        span_m = float(np.linalg.norm(self.model.fk(q1)[0] - self.model.fk(q0)[0]))
        n = max(2, int(np.ceil(span_m / step_m - 1e-9)) + 1)  # robust at whole multiples (see densify)
        qs = q0 + (q1 - q0) * np.linspace(0.0, 1.0, n)[:, None]
        qs[-1] = q1  # exactly
        tip = np.array([self.model.fk(q)[0] for q in qs])
        self.box.check(tip[1:])
        return time_parameterize(qs, tip, self._limits(speed_mps))


def turn_start_index(traj: TimedTrajectory, vertical_tol_rad: float) -> Optional[int]:
    """The waypoint of a planned path where its finger starts to turn away from vertical (the last one
    whose target axis is within ``vertical_tol_rad`` of +z, before the tilted ones); None when the plan
    has no axes or ends vertical."""
    axes = traj.meta.get("axes_xyz")
    if axes is None or not len(axes):
        return None
    vertical = np.arccos(np.clip(np.asarray(axes, dtype=float)[:, 2], -1.0, 1.0)) <= vertical_tol_rad
    if vertical[-1] or not vertical.any():
        return None
    return int(np.flatnonzero(vertical)[-1])


def path_point_before(traj: TimedTrajectory, start_s: float, contact_s: float,
                      clearance_m: float) -> Optional[np.ndarray]:
    """Joints of the last waypoint of ``traj`` (started at ``start_s``) at least ``clearance_m`` of tip
    travel before where the tip was at ``contact_s``; the path's first waypoint when the contact came
    sooner (the arm was there, in free space, when the path began). None for a path of one point.

    Always a waypoint of the plan, never a point that depends on where the arm stopped: the touch
    then ends on the same joints on every run (before, a contact within ``clearance_m`` of the path's
    start backed off straight from the stopped tip, so the next touch started from joints that
    depended on the stopping latency, and graph runs of one seed parted there)."""
    if len(traj.times_s) < 2:
        return None
    travelled = waypoint_travel_m(traj)
    ok = np.flatnonzero(travelled <= tip_travel_at(traj, start_s, contact_s) - clearance_m)
    return np.array(traj.positions_rad[ok[-1] if len(ok) else 0], dtype=float)


def waypoint_travel_m(traj: TimedTrajectory) -> np.ndarray:
    """(K,) tip path length from the start of ``traj`` to each of its waypoints (m)."""
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(traj.tip_xyz, axis=0), axis=1))])


def tip_travel_at(traj: TimedTrajectory, start_s: float, t_s: float) -> float:
    """Tip path length of ``traj`` (started at ``start_s``) done by ``t_s`` (m; linear between waypoints)."""
    return float(np.interp(t_s - start_s, traj.times_s, waypoint_travel_m(traj)))


def timed_start_ns(now_ns: int, lead_s: float, grid_s: float) -> int:
    """Start time of a trajectory sent at ``now_ns`` (0: on receipt, the ros2_control default).

    With ``lead_s`` > 0 the controller starts it ``lead_s`` later, on the next multiple of ``grid_s``
    (the simulated rig's tick): the rig then samples every motion at the same offsets from its start.
    """
    if lead_s <= 0:
        return 0
    t_ns = int(now_ns) + int(round(lead_s * 1e9))
    grid_ns = int(round(grid_s * 1e9))
    return -(-t_ns // grid_ns) * grid_ns if grid_ns > 0 else t_ns
