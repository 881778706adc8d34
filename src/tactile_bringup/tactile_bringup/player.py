"""Read a rosbag2-style MCAP recording for playback (ROS-free).

:class:`Recording` gives the topics (type, offered QoS profiles, type hash
from the channel metadata) and the serialized messages in ``log_time``
order. :class:`PlaybackClock` maps recorded time to wall time for a rate:
``wall(t) = wall_start + (t - t_start) / rate``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Dict, Iterable, Iterator, List, Optional, Tuple

import yaml
from mcap.exceptions import McapError
from mcap.reader import make_reader

_RECOVER_HINT = "recover it first: python -m tactile_bringup.mcap_recorder --recover IN.mcap OUT.mcap"


@dataclass(frozen=True)
class RecordedTopic:
    name: str
    type_name: str
    offered_qos_profiles: List[Dict[str, Any]]
    type_hash: str
    message_count: int


class Recording:
    """An MCAP file written by the recorder (or rosbag2).

    Raises:
        ValueError: the file is missing, not MCAP, not profile ``ros2`` or not
            finalised (a recording cut by SIGKILL: run ``recover`` first).
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        if not self.path.is_file():
            raise ValueError(f"recording '{self.path}' does not exist")
        try:
            with open(self.path, "rb") as fh:
                reader = make_reader(fh)
                header = reader.get_header()
                summary = reader.get_summary()
        except (McapError, OSError, ValueError) as exc:
            raise ValueError(
                f"'{self.path}' is not a readable, finalised MCAP file ({exc}); if the recorder "
                f"was killed, {_RECOVER_HINT}"
            ) from None
        if header.profile != "ros2":
            raise ValueError(f"'{self.path}' has MCAP profile '{header.profile}', not 'ros2'")
        if summary is None or summary.statistics is None:
            raise ValueError(f"'{self.path}' is not finalised (recorder killed?): {_RECOVER_HINT}")
        counts = summary.statistics.channel_message_counts
        self.topics: Dict[str, RecordedTopic] = {}
        for cid, ch in summary.channels.items():
            schema = summary.schemas.get(ch.schema_id)
            profiles = yaml.safe_load(ch.metadata.get("offered_qos_profiles", "") or "[]") or []
            self.topics[ch.topic] = RecordedTopic(
                ch.topic, schema.name if schema else "", list(profiles),
                ch.metadata.get("topic_type_hash", ""), int(counts.get(cid, 0)),
            )
        self.message_count = int(summary.statistics.message_count)
        self.start_ns = int(summary.statistics.message_start_time)
        self.end_ns = int(summary.statistics.message_end_time)

    @property
    def duration_s(self) -> float:
        return (self.end_ns - self.start_ns) * 1e-9 if self.message_count else 0.0

    def select(self, topics: Optional[Iterable[str]]) -> List[str]:
        """The recorded topics to play: all if ``topics`` is empty; ValueError on unknown names."""
        wanted = list(topics or [])
        unknown = [t for t in wanted if t not in self.topics]
        if unknown:
            raise ValueError(f"topics {unknown} are not in '{self.path}' (it has {sorted(self.topics)})")
        return wanted or sorted(self.topics)

    def messages(self, topics: Optional[Iterable[str]] = None) -> Iterator[Tuple[str, int, bytes]]:
        """(topic, log_time_ns, cdr_bytes) in log-time order (ties: file order)."""
        selected = list(topics) if topics else None
        with open(self.path, "rb") as fh:
            reader = make_reader(fh)
            for _, channel, message in reader.iter_messages(topics=selected, log_time_order=True):
                yield channel.topic, message.log_time, message.data


class PlaybackClock:
    """Recorded time <-> wall time for playback at ``rate`` (2.0 = twice as fast)."""

    def __init__(self, start_recorded_ns: int, start_wall_s: float, rate: float) -> None:
        if not rate > 0:
            raise ValueError(f"rate must be > 0, got {rate}")
        self.start_recorded_ns = int(start_recorded_ns)
        self.start_wall_s = float(start_wall_s)
        self.rate = float(rate)

    def wall_s(self, recorded_ns: int) -> float:
        """Wall time (s) at which a message recorded at ``recorded_ns`` is due."""
        return self.start_wall_s + (int(recorded_ns) - self.start_recorded_ns) * 1e-9 / self.rate

    def recorded_ns(self, wall_s: float) -> int:
        """Recorded time (ns) shown at wall time ``wall_s`` (for /clock)."""
        return self.start_recorded_ns + int(round((wall_s - self.start_wall_s) * self.rate * 1e9))
