"""``player``: publish an MCAP recording back onto the graph at its recorded timing.

One publisher per recorded topic with the recorded QoS adapted to its
offers (latched topics stay TRANSIENT_LOCAL); messages are published as raw
CDR bytes in ``log_time`` order at ``wall = start + (t - t0) / rate``.
Before starting it waits up to ``wait_for_subscribers_s`` for every
volatile topic to have a subscriber. Optionally publishes ``/clock`` from the recorded
times. Exits when done (unless ``loop``), after ``linger_s``.
"""

from __future__ import annotations

import time
from typing import Iterator, Optional, Tuple

from rclpy.duration import Duration
from rclpy.node import Node
from rosgraph_msgs.msg import Clock

from tactile_bringup.bag_ros import adapted_qos, declare_checked, message_class, string_list_parameter
from tactile_bringup.player import PlaybackClock, Recording
from tactile_common import qos, topics
from tactile_common.node_main import run_node
from tactile_common.stamps import time_from_ns

_EARLY_S = 0.0005  # publish a message this close to its due time now
_ACK_TIMEOUT_S = 2.0  # at the end, wait at most this long for acknowledgements
_LOOP_GAP_S = 0.01  # pause between two passes of a loop


PARAMS = {
    "bag": ("", "path of the .mcap recording to play"),
    "rate": (1.0, "playback speed factor", {"gt": 0.0}),
    "loop": (False, "start again at the end", {"dynamic": True}),
    "clock": (False, "publish /clock from the recorded times"),
    "clock_hz": (100.0, "/clock publish rate", {"gt": 0.0}),
    "wait_for_subscribers_s": (2.0, "wait at most this long for subscribers before starting", {"ge": 0.0, "dynamic": True}),
    "linger_s": (0.0, "keep publishers alive this long after the end (latched topics)", {"ge": 0.0, "dynamic": True}),
    "progress_period_s": (1.0, "progress log period", {"gt": 0.0}),
    "queue_depth": (100, "publisher depth of volatile topics", {"ge": 1}),
}


class PlayerNode(Node):
    def __init__(self) -> None:
        super().__init__("player")
        p = declare_checked(self, PARAMS)
        selected = string_list_parameter(self, "topics", "topics to play; empty = all recorded")
        if not p.bag:
            raise ValueError("parameter 'bag' (the .mcap to play) is required")
        if not p.rate > 0:
            raise ValueError(f"rate must be > 0, got {p.rate}")
        if p.clock and not p.clock_hz > 0:
            raise ValueError(f"clock_hz must be > 0, got {p.clock_hz}")
        if not p.progress_period_s > 0:
            raise ValueError(f"progress_period_s must be > 0, got {p.progress_period_s}")
        self._rec = Recording(p.bag)
        self._topics = self._rec.select(selected)
        if p.clock and topics.CLOCK in self._topics:
            self.get_logger().warning("publishing /clock from the recorded times; the recorded /clock is skipped")
            self._topics.remove(topics.CLOCK)
        self._p = p
        self._pubs = {
            name: self.create_publisher(
                message_class(self._rec.topics[name].type_name), name,
                adapted_qos(self._rec.topics[name].offered_qos_profiles, p.queue_depth),
            )
            for name in self._topics
        }
        self._clock_pub = self.create_publisher(Clock, topics.CLOCK, qos.CLOCK) if p.clock else None
        self._total = sum(self._rec.topics[t].message_count for t in self._topics)
        if self._total == 0:
            raise ValueError(f"no messages to play in {p.bag} on {self._topics}")
        self._played = 0
        self._loops = 0
        self._iter: Optional[Iterator[Tuple[str, int, bytes]]] = None
        self._next: Optional[Tuple[str, int, bytes]] = None
        self._pclock: Optional[PlaybackClock] = None
        self._timer = None
        self._wait_started_s = time.monotonic()
        self._wait_timer = self.create_timer(0.05, self._wait_for_subscribers)
        if p.clock:
            self.create_timer(1.0 / p.clock_hz, self._publish_clock)
        self._progress_timer = None
        self.get_logger().info(
            f"playing {self._total} messages on {len(self._topics)} topics, "
            f"{self._rec.duration_s:.1f} s recorded, at rate {p.rate} from {p.bag}"
        )

    # -- start -----------------------------------------------------------------
    def _wait_for_subscribers(self) -> None:
        # Every topic, durable ones too: the graph's event topics are TRANSIENT_LOCAL now, and a
        # durable publisher's history (depth 1 here) would hand a late subscriber only the last event.
        unmatched = [t for t, pub in self._pubs.items() if pub.get_subscription_count() == 0]
        waited_s = time.monotonic() - self._wait_started_s
        if unmatched and waited_s < self._p.wait_for_subscribers_s:
            return
        self.destroy_timer(self._wait_timer)
        if unmatched:
            self.get_logger().info(f"no subscriber after {waited_s:.1f} s on {unmatched}; starting anyway")
        self._progress_timer = self.create_timer(self._p.progress_period_s, self._log_progress)
        self._start_pass()

    def _start_pass(self) -> None:
        self._cancel_timer()
        self._iter = self._rec.messages(self._topics)
        self._next = next(self._iter, None)
        self._pclock = PlaybackClock(self._rec.start_ns, time.monotonic(), self._p.rate)
        self._tick()

    # -- playback --------------------------------------------------------------
    def _cancel_timer(self) -> None:
        if self._timer is not None:
            self.destroy_timer(self._timer)
            self._timer = None

    def _tick(self) -> None:
        self._cancel_timer()
        while self._next is not None:
            topic, t_ns, data = self._next
            delay_s = self._pclock.wall_s(t_ns) - time.monotonic()
            if delay_s > _EARLY_S:
                self._timer = self.create_timer(delay_s, self._tick)
                return
            self._pubs[topic].publish(data)
            self._played += 1
            self._next = next(self._iter, None)
        self._end_pass()

    def _end_pass(self) -> None:
        if self._p.loop:
            self._loops += 1
            self.get_logger().info(f"pass {self._loops} done; looping")
            self._timer = self.create_timer(_LOOP_GAP_S, self._start_pass)  # not recursive
            return
        self._log_progress()
        self.get_logger().info(f"done: {self._played} messages played")
        if self._p.linger_s > 0:
            self._timer = self.create_timer(self._p.linger_s, self._finish)
        else:
            self._finish()

    def _finish(self) -> None:
        """Wait (bounded) until reliable subscribers acknowledged everything, then stop."""
        deadline_s = time.monotonic() + _ACK_TIMEOUT_S
        for topic, pub in self._pubs.items():
            left_s = max(deadline_s - time.monotonic(), 0.0)
            if not pub.wait_for_all_acked(Duration(nanoseconds=int(left_s * 1e9))):
                self.get_logger().warning(f"{topic}: not every subscriber acknowledged the last messages")
        self.context.try_shutdown()

    def _publish_clock(self) -> None:
        t_ns = self._rec.start_ns if self._pclock is None else self._pclock.recorded_ns(time.monotonic())
        t_ns = min(t_ns, self._rec.end_ns) if not self._p.loop else t_ns
        msg = Clock(clock=time_from_ns(t_ns))
        self._clock_pub.publish(msg)

    def _log_progress(self) -> None:
        if self._pclock is None:
            return
        t_s = min((self._pclock.recorded_ns(time.monotonic()) - self._rec.start_ns) * 1e-9, self._rec.duration_s)
        self.get_logger().info(
            f"played {self._played}"
            + (f" messages (pass {self._loops + 1}, {self._total} per pass)" if self._p.loop else f"/{self._total} messages")
            + f", {t_s:.1f}/{self._rec.duration_s:.1f} s"
        )


def main(args=None) -> int:
    return run_node(PlayerNode, args)
