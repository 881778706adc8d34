"""Offline guarded approach with the driver's own sensing code (ROS-free).

The offline exploration loop calls :func:`simulate_approach` where the graph
runs the arm commander's guarded approach, so both see the same sensor model
and the same :class:`tactile_driver.contact.ContactDetector`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Optional

import numpy as np

from tactile_driver import protocol
from tactile_driver.contact import ContactDetector
from tactile_driver.taxels import TaxelLayout
from tactile_sim.sensor_model import SensorModel


@dataclass(frozen=True)
class ApproachResult:
    """Outcome of one guarded approach (world frame).

    ``point_xyz``/``normal_xyz``/``force_n`` are the detector's contact
    (surface point, unit outward object normal, N); NaN / 0 without contact.
    ``tip_xyz_at_stop``: fingertip centre where the approach stopped;
    ``travel_m``: distance moved from the start.
    """

    contact: bool
    point_xyz: np.ndarray
    normal_xyz: np.ndarray
    force_n: float
    tip_xyz_at_stop: np.ndarray
    travel_m: float


def simulate_approach(
    obj: Any,
    layout: TaxelLayout,
    model: SensorModel,
    detector: ContactDetector,
    start_xyz: np.ndarray,
    direction_xyz: np.ndarray,
    max_travel_m: float,
    step_m: float,
    rotation: np.ndarray = np.eye(3),
    rng: Optional[np.random.Generator] = None,
    through_protocol: bool = False,
) -> ApproachResult:
    """Move the tip from ``start_xyz`` along ``direction_xyz`` one sensor frame at a time.

    Frame k is taken at start + k * step_m * d (k = 0, 1, ...; d normalised;
    step_m = approach speed / frame rate) until the detector reports a
    contact onset or the travel exceeds ``max_travel_m`` (the last frame is at
    exactly ``max_travel_m``). An uncalibrated detector is first calibrated
    with frames at the start pose, which must be in free space.
    ``through_protocol`` sends every frame through the encoder and decoder.
    ``rng`` draws the sensor noise (default: a generator seeded with 0).

    Raises:
        ValueError: a zero direction or a non-positive step/travel, or a
            layout that differs from the model's/detector's.
    """
    d = np.asarray(direction_xyz, dtype=float)
    norm = float(np.linalg.norm(d))
    if norm < 1e-12 or step_m <= 0 or max_travel_m < 0:
        raise ValueError("need a non-zero direction, step_m > 0 and max_travel_m >= 0")
    if model.layout.n_taxels != layout.n_taxels or detector.layout.n_taxels != layout.n_taxels:
        raise ValueError("layout, model and detector must share one taxel layout")
    d = d / norm
    rng = np.random.default_rng(0) if rng is None else rng
    start = np.asarray(start_xyz, dtype=float)
    R = np.asarray(rotation, dtype=float)
    decoder = protocol.FrameDecoder() if through_protocol else None
    seq = 0

    def read(tip: np.ndarray) -> np.ndarray:
        nonlocal seq
        values = model.frame(obj, tip, R, rng)
        if decoder is None:
            return values
        (frame,) = decoder.feed(protocol.encode_frame(seq, seq * 5000, values))
        seq += 1
        return frame.values

    while not detector.calibrated:
        detector.update(read(start))
    n_steps = int(np.ceil(max_travel_m / step_m - 1e-9))
    travels = np.minimum(np.arange(n_steps + 1) * step_m, max_travel_m)
    for travel in travels:
        tip = start + travel * d
        est = detector.update(read(tip))
        if est is not None:
            point, normal = est.to_world(tip, R)
            return ApproachResult(True, point, normal, est.force_n, tip, float(travel))
    nan3 = np.full(3, np.nan)
    return ApproachResult(False, nan3, nan3, 0.0, start + max_travel_m * d, float(max_travel_m))
