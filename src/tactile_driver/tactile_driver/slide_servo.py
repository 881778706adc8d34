"""Tactile servoing of a slide, one control tick at a time (ROS-free).

World frame, metres, newtons, seconds. After a guarded approach has met the
surface, each control tick k takes the fingertip centre p_k and the latest
contact the driver senses (point c_k, the object's outward unit normal n_k,
normal force F_k; None without contact) and returns the next tip target:

- tangent ``t_k = normalize(t_{k−1} − (t_{k−1}·n_k) n_k)`` — the planned
  direction, projected on the sensed tangent plane tick after tick (in 2D the
  z components are dropped), so the finger follows the surface as it turns;
- normal correction ``Δ_k = clip(gain_m_per_n · (F* − F_k), ±max_correction_m)``
  into the surface (along −n_k); F* = ``target_force_n``; below the band
  (F_k < ``min_force_n``) ``Δ_k = max_correction_m``: a round tip's force
  grows with the square of its depth, so near a grazing touch the
  proportional law would creep in by micrometres per tick;
- step ``h = slide_speed_mps / control_rate_hz`` along t_k, taken only while
  ``F_k ≥ min_force_n`` (a weak or lost contact is regained first);
- target ``p_{k+1} = p_k + h·t_k − Δ_k·n_k``; without contact the target
  moves ``max_correction_m`` along −n (the last sensed normal) to regain it
  (a convex corner: the round tip wraps around the vertex).

A contact without a normal (the finger's rim: :mod:`tactile_driver.contact`)
keeps the last one; before the first normal is sensed the servo uses the one
it is given (``normal_xyz``: the guarded approach's direction reversed), so a
slide whose first contact is on the rim (a lip facing down) follows it instead
of ending at once.

The slide ends (:class:`SlideStop`) when the slid length (the sum of the
tangent steps) reaches the planned length, when the contact is weak or lost
for ``lost_ticks`` ticks in a row (an edge, a corner it cannot wrap), when the
force exceeds ``max_force_n`` (the band's top: the finger is jammed, e.g. in
a concave corner narrower than the tip), when the next target would leave
the workspace box (3D: one below the box's floor, the table's margin, goes on
along the floor instead while the tangent heads along more than down,
|t_xy| ≥ ``FLOOR_MIN_TXY``: the foot of a wall), when the contact returns
within ``lap_radius_m`` of the slide's first firm contact, and the tip within
that of where it was then, after sliding 4× that radius or more (a closed
contour has been sensed all round; 0 = off; the contact alone is not enough:
rolling round a sharp convex corner, the contact stays on the edge while the
tip goes round it, up to π r_tip), when the tip comes back within
``lap_radius_m`` of where it was 4× that radius of slide or more before (it
senses a band it has sensed: a 3D slide that settled at another height than
its first contact laps there without ever meeting that contact again), or
after ``max_ticks``. The e-stop and the joint-state
watchdog stay the commander's (they stop every motion, a slide included).

:class:`ContactThinner` keeps the contacts worth publishing from the per-tick
stream: one every ``thin_distance_m`` of contact travel, or sooner when the
normal has turned by ``thin_angle_rad`` (corners), so that the estimator is
not flooded.

``approach_depth_m`` is the guarded approach's depth before a slide (how far
the skin may go beyond the estimated surface point: a slide's contact is
worth a deeper search than a poke's ``max_depth_m``).

How the commander uses it: at slide start build ``SlideServo(config,
direction, length, box)``; on each control tick (``control_rate_hz``) call
``step(tip_xyz, contact)`` with the forward-kinematics tip and the driver's
latest contact in the world frame, send the returned ``target_xyz`` as a
short replacing trajectory (one tick long), and publish
``thinner.offer(contact)`` when it returns True; on ``stop`` retract.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, fields
from typing import Any, Mapping, Optional

import numpy as np


class SlideStop(enum.Enum):
    """Why a slide ended."""

    LENGTH = "length"  # the planned length was slid
    LOST = "lost"  # the contact was weak or lost for lost_ticks ticks (an edge, a corner)
    FORCE = "force"  # the force exceeded the band's top (jammed)
    BOX = "box"  # the next target would leave the workspace box
    TICKS = "ticks"  # max_ticks reached (no progress)
    LAP = "lap"  # the contact came back to where the slide began (a closed contour: all of it sensed)


@dataclass(frozen=True)
class SlideServoConfig:
    """Servo parameters (see the module docstring for each symbol)."""

    slide_speed_mps: float = 0.05
    control_rate_hz: float = 100.0
    target_force_n: float = 0.15
    min_force_n: float = 0.06
    max_force_n: float = 3.0
    gain_m_per_n: float = 2.0e-4
    max_correction_m: float = 3.0e-4
    lost_ticks: int = 30
    thin_distance_m: float = 0.005
    thin_angle_rad: float = 0.25
    lap_radius_m: float = 0.005
    approach_depth_m: float = 0.06

    @classmethod
    def from_params(cls, params: Mapping[str, Any], prefix: str = "") -> "SlideServoConfig":
        """From the ``prefix + field`` keys present in ``params`` (the rest: defaults)."""
        kw = {f.name: type(f.default)(params[prefix + f.name]) for f in fields(cls) if prefix + f.name in params}
        return cls(**kw).validate()

    @property
    def step_m(self) -> float:
        """Tangent step per control tick: slide_speed_mps / control_rate_hz."""
        return self.slide_speed_mps / self.control_rate_hz

    def validate(self) -> "SlideServoConfig":
        for name in ("slide_speed_mps", "control_rate_hz", "target_force_n", "gain_m_per_n", "max_correction_m",
                     "thin_distance_m", "approach_depth_m"):
            if not getattr(self, name) > 0:
                raise ValueError(f"slide servo {name} = {getattr(self, name)}: must be > 0")
        if not 0 <= self.min_force_n < self.target_force_n < self.max_force_n:
            raise ValueError(f"slide servo force band: need 0 ≤ min_force_n ({self.min_force_n}) < target_force_n "
                             f"({self.target_force_n}) < max_force_n ({self.max_force_n})")
        if not self.lap_radius_m >= 0:
            raise ValueError(f"slide servo lap_radius_m = {self.lap_radius_m}: must be ≥ 0")
        if self.lost_ticks < 1:
            raise ValueError(f"slide servo lost_ticks = {self.lost_ticks}: must be ≥ 1")
        if not self.thin_angle_rad > 0:
            raise ValueError(f"slide servo thin_angle_rad = {self.thin_angle_rad}: must be > 0")
        return self


@dataclass(frozen=True)
class ContactSense:
    """One tick's sensed contact, world frame: point (3,), object's outward unit normal (3,), force (N)."""

    point_xyz: np.ndarray
    normal_xyz: np.ndarray
    force_n: float


@dataclass(frozen=True)
class SlideStep:
    """The servo's answer for one tick: the next tip target (None once stopped), why it stopped, and
    the tangent step in it (``step_m`` along ``tangent_xyz``; 0 while the contact is regained)."""

    target_xyz: Optional[np.ndarray]
    stop: Optional[SlideStop] = None
    step_m: float = 0.0
    tangent_xyz: Optional[np.ndarray] = None


#: 3D: a slide at the box's floor whose tangent's horizontal part is at least this long goes on along the
#: floor (the foot of a wall); one heading down more steeply ends there (``box``)
FLOOR_MIN_TXY = 0.5


def _unit(v: np.ndarray) -> Optional[np.ndarray]:
    n = float(np.linalg.norm(v))
    return v / n if np.isfinite(n) and n > 1e-9 else None


class SlideServo:
    """The slide's control law and stop rules (module docstring); one instance per slide."""

    def __init__(self, config: SlideServoConfig, direction_xyz: np.ndarray, length_m: float,
                 box_min_xyz: np.ndarray, box_max_xyz: np.ndarray, planar: bool = False,
                 max_ticks: Optional[int] = None, normal_xyz: Optional[np.ndarray] = None) -> None:
        """``normal_xyz``: the outward normal to servo on until one is sensed (None: the slide ends
        without one; module docstring)."""
        self.config = config.validate()
        self.planar = bool(planar)
        d = self._flat(np.asarray(direction_xyz, dtype=float).reshape(3))
        t = _unit(d)
        if t is None:
            raise ValueError(f"slide direction {np.asarray(direction_xyz).tolist()}: must be a non-zero vector"
                             + (" in the x-y plane" if planar else ""))
        if not (np.isfinite(length_m) and length_m > 0):
            raise ValueError(f"slide length {length_m}: must be a finite number > 0")
        self.box_min = np.asarray(box_min_xyz, dtype=float).reshape(3)
        self.box_max = np.asarray(box_max_xyz, dtype=float).reshape(3)
        if not np.all(self.box_max > self.box_min):
            raise ValueError(f"slide box {self.box_min.tolist()} .. {self.box_max.tolist()}: max must exceed min")
        self.length_m = float(length_m)
        self.tangent = t
        # last sensed outward normal (or the given one, until a contact has one)
        self.normal: Optional[np.ndarray] = None if normal_xyz is None else \
            _unit(self._flat(np.asarray(normal_xyz, dtype=float).reshape(3)))
        self.slid_m = 0.0
        self.ticks = 0
        self.weak_ticks = 0
        self.max_ticks = int(max_ticks) if max_ticks is not None else \
            int(np.ceil(3.0 * self.length_m / self.config.step_m)) + 10 * self.config.lost_ticks
        self.stopped: Optional[SlideStop] = None
        # first firm contact and the tip then (the lap rule: both back; round a sharp convex corner the
        # contact stays at the edge while the tip rolls on)
        self.first_point: Optional[np.ndarray] = None
        self.first_tip: Optional[np.ndarray] = None
        # the tip every lap_radius_m / 2 of slide, with the slid length there (the lap rule)
        self._trail_xyz = np.empty((0, 3))
        self._trail_s = np.empty(0)

    @property
    def duration_s(self) -> float:
        """Robot time of the slide so far: ticks / control_rate_hz."""
        return self.ticks / self.config.control_rate_hz

    def _flat(self, v: np.ndarray) -> np.ndarray:
        if self.planar:
            v = v.copy()
            v[2] = 0.0
        return v

    def step(self, tip_xyz: np.ndarray, contact: Optional[ContactSense]) -> SlideStep:
        """One control tick: the next tip target from the tip centre and the latest contact (or None)."""
        if self.stopped is not None:
            return SlideStep(None, self.stopped)
        cfg = self.config
        tip = np.asarray(tip_xyz, dtype=float).reshape(3)
        self.ticks += 1
        normal = None
        force = 0.0
        if contact is not None:
            normal = _unit(self._flat(np.asarray(contact.normal_xyz, dtype=float).reshape(3)))
            force = float(contact.force_n)
        if normal is None and contact is not None:  # a contact without a usable normal: keep the last one
            normal = self.normal
        if force > cfg.max_force_n:
            return self._stop(SlideStop.FORCE)
        if normal is not None:
            self.normal = normal
        if self.normal is None:  # never sensed a contact: nothing to servo on
            return self._stop(SlideStop.LOST)
        n = self.normal
        weak = contact is None or force < cfg.min_force_n
        self.weak_ticks = self.weak_ticks + 1 if weak else 0
        if self.weak_ticks >= cfg.lost_ticks:
            return self._stop(SlideStop.LOST)
        if self.ticks > self.max_ticks:
            return self._stop(SlideStop.TICKS)
        if not weak and cfg.lap_radius_m > 0:
            p = np.asarray(contact.point_xyz, dtype=float).reshape(3)
            if self.first_point is None:
                self.first_point, self.first_tip = p, tip.copy()
            elif self.slid_m >= 4.0 * cfg.lap_radius_m and \
                    float(np.linalg.norm(self._flat(p - self.first_point))) < cfg.lap_radius_m and \
                    float(np.linalg.norm(self._flat(tip - self.first_tip))) < cfg.lap_radius_m:
                return self._stop(SlideStop.LAP)
            if self._tip_revisits(tip):
                return self._stop(SlideStop.LAP)
        t = _unit(self._flat(self.tangent - float(self.tangent @ n) * n))
        if t is None:  # the direction is along the normal: any tangent (z × n, else x × n)
            t = _unit(np.cross([0.0, 0.0, 1.0], n))
            t = t if t is not None else _unit(np.cross([1.0, 0.0, 0.0], n))
        self.tangent = t
        if weak:  # regain the band at full rate (the spring force grows with the square of the depth)
            correction = cfg.max_correction_m
        else:
            correction = float(np.clip(cfg.gain_m_per_n * (cfg.target_force_n - force),
                                       -cfg.max_correction_m, cfg.max_correction_m))
        step = 0.0 if weak else max(0.0, min(cfg.step_m, self.length_m - self.slid_m))
        target = tip + step * self.tangent - correction * n
        if not self.planar and target[2] < self.box_min[2] and \
                (along := float(np.hypot(self.tangent[0], self.tangent[1]))) >= FLOOR_MIN_TXY:
            # at the box's floor (above the table), going along more than down: on along the floor,
            # the tangent's horizontal part (the foot of a wall the slide came down to)
            self.tangent = self.tangent * [1.0, 1.0, 0.0] / along
            target = tip + step * self.tangent - correction * n
            target[2] = max(float(target[2]), float(self.box_min[2]))
        if np.any(target < self.box_min) or np.any(target > self.box_max):
            return self._stop(SlideStop.BOX)
        self.slid_m += step
        if self.slid_m >= self.length_m - 1e-12:
            self.stopped = SlideStop.LENGTH
            return SlideStep(target, SlideStop.LENGTH, step, self.tangent.copy())
        return SlideStep(target, None, step, self.tangent.copy())

    def _tip_revisits(self, tip: np.ndarray) -> bool:
        """The tip is within r = lap_radius_m of where it was ≥ 4 r of slide ago (module docstring);
        records it every r / 2 of slide."""
        r = self.config.lap_radius_m
        if self._trail_s.size == 0 or self.slid_m - self._trail_s[-1] >= 0.5 * r:
            self._trail_xyz = np.vstack([self._trail_xyz, tip[None]])
            self._trail_s = np.append(self._trail_s, self.slid_m)
        old = self._trail_s <= self.slid_m - 4.0 * r
        if not old.any():
            return False
        return bool(np.min(np.sum((self._trail_xyz[old] - tip) ** 2, axis=1)) < r * r)

    def _stop(self, why: SlideStop) -> SlideStep:
        self.stopped = why
        return SlideStep(None, why)


class ContactThinner:
    """Which contacts of a slide's per-tick stream to publish (module docstring)."""

    def __init__(self, distance_m: float, angle_rad: float) -> None:
        if not (distance_m > 0 and angle_rad > 0):
            raise ValueError(f"thinning: distance_m ({distance_m}) and angle_rad ({angle_rad}) must be > 0")
        self.distance_m = float(distance_m)
        self.cos_angle = float(np.cos(angle_rad))
        self._point: Optional[np.ndarray] = None
        self._normal: Optional[np.ndarray] = None

    def offer(self, contact: ContactSense) -> bool:
        """True when this contact is to be published (the first one, then by distance or turn)."""
        p = np.asarray(contact.point_xyz, dtype=float).reshape(3)
        n = np.asarray(contact.normal_xyz, dtype=float).reshape(3)
        if not np.all(np.isfinite(p)):
            return False
        if self._point is not None:
            far = float(np.linalg.norm(p - self._point)) >= self.distance_m
            turned = (np.all(np.isfinite(n)) and self._normal is not None
                      and float(n @ self._normal) <= self.cos_angle)
            if not (far or turned):
                return False
        self._point = p
        if np.all(np.isfinite(n)):
            self._normal = n
        return True
