"""The touch state machine over a scripted fake commander (no ROS graph): outcomes, order of verbs, reports."""

from types import SimpleNamespace

import numpy as np
import pytest

from tactile_common import fields
from tactile_driver.commander_api import TaskResult
from tactile_driver.safety import EStopLatch, OutsideWorkspace
from tactile_driver.touch_executor import SENSOR_RETRIES, TouchExecutor, TouchRequest
from tactile_driver.trajectory import TimedTrajectory


def _traj(length_m):
    """A motion of ``length_m``; its joint 0 is the fake tip's height above the end (FakeArm.model.fk)."""
    tip = np.array([[0.0, 0.0, 0.0], [length_m, 0.0, 0.0]])
    q = np.zeros((2, 7))
    q[0, 0] = length_m
    return TimedTrajectory(np.array([0.0, 1.0]), q, np.zeros((2, 7)), tip)


class FakeArm:
    """Completes each verb at the next update with a scripted result."""

    def __init__(self, results, plan_error=None):
        self.results = list(results)  # one TaskResult per verb, in order
        self.plan_error = plan_error
        self.calls = []
        self.cfg = SimpleNamespace(dry_run=False, approach_speed_mps=0.02, approach_step_m=0.005,
                                   sensor_confirm_timeout_s=10.0, max_tilt_rad=0.1)
        self.tilt_rad = 0.0  # the finger's tilt now (a test sets it)
        self.paths = []  # (path, axes) of each follow_path
        self.sensor_decided_s = np.inf  # the driver has judged every frame (a test sets it behind)
        self.estop = EStopLatch()
        self.model = SimpleNamespace(fk=lambda q: (np.array([0.4, 0.2, 0.06 + q[0]]), np.eye(3)))
        self.tip_xyz = np.zeros(3)
        self.odometer_m = 0.0
        self.motion_time_s = 0.0  # robot time in motions (each scripted verb takes 0.3 s)
        self.t = 0.0
        self._last = None
        self.approach_origin_q = None  # the joints the last approach began from (retract goes back there)
        self.approach_q_starts = []  # q_start of each approach (None: the measured joints)

    def now_s(self):
        return self.t

    def approach_depth_m(self, start_xyz, direction_xyz, depth_m, min_depth_m=0.0):
        return depth_m  # the box never shortens an approach here

    def plan(self, path, q_start=None, speed_mps=None, step_m=None, axes_xyz=None):
        self.calls.append("plan")
        if self.plan_error:
            raise self.plan_error
        return _traj(0.1)

    def _verb(self, name, length):
        """A result, or (result, contact xyz) for a verb stopped by a contact."""
        self.calls.append(name)
        result, contact, lost = self.results.pop(0), None, False
        if result == "sensor_lost":  # an approach the commander stopped for a silent sensor
            result, lost = TaskResult.ABORTED, True
        if isinstance(result, tuple):
            result, xyz = result
            contact = np.zeros((), dtype=fields.CONTACT_DTYPE)[()]
            contact["x"], contact["y"], contact["z"], contact["label"] = *xyz, fields.LABEL_CONTACT
        if result == TaskResult.REJECTED:
            self._last = SimpleNamespace(result=result, reason="refused", traj=_traj(0.0), contact_stamp_ns=0,
                                         contact=None)
            return False
        self.odometer_m += length
        self.motion_time_s += 0.3
        self._last = SimpleNamespace(result=result, reason=result.name, traj=_traj(length), contact=contact,
                                     sensor_lost=lost,
                                     contact_stamp_ns=42 if contact is not None or result == TaskResult.CONTACT else 0)
        return True

    def follow_path(self, path, axes_xyz=None):
        self.paths.append((np.asarray(path), None if axes_xyz is None else np.asarray(axes_xyz)))
        ok = self._verb("follow_path", 0.3)
        if axes_xyz is not None:  # the plan's waypoints: one per path point here
            self._last.traj.meta["axes_xyz"] = np.asarray(axes_xyz)
        return ok

    def retrace(self, traj, to_index):
        self.retraced = (traj, to_index)
        return self._verb("retrace", 0.3)

    def finger_tilt_rad(self):
        return self.tilt_rad

    def approach(self, direction, depth, q_start=None):
        self.approach_q_starts.append(None if q_start is None else np.array(q_start))
        if q_start is None:
            self.approach_origin_q = np.array([0.1 * len(self.approach_q_starts)] * 7)  # "measured" here
        return self._verb("approach", 0.02)

    def retract(self):
        return self._verb("retract", 0.02)

    def back_off(self, contact_xyz, clearance_m, contact_stamp_ns=None):
        self.back_off_args = (np.asarray(contact_xyz), clearance_m)
        self.back_off_xyz = np.asarray(contact_xyz) + [0.0, 0.0, 0.02]  # where the fake backs off to
        return self._verb("back_off", 0.01)

    def is_task_complete(self):
        return True

    def get_result(self):
        return self._last.result

    @property
    def last_task(self):
        return self._last


def run(arm):
    free, done = [], []
    ex = TouchExecutor(arm, 0.04, 0.5, lambda p, s, sweep: free.append((p, s, sweep)), done.append)
    ex.submit(TouchRequest(7, np.array([0.4, 0.2, 0.06]), np.array([0.0, 1.0, 0.0]), np.zeros((1, 3))))
    for _ in range(10):
        arm.t += 0.3
        ex.update()
    return free, done


def test_contact_touch():
    arm = FakeArm([TaskResult.SUCCEEDED, TaskResult.CONTACT, TaskResult.SUCCEEDED])
    free, done = run(arm)
    assert [c for c in arm.calls if c != "plan"] == ["follow_path", "approach", "retract"]
    assert free == [] and len(done) == 1
    r = done[0]
    assert (r.outcome, r.observation_stamp_ns, r.goal_stamp_ns) == ("contact", 42, 7)
    assert r.travel_m == pytest.approx(0.34)
    assert r.duration_s == pytest.approx(3 * 0.3 + 0.5)  # three motions and the dwell, nothing else
    assert r.end_xyz_m == (0.4, 0.2, 0.06)  # nominal end: the pre-touch point (not the measured pose)


def test_free_space_touch_publishes_the_probe_end():
    arm = FakeArm([TaskResult.SUCCEEDED, TaskResult.SUCCEEDED, TaskResult.SUCCEEDED])
    free, done = run(arm)
    assert len(free) == 1 and done[0].outcome == "free_space"
    np.testing.assert_allclose(free[0][0], [0.4, 0.2, 0.06])
    # the sweep: from the probe end back to the approach's first point (the fake approach: 20 mm)
    np.testing.assert_allclose(free[0][2], [0.0, 0.0, 0.02], atol=1e-12)
    assert done[0].observation_stamp_ns == free[0][1]
    assert done[0].values()["observation_stamp_ns"] == str(free[0][1])


def test_unreachable_touch_moves_nothing():
    err = OutsideWorkspace(0, np.array([0.9, 0.0, 0.1]), np.zeros(3), np.ones(3))
    arm = FakeArm([], plan_error=err)
    free, done = run(arm)
    assert "follow_path" not in arm.calls
    assert done[0].outcome == "unreachable" and done[0].travel_m == 0.0 and "safety box" in done[0].reason
    assert done[0].values()["observation_stamp_ns"] == ""


@pytest.mark.parametrize("results, where", [
    ([TaskResult.ABORTED], "path"),
    ([TaskResult.SUCCEEDED, TaskResult.REJECTED], "approach"),
    ([TaskResult.SUCCEEDED, TaskResult.ABORTED], "approach"),
    ([TaskResult.SUCCEEDED, TaskResult.CONTACT, TaskResult.ABORTED], "retract"),
])
def test_aborts_end_the_touch(results, where):
    arm = FakeArm(results)
    free, done = run(arm)
    assert done[0].outcome == "aborted" and done[0].reason.startswith(where)
    assert len(done) == 1 and arm.results == []


def test_contact_on_the_path_is_kept_and_the_arm_backs_off():
    arm = FakeArm([(TaskResult.ABORTED, [0.45, 0.1, 0.06]), TaskResult.SUCCEEDED])
    free, done = run(arm)
    assert [c for c in arm.calls if c != "plan"] == ["follow_path", "back_off"]  # no approach, no retract
    np.testing.assert_allclose(arm.back_off_args[0], [0.45, 0.1, 0.06])
    assert arm.back_off_args[1] == 0.01  # the clearance (commander: standoff_m)
    r = done[0]
    assert (r.outcome, r.observation_stamp_ns) == ("contact", 42) and r.reason.startswith("path:")
    assert free == [] and r.travel_m == pytest.approx(0.31)
    np.testing.assert_allclose(r.end_xyz_m, [0.45, 0.1, 0.08])  # the next touch is planned from the back-off point


@pytest.mark.parametrize("back_off, where", [(TaskResult.REJECTED, "path"), (TaskResult.ABORTED, "retract")])
def test_a_failed_back_off_aborts(back_off, where):
    arm = FakeArm([(TaskResult.ABORTED, [0.45, 0.1, 0.06]), back_off])
    free, done = run(arm)
    assert done[0].outcome == "aborted" and done[0].reason.startswith(where) and len(done) == 1


def test_estop_during_dwell_skips_the_retract():
    arm = FakeArm([TaskResult.SUCCEEDED, TaskResult.CONTACT])
    free, done = [], []
    ex = TouchExecutor(arm, 0.04, 0.5, lambda p, s, sweep: free.append((p, s, sweep)), done.append)
    ex.submit(TouchRequest(1, np.zeros(3), np.array([1.0, 0, 0]), np.zeros((1, 3))))
    ex.update()  # -> approach
    ex.update()  # contact -> dwell
    arm.estop.set(True)
    arm.t += 1.0
    ex.update()
    assert done[0].outcome == "aborted" and done[0].reason == "e-stop"
    assert "retract" not in arm.calls


def test_an_approach_stopped_for_a_silent_sensor_waits_for_it_retracts_and_approaches_again():
    arm = FakeArm([TaskResult.SUCCEEDED, "sensor_lost", TaskResult.SUCCEEDED, TaskResult.CONTACT,
                   TaskResult.SUCCEEDED])
    free, done = [], []
    ex = TouchExecutor(arm, 0.04, 0.5, lambda p, s, sweep: free.append((p, s, sweep)), done.append)
    ex.submit(TouchRequest(7, np.array([0.4, 0.2, 0.06]), np.array([0.0, 1.0, 0.0]), np.zeros((1, 3))))
    ex.update()  # path -> approach
    arm.sensor_decided_s = arm.t - 1.0  # the driver fell behind
    ex.update()  # approach stopped: wait for the driver
    for _ in range(5):
        arm.t += 0.3
        ex.update()
    assert [c for c in arm.calls if c != "plan"] == ["follow_path", "approach"] and not done  # the arm waits
    arm.sensor_decided_s = arm.t  # the driver judged the frames up to now
    for _ in range(6):
        arm.t += 0.3
        ex.update()
    assert [c for c in arm.calls if c != "plan"] == ["follow_path", "approach", "retract", "approach", "retract"]
    r = done[0]
    assert r.outcome == "contact" and r.observation_stamp_ns == 42 and "repeated" in r.reason
    # the repeat is planned from the joints the first approach began from (where the retract went back to),
    # not from whatever joint state was sampled last: the same motion
    first, repeat = arm.approach_q_starts
    assert first is None and np.array_equal(repeat, np.full(7, 0.1))


def test_a_sensor_that_stays_silent_ends_the_touch_after_a_retract():
    arm = FakeArm([TaskResult.SUCCEEDED, "sensor_lost", TaskResult.SUCCEEDED])
    arm.sensor_decided_s = -np.inf  # the driver never speaks again
    free, done = [], []
    ex = TouchExecutor(arm, 0.04, 0.5, lambda p, s, sweep: free.append(p), done.append)
    ex.submit(TouchRequest(7, np.array([0.4, 0.2, 0.06]), np.array([0.0, 1.0, 0.0]), np.zeros((1, 3))))
    for _ in range(30):  # 9 s of node clock: still waiting
        arm.t += 0.3
        ex.update()
    assert not done and "retract" not in arm.calls
    for _ in range(10):  # past sensor_confirm_timeout_s (10 s): leave the surface, give up
        arm.t += 0.3
        ex.update()
    assert [c for c in arm.calls if c != "plan"] == ["follow_path", "approach", "retract"]
    assert done[0].outcome == "aborted" and "silent" in done[0].reason and free == []


def test_an_approach_stopped_for_the_sensor_again_and_again_ends_the_touch():
    arm = FakeArm([TaskResult.SUCCEEDED] + ["sensor_lost", TaskResult.SUCCEEDED] * SENSOR_RETRIES + ["sensor_lost"])
    free, done = run(arm)
    assert [c for c in arm.calls if c != "plan"].count("approach") == SENSOR_RETRIES + 1
    assert done[0].outcome == "aborted" and done[0].reason.startswith("approach:") and arm.results == []


def _tilted_request():
    from tactile_common.finger_axis import TiltedTail

    a = np.array([0.0, -np.sin(1.0), np.cos(1.0)])
    entry, pre = np.array([0.4, 0.25, 0.09]), np.array([0.4, 0.2, 0.06])
    path = np.array([[0.3, 0.3, 0.2], entry, entry])
    axes = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0], a])
    return TouchRequest(7, pre, np.array([0.0, 1.0, 0.0]), path, path_axes_xyz=axes,
                        tail=TiltedTail(entry, a)), a, entry


def run_tilted(arm, tilt_rad=1.0):
    free, done = [], []
    ex = TouchExecutor(arm, 0.04, 0.5, lambda p, s, sweep: free.append((p, s, sweep)), done.append)
    req, a, entry = _tilted_request()
    arm.tilt_rad = tilt_rad
    ex.submit(req)
    for _ in range(10):
        arm.t += 0.3
        ex.update()
    return done, a, entry


def test_a_tilted_touch_follows_its_axes_and_ends_vertical_at_its_entry_point():
    arm = FakeArm([TaskResult.SUCCEEDED, TaskResult.CONTACT, TaskResult.SUCCEEDED, TaskResult.SUCCEEDED])
    done, a, entry = run_tilted(arm)
    assert [c for c in arm.calls if c != "plan"] == ["follow_path", "approach", "retract", "retrace"]
    [(path, axes)] = arm.paths
    np.testing.assert_array_equal(axes[-1], a)  # the pre-touch point appended with the tail's axis
    assert len(axes) == len(path) == 4
    # back through the path's own waypoints to the last one with the finger vertical (at the entry)
    assert arm.retraced[1] == 1 and arm.retraced[0].meta["axes_xyz"] is not None
    r = done[0]
    assert r.outcome == "contact" and r.end_xyz_m == tuple(entry)  # the next touch starts at the entry
    assert r.travel_m == pytest.approx(0.3 + 0.02 + 0.02 + 0.3) and r.duration_s == pytest.approx(4 * 0.3 + 0.5)


def test_a_tilted_touch_that_could_not_turn_back_says_so():
    arm = FakeArm([TaskResult.SUCCEEDED, TaskResult.CONTACT, TaskResult.SUCCEEDED, TaskResult.ABORTED])
    done, _, _ = run_tilted(arm)
    assert done[0].outcome == "aborted" and "turning the finger back to vertical" in done[0].reason


@pytest.mark.parametrize("results, tilt, moves", [
    ([TaskResult.SUCCEEDED, TaskResult.CONTACT, TaskResult.SUCCEEDED], 0.05, 3),  # already vertical: no turn
    ([TaskResult.ABORTED], 0.0, 1),  # the path stopped before the turn
])
def test_a_vertical_finger_is_not_turned_back(results, tilt, moves):
    arm = FakeArm(results)
    done, _, _ = run_tilted(arm, tilt)
    assert len([c for c in arm.calls if c != "plan"]) == moves and len(done) == 1


def test_an_estop_leaves_a_tilted_finger_where_it_is():
    arm = FakeArm([TaskResult.SUCCEEDED, TaskResult.CONTACT])
    free, done = [], []
    ex = TouchExecutor(arm, 0.04, 0.5, lambda p, s, sweep: free.append((p, s, sweep)), done.append)
    req, _, _ = _tilted_request()
    arm.tilt_rad = 1.0
    ex.submit(req)
    ex.update()
    ex.update()
    arm.estop.set(True)
    arm.t += 1.0
    ex.update()
    assert done[0].reason == "e-stop" and "retrace" not in arm.calls
