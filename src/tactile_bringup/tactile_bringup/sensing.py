"""The simulated finger of the offline loop: sim sensor model + the driver's detector.

The graph senses with ``sim_rig``'s simulated device and the ``tactile_sensor``
driver; offline, :func:`tactile_sim.touch.simulate_approach` runs the same
sensor model and the same :class:`~tactile_driver.contact.ContactDetector`
one frame at a time, with the same parameters.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any, Mapping, Optional

import numpy as np

from tactile_common.touch_geometry import TouchGeometry
from tactile_driver.commander_api import CommanderConfig
from tactile_driver.contact import ContactConfig, ContactDetector, back_off_target
from tactile_driver.safety import WorkspaceBox
from tactile_driver.taxels import TaxelLayout, load_layout, resolve_layout_file
from tactile_sim.sensor_model import SensorModel, SensorModelConfig, world_sdf
from tactile_sim.touch import ApproachResult, simulate_approach
from tactile_driver.slide_servo import ContactThinner, SlideServo, SlideServoConfig
from tactile_sim.slide import SlideResult, simulate_slide

from .poke_result import PokeResult


def _dataclass_from(cls, params: Mapping[str, Any], prefix: str = ""):
    """An instance of dataclass ``cls`` from the ``prefix + field`` keys present in params."""
    values = {f.name: params[prefix + f.name] for f in fields(cls) if prefix + f.name in params}
    return cls(**values)


def layout_for(mode: str, sensor_params: Mapping[str, Any]) -> TaxelLayout:
    """The taxel layout the driver loads: its ``layout_file`` parameter, else the mode's default."""
    return load_layout(resolve_layout_file(sensor_params.get("layout_file") or "", mode))


@dataclass
class SimulatedFinger:
    """Guarded approaches of a fingertip against a hidden object (world frame)."""

    obj: Any
    model: SensorModel
    detector: ContactDetector
    step_m: float
    max_travel_m: float
    seed: int
    path_step_m: float = 0.0005  # tip travel per sensor frame on a free-space path (tip speed / frame rate)
    back_off_m: float = 0.02  # tip centre to a contact after backing off (tip radius + standoff)
    servo: SlideServoConfig = SlideServoConfig()  # slides: the commander's servo parameters ('slide.' prefix)
    box_m: Optional[np.ndarray] = None  # (2, 3) the commander's safety box for the tip centre (slides, approaches)

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
        geometry = TouchGeometry.from_params({**planner, "tip_radius_m": layout.tip_radius_m})
        max_travel_m = geometry.approach_length_m
        path_step_m = float(planner.get("tip_speed_mps", 0.1)) / frame_rate_hz
        back_off_m = geometry.pretouch_offset_m
        servo = SlideServoConfig.from_params({**experiment.arm_params, "slide.slide_speed_mps":
                                              planner.get("slide_speed_mps", 0.05)}, "slide.")
        # The commander's safety box, floor above the table included: the graph's slides stop there too.
        safety = WorkspaceBox.of_commander(_dataclass_from(CommanderConfig, experiment.arm_params))
        box = np.array([safety.lower_xyz, safety.upper_xyz], dtype=float)
        return cls(obj, model, detector, step_m, max_travel_m, int(experiment.seed), path_step_m, back_off_m,
                   servo, box)

    def slide(self, approach: ApproachResult, direction_xyz: np.ndarray, length_m: float,
              touch_index: int, normal_xyz: Optional[np.ndarray] = None) -> tuple[SlideResult, np.ndarray]:
        """Slide on from an approach's contact (the servo of :mod:`tactile_driver.slide_servo`), then
        back off ``back_off_m`` from the last contact; returns (the slide, the tip after backing off).
        ``normal_xyz``: the normal to servo on until a contact has one (the approach's, reversed)."""
        rng = np.random.default_rng([self.seed, touch_index, 2])
        box = self.box_m if self.box_m is not None else np.array([[-np.inf] * 3, [np.inf] * 3])
        servo = SlideServo(self.servo, direction_xyz, length_m, box[0], box[1], planar=self.obj.dim == 2,
                           normal_xyz=normal_xyz)
        thinner = ContactThinner(self.servo.thin_distance_m, self.servo.thin_angle_rad)
        result = simulate_slide(self.obj, self.model, self.detector, servo, thinner, approach.tip_xyz_at_stop,
                                rng=rng)
        end = result.tip_path_xyz[-1]
        last = result.points_xyz[-1] if result.n_contacts else approach.point_xyz
        back = back_off_target(last, end, self.back_off_m)
        if back is None:
            back = end
        self.detector.update(self.model.frame(self.obj, back, np.eye(3), rng))  # off the surface: release
        return result, back

    def approach(self, start_xyz: np.ndarray, direction_xyz: np.ndarray, touch_index: int,
                 max_travel_m: Optional[float] = None) -> ApproachResult:
        """One guarded approach from the pre-touch point (``max_travel_m``: default the poke's
        approach length); the noise is seeded per touch."""
        rng = np.random.default_rng([self.seed, touch_index])
        start = np.asarray(start_xyz, dtype=float)
        travel = self.max_travel_m if max_travel_m is None else float(max_travel_m)
        if self.box_m is not None:  # as the commander: shortened to end inside its box (ArmMotions.approach_depth_m)
            box = WorkspaceBox(self.box_m[0], self.box_m[1])
            travel = max(box.approach_depth_m(np.clip(start, box.lower_xyz, box.upper_xyz), direction_xyz, travel), 0.0)
        result = simulate_approach(self.obj, self.model.layout, self.model, self.detector, start,
                                   direction_xyz, travel, self.step_m, rng=rng)
        # Retract: the finger leaves the object, so the detector's hysteresis releases.
        self.detector.update(self.model.frame(self.obj, start, np.eye(3), rng))
        return result

    def poke(self, plan, tip_xyz: np.ndarray, touch_index: int):
        """One poke of a planner decision from ``tip_xyz`` with this model of the motion (a straight
        approach at constant speed, no arm); the result as :class:`~tactile_bringup.poke_result.PokeResult`."""
        path = np.vstack([np.asarray(tip_xyz, dtype=float)[None, :], plan.path_xyz])
        hit = self.path_contact(path, touch_index)
        if hit is not None:
            free_m, result, back = hit
            return PokeResult("contact", result.point_xyz, result.normal_xyz, result.force_n, None, back, free_m,
                              result.travel_m, float(np.linalg.norm(back - result.tip_xyz_at_stop)))
        pretouch = np.asarray(plan.pretouch_xyz, dtype=float)
        result = self.approach(pretouch, -np.asarray(plan.normal_xyz), touch_index)
        if result.contact:
            return PokeResult("contact", result.point_xyz, result.normal_xyz, result.force_n, None, pretouch, None,
                              result.travel_m)
        end = result.tip_xyz_at_stop
        return PokeResult("free_space", end, result.normal_xyz, 0.0, pretouch - end, pretouch, None, result.travel_m)

    def path_contact(self, path_xyz: np.ndarray, touch_index: int,
                     sample_m: float = 0.002) -> Optional[tuple[float, ApproachResult, np.ndarray]]:
        """Where a free-space path (K, 3) first meets the object, sensed as the arm commander does.

        The path is sampled every ``sample_m``; the first sample where the skin
        would carry force is the collision. From the last sample whose skin is
        clear of the object (sdf of the centre > the skin's bounding radius) the
        finger moves towards it one frame at path speed at a time, with the
        driver's detector. Returns (path length before that free sample, the
        contact, the tip after backing off ``back_off_m`` from the contact point
        along tip − contact), or None when the path stays free.
        """
        P = np.asarray(path_xyz, dtype=float).reshape(-1, 3)
        seg = np.linalg.norm(np.diff(P, axis=0), axis=1)
        if len(P) < 2 or seg.sum() <= 0:
            return None
        cum = np.concatenate([[0.0], np.cumsum(seg)])
        s = np.append(np.arange(0.0, cum[-1], sample_m), cum[-1])
        pts = np.column_stack([np.interp(s, cum, P[:, i]) for i in range(3)])
        clear = world_sdf(self.obj, pts) > self.model.bounding_radius_m
        for k in np.nonzero(~clear)[0]:
            if self.model.force_n(self.obj, pts[k]) > 0.0:
                break
        else:
            return None
        free = np.nonzero(clear[:k])[0]
        if len(free) == 0:
            return None  # starts in contact: nothing to sense a path collision from
        j = free[-1]
        rng = np.random.default_rng([self.seed, touch_index, 1])
        result = simulate_approach(self.obj, self.model.layout, self.model, self.detector, pts[j], pts[k] - pts[j],
                                   float(s[k] - s[j]) + 0.005, self.path_step_m, rng=rng)
        back = back_off_target(result.point_xyz, result.tip_xyz_at_stop, self.back_off_m) if result.contact else None
        if back is None:
            return None
        self.detector.update(self.model.frame(self.obj, back, np.eye(3), rng))  # off the surface: release
        return float(s[j]), result, back
