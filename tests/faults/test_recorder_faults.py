"""Input the recorder cannot handle: one clear line, and nothing else lost.

Each test starts the recorder node on its own domain, gives it one kind of input
it cannot record (a type not installed where it runs, a topic whose type changes,
a message above ``max_message_bytes``, an output it cannot create, a file that
cannot grow mid-run) next to an ordinary stream, and checks with the independent
readers (``rosbags``, ``mcap``'s stream reader) that everything else is in the
file, and that the node said what it did in one line, without a traceback.
"""

from __future__ import annotations

import io
import os
import stat
import struct
import time
from pathlib import Path

import pytest
from mcap.exceptions import McapError
from mcap.records import Channel, Message
from mcap.stream_reader import StreamReader
from rclpy.qos import QoSProfile, ReliabilityPolicy
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore
from shape_msgs.msg import Plane
from std_msgs.msg import Int32, String, UInt8MultiArray

from tactile_bringup.mcap_recorder import recover
from tactile_common import qos

pytestmark = pytest.mark.graph

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
N_NOTES = 10


def _on_disk(path: Path) -> dict:
    """Messages per topic in the chunks written so far (the file may still be open or cut)."""
    counts: dict = {}
    topic_of: dict = {}
    if not path.exists():
        return counts
    try:
        for record in StreamReader(io.BytesIO(path.read_bytes()), skip_magic=False).records:
            if isinstance(record, Channel):
                topic_of[record.id] = record.topic
            elif isinstance(record, Message):
                counts[topic_of[record.channel_id]] = counts.get(topic_of[record.channel_id], 0) + 1
    except (McapError, EOFError, ValueError, struct.error):
        pass  # the record being written
    return counts


def _recorder(graph, output: Path, *params: str, wrap: str = ""):
    args = ["recorder", "--ros-args", "-p", f"output:={output}", "-p", "discovery_period_s:=0.2",
            "-p", "max_chunk_interval_s:=0.1", "-p", "exclude:=['/rosout', '/parameter_events']"]
    for p in params:
        args += ["-p", p]
    cmd = ["bash", "-c", f"{wrap}exec \"$@\"", "recorder", *args] if wrap else args
    return graph.start("recorder", cmd)


def _subscribed(graph, topic: str) -> bool:
    return any(i.node_name == "recorder" for i in graph.node.get_subscriptions_info_by_topic(topic))


def _messages(path: Path) -> dict:
    """Every message of the finalised recording, decoded by rosbags, by topic."""
    out: dict = {}
    with Reader(path) as reader:
        for conn, _, data in reader.messages():
            out.setdefault(conn.topic, []).append(TYPESTORE.deserialize_cdr(data, conn.msgtype))
    return out


def _lines(log: str, text: str) -> list[str]:
    return [line for line in log.splitlines() if text in line]


def _send_notes(graph, pub, path: Path, n: int = N_NOTES) -> None:
    """Publish n notes and wait until all are on disk."""
    for i in range(n):
        pub.publish(String(data=f"note {i}"))
    graph.wait_for(lambda: _on_disk(path).get("/note", 0) == n, 20, f"{n} notes in the file")


def _stop(graph) -> tuple[int, str]:
    rec = graph.procs["recorder"]
    code = rec.stop()
    return code, rec.log()


def test_a_type_not_installed_here_is_skipped_with_one_line(ros_graph, tmp_path):
    # shape_msgs is shadowed for the recorder only: a publisher with a type its Python cannot import
    shadow = tmp_path / "shadow" / "shape_msgs"
    shadow.mkdir(parents=True)
    (shadow / "__init__.py").write_text("raise ImportError('shape_msgs is not installed here (test shadow)')\n")
    path = tmp_path / "run.mcap"
    env_path = f"{shadow.parent}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"
    ros_graph.start("recorder", ["recorder", "--ros-args", "-p", f"output:={path}", "-p", "discovery_period_s:=0.2",
                                 "-p", "max_chunk_interval_s:=0.1"], env={"PYTHONPATH": env_path})
    plane_pub = ros_graph.node.create_publisher(Plane, "/plane", qos.EVENTS)
    note_pub = ros_graph.node.create_publisher(String, "/note", qos.EVENTS)
    ros_graph.wait_for(lambda: _subscribed(ros_graph, "/note") and
                       "not recording /plane" in ros_graph.procs["recorder"].log(), 30,
                       "the recorder on /note and its line about /plane")
    for _ in range(5):
        plane_pub.publish(Plane(coef=[0.0, 0.0, 1.0, 0.5]))
    _send_notes(ros_graph, note_pub, path)
    code, log = _stop(ros_graph)
    assert code == 0, log
    assert "Traceback" not in log
    assert len(_lines(log, "not recording /plane")) == 1, log  # once, not every discovery period
    assert "shape_msgs/msg/Plane' is not installed" in log
    got = _messages(path)
    assert "/plane" not in got
    assert [m.data for m in got["/note"]] == [f"note {i}" for i in range(N_NOTES)]


def test_a_topic_whose_type_changes_keeps_its_first_type_and_says_so(ros_graph, tmp_path):
    path = tmp_path / "run.mcap"
    _recorder(ros_graph, path)
    node = ros_graph.node
    first = node.create_publisher(String, "/changing", qos.EVENTS)
    note_pub = node.create_publisher(String, "/note", qos.EVENTS)
    ros_graph.wait_for(lambda: _subscribed(ros_graph, "/changing") and _subscribed(ros_graph, "/note"), 30,
                       "the recorder on /changing and /note")
    for i in range(3):
        first.publish(String(data=f"as string {i}"))
    ros_graph.wait_for(lambda: _on_disk(path).get("/changing", 0) == 3, 20, "the string messages in the file")
    node.destroy_publisher(first)
    second = node.create_publisher(Int32, "/changing", qos.EVENTS)  # the same topic, another type
    ros_graph.wait_for(lambda: "also published as std_msgs/msg/Int32" in ros_graph.procs["recorder"].log(), 30,
                       "the recorder's line about the new type")
    for i in range(3):
        second.publish(Int32(data=i))
    _send_notes(ros_graph, note_pub, path)
    ros_graph.observe(1.0, "further discovery periods (the line is not repeated)")
    code, log = _stop(ros_graph)
    assert code == 0 and "Traceback" not in log, log
    assert len(_lines(log, "also published as std_msgs/msg/Int32")) == 1, log
    got = _messages(path)
    assert [m.data for m in got["/changing"]] == [f"as string {i}" for i in range(3)]
    assert [m.data for m in got["/note"]] == [f"note {i}" for i in range(N_NOTES)]


def test_a_message_above_max_message_bytes_is_counted_the_rest_recorded(ros_graph, tmp_path):
    path = tmp_path / "run.mcap"
    cap = 3_000_000
    _recorder(ros_graph, path, f"max_message_bytes:={cap}")
    reliable = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
    blob_pub = ros_graph.node.create_publisher(UInt8MultiArray, "/blob", reliable)
    ros_graph.wait_for(lambda: _subscribed(ros_graph, "/blob"), 30, "the recorder on /blob")
    sizes = [10, 2_000_000, 5_000_000, 20, 6_000_000, 30]  # bytes of data; 5 and 6 MB exceed the cap
    for i, n in enumerate(sizes):
        blob_pub.publish(UInt8MultiArray(data=bytes([i % 256]) * n))
        if n < cap:  # in order: each recorded one is on disk before the next is sent (a 2 MB burst is slow)
            want = sum(1 for m in sizes[:i + 1] if m < cap)
            ros_graph.wait_for(lambda w=want: _on_disk(path).get("/blob", 0) == w, 60, f"{want} blobs in the file")
    code, log = _stop(ros_graph)
    assert code == 0 and "Traceback" not in log, log
    assert len(_lines(log, "larger than max_message_bytes")) == 1, log  # one line per topic
    assert "not recording a 4.8 MiB message of /blob" in log
    assert "oversized {'/blob': 2}" in log, log
    got = _messages(path)
    assert [(len(m.data), int(m.data[0])) for m in got["/blob"]] == [(10, 0), (2_000_000, 1), (20, 3), (30, 5)]


def _read_only_dir(tmp_path: Path) -> Path:
    """A directory the recorder cannot create files in (root ignores mode bits: then sysfs)."""
    ro = tmp_path / "read_only"
    ro.mkdir()
    ro.chmod(stat.S_IRUSR | stat.S_IXUSR | stat.S_IRGRP | stat.S_IXGRP | stat.S_IROTH | stat.S_IXOTH)
    for candidate in (ro, Path("/sys")):
        try:
            (candidate / ".probe").open("xb").close()
        except OSError:
            return candidate
        (candidate / ".probe").unlink()
    pytest.skip("no directory here refuses to create a file")


@pytest.mark.parametrize("where", ["parent is a file", "read-only directory", "missing directory"])
def test_an_output_it_cannot_create_is_one_fatal_line(ros_graph, tmp_path, where):
    if where == "parent is a file":
        (tmp_path / "a_file").write_text("not a folder")
        path, says = tmp_path / "a_file" / "run.mcap", "is not a directory"
    elif where == "read-only directory":
        path, says = _read_only_dir(tmp_path) / "run.mcap", "cannot create the recording"
    else:
        path, says = tmp_path / "nowhere" / "run.mcap", "does not exist"
    rec = _recorder(ros_graph, path)
    assert rec.popen.wait(30) == 2
    log = rec.log()
    assert "Traceback" not in log, log
    fatal = _lines(log, "FATAL")
    assert len(fatal) == 1 and says in fatal[0] and str(path.parent) in fatal[0], log
    assert not path.exists()


def test_a_file_that_cannot_grow_mid_run_stops_the_recorder_with_one_line(ros_graph, tmp_path):
    """Disk full, simulated by a file size limit (``ulimit -f``): writes past it fail with EFBIG."""
    path = tmp_path / "run.mcap"
    limit_kib = 64
    _recorder(ros_graph, path, "chunk_size_bytes:=4000", "compression:=none", "max_chunk_interval_s:=0.0",
              wrap=f"ulimit -f {limit_kib}; ")
    pub = ros_graph.node.create_publisher(String, "/note", qos.EVENTS)
    ros_graph.wait_for(lambda: _subscribed(ros_graph, "/note"), 30, "the recorder on /note")
    rec = ros_graph.procs["recorder"]
    sent = []

    def publish():
        if rec.alive() and len(sent) < 2000:
            sent.append(f"note {len(sent):04d} " + "x" * 200)
            pub.publish(String(data=sent[-1]))

    timer = ros_graph.node.create_timer(0.002, publish)
    end = time.monotonic() + 60
    while rec.alive() and time.monotonic() < end:  # the recorder's exit is the condition waited on
        ros_graph.spin_once(0.05)
    ros_graph.node.destroy_timer(timer)
    assert not rec.alive(), f"the recorder still runs after {len(sent)} notes past a {limit_kib} KiB limit"
    code, log = _stop(ros_graph)
    assert code == 1, log
    assert "Traceback" not in log, log
    errors = _lines(log, "ERROR")
    assert len(errors) == 1 and "cannot write" in errors[0] and "File too large" in errors[0], log
    assert "--recover" in errors[0]
    assert "not recorded:" in log
    assert path.stat().st_size <= limit_kib * 1024
    fixed = tmp_path / "recovered.mcap"
    n = recover(path, fixed)
    got = [m.data for m in _messages(fixed).get("/note", [])]
    assert n == len(got) and n >= 100, (n, log)  # ~60 KiB of 4 kB chunks of ~250-byte notes
    assert got == sent[:n], "the recording is the first notes sent, in order, none missing"
