"""The graph's poke on the simulated rig, run in one process (ROS-free): what the offline loop senses.

A graph run senses through ``sim_rig`` (the emulated joint_trajectory_controller,
the simulated sensor device), ``tactile_sensor`` (the driver core) and
``arm_commander`` (the touch's motion plans). :class:`RigFinger` runs the same
objects in the same order without processes or wall-clock timing, so that the
offline loop makes the graph's observations (docs/exploration.md, "Determinism"):

1. The commander's plans (:class:`~tactile_driver.arm_motions.ArmMotions`): the
   start-up move from the rig's home joints, then per touch the free-space path
   (goal and path as the planner node encodes them: the approach direction is
   the x-axis of the goal's quaternion), the guarded approach re-planned from the
   path's end joints, and the back-off along a path that met the object. An
   infeasible touch is ``unreachable`` (nothing moves), as on the graph; an
   approach refused when re-planned from the path's end is ``aborted`` (the arm
   stays there and the loop re-plans from it, as the explorer re-issues it).
2. The rig's sampling: each motion starts on the 10 ms tick grid (the graph's
   timed starts); per tick the controller's joints (the trajectory's times
   rounded to the nanosecond, as a JointTrajectory carries them), the
   fingertip at their forward kinematics, then the sensor frames due at 200 Hz
   (two per tick, both at the tick's pose) with the device's noise keyed on
   (seed, motion, frame within the motion) (:meth:`SimulatedSensorDevice.frame_values`).
3. The driver core (:class:`~tactile_driver.driver.SensorDriver`): the frames
   through the sensor protocol, the fingertip poses at the joint states' stamps,
   the contact onset in the world frame with the pose interpolated at the frame.
   An approach that reaches its depth counts the frames of ``contact_latency_s``
   at rest there (the commander's rule); a path counts its frames to its end.

What differs from the graph: absolute times (the graph's motions start later,
after planning in simulated time), which change the controller's joints in the
last bits only; the frames after a contact (the graph presses on until the stop
arrives, dwells and retracts; here the detector is released at the retract's
end), which a poke never observes. Slides use :class:`~tactile_bringup.sensing.SimulatedFinger`.
World frame, metres, seconds.
"""

from __future__ import annotations

from dataclasses import fields, replace
from typing import Any, Optional

import numpy as np

from tactile_common.finger_axis import TiltedTail, axes_from_quaternions, finger_frame, tilted_tail
from tactile_common.rotations import matrix_to_quaternion, quaternion_to_matrix
from tactile_common.slide_goal import decode_path
from tactile_common.stamps import duration_from_s, ns_from_s, stamp_s, time_from_ns
from tactile_common.touch_geometry import TouchGeometry, back_off_target
from tactile_driver.arm_motions import ArmMotions, path_point_before, tip_travel_at, turn_start_index
from tactile_driver.commander_api import CommanderConfig
from tactile_driver.contact import ContactConfig
from tactile_driver.driver import DriverConfig, SensorDriver, WorldContact
from tactile_driver.ik import tilt_of
from tactile_driver.kinematics import ArmModel, home_configuration
from tactile_driver.protocol import encode_frame
from tactile_driver.safety import OutsideWorkspace
from tactile_driver.trajectory import TimedTrajectory, TrajectoryError
from tactile_planner.pose import approach_rotation, quaternion_xyzw
from tactile_sim.controller import TrajectoryController
from tactile_sim.sdf_object import Prism
from tactile_sim.sensor_device import SimulatedSensorDevice, motion_key
from tactile_sim.sensor_model import SensorModelConfig

from .poke_result import PokeResult
from .sensing import layout_for

TICK_NS = 10_000_000  # the rig's tick (sim_rig rate_hz 100)


class RigError(RuntimeError):
    """The simulated rig cannot go on (the run stops with this reason)."""


def _from_params(cls, params: dict, prefix: str = ""):
    return cls(**{f.name: params[prefix + f.name] for f in fields(cls) if prefix + f.name in params})


class RigFinger:
    """The simulated rig, sensor driver and commander plans of one experiment (module docstring)."""

    def __init__(self, experiment: Any, obj: Any) -> None:
        arm, sim, sensor = experiment.arm_params, experiment.sim_params, experiment.sensor_params
        cfg = _from_params(CommanderConfig, arm)
        self.motions = ArmMotions(cfg)
        self.cfg = cfg
        self.geometry = TouchGeometry(float(arm.get("tip_radius_m", cfg.tip_radius_m)),
                                      float(arm.get("standoff_m", 0.01)), float(arm.get("max_depth_m", 0.02)))
        self.back_off_clearance_m = self.geometry.standoff_m
        # The rig: its own arm model and home joints, the physical (3D) object, the sensor device.
        rig_model = ArmModel(str(sim.get("urdf_path", "")), list(sim.get("joint_names", cfg.joint_names)),
                             str(sim.get("flange_frame", cfg.flange_frame)), float(sim.get("tip_offset_m", 0.16)))
        self.rig_model = rig_model
        q0 = home_configuration(rig_model, sim.get("home_rad", list(cfg.home_rad)))
        self.controller = TrajectoryController(rig_model.joint_names, q0)
        if abs(float(sim.get("rate_hz", 100.0)) - 1e9 / TICK_NS) > 1e-9:
            raise ValueError("the offline rig samples at the graph's 100 Hz tick (sim_rig rate_hz)")
        self.frame_rate_hz = float(sim.get("sensor_frame_rate_hz", 200.0))
        if abs(self.frame_rate_hz * TICK_NS * 1e-9 - round(self.frame_rate_hz * TICK_NS * 1e-9)) > 1e-9:
            raise ValueError("sensor_frame_rate_hz must give a whole number of frames per 10 ms tick")
        self.frames_per_tick = int(round(self.frame_rate_hz * TICK_NS * 1e-9))
        physical = Prism(obj, float(sim.get("prism_height_m", 0.12))) if obj.dim == 2 else obj
        layout = layout_for(experiment.mode, {"layout_file": sim["sensor_layout"]} if sim.get("sensor_layout")
                            else sensor)
        model_cfg = _from_params(SensorModelConfig, {k[len("model."):]: v for k, v in sim.items()
                                                     if k.startswith("model.")})
        self.device = SimulatedSensorDevice(physical, layout, "/nonexistent/offline_rig", self.frame_rate_hz,
                                            int(sim.get("sensor_seed", experiment.seed)), model_config=model_cfg)
        self.driver = SensorDriver(layout, _from_params(ContactConfig, sensor, "contact."), DriverConfig(
            max_frame_age_s=5.0, pose_wait_s=5.0, device_clock_is_ros_time=True))
        self.contact_latency_s = float(cfg.contact_latency_s)
        self.t_ns = 0  # simulated time (the rig's clock)
        self._t0_s = TICK_NS * 1e-9  # the device's first frame: the first tick
        self._calibrate()
        self.q = q0
        self.q = self._move_to_start(np.asarray(arm.get("start_tip_xyz_m", experiment.start_tip_xyz), dtype=float),
                                     float(arm.get("start_clearance_z_m", 0.25)))

    # -- the rig ---------------------------------------------------------------
    def _frame_k(self, t_ns: int) -> int:
        return int(round((t_ns - TICK_NS) * 1e-9 * self.frame_rate_hz))

    def _tick(self, t_ns: int) -> list[WorldContact]:
        """One rig tick at ``t_ns``: joints, fingertip pose to the driver, the frames due; the onsets."""
        t_s = stamp_s(time_from_ns(t_ns))
        q = self.controller.state(t_s)[0]
        p, R = self.rig_model.fk(q)
        contacts = self.driver.add_pose(t_s, p, matrix_to_quaternion(R)) or []
        clean = self.device.model.clean_counts(self.device.obj, p, R)
        k_last = self._frame_k(t_ns)
        data = b""
        for k in range(k_last - self.frames_per_tick + 1, k_last + 1):
            if k < 0:
                continue
            t_k = self._t0_s + k / self.frame_rate_hz
            data += encode_frame(k, int(round(t_k * 1e6)), self.device.frame_values(k, t_k, clean))
        contacts += self.driver.feed(data, t_s).contacts
        self.driver.take_frame_contacts()  # the slide servo's stream: nobody reads it in a poke
        return contacts

    def _calibrate(self) -> None:
        """The driver's baseline from the idle frames at the home pose (the first ticks)."""
        while not self.driver.detector.calibrated:
            self.t_ns += TICK_NS
            self._tick(self.t_ns)

    def _run(self, traj: TimedTrajectory, settle_s: float = 0.0) -> tuple[Optional[WorldContact], float]:
        """Send ``traj`` with a timed start on the next tick and sample it to its end (+ ``settle_s`` at
        rest there); stops at the first contact onset. Returns (the onset or None, its start time, s)."""
        start_ns = self.t_ns + 2 * TICK_NS
        start_s = stamp_s(time_from_ns(start_ns))
        times = np.array([stamp_s(duration_from_s(float(t))) for t in traj.times_s])
        self.controller.command(stamp_s(time_from_ns(self.t_ns)), self.rig_model.joint_names, times,
                                traj.positions_rad, traj.velocities_rad_s, start_s)
        self.device.begin_motion(motion_key(traj.positions_rad), start_s)
        end_ns = start_ns + ns_from_s(float(times[-1]) + settle_s)
        t_ns = self.t_ns
        while t_ns < end_ns:
            t_ns += TICK_NS
            hits = self._tick(t_ns)
            if hits:
                self.t_ns = t_ns
                return hits[0], start_s
        self.t_ns = t_ns
        return None, start_s

    def _release(self, q: np.ndarray, max_ticks: int = 100) -> None:
        """The arm is back at ``q`` (after the retract or back-off): hold it there and tick until the
        detector has released, at most ``max_ticks``. A touch can end with the skin still loaded (a
        pre-touch point that the object reaches, an estimate that was off): the detector then stays
        in contact and the next motion's frames release it, as on the graph."""
        now = stamp_s(time_from_ns(self.t_ns))
        self.controller.command(now, self.rig_model.joint_names, np.array([0.0]), np.asarray(q)[None],
                                np.zeros((1, len(q))), now)
        for _ in range(max_ticks):
            self.t_ns += TICK_NS
            self._tick(self.t_ns)
            if not self.driver.detector.in_contact:
                return

    def _move_to_start(self, start_xyz: np.ndarray, clearance_z_m: float) -> np.ndarray:
        """The commander's start-up move (tactile_driver.startup_move): up, across, down to the start."""
        here = self.motions.model.fk(self.q)[0]
        z = max(here[2], clearance_z_m, start_xyz[2])
        path = np.array([[here[0], here[1], z], [start_xyz[0], start_xyz[1], z], start_xyz])
        traj = self.motions.tip_path(path, self.q)
        self._run(traj)
        return np.array(traj.positions_rad[-1], dtype=float)

    # -- one poke ----------------------------------------------------------------
    def poke(self, plan: Any, tip_xyz: Optional[np.ndarray] = None, touch_index: int = 0) -> PokeResult:
        """The touch the commander makes of a planner decision (module docstring). The arm starts from
        its joints (where the last touch ended, ``tip_xyz``); the noise keys follow the motions, so
        ``touch_index`` is not needed (the model finger's signature). A tilted touch ends with the finger
        back at its entry point, vertical (tactile_common.finger_axis), as the commander ends it."""
        result, tail = self._poke(plan)
        if tail is None or result.outcome == "unreachable":
            return result
        return self._untilt(result, tail)

    def _path_axes(self, plan: Any, path: np.ndarray):
        """The finger axes of ``path`` (the plan's path and its pre-touch point) as the commander decodes
        them from the planner node's path poses, and the tilted tail (None, None: a vertical finger)."""
        plan_axes = np.asarray(getattr(plan, "path_axes_xyz", np.zeros((0, 3))), dtype=float).reshape(-1, 3)
        if not len(plan_axes):
            return None, None
        approach = -np.asarray(plan.normal_xyz, dtype=float)
        sent = np.array([quaternion_xyzw(finger_frame(approach, a)) for a in plan_axes])
        axes = axes_from_quaternions(sent)
        axes = np.vstack([axes, axes[-1:]])  # the pre-touch point appended to the path
        return axes, tilted_tail(path, axes, self.cfg.max_tilt_rad)

    def _untilt(self, result: PokeResult, tail: TiltedTail) -> PokeResult:
        """Back along the finger's axis to the entry point and turn it vertical there: the path's plan
        retraced (the commander's end of a tilted touch, :meth:`ArmMotions.retrace`); the result's end and
        the extra travel and time (``untilt_m``, ``untilt_s``)."""
        m = self.motions
        here, R = m.model.fk(self.q)
        if tilt_of(R) <= self.cfg.max_tilt_rad:
            return result  # backed off the path before the finger turned: it is vertical
        try:
            k0 = turn_start_index(self._path_traj, self.cfg.max_tilt_rad)
            if k0 is None:
                raise TrajectoryError("the path's plan has no vertical waypoint before its tilted tail")
            traj = m.retrace(self._path_traj, self.q, k0)
        except (OutsideWorkspace, TrajectoryError) as exc:
            raise RigError(f"the tilted finger cannot go back to its entry point and turn vertical: {exc}") from None
        self._run(traj)
        self.q = np.array(traj.positions_rad[-1], dtype=float)
        self._release(self.q)
        return replace(result, end_xyz=np.array(tail.entry_xyz, dtype=float),  # nominal, as the commander reports
                       untilt_m=float(np.linalg.norm(tail.entry_xyz - here)), untilt_s=float(traj.times_s[-1]))

    def _poke(self, plan: Any):
        """:meth:`poke` up to the tilted finger's way back: (the result, the tilted tail or None)."""
        nan3 = np.full(3, np.nan)
        rotation = quaternion_to_matrix(quaternion_xyzw(approach_rotation(plan.normal_xyz)))  # goal, as sent
        pretouch = np.asarray(plan.pretouch_xyz, dtype=float)
        direction = rotation[:, 0]
        free = decode_path(np.asarray(plan.path_xyz, dtype=float), pretouch).free_path_xyz
        path = np.vstack([free.reshape(-1, 3), pretouch[None]])
        depth_m = self.geometry.approach_length_m
        cfg, m = self.cfg, self.motions
        axes, tail = self._path_axes(plan, path)
        try:  # the whole touch is planned before anything moves (tactile_driver.touch_executor)
            to_goal = self._path_traj = m.tip_path(path, self.q, axes_xyz=axes)
            depth_m = m.approach_depth_m(pretouch, direction, depth_m, self.geometry.min_approach_m)
            m.tip_path(pretouch + depth_m * direction, to_goal.positions_rad[-1], cfg.approach_speed_mps,
                       cfg.approach_step_m)
        except (OutsideWorkspace, TrajectoryError) as exc:
            return PokeResult("unreachable", nan3, nan3, 0.0, None, pretouch, None, 0.0, reason=str(exc)), tail
        hit, path_start_s = self._run(to_goal)
        if hit is not None:
            return self._path_contact(hit, to_goal, path_start_s), tail
        q_origin = np.array(to_goal.positions_rad[-1], dtype=float)
        origin = m.model.fk(q_origin)[0]
        n = np.linalg.norm(direction)
        try:  # planned again from where IK put the path's end, as ArmCommander.approach
            depth_m = m.approach_depth_m(origin, direction, self.geometry.approach_length_m)
            approach = m.tip_path(m.into_box(origin) + direction / n * depth_m, q_origin, cfg.approach_speed_mps,
                                  cfg.approach_step_m)
        except (OutsideWorkspace, TrajectoryError) as exc:  # the commander's touch ends 'aborted' there
            self.q = q_origin
            return PokeResult("aborted", nan3, nan3, 0.0, None, origin, None, 0.0, reason=f"approach: {exc}"), tail
        hit, _ = self._run(approach, settle_s=self.contact_latency_s)
        travel = float(np.linalg.norm(self._tip_at(hit.stamp_s) - origin)) if hit is not None else 0.0
        self._release(q_origin)
        self.q = q_origin
        if hit is not None:
            return PokeResult("contact", np.asarray(hit.point_xyz, float), np.asarray(hit.normal_xyz, float),
                              float(hit.force_n), None, pretouch, None, travel), tail
        end = m.model.fk(approach.positions_rad[-1])[0]
        sweep = m.model.fk(approach.positions_rad[0])[0] - end
        return PokeResult("free_space", end, nan3, 0.0, sweep, pretouch, None, float(np.linalg.norm(sweep))), tail

    def _tip_at(self, t_s: float) -> np.ndarray:
        """The tip at ``t_s`` of the motion under way (forward kinematics of the controller's joints)."""
        return self.rig_model.fk(self.controller.state(t_s)[0])[0]

    def _path_contact(self, hit: WorldContact, path: TimedTrajectory, start_s: float) -> PokeResult:
        """The path met the object: back off along it to a waypoint before the contact (the commander's
        back_off; only the joints it ends on matter here)."""
        cfg, m = self.cfg, self.motions
        contact_s = ns_from_s(hit.stamp_s) * 1e-9
        q_stop = self.controller.state(stamp_s(time_from_ns(self.t_ns)))[0]
        tip_stop = m.model.fk(q_stop)[0]
        q_back = path_point_before(path, start_s, contact_s, self.back_off_clearance_m)
        followed = tip_travel_at(path, start_s, contact_s)
        if q_back is None:  # a one-point path: straight away from the contact, as the commander does
            target = back_off_target(hit.point_xyz, tip_stop, cfg.tip_radius_m + self.back_off_clearance_m)
            try:
                q_back = q_stop if target is None else np.array(m.tip_path(
                    target[None], q_stop, cfg.approach_speed_mps, cfg.approach_step_m).positions_rad[-1])
            except (OutsideWorkspace, TrajectoryError):
                q_back = q_stop  # the commander's back-off is refused there: the arm stays
        self._release(q_back)
        self.q = q_back
        end = m.model.fk(q_back)[0]
        return PokeResult("contact", np.asarray(hit.point_xyz, float), np.asarray(hit.normal_xyz, float),
                          float(hit.force_n), None, end, followed, 0.0, float(np.linalg.norm(end - tip_stop)))
