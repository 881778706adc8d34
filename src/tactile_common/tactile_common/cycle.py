"""The events of the touch cycle as typed values, ROS-free (docs/architecture.md, "Delivery").

Every event carries an identifier, so that a reader that sees it twice (a
durable topic hands its history to a restarted reader; a writer re-sends
after a time-out) can tell a duplicate from a new event:

- :class:`PlanRequest` (explorer → planner): ``request_id`` (ns, strictly
  increasing per run) and the stamp the map must at least have. A re-sent
  request keeps its id; a re-issued touch (nothing came back in time) gets a
  new one. It also carries the run's history the decision depends on (the
  targets chosen so far, those reported unreachable), so the planner keeps
  no state of its own: a restarted planner answers as the one that died.
- the goal and its path (planner → commander) carry ``header.stamp`` =
  the request id they answer, so answering one request twice gives the same
  goal stamp and the commander runs it once.
- :class:`PlannerAnswer` (planner → explorer) names the request it answers.
- :class:`TouchReport` (commander → explorer, planner) names its goal stamp.

All of them travel as ``diagnostic_msgs/DiagnosticStatus`` key/values (the
conversion is in :mod:`tactile_common.cycle_msgs`); here they are plain
dataclasses with ``values()`` and ``from_values()`` so that cores and their
tests need no ROS.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass
from typing import Mapping, Optional


class TouchOutcome(str, enum.Enum):
    """How a touch ended (the ``message`` of ``/arm/touch_done``)."""

    CONTACT = "contact"  # the finger met the object (approach or path); an observation was published
    FREE_SPACE = "free_space"  # full depth without contact; the probe end was published
    UNREACHABLE = "unreachable"  # IK or workspace box rejected the touch; nothing moved
    ABORTED = "aborted"  # e-stop, stale joint states, time-out, dry run

    @property
    def observed(self) -> bool:
        """The touch published an observation on /tactile/contacts."""
        return self in (TouchOutcome.CONTACT, TouchOutcome.FREE_SPACE)


def _int(values: Mapping[str, str], key: str, default: int = 0) -> int:
    text = values.get(key, "")
    try:
        return int(text) if text != "" else default
    except ValueError:
        raise ValueError(f"{key} must be an integer, got {text!r}") from None


def _float(values: Mapping[str, str], key: str, default: float = 0.0) -> float:
    text = values.get(key, "")
    try:
        return float(text) if text != "" else default
    except ValueError:
        raise ValueError(f"{key} must be a number, got {text!r}") from None


def _optional_float(values: Mapping[str, str], key: str) -> Optional[float]:
    """A finite number, or None when the key is absent; ValueError otherwise."""
    if key not in values:
        return None
    value = _float(values, key, float("nan"))
    if not math.isfinite(value):
        raise ValueError(f"{key} must be a finite number, got {values[key]!r}")
    return value


def xyz_text(xyz: Optional[tuple]) -> str:
    """A point as exact text, ``'x,y,z'`` (``repr``: it reads back bit for bit); None → ``''``."""
    return "" if xyz is None else ",".join(repr(float(v)) for v in xyz)


def _xyz(values: Mapping[str, str], key: str) -> Optional[tuple]:
    text = values.get(key, "")
    if text == "":
        return None
    try:
        xyz = tuple(float(v) for v in text.split(","))
    except ValueError:
        xyz = ()
    if len(xyz) != 3 or not all(math.isfinite(v) for v in xyz):
        raise ValueError(f"{key} must be three finite numbers 'x,y,z', got {text!r}")
    return xyz


def _xyz_list_text(points: Optional[tuple]) -> Optional[str]:
    return None if points is None else ";".join(xyz_text(p) for p in points)


def _xyz_list(values: Mapping[str, str], key: str) -> Optional[tuple]:
    """``'x,y,z;x,y,z'`` → ((x, y, z), ...); the key absent → None (not told), ``''`` → ()."""
    text = values.get(key)
    if text is None:
        return None
    if not text:
        return ()
    parts = text.split(";")
    if "" in parts:
        raise ValueError(f"{key} must be three finite numbers 'x,y,z' per point, ';' between points, got {text!r}")
    return tuple(_xyz({key: part}, key) for part in parts)


@dataclass(frozen=True)
class PlanRequest:
    """Plan one touch on a map whose stamp is at least ``min_map_stamp_ns``.

    ``start_xyz_m`` (world, m) is where the touch starts: the nominal end of
    the previous touch (its pre-touch point, or the back-off point after a
    path contact), or the start position. Planning from this nominal point,
    not from the measured fingertip pose (which differs by the controller's
    tolerance), makes the graph's decisions those of the offline loop. None:
    plan from the measured pose (after an aborted touch).

    ``visited_xyz_m``: the targets of this run's earlier goals, in order;
    ``excluded_xyz_m``: those reported unreachable (world, m). With them the
    answer is a function of the request and the map alone. None: not told
    (the planner uses what it remembers). ``misses_before_contact``: how many
    touches met nothing while none has met the object yet (0 after the first
    contact; the planner's ``search_after_misses``). ``fruitless_xyz_m`` and
    ``last_target_var_m2``: the planner's judgment of earlier touches, as its
    last answer gave them (:class:`PlannerAnswer`; tactile_planner.fruitless).
    """

    request_id: int
    min_map_stamp_ns: int
    start_xyz_m: Optional[tuple] = None
    visited_xyz_m: Optional[tuple] = None
    excluded_xyz_m: Optional[tuple] = None
    misses_before_contact: int = 0
    fruitless_xyz_m: Optional[tuple] = None
    last_target_var_m2: Optional[float] = None

    def values(self) -> dict:
        out = {"request_id": str(self.request_id), "min_map_stamp_ns": str(self.min_map_stamp_ns),
               "start_xyz_m": xyz_text(self.start_xyz_m),
               "misses_before_contact": str(self.misses_before_contact)}
        for key in ("visited_xyz_m", "excluded_xyz_m", "fruitless_xyz_m"):
            text = _xyz_list_text(getattr(self, key))
            if text is not None:
                out[key] = text
        if self.last_target_var_m2 is not None:
            out["last_target_var_m2"] = repr(float(self.last_target_var_m2))
        return out

    @classmethod
    def from_values(cls, values: Mapping[str, str]) -> "PlanRequest":
        request_id = _int(values, "request_id", -1)
        if request_id < 0:
            raise ValueError("a plan request needs a non-negative request_id")
        misses = _int(values, "misses_before_contact", 0)
        if misses < 0:
            raise ValueError(f"misses_before_contact must be >= 0, got {misses}")
        return cls(request_id, _int(values, "min_map_stamp_ns"), _xyz(values, "start_xyz_m"),
                   _xyz_list(values, "visited_xyz_m"), _xyz_list(values, "excluded_xyz_m"), misses,
                   _xyz_list(values, "fruitless_xyz_m"), _optional_float(values, "last_target_var_m2"))


@dataclass(frozen=True)
class PlannerAnswer:
    """The planner's answer to one request: ``status`` 'ok' (a goal with stamp
    ``goal_stamp_ns`` was published) or why there is none. An 'ok' answer's
    ``extra`` has the chosen target, ``target_xyz_m`` (world, m): the
    explorer keeps it for the history of its next requests."""

    request_id: int
    status: str
    detail: str = ""
    goal_stamp_ns: int = 0
    decision_ms: float = float("nan")
    extra: Optional[Mapping[str, str]] = None

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    @property
    def target_xyz_m(self) -> Optional[tuple]:
        """The chosen target (None: not said); raises ValueError when malformed."""
        return _xyz(self.extra or {}, "target_xyz_m")

    @property
    def target_var_m2(self) -> Optional[float]:
        """The map's variance at the chosen target when it was chosen (None: not said)."""
        return _optional_float(self.extra or {}, "target_var_m2")

    @property
    def fruitless_xyz_m(self) -> Optional[tuple]:
        """The targets of the touches the planner judged fruitless so far (None: not said)."""
        return _xyz_list(self.extra or {}, "fruitless_xyz_m")

    def values(self) -> dict:
        out = {"request_id": str(self.request_id), "detail": self.detail, "stamp_ns": str(self.goal_stamp_ns),
               "decision_ms": f"{self.decision_ms:.2f}"}
        out.update(self.extra or {})
        return out

    @classmethod
    def from_values(cls, status: str, values: Mapping[str, str]) -> "PlannerAnswer":
        known = {"request_id", "detail", "stamp_ns", "decision_ms"}
        return cls(_int(values, "request_id", -1), status, values.get("detail", ""), _int(values, "stamp_ns"),
                   _float(values, "decision_ms", float("nan")),
                   {k: v for k, v in values.items() if k not in known})


@dataclass(frozen=True)
class TouchReport:
    """The end of one touch (``/arm/touch_done``)."""

    goal_stamp_ns: int
    outcome: TouchOutcome
    reason: str
    observation_stamp_ns: Optional[int]
    travel_m: float
    duration_s: float
    end_xyz_m: Optional[tuple] = None  # nominal end of the touch (world, m); None: unknown / did not move
    #: A slide (None: a poke): its slid length (m), why it stopped, and its contact stream: every
    #: contact (label 1 on /tactile/contacts) stamped from ``first_observation_stamp_ns`` (the
    #: approach's contact) to ``observation_stamp_ns`` (the last one), ``contacts`` of them.
    slide_m: Optional[float] = None
    slide_stop: str = ""
    first_observation_stamp_ns: Optional[int] = None
    contacts: int = 0

    @property
    def is_slide(self) -> bool:
        return self.slide_m is not None

    def values(self) -> dict:
        out = {
            "goal_stamp_ns": str(self.goal_stamp_ns),
            "observation_stamp_ns": "" if self.observation_stamp_ns is None else str(self.observation_stamp_ns),
            "travel_m": f"{self.travel_m:.6f}",
            "duration_s": f"{self.duration_s:.6f}",
            "reason": self.reason,
            "end_xyz_m": xyz_text(self.end_xyz_m),
        }
        if self.is_slide:  # a poke's report is unchanged
            out.update({"slide_m": f"{self.slide_m:.6f}", "slide_stop": self.slide_stop,
                        "first_observation_stamp_ns": "" if self.first_observation_stamp_ns is None
                        else str(self.first_observation_stamp_ns),
                        "contacts": str(int(self.contacts))})
        return out

    @classmethod
    def from_values(cls, outcome: str, values: Mapping[str, str]) -> "TouchReport":
        try:
            kind = TouchOutcome(outcome)
        except ValueError:
            raise ValueError(f"unknown touch outcome {outcome!r}; one of "
                             f"{', '.join(o.value for o in TouchOutcome)}") from None
        obs = values.get("observation_stamp_ns", "")
        slide = values.get("slide_m", "") != ""
        first = values.get("first_observation_stamp_ns", "")
        return cls(_int(values, "goal_stamp_ns"), kind, values.get("reason", ""),
                   _int(values, "observation_stamp_ns") if obs != "" else None,
                   _float(values, "travel_m"), _float(values, "duration_s"), _xyz(values, "end_xyz_m"),
                   _float(values, "slide_m") if slide else None, values.get("slide_stop", ""),
                   _int(values, "first_observation_stamp_ns") if first != "" else None,
                   _int(values, "contacts"))
