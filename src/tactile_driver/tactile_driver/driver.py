"""The driver pipeline without ROS: bytes -> frames -> contacts in the world frame.

``SensorDriver.feed(data, now_s)`` decodes the bytes read from the device,
stamps each frame with host time (:class:`DeviceClock`), drops stale frames
(older than ``max_frame_age_s`` when read) and frames with the wrong taxel
count, runs the :class:`ContactDetector`, and turns each contact onset into
a world-frame contact with the fingertip pose interpolated at the frame's
time (:class:`PoseBuffer`). An onset newer than the newest pose waits for
the pose that covers its time, which arrives by another path (joint states
-> commander), however long the pose stream lags: while it waits it holds
``decided_through_s``, so the commander cannot end that approach as free
space (before, an onset whose wait expired was refused, the approach ended as
"free space" inside the object, and the re-armed detector reported the
contact later, deep; seen under load on the graph). ``add_pose`` returns the
contacts it completes. An onset the poses have passed without one within
tolerance of its time (older than the buffer, or a gap) is refused (counted)
and the detector re-armed, so a later frame with a pose can report it. The node publishes what ``feed`` and ``add_pose`` return.

The per-frame stream (``frame_contacts``, what a slide's servo reads): every
frame while the detector is in contact gives its current estimate in the
world frame (the pose at the frame's time, waited for like an onset's), and
the first frame out of contact gives a release (None). They come out in
frame order; a frame whose pose does not come within ``pose_wait_s`` is
dropped (counted in ``dropped_frame_contacts``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from tactile_driver.contact import ContactConfig, ContactDetector
from tactile_driver.device_clock import DeviceClock
from tactile_driver.pose_buffer import PoseBuffer
from tactile_driver.protocol import FrameDecoder
from tactile_driver.taxels import TaxelLayout


@dataclass(frozen=True)
class DriverConfig:
    max_frame_age_s: float = 0.25
    pose_tolerance_s: float = 0.02
    pose_buffer_s: float = 2.0
    clock_window_s: float = 2.0
    #: The device stamps frames in ROS time already (the simulated device stamps
    #: simulated time): use its stamps as they are instead of estimating the offset.
    device_clock_is_ros_time: bool = False
    pose_wait_s: float = 0.2


@dataclass(frozen=True)
class WorldContact:
    """A contact onset: host time, surface point (m), unit outward object normal, force (N)."""

    stamp_s: float
    point_xyz: np.ndarray
    normal_xyz: np.ndarray
    force_n: float


@dataclass
class DriverOutput:
    frames: list = field(default_factory=list)  # (stamp_s, values uint16) of every accepted frame
    contacts: list = field(default_factory=list)  # WorldContact
    frame_contacts: list = field(default_factory=list)  # (stamp_s, WorldContact or None = released), in order


@dataclass
class DriverStats:
    frames: int = 0  # accepted frames
    stale_frames: int = 0
    wrong_size_frames: int = 0
    contacts: int = 0
    refused_no_pose: int = 0
    dropped_frame_contacts: int = 0


class SensorDriver:
    """Decoder + device clock + detector + pose buffer."""

    def __init__(self, layout: TaxelLayout, contact: ContactConfig = ContactConfig(),
                 config: DriverConfig = DriverConfig()) -> None:
        self.layout = layout
        self.config = config
        self.decoder = FrameDecoder()
        self.detector = ContactDetector(layout, contact)
        self.poses = PoseBuffer(config.pose_buffer_s, config.pose_tolerance_s)
        self.clock = DeviceClock(config.clock_window_s)
        self.stats = DriverStats()
        self._pending: list = []  # (stamp_s, ContactEstimate) waiting for a pose
        self._frames_pending: list = []  # (stamp_s, ContactEstimate or None) of the per-frame stream, in order
        self.newest_frame_s = -np.inf  # stamp of the newest frame run through the detector

    @property
    def decided_through_s(self) -> float:
        """Every frame up to this stamp has been judged and its contact, if any, returned.

        A contact waiting for its pose holds it back to just before that frame.
        The arm commander ends an approach as free space only once this has
        passed the end of the approach: a fixed latency would decide by timing.
        """
        waiting = [s for s, _ in self._pending] + [s for s, e in self._frames_pending[:1] if e is not None]
        if waiting:
            return min(waiting) - 1e-9
        return self.newest_frame_s

    def device_reset(self) -> None:
        """After a reconnect: drop partial bytes and the sequence.

        The clock offset is kept: a device that kept running keeps its clock,
        so frames queued during the outage are recognised as stale; a device
        that restarted shows a backwards time jump and resets the estimate.
        """
        self.decoder.reset()

    def add_pose(self, t_s: float, position_m: np.ndarray, q_xyzw: np.ndarray) -> Optional[list]:
        """Buffer a fingertip pose; the pending contacts it completes (None: pose rejected)."""
        if not self.poses.add(t_s, position_m, q_xyzw):
            return None
        return self._resolve_pending(now_s=None)

    def take_frame_contacts(self, now_s: Optional[float] = None) -> list:
        """The per-frame stream resolved so far (module docstring), in frame order: a head that
        waits for its pose holds the rest back; with ``now_s`` a head waiting longer than
        ``pose_wait_s`` is dropped."""
        out = []
        newest = self.poses.newest_s
        while self._frames_pending:
            stamp_s, est = self._frames_pending[0]
            if est is None:
                out.append((stamp_s, None))
            else:
                pose = self.poses.at(stamp_s) if newest is not None and newest >= stamp_s else None
                if pose is not None:
                    point, normal = est.to_world(*pose)
                    out.append((stamp_s, WorldContact(stamp_s, point, normal, est.force_n)))
                elif now_s is not None and now_s - stamp_s > self.config.pose_wait_s:
                    self.stats.dropped_frame_contacts += 1
                else:
                    break
            self._frames_pending.pop(0)
        return out

    def _resolve_pending(self, now_s: Optional[float]) -> list:
        done, keep = [], []
        newest = self.poses.newest_s
        for stamp_s, est in self._pending:
            # Only a pose at or after the frame's time completes it (not the newest one within tolerance).
            pose = self.poses.at(stamp_s) if newest is not None and newest >= stamp_s else None
            if pose is not None:
                done.append(self._world(stamp_s, est, pose))
            elif newest is not None and newest >= stamp_s:  # the poses passed its time, none covers it
                self._refuse()
            else:  # the pose stream is behind: wait (it holds decided_through, so no approach ends as free space)
                keep.append((stamp_s, est))
        self._pending = keep
        return done

    def _world(self, stamp_s: float, est, pose) -> WorldContact:
        point, normal = est.to_world(*pose)
        self.stats.contacts += 1
        return WorldContact(stamp_s, point, normal, est.force_n)

    def _refuse(self) -> None:
        self.stats.refused_no_pose += 1
        self.detector.in_contact = False  # re-arm: report it from a frame with a pose

    def feed(self, data: bytes, now_s: float) -> DriverOutput:
        """Process the bytes read at host time ``now_s``."""
        out = DriverOutput(contacts=self._resolve_pending(now_s))
        for frame in self.decoder.feed(data):
            stamp_s = (frame.timestamp_s if self.config.device_clock_is_ros_time
                       else self.clock.to_host(frame.timestamp_s, now_s))
            if now_s - stamp_s > self.config.max_frame_age_s:
                self.stats.stale_frames += 1
                continue
            if frame.values.size != self.layout.n_taxels:
                self.stats.wrong_size_frames += 1
                continue
            self.stats.frames += 1
            self.newest_frame_s = max(self.newest_frame_s, stamp_s)
            out.frames.append((stamp_s, frame.values))
            was_in_contact = self.detector.in_contact
            est = self.detector.update(frame.values)
            if self.detector.in_contact and self.detector.current is not None:
                self._frames_pending.append((stamp_s, self.detector.current))
            elif was_in_contact and not self.detector.in_contact:
                self._frames_pending.append((stamp_s, None))  # released
            if est is None:
                continue
            newest = self.poses.newest_s
            if newest is not None and stamp_s > newest:
                # Its pose is on the way: wait for the pose that covers its time rather than take
                # the newest one (which pose had arrived would depend on timing, not on the touch).
                self._pending.append((stamp_s, est))
                continue
            pose = self.poses.at(stamp_s)
            if pose is not None:
                out.contacts.append(self._world(stamp_s, est, pose))
            else:
                self._refuse()
        out.frame_contacts = self.take_frame_contacts(now_s)
        return out
