"""Offline slide along an object with the driver's sensing and servo code (ROS-free).

Where the graph runs the commander's slide (the sim rig's sensor device, the
``tactile_sensor`` driver, :class:`tactile_driver.slide_servo.SlideServo` per
control tick), the offline loop calls :func:`simulate_slide`: one sensor frame
of :class:`~tactile_sim.sensor_model.SensorModel` per control tick at the tip,
the same :class:`~tactile_driver.contact.ContactDetector` (its per-frame
``current`` estimate), the same servo and the same thinning. The arm is
taken to reach each target within the tick (targets are ≤ 0.5 mm apart).
World frame, metres.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Optional

import numpy as np

from tactile_driver.contact import ContactDetector
from tactile_driver.slide_servo import ContactSense, ContactThinner, SlideServo, SlideStop
from tactile_sim.sensor_model import SensorModel


@dataclass(frozen=True)
class SlideResult:
    """Outcome of one slide (world frame).

    ``points_xyz``/``normals_xyz``/``forces_n``: the thinned contacts (K, 3),
    (K, 3), (K,), in the order sensed; ``tip_path_xyz`` (T, 3): the tip centre
    at every tick, from the start; ``slid_m``: the servo's slid length (sum of
    tangent steps); ``travel_m``: tip path length; ``stop``: why it ended;
    ``forces_all_n``: the force of every tick in contact (for tests);
    ``duration_s``: robot time of the slide (ticks / control rate);
    ``point_ticks`` (K,): for each contact, the index into ``tip_path_xyz`` of
    the tip where it was sensed (its time is that index / control rate).
    """

    points_xyz: np.ndarray
    normals_xyz: np.ndarray
    forces_n: np.ndarray
    tip_path_xyz: np.ndarray
    slid_m: float
    travel_m: float
    stop: SlideStop
    forces_all_n: np.ndarray
    duration_s: float = 0.0
    point_ticks: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))

    @property
    def n_contacts(self) -> int:
        return int(len(self.points_xyz))

    @property
    def last_contact(self) -> Optional[int]:
        return len(self.points_xyz) - 1 if len(self.points_xyz) else None


def simulate_slide(obj: Any, model: SensorModel, detector: ContactDetector, servo: SlideServo,
                   thinner: ContactThinner, start_tip_xyz: np.ndarray,
                   rotation: np.ndarray = np.eye(3), rng: Optional[np.random.Generator] = None) -> SlideResult:
    """Slide from ``start_tip_xyz`` (the tip where the approach met the surface) until the servo stops.

    The detector must be calibrated and in contact (the approach's onset);
    ``rng`` draws the sensor noise (default: seeded with 0).

    Raises:
        ValueError: an uncalibrated detector, or a layout that differs from the model's.
    """
    if not detector.calibrated:
        raise ValueError("the slide needs a calibrated detector (run the guarded approach first)")
    if detector.layout.n_taxels != model.layout.n_taxels:
        raise ValueError("model and detector must share one taxel layout")
    rng = np.random.default_rng(0) if rng is None else rng
    R = np.asarray(rotation, dtype=float)
    tip = np.asarray(start_tip_xyz, dtype=float).reshape(3).copy()
    path = [tip.copy()]
    pts, nrm, frc, f_all, ticks = [], [], [], [], []
    last_sense: Optional[ContactSense] = None
    last_tick = 0
    while True:
        detector.update(model.frame(obj, tip, R, rng))
        est = detector.current if detector.in_contact else None
        sense = None
        if est is not None:
            point, normal = est.to_world(tip, R)
            sense = ContactSense(point, normal, est.force_n)
            f_all.append(est.force_n)
            if est.force_n >= servo.config.min_force_n:
                last_sense, last_tick = sense, len(path) - 1
                if thinner.offer(sense):
                    pts.append(point)
                    nrm.append(normal)
                    frc.append(est.force_n)
                    ticks.append(last_tick)
        step = servo.step(tip, sense)
        if step.target_xyz is not None:
            tip = np.asarray(step.target_xyz, dtype=float)
            path.append(tip.copy())
        if step.stop is not None:
            break
    # the last good contact closes the stream (it ends the sensed arc)
    if last_sense is not None and (not pts or np.linalg.norm(pts[-1] - last_sense.point_xyz) > 1e-9):
        pts.append(last_sense.point_xyz)
        nrm.append(last_sense.normal_xyz)
        frc.append(last_sense.force_n)
        ticks.append(last_tick)
    P = np.asarray(path)
    travel = float(np.linalg.norm(np.diff(P, axis=0), axis=1).sum()) if len(P) > 1 else 0.0
    return SlideResult(np.asarray(pts).reshape(-1, 3), np.asarray(nrm).reshape(-1, 3), np.asarray(frc),
                       P, float(servo.slid_m), travel, step.stop, np.asarray(f_all), servo.duration_s,
                       np.asarray(ticks, dtype=int))
