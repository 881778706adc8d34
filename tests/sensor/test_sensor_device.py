"""Simulated sensor device on a pty: frames at the simulated rate, faults, reconnect."""

import os

import numpy as np
import pytest
import serial
from sensor_shapes import Sphere

from tactile_driver.protocol import FrameDecoder
from tactile_driver.taxels import hemisphere_layout
from tactile_sim.sensor_device import FaultConfig, SimulatedSensorDevice

LAYOUT = hemisphere_layout()
BALL = Sphere([0.5, 0.0, 0.03], 0.03)


def read_all(port):
    out = b""
    while True:
        chunk = port.read(65536)
        if not chunk:
            return out
        out += chunk


def test_frames_follow_simulated_time_and_pose(tmp_path):
    link = tmp_path / "tactile0"
    dev = SimulatedSensorDevice(BALL, LAYOUT, link, frame_rate_hz=200.0, seed=1)
    dev.open()
    try:
        port = serial.Serial(str(link), 921600, timeout=0)
        dev.set_pose([0.5, 0.0, 0.2], np.eye(3))
        assert dev.step(10.0) == 1  # first frame at t0
        dec = FrameDecoder()
        frames = dec.feed(read_all(port))
        for t in np.arange(10.05, 10.5001, 0.05):  # 0.5 s at 200 Hz, however fast the caller runs
            assert dev.step(t) == 10
            frames += dec.feed(read_all(port))
        assert [f.seq for f in frames] == list(range(101))
        assert frames[-1].timestamp_us == 10_500_000
        free = frames[-1].values.astype(float)
        dev.set_pose([0.5, 0.0, 0.0695], np.eye(3))  # 0.5 mm into the ball's top
        dev.step(10.6)
        pressed = dec.feed(read_all(port))[-1].values.astype(float)
        bottom = np.argmin(LAYOUT.positions_m[:, 2])
        assert pressed[bottom] - free[bottom] > 100
        port.close()
    finally:
        dev.close()
    assert not link.exists() and not link.is_symlink()


def test_faults_are_injected_and_match_decoder_counts(tmp_path):
    link = tmp_path / "tactile0"
    faults = FaultConfig(garbage_prob=0.1, crc_error_prob=0.1, drop_prob=0.1, stuck_taxel=3, stuck_value=9000)
    dev = SimulatedSensorDevice(BALL, LAYOUT, link, seed=2, faults=faults)
    dev.open()
    try:
        port = serial.Serial(str(link), 921600, timeout=0)
        dec = FrameDecoder()
        frames = []
        for i in range(400):
            dev.step(i * 0.005)
            frames += dec.feed(read_all(port))
        port.close()
    finally:
        dev.close()
    s = dev.stats
    assert s.garbage_bursts > 10 and s.crc_corrupted > 10 and s.frames_dropped > 10
    assert dec.stats.crc_errors >= s.crc_corrupted
    assert len(frames) == s.frames_sent - s.crc_corrupted
    # the decoder counts gaps between frames it saw: lost frames before the first or after the last are invisible
    assert dec.stats.lost_frames == s.frames_dropped + s.crc_corrupted - frames[0].seq - (399 - frames[-1].seq)
    assert all(f.values[3] == 9000 for f in frames)


def test_disconnect_then_new_pty_at_the_same_link(tmp_path):
    link = tmp_path / "tactile0"
    faults = FaultConfig(disconnect_at_s=0.2, disconnect_for_s=0.1)
    dev = SimulatedSensorDevice(BALL, LAYOUT, link, seed=3, faults=faults)
    dev.open()
    first = os.readlink(link)
    try:
        port = serial.Serial(str(link), 921600, timeout=0)
        for i in range(40):
            dev.step(i * 0.005)
            read_all(port)
        dev.step(0.21)
        assert not link.exists()
        with pytest.raises(serial.SerialException):
            read_all(port)
        port.close()
        dev.step(0.31)
        assert link.is_symlink() and dev.stats.reconnects == 1
        port = serial.Serial(str(link), 921600, timeout=0)
        dev.step(0.4)
        frames = FrameDecoder().feed(read_all(port))
        assert len(frames) >= 15 and frames[-1].timestamp_us == 400_000
        port.close()
    finally:
        dev.close()
    assert first  # the old pty's name may be reused by the kernel; only the link matters


def test_stale_link_is_replaced(tmp_path):
    link = tmp_path / "tactile0"
    os.symlink("/nonexistent/tty", link)
    dev = SimulatedSensorDevice(BALL, LAYOUT, link)
    dev.open()
    try:
        assert os.readlink(link).startswith("/dev/pts/")
    finally:
        dev.close()


def test_bad_fault_config_is_a_clear_error(tmp_path):
    with pytest.raises(ValueError, match="probability"):
        SimulatedSensorDevice(BALL, LAYOUT, tmp_path / "x", faults=FaultConfig(drop_prob=2.0))


def test_loaded_frames_draw_noise_keyed_on_the_motion_not_on_the_time_before_it(tmp_path):
    """Two devices that idle for different times before the same motion sense the same frames."""
    a = SimulatedSensorDevice(BALL, LAYOUT, tmp_path / "a", seed=5)
    b = SimulatedSensorDevice(BALL, LAYOUT, tmp_path / "b", seed=5)
    a.begin_motion(1234, start_s=0.50)
    b.begin_motion(1234, start_s=2.75)
    for j in range(5):
        na = a.noise_rng(k=100 + j, t_s=0.50 + j * 0.005, loaded=True).normal(size=8)
        nb = b.noise_rng(k=550 + j, t_s=2.75 + j * 0.005, loaded=True).normal(size=8)
        np.testing.assert_array_equal(na, nb)
    other = a.noise_rng(k=100, t_s=0.50, loaded=True).normal(size=8)
    a.begin_motion(999, start_s=0.50)
    assert not np.array_equal(other, a.noise_rng(k=100, t_s=0.50, loaded=True).normal(size=8))


def test_unloaded_noise_repeats_so_any_calibration_window_gives_the_same_baseline(tmp_path):
    dev = SimulatedSensorDevice(BALL, LAYOUT, tmp_path / "c", seed=1)
    n = 40  # the driver's default calibration_frames, a multiple of the idle period
    assert n % dev.IDLE_NOISE_PERIOD == 0
    clean = dev.model.baseline_counts
    frames = np.array([dev.model.add_noise(clean, dev.noise_rng(k, k * 0.005, loaded=False)) for k in range(200)],
                      dtype=float)
    windows = [frames[s:s + n] for s in (0, 3, 17, 101)]
    for w in windows[1:]:
        np.testing.assert_allclose(w.mean(axis=0), windows[0].mean(axis=0), atol=1e-9)
        np.testing.assert_allclose(w.std(axis=0), windows[0].std(axis=0), atol=1e-9)
    assert (np.diff(frames[:n], axis=0) != 0).mean() > 0.5  # values keep changing: never taken for stuck


def test_a_motion_with_a_timed_start_takes_over_only_at_its_start(tmp_path):
    """Frames before a queued motion's start keep the running motion's keys (never one key repeated)."""
    dev = SimulatedSensorDevice(BALL, LAYOUT, tmp_path / "e", seed=5)
    dev.begin_motion(1, start_s=1.0)
    dev.begin_motion(2, start_s=2.0)  # sent at 1.5 s, starts at 2.0 s
    before = [dev.noise_rng(0, 1.5 + j * 0.005, loaded=True).normal(size=4) for j in range(3)]
    assert not np.array_equal(before[0], before[1])  # still motion 1, frames 100, 101, ...
    np.testing.assert_array_equal(before[0], np.random.default_rng([5, 1, 1, 100]).normal(size=4))
    np.testing.assert_array_equal(dev.noise_rng(0, 2.0, loaded=True).normal(size=4),
                                  np.random.default_rng([5, 1, 2, 0]).normal(size=4))
