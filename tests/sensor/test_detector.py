"""Contact detector: calibration, hysteresis, dead and stuck taxels, lone spikes."""

import numpy as np
import pytest
from sensor_shapes import Plane

from tactile_driver.contact import ContactConfig, ContactDetector
from tactile_driver.taxels import ring_layout
from tactile_sim.sensor_model import SensorModel

LAYOUT = ring_layout()
WALL = Plane([0.51, 0.0, 0.0], [-1.0, 0.0, 0.0], dim=2)  # wall 1 cm in front of x = 0.5


def calibrated(model, rng, config=ContactConfig()):
    det = ContactDetector(LAYOUT, config)
    for _ in range(config.calibration_frames):
        assert det.update(model.frame(WALL, [0.45, 0.0, 0.06], np.eye(3), rng)) is None
    assert det.calibrated
    return det


def test_onset_only_once_with_hysteresis():
    model, rng = SensorModel(LAYOUT, seed=0), np.random.default_rng(0)
    det = calibrated(model, rng)
    xs = np.r_[np.linspace(0.499, 0.5006, 30), np.linspace(0.5006, 0.499, 30), np.linspace(0.499, 0.5006, 30)]
    onsets = []
    for x in xs:
        if det.update(model.frame(WALL, [x, 0.0, 0.06], np.eye(3), rng)) is not None:
            onsets.append(x)
    assert len(onsets) == 2, "one onset per press"
    forces = [model.force_n(WALL, [x, 0.0, 0.06]) for x in onsets]
    assert all(f >= det.config.on_threshold_n * 0.7 for f in forces)


def test_no_contact_from_noise_in_free_space():
    model, rng = SensorModel(LAYOUT, seed=0), np.random.default_rng(1)
    det = calibrated(model, rng)
    for _ in range(2000):
        assert det.update(model.frame(WALL, [0.45, 0.0, 0.06], np.eye(3), rng)) is None


def test_stuck_high_taxel_is_no_contact_and_gets_ignored():
    model, rng = SensorModel(LAYOUT, seed=0), np.random.default_rng(2)
    det = calibrated(model, rng)
    for _ in range(100):
        v = model.frame(WALL, [0.45, 0.0, 0.06], np.eye(3), rng)
        v[5] = 30000  # stuck high after calibration
        assert det.update(v) is None
    assert det.stuck[5] and det.stuck.sum() == 1


def test_two_adjacent_stuck_taxels_are_ignored_after_stuck_frames():
    config = ContactConfig(stuck_frames=10)
    model, rng = SensorModel(LAYOUT, seed=0), np.random.default_rng(3)
    det = calibrated(model, rng, config)
    events = 0
    for _ in range(50):
        v = model.frame(WALL, [0.45, 0.0, 0.06], np.eye(3), rng)
        v[[0, 1]] = 20000
        events += det.update(v) is not None
    assert events <= 1 and det.stuck[[0, 1]].all()
    # a real contact later is still located correctly (the stuck pair is ignored)
    det.in_contact = False
    for x in np.linspace(0.4995, 0.5006, 20):
        v = model.frame(WALL, [x, 0.0, 0.06], np.eye(3), rng)
        v[[0, 1]] = 20000
        est = det.update(v)
        if est is not None:
            break
    assert est is not None
    assert np.degrees(np.arccos(est.finger_normal @ [1.0, 0.0, 0.0])) < 5.0


def test_dead_taxel_found_in_calibration():
    model, rng = SensorModel(LAYOUT, seed=0), np.random.default_rng(4)
    det = ContactDetector(LAYOUT, ContactConfig())
    for _ in range(det.config.calibration_frames):
        v = model.frame(WALL, [0.45, 0.0, 0.06], np.eye(3), rng)
        v[7] = 0
        det.update(v)
    assert det.dead[7] and det.dead.sum() == 1


def test_wrong_taxel_count_and_bad_config_are_clear_errors():
    det = ContactDetector(LAYOUT)
    with pytest.raises(ValueError, match="frame has 5 taxels"):
        det.update(np.zeros(5))
    with pytest.raises(ValueError, match="hysteresis"):
        ContactDetector(LAYOUT, ContactConfig(on_threshold_n=0.01, off_threshold_n=0.02))
