"""Write serialized ROS 2 messages to MCAP exactly as rosbag2's MCAP storage does.

File layout (what ``ros2 bag info``, rosbags and Foxglove expect):

- header profile ``ros2``;
- one schema per message type: name ``pkg/msg/Type``, encoding ``ros2msg``,
  data = the full definition (:mod:`tactile_bringup.msgdefs`);
- one channel per topic: message encoding ``cdr``, metadata
  ``offered_qos_profiles`` (YAML list in rosbag2's format) and
  ``topic_type_hash`` (``RIHS01_...``);
- messages with ``log_time`` = receive time and ``publish_time`` = send time
  (nanoseconds), in zstd-compressed chunks;
- at :meth:`McapBagWriter.close`, a metadata record ``rosbag2`` with
  ``serialized_metadata`` (the YAML of rosbag2's ``metadata.yaml``, version 9).

Each completed chunk is flushed to the file at once, so after a SIGKILL every
completed chunk is still readable (:func:`recover` rewrites such a file into
a finalised one).

ROS-free: QoS profiles are plain dicts (see :func:`qos_profile_dict`).
"""

from __future__ import annotations

import logging
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional, Sequence

import yaml
from mcap.exceptions import McapError
from mcap.records import Channel, Message, Schema
from mcap.stream_reader import StreamReader
from mcap.writer import CompressionType, Writer

from tactile_bringup.msgdefs import full_definition

_LOG = logging.getLogger(__name__)

PROFILE = "ros2"
LIBRARY = "tactile_bringup.mcap_recorder"
ROSBAG2_METADATA_VERSION = 9
ROS_DISTRO = "jazzy"
COMPRESSIONS = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "none": CompressionType.NONE}
#: rmw's "infinite" duration (INT64_MAX ns) as rosbag2 writes it.
INFINITE_NS = 2**63 - 1


def duration_dict(ns: int) -> Dict[str, int]:
    """Nanoseconds -> ``{sec, nsec}`` as in rosbag2's QoS YAML (INT64_MAX = infinite)."""
    sec, nsec = divmod(int(ns), 1_000_000_000)
    return {"sec": sec, "nsec": nsec}


def qos_profile_dict(
    history: str,
    depth: int,
    reliability: str,
    durability: str,
    deadline_ns: int = INFINITE_NS,
    lifespan_ns: int = INFINITE_NS,
    liveliness: str = "automatic",
    liveliness_lease_duration_ns: int = INFINITE_NS,
    avoid_ros_namespace_conventions: bool = False,
) -> Dict[str, Any]:
    """One offered QoS profile in rosbag2's (metadata version 9) YAML layout.

    Policies are lower-case names: ``keep_last``/``keep_all``,
    ``reliable``/``best_effort``, ``transient_local``/``volatile``,
    ``automatic``/``manual_by_topic``.
    """
    return {
        "history": history,
        "depth": int(depth),
        "reliability": reliability,
        "durability": durability,
        "deadline": duration_dict(deadline_ns),
        "lifespan": duration_dict(lifespan_ns),
        "liveliness": liveliness,
        "liveliness_lease_duration": duration_dict(liveliness_lease_duration_ns),
        "avoid_ros_namespace_conventions": bool(avoid_ros_namespace_conventions),
    }


def dump_qos_profiles(profiles: Sequence[Mapping[str, Any]]) -> str:
    """The ``offered_qos_profiles`` channel metadata string (a YAML list)."""
    if not profiles:
        return ""
    return yaml.safe_dump([dict(p) for p in profiles], sort_keys=False).rstrip("\n")


@dataclass
class TopicRecord:
    """One recorded topic: its channel and counters."""

    name: str
    type_name: str
    channel_id: int
    offered_qos_profiles: List[Dict[str, Any]]
    type_hash: str
    message_count: int = 0


@dataclass
class _Stats:
    count: int = 0
    start_ns: Optional[int] = None
    end_ns: Optional[int] = None

    def add(self, t_ns: int) -> None:
        self.count += 1
        self.start_ns = t_ns if self.start_ns is None else min(self.start_ns, t_ns)
        self.end_ns = t_ns if self.end_ns is None else max(self.end_ns, t_ns)


class McapBagWriter:
    """A rosbag2-compatible MCAP file being written.

    Usage::

        w = McapBagWriter("run.mcap")
        w.add_topic("/chatter", "std_msgs/msg/String", [qos_profile_dict(...)], "RIHS01_...")
        w.write("/chatter", cdr_bytes, log_time_ns, publish_time_ns)
        w.close()

    A write that fails (disk full, file size limit, I/O error) raises ``OSError`` and
    leaves the writer *failed* (``error`` holds the first error): every later
    :meth:`write` and :meth:`flush` raises at once, and :meth:`close` only closes the
    file, so nothing is appended after the partial record. The chunks completed
    before the error stay readable (:func:`recover`).

    Raises:
        FileExistsError: ``path`` exists (never overwrites a recording).
        FileNotFoundError: the directory of ``path`` does not exist or is not a directory.
        PermissionError: the file cannot be created (read-only directory, ...).
        ValueError: unknown compression or a non-positive chunk size.
    """

    def __init__(self, path: str | Path, chunk_size_bytes: int = 1024 * 1024, compression: str = "zstd") -> None:
        self.path = Path(path)
        if compression not in COMPRESSIONS:
            raise ValueError(f"compression '{compression}' is not one of {sorted(COMPRESSIONS)}")
        if chunk_size_bytes <= 0:
            raise ValueError(f"chunk size must be positive, got {chunk_size_bytes}")
        if self.path.exists():
            raise FileExistsError(f"refusing to overwrite existing recording '{self.path}'")
        parent = self.path.parent
        if not parent.is_dir():
            what = "is not a directory" if parent.exists() else "does not exist"
            raise FileNotFoundError(f"output directory '{parent}' {what}")
        try:
            self._stream = open(self.path, "xb")
        except OSError as exc:  # read-only directory or file system, no space, ...
            raise PermissionError(f"cannot create the recording '{self.path}': {exc.strerror or exc}") from None
        self._writer = Writer(self._stream, chunk_size=chunk_size_bytes, compression=COMPRESSIONS[compression])
        self._writer.start(profile=PROFILE, library=LIBRARY)
        self._stream.flush()
        self._schemas: Dict[str, int] = {}
        self.topics: Dict[str, TopicRecord] = {}
        self._stats = _Stats()
        self._pending = 0  # messages not yet in a written chunk
        self._closed = False
        self.error: Optional[OSError] = None  # the first failed write; the file ends at the last chunk before it

    # -- topics ----------------------------------------------------------------
    def add_topic(
        self,
        name: str,
        type_name: str,
        offered_qos_profiles: Sequence[Mapping[str, Any]] = (),
        type_hash: str = "",
        definition: Optional[str] = None,
    ) -> TopicRecord:
        """Register a topic (its schema once per type); ``definition`` defaults to the .msg files."""
        if name in self.topics:
            raise ValueError(f"topic '{name}' is already recorded")
        if type_name not in self._schemas:
            text = full_definition(type_name) if definition is None else definition
            self._schemas[type_name] = self._writer.register_schema(type_name, "ros2msg", text.encode())
        profiles = [dict(p) for p in offered_qos_profiles]
        channel_id = self._writer.register_channel(
            topic=name,
            message_encoding="cdr",
            schema_id=self._schemas[type_name],
            metadata={"offered_qos_profiles": dump_qos_profiles(profiles), "topic_type_hash": type_hash},
        )
        record = TopicRecord(name, type_name, channel_id, profiles, type_hash)
        self.topics[name] = record
        return record

    # -- messages --------------------------------------------------------------
    def write(self, topic: str, data: bytes, log_time_ns: int, publish_time_ns: Optional[int] = None) -> None:
        """Append one serialized (CDR) message; a completed chunk goes to disk at once.

        Raises:
            OSError: the file cannot be written (the writer is failed from then on).
        """
        record = self.topics[topic]
        self._check_failed()
        try:
            before = self._stream.tell()
            self._writer.add_message(
                channel_id=record.channel_id,
                log_time=int(log_time_ns),
                data=bytes(data),
                publish_time=int(log_time_ns if publish_time_ns is None else publish_time_ns),
                sequence=record.message_count,
            )
            record.message_count += 1
            self._stats.add(int(log_time_ns))
            self._pending += 1
            if self._stream.tell() != before:  # a chunk was completed: make it durable now
                self._stream.flush()
                self._pending = 0
        except OSError as exc:
            self.error = exc
            raise

    def flush(self) -> None:
        """Close the chunk in progress (if it has messages) and write it to disk.

        Raises:
            OSError: the file cannot be written (the writer is failed from then on).
        """
        self._check_failed()
        if self._pending:
            try:
                self._writer.flush()
                self._stream.flush()
            except OSError as exc:
                self.error = exc
                raise
            self._pending = 0

    @property
    def pending(self) -> int:
        """Messages in the chunk in progress (not yet on disk)."""
        return self._pending

    def _check_failed(self) -> None:
        if self.error is not None:
            raise OSError(self.error.errno, f"the recording stopped at an earlier error: {self.error.strerror or self.error}")

    @property
    def message_count(self) -> int:
        return self._stats.count

    # -- finalise --------------------------------------------------------------
    def bag_metadata(self) -> Dict[str, Any]:
        """rosbag2's ``metadata.yaml`` content (version 9) for what was written so far."""
        start = self._stats.start_ns or 0
        duration = (self._stats.end_ns - self._stats.start_ns) if self._stats.count else 0
        topics = [
            {
                "topic_metadata": {
                    "name": t.name,
                    "type": t.type_name,
                    "serialization_format": "cdr",
                    "offered_qos_profiles": t.offered_qos_profiles,
                    "type_description_hash": t.type_hash,
                },
                "message_count": t.message_count,
            }
            for t in self.topics.values()
        ]
        return {
            "rosbag2_bagfile_information": {
                "version": ROSBAG2_METADATA_VERSION,
                "storage_identifier": "mcap",
                "duration": {"nanoseconds": duration},
                "starting_time": {"nanoseconds_since_epoch": start},
                "message_count": self._stats.count,
                "topics_with_message_count": topics,
                "compression_format": "",
                "compression_mode": "",
                "relative_file_paths": [self.path.name],
                "files": [{
                    "path": self.path.name,
                    "starting_time": {"nanoseconds_since_epoch": start},
                    "duration": {"nanoseconds": duration},
                    "message_count": self._stats.count,
                }],
                "custom_data": {},
                "ros_distro": ROS_DISTRO,
            }
        }

    def close(self) -> None:
        """Write the last chunk, the ``rosbag2`` metadata record and the summary; close the file.

        A failed writer only closes the file (it ends with the chunks written before the
        error, readable with :func:`recover`).

        Raises:
            OSError: finalising failed (the file is closed; the completed chunks stay readable).
        """
        if self._closed:
            return
        self._closed = True
        if self.error is not None:
            try:
                self._stream.close()  # may try to write what the buffer holds again
            except OSError:
                pass
            return
        try:
            self._finish()
        except OSError as exc:
            self.error = exc
            try:
                self._stream.close()
            except OSError:
                pass
            raise

    def _finish(self) -> None:
        self._writer.add_metadata("rosbag2", {
            "serialized_metadata": yaml.safe_dump(self.bag_metadata(), sort_keys=False),
            "ROS_DISTRO": ROS_DISTRO,
        })
        self._writer.finish()
        self._stream.close()


def recover(damaged: str | Path, output: str | Path) -> int:
    """Copy every readable message of an unfinished MCAP (e.g. after SIGKILL) into a finalised file.

    Reads records in file order until the data ends or a record is truncated;
    schemas, channels and their metadata are kept. Returns the number of
    messages recovered.
    """
    schemas: Dict[int, Schema] = {}
    channels: Dict[int, Channel] = {}
    messages: List[Message] = []
    with open(damaged, "rb") as fh:
        try:
            for record in StreamReader(fh, skip_magic=False).records:
                if isinstance(record, Schema):
                    schemas[record.id] = record
                elif isinstance(record, Channel):
                    channels[record.id] = record
                elif isinstance(record, Message):
                    messages.append(record)
        except (McapError, EOFError, ValueError, struct.error) as exc:  # the truncated tail
            _LOG.info("recover: stopped at a truncated record (%s)", exc)
    writer = McapBagWriter(output)
    by_channel = {}
    for cid, ch in channels.items():
        schema = schemas.get(ch.schema_id)
        profiles = yaml.safe_load(ch.metadata.get("offered_qos_profiles", "") or "[]") or []
        by_channel[cid] = writer.add_topic(
            ch.topic, schema.name if schema else "", profiles, ch.metadata.get("topic_type_hash", ""),
            definition=schema.data.decode() if schema else "",
        ).name
    for msg in messages:
        if msg.channel_id in by_channel:
            writer.write(by_channel[msg.channel_id], msg.data, msg.log_time, msg.publish_time)
    writer.close()
    return writer.message_count


def main(argv: Optional[Sequence[str]] = None) -> int:
    """``python -m tactile_bringup.mcap_recorder --recover IN.mcap OUT.mcap``."""
    import argparse
    import sys

    parser = argparse.ArgumentParser(description="Recover the completed chunks of an unfinished MCAP recording.")
    parser.add_argument("--recover", nargs=2, metavar=("IN", "OUT"), required=True)
    args = parser.parse_args(argv)
    try:
        n = recover(*args.recover)
    except (OSError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"recovered {n} messages into {args.recover[1]}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
