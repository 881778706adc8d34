"""Replay a recording onto a fresh graph: every message in order, latched topics latched, /clock."""

from __future__ import annotations

import pytest
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import serialize_message
from rosbags.rosbag2 import Reader
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import PointCloud2
from geometry_msgs.msg import PoseStamped
from std_msgs.msg import String

from tactile_common import qos, topics
from tactile_common.stamps import stamp_ns
from tactile_common.testing import DomainLease, RosGraph

from test_recorder_graph import LATCHED_TEXT, N_POSES, cloud_key, decode, record_short_graph

pytestmark = pytest.mark.graph
POSE_T = "geometry_msgs/msg/PoseStamped"
# The recorded publishers were volatile, so the player's are too: a durable (qos.EVENTS) reader would not match.
VOLATILE = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)


@pytest.fixture
def fresh_graph(tmp_path):
    """A second graph on its own ROS_DOMAIN_ID (the recording's graph stays separate)."""
    lease = DomainLease()
    graph = RosGraph(lease.domain_id, tmp_path / "replay_logs")
    try:
        yield graph
    finally:
        print(f"replay graph ROS_DOMAIN_ID={lease.domain_id} exit codes: {graph.close()}")
        print(graph.logs())
        lease.release()


def test_replay_delivers_every_message_in_order(ros_graph, fresh_graph, tmp_path):
    path = tmp_path / "run.mcap"
    record_short_graph(ros_graph, path)
    ros_graph.stop_all()
    assert fresh_graph.domain_id != ros_graph.domain_id
    with Reader(path) as reader:
        recorded = {}
        for conn, t_ns, data in reader.messages():
            recorded.setdefault(conn.topic, []).append(bytes(data))
        start_ns, end_ns = reader.start_time, reader.end_time

    poses = fresh_graph.collect("/pose", PoseStamped, VOLATILE, raw=True)
    clouds = fresh_graph.collect("/cloud", PointCloud2, VOLATILE, raw=True)
    clocks = fresh_graph.collect(topics.CLOCK, Clock, qos.CLOCK)
    fresh_graph.start("player", [
        "player", "--ros-args", "-p", f"bag:={path}", "-p", "rate:=2.0", "-p", "clock:=true",
        "-p", "topics:=['/pose', '/cloud', '/latched_note']", "-p", "wait_for_subscribers_s:=10.0",
        "-p", "linger_s:=20.0",
    ])
    fresh_graph.wait_for(
        lambda: len(poses) == N_POSES and len(clouds) == len(recorded["/cloud"]),
        timeout_s=25, what="every recorded pose and cloud",
    )
    assert [decode(d, POSE_T) for d in poses] == [decode(d, POSE_T) for d in recorded["/pose"]]
    assert [cloud_key(d) for d in clouds] == [cloud_key(d) for d in recorded["/cloud"]]
    fresh_graph.wait_for(lambda: "done:" in fresh_graph.procs["player"].log(), 20, "the end of playback")

    # A subscriber that joins after playback still gets the latched message.
    late = fresh_graph.wait_for_message("/latched_note", String, qos.LATCHED, timeout_s=15)
    assert late.data == LATCHED_TEXT

    stamps = [stamp_ns(c.clock) for c in clocks]
    assert stamps and stamps == sorted(stamps)
    assert all(start_ns <= s <= end_ns for s in stamps)
    assert fresh_graph.stop_all() == {"player": 0}


def test_player_exits_when_done(fresh_graph, tmp_path):
    """A recording written by the core (no graph needed) plays out and the player exits 0."""
    from tactile_bringup.mcap_recorder import McapBagWriter, qos_profile_dict

    path = tmp_path / "small.mcap"
    writer = McapBagWriter(path)
    writer.add_topic("/note", "std_msgs/msg/String", [qos_profile_dict("keep_last", 10, "reliable", "volatile")])
    for i in range(10):
        writer.write("/note", serialize_message(String(data=f"n{i}")), 10**9 + i * 10**7)
    writer.close()
    notes = fresh_graph.collect("/note", String, VOLATILE)
    proc = fresh_graph.start("player", ["player", "--ros-args", "-p", f"bag:={path}", "-p", "wait_for_subscribers_s:=10.0"])
    assert proc.popen.wait(30) == 0, proc.log()
    proc.stop()  # closes its log
    del fresh_graph.procs["player"]  # exited; its messages were acknowledged before it did
    fresh_graph.wait_for(lambda: len(notes) == 10, timeout_s=5, what="ten notes")
    assert [n.data for n in notes] == [f"n{i}" for i in range(10)]
    assert "done: 10 messages played" in proc.log()


def test_bad_bag_is_a_clear_error(fresh_graph, tmp_path):
    (tmp_path / "junk.mcap").write_bytes(b"not an mcap file")
    for name, bag in (("missing", tmp_path / "nope.mcap"), ("junk", tmp_path / "junk.mcap")):
        proc = fresh_graph.start(name, ["player", "--ros-args", "-p", f"bag:={bag}"])
        assert proc.popen.wait(30) == 2
        assert str(bag) in proc.log() and "Traceback" not in proc.log()
