"""The simulated finger of the offline loop: sim sensor model + the driver's detector.

The graph senses with ``sim_rig``'s simulated device and the ``tactile_sensor``
driver; offline, :func:`tactile_sim.touch.simulate_approach` runs the same
sensor model and the same :class:`~tactile_driver.contact.ContactDetector`
one frame at a time, with the same parameters.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from tactile_common.params_file import package_config
from tactile_driver.contact import ContactConfig, ContactDetector
from tactile_driver.taxels import TaxelLayout, load_layout
from tactile_sim.sensor_model import SensorModel, SensorModelConfig
from tactile_sim.touch import ApproachResult, simulate_approach


def _dataclass_from(cls, params: Mapping[str, Any], prefix: str = ""):
    """An instance of dataclass ``cls`` from the ``prefix + field`` keys present in params."""
    values = {f.name: params[prefix + f.name] for f in fields(cls) if prefix + f.name in params}
    return cls(**values)


def layout_for(mode: str, sensor_params: Mapping[str, Any]) -> TaxelLayout:
    """The taxel layout the driver loads: its ``layout_file`` parameter, else the mode's default."""
    name = sensor_params.get("layout_file") or ("taxels_ring.yaml" if mode == "2d" else "taxels_hemisphere.yaml")
    path = Path(name)
    if not path.is_absolute() and len(path.parts) == 1:  # a bare name: the driver's config folder
        path = package_config("tactile_driver", name)
    return load_layout(path)


@dataclass
class SimulatedFinger:
    """Guarded approaches of a fingertip against a hidden object (world frame)."""

    obj: Any
    model: SensorModel
    detector: ContactDetector
    step_m: float
    max_travel_m: float
    seed: int

    @classmethod
    def from_params(cls, experiment, obj) -> "SimulatedFinger":
        sensor, sim, planner = experiment.sensor_params, experiment.sim_params, experiment.planner_params
        # sim_rig's own layout when set, else the driver's: both must be the same file.
        layout = layout_for(experiment.mode, {"layout_file": sim.get("sensor_layout")} if sim.get("sensor_layout") else sensor)
        model = SensorModel(layout, _dataclass_from(SensorModelConfig, sim, "model."),
                            seed=int(sim.get("sensor_seed", experiment.seed)))
        detector = ContactDetector(layout, _dataclass_from(ContactConfig, sensor, "contact."))
        frame_rate_hz = float(sim.get("sensor_frame_rate_hz", 200.0))
        step_m = float(planner.get("approach_speed_mps", 0.02)) / frame_rate_hz
        max_travel_m = (float(planner.get("standoff_m", 0.01)) + float(planner.get("max_depth_m", 0.02)))
        return cls(obj, model, detector, step_m, max_travel_m, int(experiment.seed))

    def approach(self, start_xyz: np.ndarray, direction_xyz: np.ndarray, touch_index: int) -> ApproachResult:
        """One guarded approach from the pre-touch point; the noise is seeded per touch."""
        rng = np.random.default_rng([self.seed, touch_index])
        start = np.asarray(start_xyz, dtype=float)
        result = simulate_approach(self.obj, self.model.layout, self.model, self.detector, start,
                                   direction_xyz, self.max_travel_m, self.step_m, rng=rng)
        # Retract: the finger leaves the object, so the detector's hysteresis releases.
        self.detector.update(self.model.frame(self.obj, start, np.eye(3), rng))
        return result
