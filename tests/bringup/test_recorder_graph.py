"""The recorder on a real graph: files that rosbags opens, and chunks that survive SIGKILL."""

from __future__ import annotations

import io
import os
import signal
import struct
from pathlib import Path

import pytest
import yaml
from geometry_msgs.msg import PoseStamped
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Channel, Message
from mcap.stream_reader import StreamReader
from rclpy.serialization import serialize_message
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from std_msgs.msg import String

from tactile_bringup.mcap_recorder import recover
from tactile_common import qos, topics
from tactile_common.pointcloud import to_pointcloud2
from tactile_common.smoke import seeded_cloud
from tactile_common.stamps import time_from_ns

pytestmark = pytest.mark.graph

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
N_POSES = 20
N_POINTS = 50
LATCHED_TEXT = "latched hello"


def decode(data: bytes, type_name: str):
    """A message deserialised by rosbags (independent of rclpy)."""
    return TYPESTORE.deserialize_cdr(data, type_name)


def cloud_key(data: bytes) -> tuple:
    """Comparable content of a PointCloud2 (CDR padding bytes may differ between serializers)."""
    msg = decode(data, "sensor_msgs/msg/PointCloud2")
    return (msg.header.frame_id, msg.width, msg.point_step, [f.name for f in msg.fields], msg.data.tobytes())


def talker_cloud_key() -> tuple:
    """What cloud_talker (seed 0) publishes."""
    return cloud_key(serialize_message(to_pointcloud2(seeded_cloud(0, N_POINTS), topics.WORLD_FRAME)))


def _on_disk(path: Path) -> dict:
    """Messages per topic in the chunks the recorder has written so far (its file still open)."""
    counts: dict = {}
    topic_of: dict = {}
    if not path.exists():
        return counts
    try:
        for record in StreamReader(io.BytesIO(path.read_bytes()), skip_magic=False).records:
            if isinstance(record, Channel):
                topic_of[record.id] = record.topic
            elif isinstance(record, Message):
                topic = topic_of[record.channel_id]
                counts[topic] = counts.get(topic, 0) + 1
    except (McapError, EOFError, ValueError, struct.error):
        pass  # the record being written
    return counts


def _subscribed(node, topic: str, node_name: str) -> bool:
    return any(i.node_name == node_name for i in node.get_subscriptions_info_by_topic(topic))


def record_short_graph(graph, output: Path) -> dict:
    """Record cloud_talker, a latched String and a PoseStamped stream; stop the recorder (SIGINT).

    Returns the serialized messages the test published, by topic.
    """
    graph.start("talker", ["cloud_talker", "--ros-args", "-p", f"n_points:={N_POINTS}", "-p", "period_s:=0.05"])
    graph.start("recorder", ["recorder", "--ros-args", "-p", f"output:={output}", "-p", "discovery_period_s:=0.2",
                              "-p", "max_chunk_interval_s:=0.1"])  # chunks on disk every 0.1 s: the test reads them
    node = graph.node
    latched_pub = node.create_publisher(String, "/latched_note", qos.LATCHED)
    latched_pub.publish(String(data=LATCHED_TEXT))
    pose_pub = node.create_publisher(PoseStamped, "/pose", qos.EVENTS)
    graph.wait_for(
        lambda: pose_pub.get_subscription_count() and latched_pub.get_subscription_count() and
        _subscribed(node, "/cloud", "recorder"),
        timeout_s=20, what="the recorder to subscribe",
    )
    poses = []

    def publish_pose():
        if len(poses) < N_POSES:
            msg = PoseStamped()
            msg.header.frame_id = topics.WORLD_FRAME
            msg.header.stamp.sec = len(poses)
            msg.pose.position.x = float(len(poses))
            msg.pose.orientation.w = 1.0
            pose_pub.publish(msg)
            poses.append(serialize_message(msg))

    timer = node.create_timer(0.02, publish_pose)
    graph.wait_for(lambda: len(poses) == N_POSES, timeout_s=20, what="the poses to be sent")
    node.destroy_timer(timer)
    def recorded():
        n = _on_disk(output)
        return n.get("/pose") == N_POSES and n.get("/latched_note") == 1 and n.get("/cloud", 0) >= 5

    graph.wait_for(recorded, timeout_s=20, what="every pose, the latched note and five clouds in the file")
    assert graph.procs["recorder"].stop() == 0, graph.logs()
    return {"/pose": poses, "/latched_note": [serialize_message(String(data=LATCHED_TEXT))]}


def test_recording_opens_in_rosbags(ros_graph, tmp_path):
    path = tmp_path / "run.mcap"
    sent = record_short_graph(ros_graph, path)

    by_topic: dict = {}
    with Reader(path) as reader:
        conns = {c.topic: c for c in reader.connections}
        assert {"/cloud", "/pose", "/latched_note"} <= set(conns)
        for conn in reader.connections:  # the schema text is what rosbags itself knows the type as
            parsed = get_types_from_msg(conn.msgdef.data, conn.msgtype)
            assert conn.msgdef.format.name == "MSG"
            assert all(parsed[n] == TYPESTORE.fielddefs[n] for n in parsed), conn.topic
        for conn, _, data in reader.messages():
            TYPESTORE.deserialize_cdr(data, conn.msgtype)  # every message deserialises
            by_topic.setdefault(conn.topic, []).append(bytes(data))
        latched_offers = conns["/latched_note"].ext.offered_qos_profiles
        total = reader.message_count

    pose_t = "geometry_msgs/msg/PoseStamped"
    assert [decode(d, pose_t) for d in by_topic["/pose"]] == [decode(d, pose_t) for d in sent["/pose"]]
    xs = [decode(d, pose_t).pose.position.x for d in by_topic["/pose"]]
    assert xs == [float(i) for i in range(N_POSES)], "every pose, in order"
    assert [decode(d, "std_msgs/msg/String").data for d in by_topic["/latched_note"]] == [LATCHED_TEXT]
    assert [o.durability.name for o in latched_offers] == ["TRANSIENT_LOCAL"]
    assert len(by_topic["/cloud"]) >= 5
    assert all(cloud_key(d) == talker_cloud_key() for d in by_topic["/cloud"])

    with open(path, "rb") as fh:
        mreader = make_reader(fh)
        summary = mreader.get_summary()
        for channel in summary.channels.values():
            type_name = summary.schemas[channel.schema_id].name
            assert channel.metadata["topic_type_hash"] == TYPESTORE.hash_rihs01(type_name), channel.topic
            assert yaml.safe_load(channel.metadata["offered_qos_profiles"])  # a non-empty YAML list
        for _, _, message in mreader.iter_messages():
            assert message.publish_time <= message.log_time  # sent before received (one host clock)
        (meta,) = [m for m in mreader.iter_metadata() if m.name == "rosbag2"]
    info = yaml.safe_load(meta.metadata["serialized_metadata"])["rosbag2_bagfile_information"]
    assert info["message_count"] == total
    counts = {t["topic_metadata"]["name"]: t["message_count"] for t in info["topics_with_message_count"]}
    assert counts["/pose"] == N_POSES and counts["/cloud"] == len(by_topic["/cloud"])


def test_refuses_to_overwrite(ros_graph, tmp_path):
    path = tmp_path / "exists.mcap"
    path.write_bytes(b"old")
    proc = ros_graph.start("recorder", ["recorder", "--ros-args", "-p", f"output:={path}"])
    assert proc.popen.wait(30) == 2
    assert "refusing to overwrite" in proc.log() and "Traceback" not in proc.log()
    assert path.read_bytes() == b"old"


def test_sigkill_keeps_completed_chunks(ros_graph, tmp_path):
    path = tmp_path / "killed.mcap"
    ros_graph.start("talker", ["cloud_talker", "--ros-args", "-p", f"n_points:={N_POINTS}", "-p", "period_s:=0.02"])
    rec = ros_graph.start("recorder", [
        "recorder", "--ros-args", "-p", f"output:={path}", "-p", "topics:=['/cloud']",
        "-p", "chunk_size_bytes:=8000", "-p", "max_chunk_interval_s:=0.0", "-p", "discovery_period_s:=0.2",
    ])
    ros_graph.wait_for(lambda: path.exists() and path.stat().st_size > 8000, timeout_s=25, what="a few chunks")
    os.killpg(rec.popen.pid, signal.SIGKILL)
    assert rec.popen.wait(10) == -signal.SIGKILL
    rec.stop()  # closes its log
    del ros_graph.procs["recorder"]  # no longer a live node of the graph

    fixed = tmp_path / "recovered.mcap"
    n = recover(path, fixed)
    assert n >= 3
    with Reader(fixed) as reader:
        got = [(c.topic, cloud_key(d)) for c, _, d in reader.messages()]
    assert got == [("/cloud", talker_cloud_key())] * n


def test_sim_time_log_times_and_exclude(ros_graph, tmp_path):
    """With use_sim_time, log_time is the /clock time; excluded topics are not recorded; SIGTERM finalises."""
    from rosgraph_msgs.msg import Clock

    path = tmp_path / "sim.mcap"
    ros_graph.start("recorder", [
        "recorder", "--ros-args", "-p", f"output:={path}", "-p", "use_sim_time:=true",
        "-p", "exclude:=['/rosout', '/parameter_events']", "-p", "discovery_period_s:=0.2",
        "-p", "max_chunk_interval_s:=0.1",
    ])
    node = ros_graph.node
    clock_pub = node.create_publisher(Clock, topics.CLOCK, qos.CLOCK)
    note_pub = node.create_publisher(String, "/note", qos.EVENTS)
    sim = {"ticks": 0, "notes": 0, "notes_on": False}
    t0_ns = 1000 * 10**9
    tick_ns = 10**8

    def tick():  # /clock at 50 Hz advancing 0.1 s per tick; then ten notes
        msg = Clock(clock=time_from_ns(t0_ns + sim["ticks"] * tick_ns))
        clock_pub.publish(msg)
        sim["ticks"] += 1
        if sim["notes_on"] and sim["notes"] < 10:
            note_pub.publish(String(data=f"note {sim['notes']}"))
            sim["notes"] += 1

    node.create_timer(0.02, tick)
    # notes once the recorder listens to /note and has recorded /clock (its clock has ticked too)
    ros_graph.wait_for(lambda: note_pub.get_subscription_count() and _on_disk(path).get(topics.CLOCK), 30,
                       "the recorder on /note and /clock")
    sim["notes_on"] = True
    ros_graph.wait_for(lambda: _on_disk(path).get("/note") == 10, 30, "ten notes in the file")
    last_clock_ns = t0_ns + sim["ticks"] * tick_ns
    recorder = ros_graph.procs["recorder"]
    os.killpg(recorder.popen.pid, signal.SIGTERM)  # SIGTERM finalises the file too
    assert recorder.popen.wait(20) == 0, recorder.log()
    with Reader(path) as reader:
        names = {c.topic for c in reader.connections}
        notes = [(t, decode(d, "std_msgs/msg/String").data) for c, t, d in reader.messages() if c.topic == "/note"]
    assert "/rosout" not in names and "/parameter_events" not in names
    assert [text for _, text in notes] == [f"note {i}" for i in range(10)]
    assert all(t0_ns <= t <= last_clock_ns for t, _ in notes), "log_time is simulated time"
