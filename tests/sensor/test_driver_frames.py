"""The driver's per-frame contact stream (what a slide's servo reads), without ROS: every frame in
contact in the world frame with the pose at its time, a release at the frame the contact ends, in
frame order, waiting for late poses; the wall's geometry is the check."""

import numpy as np
from sensor_shapes import Plane

from tactile_driver.driver import DriverConfig, SensorDriver
from tactile_driver.protocol import encode_frame
from tactile_driver.taxels import ring_layout
from tactile_sim.sensor_model import SensorModel


def _stream(tips, t0_s=10.0):
    layout = ring_layout()
    model = SensorModel(layout, seed=0)
    wall = Plane([0.51, 0.0, 0.0], [-1.0, 0.0, 0.0], dim=2)
    rng = np.random.default_rng(0)
    frames = [encode_frame(k, int((t0_s + 0.005 * k) * 1e6), model.frame(wall, tip, np.eye(3), rng))
              for k, tip in enumerate(tips)]
    return layout, frames


# free (calibration), press onto the wall at x = 0.51, slide along it (+y), lift off
TIPS = ([[0.45, 0.0, 0.06]] * 40 + [[x, 0.0, 0.06] for x in np.linspace(0.499, 0.5005, 20)]
        + [[0.5005, y, 0.06] for y in np.linspace(0.0, 0.02, 40)] + [[0.49, 0.02, 0.06]] * 5)


def _run(lag_frames):
    layout, frames = _stream(TIPS)
    drv = SensorDriver(layout, config=DriverConfig(device_clock_is_ros_time=True, pose_wait_s=0.2))
    out = []
    for k, f in enumerate(frames):
        t = 10.0 + 0.005 * k
        j = k - lag_frames  # the pose of frame j arrives now
        if j >= 0:
            drv.add_pose(10.0 + 0.005 * j, TIPS[j], [0, 0, 0, 1])
            out += drv.take_frame_contacts()
        out += drv.feed(f, t + 0.001).frame_contacts
    for j in range(max(len(frames) - lag_frames, 0), len(frames)):
        drv.add_pose(10.0 + 0.005 * j, TIPS[j], [0, 0, 0, 1])
        out += drv.take_frame_contacts()
    return drv, out


def test_every_frame_in_contact_then_a_release_in_frame_order():
    for lag in (0, 6):  # poses on time, and 30 ms late
        drv, out = _run(lag)
        stamps = [s for s, _ in out]
        assert stamps == sorted(stamps) and len(set(stamps)) == len(stamps)
        contacts = [c for _, c in out if c is not None]
        assert out[-1][1] is None and sum(c is None for _, c in out) == 1  # one release, the last
        assert len(contacts) > 40  # the press and the whole slide, frame by frame
        P = np.array([c.point_xyz for c in contacts])
        assert np.abs(P[:, 0] - 0.51).max() < 0.001  # on the wall
        assert P[-1, 1] > 0.015 and np.all(np.diff(P[10:, 1]) > -0.001)  # along the slide, in order
        N = np.array([c.normal_xyz for c in contacts])
        assert np.min(N[:, 0] * -1.0) > np.cos(np.radians(5))
        assert drv.stats.dropped_frame_contacts == 0


def test_a_frame_whose_pose_never_comes_is_dropped_and_does_not_hold_the_stream():
    layout, frames = _stream(TIPS)
    drv = SensorDriver(layout, config=DriverConfig(device_clock_is_ros_time=True, pose_wait_s=0.05))
    out = []
    for k, f in enumerate(frames):
        out += drv.feed(f, 10.0 + 0.005 * k + 0.001).frame_contacts  # no pose at all
    assert [c for _, c in out if c is not None] == [] and drv.stats.dropped_frame_contacts > 0
    assert np.isfinite(drv.decided_through_s)
