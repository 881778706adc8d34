"""``recorder``: record graph topics as serialized messages into a rosbag2-style MCAP file.

Subscribes with ``raw=True`` (CDR bytes, no deserialisation) to the listed
topics, or to every topic seen on the graph (re-discovered every
``discovery_period_s``), minus ``exclude``. A topic is subscribed once it has
a publisher, with a QoS adapted to its publishers' offers (latched topics are
recorded latched). ``log_time`` = receive time on the node clock (sim time
with ``use_sim_time``), ``publish_time`` = the publisher's source timestamp.
SIGINT/SIGTERM finalise the file (``close``).

What it cannot record is said in one line and counted; the rest is recorded:

- a topic with a type that is not installed here (or has no ``.msg``), or with
  several types at once: ``not recording <topic>: <why>``, once;
- a topic whose type changes (or gains a second type) after it was subscribed:
  only the first type is recorded (one channel per topic, as rosbag2), one warning;
- a message larger than ``max_message_bytes``: not recorded, counted, one warning
  per topic;
- an output that cannot be created (its folder missing, a file, read-only):
  one FATAL line, exit status 2;
- a write that fails mid-run (disk full, file size limit): one ERROR line, the
  recorder stops with status 1 (``scripts/explore.sh`` restarts it into the next
  file of the run, which the durable topics refill); the chunks written before
  stay readable (``python -m tactile_bringup.mcap_recorder --recover``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Dict, Optional

from rclpy.node import Node

from tactile_bringup.bag_ros import adapted_qos, declare_checked, message_class, qos_to_dict, string_list_parameter
from tactile_bringup.mcap_recorder import COMPRESSIONS, McapBagWriter
from tactile_bringup.msgdefs import DefinitionNotFound
from tactile_common.node_main import run_node


PARAMS = {
    "output": ("", "path of the .mcap file to write (never overwritten)"),
    "chunk_size_bytes": (1048576, "uncompressed size at which a chunk is written", {"ge": 1}),
    "compression": ("zstd", f"chunk compression: {', '.join(sorted(COMPRESSIONS))}", {"choices": tuple(sorted(COMPRESSIONS))}),
    "max_chunk_interval_s": (5.0, "write the open chunk at least this often (0 = only when full)", {"ge": 0.0}),
    "discovery_period_s": (1.0, "period of the topic discovery", {"gt": 0.0}),
    "queue_depth": (100, "subscription depth for volatile topics", {"ge": 1}),
    "max_message_bytes": (64 * 1024 * 1024, "larger serialized messages are counted, not recorded", {"ge": 1}),
}


class RecorderNode(Node):
    def __init__(self) -> None:
        super().__init__("recorder")
        p = declare_checked(self, PARAMS)
        self._topics = string_list_parameter(self, "topics", "topics to record; empty = every topic seen")
        self._exclude = set(string_list_parameter(self, "exclude", "topics never recorded"))
        if not p.output:
            raise ValueError("parameter 'output' (path of the .mcap to write) is required")
        if p.discovery_period_s <= 0:
            raise ValueError(f"discovery_period_s must be > 0, got {p.discovery_period_s}")
        output = Path(p.output).expanduser()
        try:
            self._writer = McapBagWriter(output, p.chunk_size_bytes, p.compression)
        except (FileExistsError, FileNotFoundError, PermissionError) as exc:
            raise ValueError(str(exc)) from None
        self._queue_depth = p.queue_depth
        self._max_bytes = p.max_message_bytes
        self._types: Dict[str, str] = {}  # recorded topic -> its type
        self._oversized: Dict[str, int] = {}  # topic -> messages above max_message_bytes
        self.lost_count = 0  # messages received after (or in the chunk open at) a write error
        self.done = False  # set after a write error: the spin ends, exit status 1
        self.exit_status = 0
        self._subs: Dict[str, object] = {}
        self._skipped: Dict[str, str] = {}  # topic -> why it is not recorded (logged once)
        self.invalid_count = 0
        self._closed = False
        self.create_timer(p.discovery_period_s, self._discover)
        if p.max_chunk_interval_s > 0:
            self.create_timer(p.max_chunk_interval_s, self._flush)
        self.get_logger().info(
            f"recording {'all topics' if not self._topics else self._topics} to {output}"
            + (f" (excluding {sorted(self._exclude)})" if self._exclude else "")
        )
        self._discover()

    def _wanted(self, topic: str) -> bool:
        return topic not in self._exclude and (not self._topics or topic in self._topics)

    def _skip(self, topic: str, why: str) -> None:
        if self._skipped.get(topic) != why:
            self._skipped[topic] = why
            self.get_logger().warning(f"not recording {topic}: {why}")

    def _discover(self) -> None:
        for topic, types in self.get_topic_names_and_types():
            if not self._wanted(topic):
                continue
            if topic in self._subs:
                others = [t for t in types if t != self._types[topic]]
                if others:  # one channel per topic (rosbag2): the first type only
                    self._skip(topic, f"also published as {', '.join(others)}; recording only its "
                                      f"{self._types[topic]} messages")
                continue
            if len(types) != 1:
                self._skip(topic, f"several types {types}")
                continue
            publishers = self.get_publishers_info_by_topic(topic)
            if not publishers:
                continue  # QoS unknown until a publisher appears
            self._subscribe(topic, types[0], publishers)

    def _subscribe(self, topic: str, type_name: str, publishers: list) -> None:
        offers = [qos_to_dict(info.qos_profile) for info in publishers]
        type_hash = str(publishers[0].topic_type_hash)
        try:
            msg_class = message_class(type_name)
            self._writer.add_topic(topic, type_name, offers, "" if type_hash == "INVALID" else type_hash)
        except (ValueError, DefinitionNotFound) as exc:
            self._skip(topic, str(exc))
            return
        self._types[topic] = type_name
        self._subs[topic] = self.create_subscription(
            msg_class, topic, lambda data, info, t=topic: self._on_message(t, data, info),
            # Durable event topics hand over their history in a burst when we match
            # late: the reader keeps as deep a queue as for volatile topics.
            adapted_qos(offers, self._queue_depth, latched_depth=self._queue_depth), raw=True,
        )
        self.get_logger().info(f"recording {topic} [{type_name}]")

    def _on_message(self, topic: str, data: bytes, info: Optional[dict]) -> None:
        if self._writer.error is not None:
            self.lost_count += 1
            return
        if len(data) > self._max_bytes:
            n = self._oversized[topic] = self._oversized.get(topic, 0) + 1
            if n == 1:
                self.get_logger().warning(
                    f"not recording a {len(data) / 2**20:.1f} MiB message of {topic}: larger than max_message_bytes "
                    f"({self._max_bytes} bytes); such messages are counted, the rest of {topic} is recorded")
            return
        log_time_ns = self.get_clock().now().nanoseconds
        sent_ns = (info or {}).get("source_timestamp") or log_time_ns
        try:
            self._writer.write(topic, data, log_time_ns, sent_ns)
        except OSError as exc:
            self._write_failed(exc, 1)
        except ValueError as exc:
            self.invalid_count += 1
            self.get_logger().error(f"could not write a message of {topic}: {exc}")

    def _flush(self) -> None:
        if self._writer.error is not None:
            return
        try:
            self._writer.flush()
        except OSError as exc:
            self._write_failed(exc, 0)

    def _write_failed(self, exc: OSError, in_hand: int) -> None:
        """A write failed (disk full, ...): one line, then stop (status 1); the written chunks stay."""
        self.lost_count += self._writer.pending + in_hand  # the open chunk did not reach the disk
        self.exit_status = 1
        self.done = True
        self.get_logger().error(
            f"cannot write {self._writer.path}: {exc.strerror or exc}; stopping the recorder (exit status 1). "
            f"Messages before the open chunk stay readable: python -m tactile_bringup.mcap_recorder "
            f"--recover {self._writer.path} OUT.mcap")

    def close(self) -> None:
        """Finalise the MCAP file (last chunk, rosbag2 metadata, summary)."""
        if self._closed:
            return
        self._closed = True
        failed_before = self._writer.error is not None
        try:
            self._writer.close()
        except OSError as exc:
            self.get_logger().error(
                f"could not finalise {self._writer.path}: {exc.strerror or exc}; its completed chunks stay readable: "
                f"python -m tactile_bringup.mcap_recorder --recover {self._writer.path} OUT.mcap")
        counts = {name: t.message_count for name, t in self._writer.topics.items()}
        missing = [t for t in self._topics if t not in counts]
        not_recorded = []
        if failed_before:
            not_recorded.append(f"{self.lost_count} messages from the open chunk on (write error)")
        if self._oversized:
            not_recorded.append(f"oversized {self._oversized}")
        self.get_logger().info(
            f"{'received' if failed_before else 'wrote'} {self._writer.message_count} messages "
            f"{'for' if failed_before else 'to'} {self._writer.path}: {counts}"
            + (f"; never seen: {missing}" if missing else "")
            + (f"; not recorded: {', '.join(not_recorded)}" if not_recorded else "")
        )


def main(args=None) -> int:
    return run_node(RecorderNode, args)
