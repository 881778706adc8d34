"""Driver helpers without ROS: pose interpolation, device clock, serial reconnect, the pipeline."""

import numpy as np
import pytest
import serial
from sensor_shapes import Plane, rotation_about

from tactile_common.rotations import matrix_to_quaternion as matrix_to_quat
from tactile_common.rotations import quaternion_to_matrix as quat_to_matrix
from tactile_driver.contact import ContactConfig
from tactile_driver.device_clock import DeviceClock
from tactile_driver.driver import DriverConfig, SensorDriver
from tactile_driver.pose_buffer import PoseBuffer
from tactile_driver.protocol import encode_frame
from tactile_driver.serial_link import SerialLink
from tactile_driver.taxels import ring_layout
from tactile_sim.sensor_model import SensorModel


def test_quaternion_round_trip_and_interpolation_against_rodrigues():
    rng = np.random.default_rng(0)
    axis = rng.normal(size=3)
    R0, R1 = rotation_about(axis, 0.2), rotation_about(axis, 0.8)
    np.testing.assert_allclose(quat_to_matrix(matrix_to_quat(R1)), R1, atol=1e-12)
    buf = PoseBuffer(max_age_s=5.0, tolerance_s=0.01, max_gap_s=2.0)  # the math, not the gap rule
    buf.add(1.0, [0.0, 0.0, 0.0], matrix_to_quat(R0))
    buf.add(2.0, [1.0, 2.0, 3.0], matrix_to_quat(R1))
    p, R = buf.at(1.25)
    np.testing.assert_allclose(p, [0.25, 0.5, 0.75], atol=1e-12)
    np.testing.assert_allclose(R, rotation_about(axis, 0.35), atol=1e-9)  # slerp = angle interpolation
    assert buf.at(2.005) is not None and buf.at(2.02) is None and buf.at(0.98) is None


def test_pose_buffer_rejects_out_of_order_and_forgets_old():
    buf = PoseBuffer(max_age_s=1.0)
    assert buf.add(1.0, [0, 0, 0], [0, 0, 0, 1])
    assert not buf.add(0.5, [0, 0, 0], [0, 0, 0, 1])
    assert not buf.add(1.1, [np.nan, 0, 0], [0, 0, 0, 1])
    assert not buf.add(1.2, [0, 0, 0], [0, 0, 0, 0])
    buf.add(3.0, [0, 0, 0], [0, 0, 0, 1])
    assert len(buf) == 1 and buf.rejected == 3


def test_device_clock_offset_is_the_minimum_delay():
    clock = DeviceClock(window_s=2.0)
    rng = np.random.default_rng(1)
    offset = 1000.0
    for k in range(400):
        dev = 0.005 * k
        delay = 0.001 + rng.exponential(0.004)
        host = clock.to_host(dev, dev + offset + delay)
    assert host == pytest.approx(dev + offset + 0.001, abs=0.0015)
    # a device reboot: time goes back, the estimate restarts
    assert clock.to_host(0.0, 5000.0) == pytest.approx(5000.0)
    assert clock.resets == 1


class FakePort:
    """Stands in for serial.Serial: plays chunks, raises when unplugged."""

    def __init__(self, world):
        self.world = world

    def read(self, n):
        if not self.world["plugged"]:
            raise serial.SerialException("read failed: device disconnected")
        return self.world["chunks"].pop(0) if self.world["chunks"] else b""

    def reset_input_buffer(self):
        pass

    def close(self):
        pass


def test_serial_link_reconnects_with_exponential_backoff():
    world = {"plugged": True, "chunks": [b"abc"], "opens": []}

    def opener(port, baud, timeout):
        world["opens"].append(now[0])
        if not world["plugged"]:
            raise serial.SerialException(f"could not open port {port}")
        return FakePort(world)

    now = [0.0]
    link = SerialLink("/dev/fake", 115200, backoff_min_s=0.1, backoff_max_s=0.4, opener=opener)
    assert link.poll(0.0) == b"abc" and link.connected
    world["plugged"] = False
    for t in np.arange(0.01, 2.0, 0.01):
        now[0] = round(float(t), 3)
        assert link.poll(now[0]) == b""
    assert link.disconnects == 1 and not link.connected
    attempts = np.diff(world["opens"][1:])  # delays between failed attempts double up to the maximum
    np.testing.assert_allclose(attempts[:4], [0.1, 0.2, 0.4, 0.4], atol=0.015)  # + poll granularity
    world["plugged"], world["chunks"] = True, [b"xyz"]
    t, got = 2.0, b""
    while not link.connected:
        got += link.poll(t)
        t += 0.01
    assert t < 2.42, "the next attempt comes within the maximum back-off"
    assert link.reconnects == 1 and got == b"xyz"


def test_bad_serial_parameters_are_clear_errors():
    with pytest.raises(ValueError, match="empty"):
        SerialLink("", 9600)
    with pytest.raises(ValueError, match="baud"):
        SerialLink("/dev/x", 0)


def make_stream(model, obj, tips, t0_s=10.0):
    rng = np.random.default_rng(0)
    return [encode_frame(k, int((t0_s + 0.005 * k) * 1e6), model.frame(obj, tip, np.eye(3), rng))
            for k, tip in enumerate(tips)]


def wall_approach():
    """A ring layout, the tips of 40 free frames then a slow approach to a wall at x = 0.51, their frames."""
    layout = ring_layout()
    model = SensorModel(layout, seed=0)
    wall = Plane([0.51, 0.0, 0.0], [-1.0, 0.0, 0.0], dim=2)
    tips = [[0.45, 0.0, 0.06]] * 40 + [[x, 0.0, 0.06] for x in np.linspace(0.499, 0.5006, 40)]
    return layout, tips, make_stream(model, wall, tips)


def test_pipeline_publishes_world_contact_only_with_a_pose():
    layout, tips, frames = wall_approach()
    # no pose at all: the onset is refused, and retried on every later frame
    drv = SensorDriver(layout)
    out = [drv.feed(f, 10.0 + 0.005 * k + 0.001) for k, f in enumerate(frames)]
    assert sum(len(o.contacts) for o in out) == 0 and drv.stats.refused_no_pose > 1
    # with poses: one contact, mapped to the world with the pose at the frame's time
    drv = SensorDriver(layout)
    contacts = []
    for k, (f, tip) in enumerate(zip(frames, tips)):
        t = 10.0 + 0.005 * k
        contacts += drv.add_pose(t, tip, [0, 0, 0, 1]) or []  # a pose completes contacts waiting for it
        contacts += drv.feed(f, t + 0.001).contacts
    assert len(contacts) == 1
    c = contacts[0]
    assert 10.2 < c.stamp_s < 10.4 + 0.001  # an approach frame, stamped with device time + offset
    assert abs(c.point_xyz[0] - 0.51) < 0.001 and abs(c.point_xyz[1]) < 0.001
    np.testing.assert_allclose(c.normal_xyz, [-1.0, 0.0, 0.0], atol=0.03)


def test_pipeline_drops_stale_and_wrong_size_frames():
    layout = ring_layout()
    drv = SensorDriver(layout, config=DriverConfig(max_frame_age_s=0.1))
    ok = encode_frame(0, 1_000_000, np.full(layout.n_taxels, 1000, np.uint16))
    drv.feed(ok, 1.001)
    stale = encode_frame(1, 1_005_000, np.full(layout.n_taxels, 1000, np.uint16))
    wrong = encode_frame(2, 2_000_000, np.full(10, 1000, np.uint16))
    assert drv.feed(stale, 1.5).frames == []
    assert drv.feed(wrong, 2.001).frames == []
    assert drv.stats.stale_frames == 1 and drv.stats.wrong_size_frames == 1 and drv.stats.frames == 1


def test_onset_ahead_of_the_poses_waits_for_its_pose():
    layout = ring_layout()
    model = SensorModel(layout, seed=0)
    wall = Plane([0.51, 0.0, 0.0], [-1.0, 0.0, 0.0], dim=2)
    tips = [[0.45, 0.0, 0.06]] * 40 + [[x, 0.0, 0.06] for x in np.linspace(0.499, 0.5006, 40)]
    frames = make_stream(model, wall, tips)
    drv = SensorDriver(layout, config=DriverConfig(pose_tolerance_s=0.002, pose_wait_s=0.2))
    contacts, lag = [], 8  # poses arrive 8 frames (40 ms) after the frames of the same time
    for k, f in enumerate(frames):
        t = 10.0 + 0.005 * k
        if k >= lag:
            contacts += drv.add_pose(t - 0.005 * lag, tips[k - lag], [0, 0, 0, 1])
        contacts += drv.feed(f, t + 0.001).contacts
    assert len(contacts) == 1 and drv.stats.refused_no_pose == 0
    c = contacts[0]
    k = int(round((c.stamp_s - 10.0) / 0.005))
    assert abs(c.point_xyz[0] - (tips[k][0] + 0.01)) < 0.001  # mapped with the pose of its own time


def test_pose_buffer_does_not_interpolate_across_a_stall():
    buf = PoseBuffer(max_age_s=5.0, tolerance_s=0.01, max_gap_s=0.1)
    buf.add(1.0, [0.0, 0.0, 0.0], [0, 0, 0, 1])
    buf.add(1.5, [0.1, 0.0, 0.0], [0, 0, 0, 1])
    assert buf.at(1.25) is None  # 0.5 s without a pose: nobody knows where the finger was
    np.testing.assert_allclose(buf.at(1.005)[0], [0.0, 0.0, 0.0])  # within tolerance of a pose: that pose
    buf.add(1.55, [0.2, 0.0, 0.0], [0, 0, 0, 1])
    np.testing.assert_allclose(buf.at(1.525)[0], [0.15, 0.0, 0.0])  # a regular bracket interpolates


def test_pending_onset_holds_decided_through_until_its_pose_comes_or_is_passed():
    """A lagging pose stream must not turn a contact into free space: the onset waits (however
    long), holding decided_through before its frame; once poses pass its time without covering it
    (a gap), it is refused and the re-armed detector reports the contact from a frame with a pose."""
    layout = ring_layout()
    model = SensorModel(layout, seed=0)
    wall = Plane([0.51, 0.0, 0.0], [-1.0, 0.0, 0.0], dim=2)
    tips = [[0.45, 0.0, 0.06]] * 40 + [[0.5006, 0.0, 0.06]] * 200
    frames = make_stream(model, wall, tips)
    drv = SensorDriver(layout, config=DriverConfig(pose_wait_s=0.1, pose_tolerance_s=0.002))
    drv.add_pose(10.0, tips[0], [0, 0, 0, 1])  # the pose stream stalls here
    out = [drv.feed(f, 10.0 + 0.005 * k + 0.001) for k, f in enumerate(frames[:120])]
    assert sum(len(o.contacts) for o in out) == 0 and drv.stats.refused_no_pose == 0
    onset_s = 10.0 + 0.005 * 40  # the first frame at the wall
    assert drv.decided_through_s < onset_s + 0.005 * 2  # held at the onset, 0.4 s of frames later
    # the stream resumes at the present: its poses passed the onset without covering it
    contacts = []
    for k in range(120, 240):
        t = 10.0 + 0.005 * k
        contacts += drv.add_pose(t, tips[k], [0, 0, 0, 1]) or []
        contacts += drv.feed(frames[k], t + 0.001).contacts
    assert drv.stats.refused_no_pose == 1 and len(contacts) == 1
    assert contacts[0].stamp_s >= 10.0 + 0.005 * 120 and abs(contacts[0].point_xyz[0] - 0.51) < 0.001
    assert drv.decided_through_s >= 10.0 + 0.005 * 239


def test_frames_queued_during_a_disconnect_are_stale_after_the_reconnect():
    layout = ring_layout()
    drv = SensorDriver(layout, config=DriverConfig(max_frame_age_s=0.1))
    values = np.full(layout.n_taxels, 1000, np.uint16)
    for k in range(50):  # 200 Hz, 1 ms transport delay: offset learnt
        drv.feed(encode_frame(k, int((5.0 + 0.005 * k) * 1e6), values), 5.0 + 0.005 * k + 0.001)
    drv.device_reset()
    # after the reconnect the first bytes are frames written 0.3 s ago
    out = drv.feed(b"".join(encode_frame(100 + j, int((5.5 + 0.005 * j) * 1e6), values) for j in range(5)), 5.82)
    assert out.frames == [] and drv.stats.stale_frames == 5
    out = drv.feed(encode_frame(200, int(5.83 * 1e6), values), 5.831)
    assert len(out.frames) == 1 and out.frames[0][0] == pytest.approx(5.831, abs=1e-6)


def test_a_waiting_contact_is_placed_with_the_pose_at_its_time_not_the_newest_one():
    """An onset newer than every pose waits; a later read must not place it with the newest pose."""
    layout, tips, frames = wall_approach()
    drv = SensorDriver(layout, ContactConfig(skin_stiffness_pa_per_m=0.0))  # the undeformed skin: r ahead
    placed = []
    lag = 3  # poses arrive three frames late
    for k, f in enumerate(frames):
        t = 10.0 + 0.005 * k
        if k >= lag:
            placed += drv.add_pose(10.0 + 0.005 * (k - lag), tips[k - lag], [0, 0, 0, 1]) or []
        placed += drv.feed(f, t + 0.001).contacts  # reads between the late poses
    k_on = int(round((placed[0].stamp_s - 10.0) / 0.005))
    true_tip = np.asarray(tips[k_on])  # the pose at the onset frame's own time
    assert len(placed) == 1
    # one tip radius ahead of the tip at the onset (the newest pose, 3 frames older, put it 80 µm short)
    assert abs((placed[0].point_xyz[0] - true_tip[0]) - 0.01) < 2e-5
