"""MCAP writer core and message definitions against the independent rosbags library."""

from __future__ import annotations

import shutil

import pytest
import yaml
from mcap.reader import make_reader
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from tactile_bringup.mcap_recorder import McapBagWriter, qos_profile_dict, recover
from tactile_bringup.msgdefs import SEPARATOR, DefinitionNotFound, full_definition, msg_dependencies
from tactile_bringup.player import PlaybackClock, Recording

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
GRAPH_TYPES = [
    "std_msgs/msg/String", "std_msgs/msg/Header", "std_msgs/msg/Bool", "std_msgs/msg/Float32MultiArray",
    "geometry_msgs/msg/PoseStamped", "sensor_msgs/msg/PointCloud2", "sensor_msgs/msg/JointState",
    "nav_msgs/msg/Path", "nav_msgs/msg/OccupancyGrid", "visualization_msgs/msg/Marker",
    "diagnostic_msgs/msg/DiagnosticStatus", "trajectory_msgs/msg/JointTrajectory",
    "rosgraph_msgs/msg/Clock", "rcl_interfaces/msg/Log", "rcl_interfaces/msg/ParameterEvent",
]


@pytest.mark.parametrize("type_name", GRAPH_TYPES)
def test_full_definition_parses_to_rosbags_types(type_name):
    """Our schema text, parsed by rosbags, gives exactly rosbags' own Jazzy field definitions."""
    parsed = get_types_from_msg(full_definition(type_name), type_name)
    assert type_name in parsed
    for name, fields in parsed.items():
        assert fields == TYPESTORE.fielddefs[name], name
    # rosbags' own definition text (field order, no comments) describes the same types
    theirs = get_types_from_msg(TYPESTORE.generate_msgdef(type_name, ros_version=2)[0], type_name)
    assert parsed == theirs


def test_full_definition_layout_pose_stamped():
    """Root text first, then each dependency once, depth first, sorted per level (rosbag2's order)."""
    text = full_definition("geometry_msgs/msg/PoseStamped")
    headers = [line for line in text.splitlines() if line.startswith("MSG: ")]
    assert headers == [
        "MSG: geometry_msgs/Pose", "MSG: geometry_msgs/Point", "MSG: geometry_msgs/Quaternion",
        "MSG: std_msgs/Header", "MSG: builtin_interfaces/Time",
    ]
    assert text.count("\n" + SEPARATOR + "MSG: ") == 5
    assert len(SEPARATOR.strip()) == 80 and set(SEPARATOR.strip()) == {"="}


def test_dependencies_skip_comments_constants_and_primitives():
    text = "# Pose comment here\nuint8 A=1\nstring<=5 s\nPoint[] pts\nstd_msgs/Header h\nfloat64[3] v\n"
    assert msg_dependencies(text, "geometry_msgs") == ["geometry_msgs/Point", "std_msgs/Header"]


def test_unknown_type_is_a_clear_error():
    with pytest.raises(DefinitionNotFound, match="no .msg definition for 'nope_msgs/msg/X'"):
        full_definition("nope_msgs/msg/X")
    with pytest.raises(ValueError, match="invalid message type name"):
        full_definition("not a type")


def _write_bag(path, n=50, chunk=1500):
    string_t = TYPESTORE.types["std_msgs/msg/String"]
    w = McapBagWriter(path, chunk_size_bytes=chunk)
    latched = qos_profile_dict("keep_last", 1, "reliable", "transient_local")
    w.add_topic("/s", "std_msgs/msg/String", [latched], TYPESTORE.hash_rihs01("std_msgs/msg/String"))
    sent = []
    for i in range(n):
        data = bytes(TYPESTORE.serialize_cdr(string_t(data=f"message {i}"), "std_msgs/msg/String"))
        w.write("/s", data, 1_000 + 10 * i, 990 + 10 * i)
        sent.append(data)
    return w, sent


def test_writer_output_reads_back_with_rosbags(tmp_path):
    w, sent = _write_bag(tmp_path / "a.mcap")
    w.close()
    with Reader(tmp_path / "a.mcap") as reader:
        assert reader.message_count == len(sent)
        (conn,) = reader.connections
        assert (conn.topic, conn.msgtype, conn.msgdef.format.name) == ("/s", "std_msgs/msg/String", "MSG")
        (offer,) = conn.ext.offered_qos_profiles
        assert offer.durability.name == "TRANSIENT_LOCAL" and offer.depth == 1
        got = [(t, bytes(d)) for _, t, d in reader.messages()]
    assert got == [(1_000 + 10 * i, d) for i, d in enumerate(sent)]
    with open(tmp_path / "a.mcap", "rb") as fh:
        mreader = make_reader(fh)
        assert mreader.get_header().profile == "ros2"
        summary = mreader.get_summary()
        assert summary.statistics.chunk_count > 1
        assert {ci.compression for ci in summary.chunk_indexes} == {"zstd"}
        (channel,) = summary.channels.values()
        assert channel.message_encoding == "cdr"
        assert channel.metadata["topic_type_hash"] == TYPESTORE.hash_rihs01("std_msgs/msg/String")
        pub_times = [m.publish_time for _, _, m in mreader.iter_messages()]
        assert pub_times == [990 + 10 * i for i in range(len(sent))]
        (meta,) = [m for m in mreader.iter_metadata() if m.name == "rosbag2"]
    info = yaml.safe_load(meta.metadata["serialized_metadata"])["rosbag2_bagfile_information"]
    assert info["version"] == 9 and info["storage_identifier"] == "mcap"
    assert info["message_count"] == len(sent)
    assert info["duration"]["nanoseconds"] == 10 * (len(sent) - 1)
    assert info["starting_time"]["nanoseconds_since_epoch"] == 1_000
    (topic,) = info["topics_with_message_count"]
    assert topic["message_count"] == len(sent)
    assert topic["topic_metadata"]["offered_qos_profiles"][0]["durability"] == "transient_local"
    assert info["relative_file_paths"] == ["a.mcap"]


def test_writer_refuses_to_overwrite(tmp_path):
    (tmp_path / "x.mcap").write_bytes(b"keep me")
    with pytest.raises(FileExistsError, match="refusing to overwrite"):
        McapBagWriter(tmp_path / "x.mcap")
    assert (tmp_path / "x.mcap").read_bytes() == b"keep me"
    with pytest.raises(ValueError, match="compression"):
        McapBagWriter(tmp_path / "y.mcap", compression="gzip")


def test_unfinished_file_keeps_completed_chunks(tmp_path):
    """A copy taken before close() (as after SIGKILL) holds every completed chunk."""
    w, sent = _write_bag(tmp_path / "a.mcap", n=60)
    shutil.copy(tmp_path / "a.mcap", tmp_path / "cut.mcap")
    w.close()
    with pytest.raises(ValueError, match="recover it first"):
        Recording(tmp_path / "cut.mcap")
    n = recover(tmp_path / "cut.mcap", tmp_path / "fixed.mcap")
    assert 0 < n < len(sent)
    with Reader(tmp_path / "fixed.mcap") as reader:
        got = [bytes(d) for _, _, d in reader.messages()]
    assert got == sent[:n]


def test_recording_and_playback_clock(tmp_path):
    w, sent = _write_bag(tmp_path / "a.mcap")
    w.close()
    rec = Recording(tmp_path / "a.mcap")
    assert rec.topics["/s"].message_count == len(sent)
    assert [d for _, _, d in rec.messages()] == sent
    with pytest.raises(ValueError, match="not in"):
        rec.select(["/missing"])
    clock = PlaybackClock(1_000, 100.0, rate=2.0)
    assert clock.wall_s(1_000 + 2_000_000_000) == pytest.approx(101.0)
    assert clock.recorded_ns(101.0) == 1_000 + 2_000_000_000
    with pytest.raises(ValueError, match="rate"):
        PlaybackClock(0, 0.0, rate=0.0)
